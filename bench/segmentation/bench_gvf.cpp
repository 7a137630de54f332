// GVF on one 512² phantom slice: organsmith's explicit scheme (single thread and TBB rows) and
// multigrid, against itk::GradientVectorFlowImageFilter with the same edge map, μ, time step
// and iteration count. Prints times, the speed-up and the agreement of the fields.

#include "core/progress.h"
#include "pipeline/phantom/phantom.h"
#include "segmentation/edge_map.h"
#include "segmentation/gvf.h"
#include "segmentation/gvf_itk_reference.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>

using namespace organsmith;
using namespace organsmith::seg;
using Clock = std::chrono::steady_clock;

template <typename F>
double best_of(int reps, F&& f) {
  double best = 1e300;
  for (int r = 0; r < reps; ++r) {
    const auto t0 = Clock::now();
    f();
    best = std::min(best, std::chrono::duration<double>(Clock::now() - t0).count());
  }
  return best;
}

int main() {
  NullProgress np;
  PhantomOptions po;
  po.slice_mm = 5.0;  // only one slice is used
  const Phantom ph = synthesize_phantom(po, np);
  // The slice through the gallbladder seed.
  const Eigen::Vector3d ijk = ph.ct.grid.lps_mm_to_index(ph.seeds_lps_mm.at("gallbladder"));
  const std::int64_t k = std::llround(ijk.z());
  const int w = int(ph.ct.grid.size_vox[0]), h = int(ph.ct.grid.size_vox[1]);
  const Image2f f = edge_map(ph.ct.slice(k), w, h, ph.ct.grid.spacing_mm.x(), ph.ct.grid.spacing_mm.y(), {});
  Image2f fx, fy;
  edge_gradient(f, fx, fy);
  const double mu = 0.2;
  const int iterations = 40;
  Image2f iu(w, h), iv(w, h);
  double itk_dt = 0;
  const double t_itk = best_of(2, [&] {
    itk_dt = gvf_itk_reference(fx.px.data(), fy.px.data(), w, h, mu, iterations, iu.px.data(), iv.px.data());
  });
  GvfOptions o;
  o.mu = mu;
  o.iterations = iterations;
  o.time_step = itk_dt;
  GvfField g;
  GvfWorkspace ws;
  o.parallel = false;
  const double t_one = best_of(10, [&] { gvf_jacobi(f, o, g, ws); });
  double diff = 0, scale = 0;
  for (std::size_t i = 0; i < iu.px.size(); ++i) {
    diff = std::max({diff, double(std::abs(g.u.px[i] - iu.px[i])), double(std::abs(g.v.px[i] - iv.px[i]))});
    scale = std::max({scale, double(std::abs(iu.px[i])), double(std::abs(iv.px[i]))});
  }
  o.parallel = true;
  const double t_par = best_of(10, [&] { gvf_jacobi(f, o, g, ws); });
  int cycles = 0;
  const double t_mg = best_of(3, [&] { gvf_multigrid(f, {}, &cycles); });
  std::printf("GVF on a %d×%d phantom slice, μ = %.2f, Δt = %.4f (ITK's 1/(4μ)), %d iterations\n", w, h, mu, itk_dt,
              iterations);
  std::printf("  itk::GradientVectorFlowImageFilter   %8.2f ms  (%.2f ms/iteration)\n", 1e3 * t_itk,
              1e3 * t_itk / iterations);
  std::printf("  gvf_jacobi, 1 thread                 %8.2f ms  (%.3f ms/iteration)  speed-up %.1f×\n", 1e3 * t_one,
              1e3 * t_one / iterations, t_itk / t_one);
  std::printf("  gvf_jacobi, TBB rows                 %8.2f ms  speed-up %.1f×\n", 1e3 * t_par, t_itk / t_par);
  std::printf("  max |field difference| / max |field| = %.2e (target ≤ 1e-3)\n", diff / scale);
  std::printf("  gvf_multigrid to steady state (tol 1e-5): %.2f ms, %d V-cycles\n", 1e3 * t_mg, cycles);
  const bool ok = t_itk / t_one >= 30.0 && diff / scale <= 1e-3;
  std::printf("%s: single-thread speed-up %s 30× and agreement %s 1e-3\n", ok ? "PASS" : "FAIL",
              t_itk / t_one >= 30 ? "≥" : "<", diff / scale <= 1e-3 ? "≤" : ">");
  return ok ? 0 : 1;
}
