// How often does a τ_D fit land within 2 % of the truth when the mass data carry 2 % weighing
// noise? Issue 8 asks that model curves with τ_D = 241.41 and 245.31, sampled at the thesis's
// days and with 2 % noise, fit back within 2 %. Whether that can hold for every noise draw is a
// property of the sampling design, not of the fitting code: this driver measures it. For each τ_D
// and sampling design it draws N noise realisations (2 % multiplicative Gaussian, seeds 1..N),
// fits each with `fit_tau_d` exactly as `organsmith degrade --fit` does, and prints the fraction
// of fits within 2 %, the spread of the error, and the linearised (Cramér–Rao) standard deviation
// of τ_D from finite-difference sensitivities for comparison.
//
//   tau_roundtrip_study [N=40]
//
// A statistical study, not a speed benchmark: it is not in `make bench`. N = 40 takes a few
// minutes on two cores (every fit runs ~30 degradation simulations of a 60-element clip).

#include "physics/materials/calibration.h"
#include "physics/degradation/clip.h"
#include "physics/degradation/degradation.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

using namespace organsmith::physics;

namespace {

struct Design {
  const char* name;
  std::vector<double> days;
};

}  // namespace

int main(int argc, char** argv) {
  const int n = argc > 1 ? std::max(1, std::atoi(argv[1])) : 40;
  const ClipModel m(builtin_clip_preset(), 60);  // the round-trip test's clip
  const std::vector<Design> designs{{"days 1,3,7,14,28", {1, 3, 7, 14, 28}},
                                    {"every 3.5 days", {3.5, 7, 10.5, 14, 17.5, 21, 24.5, 28}},
                                    {"both schedules together", {1, 3, 3.5, 7, 10.5, 14, 17.5, 21, 24.5, 28}}};
  std::printf("τ_D round trip with 2 %% multiplicative weighing noise, %d draws per row (60-element clip, 5 N)\n", n);
  std::printf("%-8s %-26s %9s %9s %9s %9s %12s\n", "tau_D", "sampling", "within2%", "median|e|", "p90|e|",
              "max|e|", "CR sd(e)");
  for (double tau : {241.41, 245.31}) {
    for (const Design& d : designs) {
      DegradationOptions o;
      o.tau_d = tau;
      const std::vector<double> clean = model_mass_at(m, o, d.days);
      // Linearised spread: sd(ln τ̂) = σ / sqrt(Σ (∂ln m_i/∂ln τ)²), central differences at ±2 %.
      DegradationOptions lo = o, hi = o;
      lo.tau_d = tau / 1.02;
      hi.tau_d = tau * 1.02;
      const auto ml = model_mass_at(m, lo, d.days), mh = model_mass_at(m, hi, d.days);
      double info = 0;
      for (std::size_t i = 0; i < d.days.size(); ++i) {
        const double s = (std::log(mh[i]) - std::log(ml[i])) / (2 * std::log(1.02));
        info += s * s;
      }
      const double cr_sd = 0.02 / std::sqrt(info);

      std::vector<double> err(static_cast<std::size_t>(n));
      tbb::parallel_for(0, n, [&](int k) {
        Rng rng(static_cast<std::uint64_t>(k + 1));
        MassSeries s;
        s.t_days = d.days;
        s.mass_fraction = clean;
        for (double& v : s.mass_fraction) v *= 1 + 0.02 * rng.normal();
        err[static_cast<std::size_t>(k)] = std::abs(fit_tau_d(m, o, s).tau_d / tau - 1);
      });
      std::sort(err.begin(), err.end());
      const auto within = std::count_if(err.begin(), err.end(), [](double e) { return e <= 0.02; });
      std::printf("%-8.2f %-26s %8.0f%% %8.2f%% %8.2f%% %8.2f%% %11.2f%%\n", tau, d.name, 100.0 * double(within) / n,
                  100 * err[err.size() / 2], 100 * err[std::min(err.size() - 1, err.size() * 9 / 10)],
                  100 * err.back(), 100 * cr_sd);
      std::fflush(stdout);
    }
  }
  return 0;
}
