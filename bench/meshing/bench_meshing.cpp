// Meshing both phantom organs from the ground-truth label map (issue: meshing).
// Targets: surfaces + remeshing ≤ 3 s; tetrahedra ≤ 10 s; peak memory ≤ 2 GB. The floor is
// vtkFlyingEdges3D on the same masks (a raw iso-surface, none of the guarantees), timed in the
// same run. Usage: bench_meshing [slice_mm] (default 2.5, the default case's phantom).

#include "core/memory.h"
#include "core/progress.h"
#include "meshing/mesh.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/phantom/phantom.h"

#include <vtkFlyingEdges3D.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPolyData.h>
#include <vtkUnsignedCharArray.h>
#include <vtkPointData.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

using namespace organsmith;
using Clock = std::chrono::steady_clock;

namespace {

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }


/// Flying edges on the 0/1 mask of `label` (grid frame; the floor does not need LPS).
double flying_edges_seconds(const LabelMap& lm, std::uint8_t label, std::size_t& triangles) {
  const auto n = lm.grid.size_vox;
  vtkNew<vtkImageData> img;
  img->SetDimensions(int(n[0]), int(n[1]), int(n[2]));
  img->SetSpacing(lm.grid.spacing_mm.x(), lm.grid.spacing_mm.y(), lm.grid.spacing_mm.z());
  vtkNew<vtkUnsignedCharArray> a;
  a->SetNumberOfTuples(vtkIdType(lm.labels.size()));
  for (std::size_t i = 0; i < lm.labels.size(); ++i) a->SetValue(vtkIdType(i), lm.labels[i] == label ? 1 : 0);
  img->GetPointData()->SetScalars(a);
  const auto t0 = Clock::now();
  vtkNew<vtkFlyingEdges3D> fe;
  fe->SetInputData(img);
  fe->SetValue(0, 0.5);
  fe->ComputeNormalsOff();
  fe->ComputeGradientsOff();
  fe->Update();
  const double s = since(t0);
  triangles = std::size_t(fe->GetOutput()->GetNumberOfCells());
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  NullProgress np;
  PhantomOptions po;
  if (argc > 1) po.slice_mm = std::atof(argv[1]);
  const Phantom ph = synthesize_phantom(po, np);
  const auto& s = ph.truth.grid.size_vox;
  std::printf("phantom ground truth %lld×%lld×%lld, %.2f mm slices\n", (long long)s[0], (long long)s[1],
              (long long)s[2], po.slice_mm);

  std::size_t fe_tris = 0, t1 = 0, t2 = 0;
  const double fe = flying_edges_seconds(ph.truth, 1, t1) + flying_edges_seconds(ph.truth, 2, t2);
  fe_tris = t1 + t2;

  const OrganRegistry& registry = builtin_organ_registry();
  MeshOptions surf;
  surf.organs = {mesh_spec(registry.at("gallbladder")), mesh_spec(registry.at("trachea"))};
  surf.tetrahedra = false;
  surf.enforce_quality = false;  // the figures are reported; this measures time
  const bool can_reset = organsmith::reset_peak_rss();
  auto t0 = Clock::now();
  const OrganMeshes a = mesh_organs(ph.truth, surf, np);
  const double surface_s = since(t0);
  const double surface_peak = organsmith::peak_rss_mib();
  std::size_t tris = 0;
  for (const auto& o : a.organs)
    for (const auto& m : o.surfaces) tris += m.mesh.triangles.size();
  // The timeline of the surfaces run: which step of which organ ran when (seconds since the
  // start of mesh_organs; the steps of an organ's two branches overlap).
  std::printf("timeline (surfaces run)  start    end   wall\n");
  for (const auto& o : a.organs) {
    auto steps = o.steps;
    std::stable_sort(steps.begin(), steps.end(), [](const auto& x, const auto& y) { return x.start_s < y.start_s; });
    for (const auto& st : steps)
      std::printf("  %-11s %-34s %5.2f  %5.2f  %5.2f\n", o.spec.name.c_str(), st.step.c_str(), st.start_s, st.end_s,
                  st.end_s - st.start_s);
  }
  for (const auto& o : a.organs)
    for (const auto& m : o.surfaces) {
      const auto& q = m.quality;
      std::printf("  %-24s %6lld triangles, %5.1f %% edges ±25 %%, min angle %5.2f°, volume error %+.2f %%, HD95 %.3f mm%s\n",
                  m.name.c_str(), (long long)q.triangles, 100 * q.edge_within_tolerance, q.angle_min_deg,
                  100 * q.volume_error, q.hd95_mm, q.ok() ? "" : " FAILS");
    }

  MeshOptions full;
  full.organs = surf.organs;
  full.enforce_quality = false;
  organsmith::reset_peak_rss();
  t0 = Clock::now();
  const OrganMeshes b = mesh_organs(ph.truth, full, np);
  const double full_s = since(t0);
  const double full_peak = organsmith::peak_rss_mib();
  std::size_t tets = 0;
  double tets_s = 0;
  for (const auto& o : b.organs) {
    tets += o.volume.tets.size();
    tets_s = std::max(tets_s, o.seconds_tets);  // organs run side by side
  }

  std::printf("flying edges (floor)   %7.2f s  %8zu triangles (raw, both masks)\n", fe, fe_tris);
  std::printf("surfaces + remeshing   %7.2f s  %8zu triangles (all surfaces, walls included)  %.1f× the floor\n",
              surface_s, tris, surface_s / fe);
  std::printf("surfaces + tetrahedra  %7.2f s  %8zu tetrahedra; tetrahedra alone (slower organ) %.2f s\n", full_s, tets,
              tets_s);
  std::printf("peak memory            %7.0f MiB surfaces, %.0f MiB with tetrahedra%s\n", surface_peak, full_peak,
              can_reset ? "" : " (process peak: VmHWM could not be reset)");
  const bool ok_surface = surface_s <= 3.0, ok_tets = tets_s <= 10.0, ok_mem = full_peak <= 2048.0;
  std::printf("%s surfaces ≤ 3 s; %s tetrahedra ≤ 10 s; %s peak ≤ 2 GB\n", ok_surface ? "PASS" : "FAIL",
              ok_tets ? "PASS" : "FAIL", ok_mem ? "PASS" : "FAIL");
  return ok_surface && ok_tets && ok_mem ? 0 : 1;
}
