// Physics benchmarks (issue 5):
//  * one GA fit, population 200 × 200 generations, 60 points (fung-wall, Table 5.1.1 means, both
//    uniaxial directions, 2 % noise) — target ≤ 50 ms; against a multi-start Levenberg–Marquardt
//    baseline on the same data (time and final SSE);
//  * Monte Carlo, 10 000 draws × 7 stretches (artery-logpoly, Table 4.1.4 with IMVFOSM σ's) —
//    target ≤ 20 ms.
// The summary lines are printed after the Google Benchmark table.

#include "physics/materials/calibration.h"
#include "physics/materials/presets.h"
#include "physics/materials/uncertainty.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <vector>

using namespace organsmith::physics;

namespace {

CalibrationData fung_data(const Model& m, const std::vector<double>& p) {
  CalibrationData d;
  Rng rng(2024);
  for (LoadCase l : {LoadCase::uniaxial_circumferential, LoadCase::uniaxial_longitudinal})
    for (int i = 1; i <= 30; ++i) {
      d.points.push_back({1.0 + 0.3 * i / 30.0, 1.0, l});
      d.specimen.push_back("");
    }
  d.measured.resize(d.points.size());
  m.respond(d.points, p, d.measured);
  for (double& y : d.measured) y *= 1.0 + 0.02 * rng.normal();
  return d;
}

struct Setup {
  std::unique_ptr<Model> fung = make_model("fung-wall");
  std::unique_ptr<Model> artery = make_model("artery-logpoly");
  std::vector<double> fung_p, artery_mean, artery_sd;
  CalibrationData data;
  std::vector<LoadPoint> stages;
  Setup() {
    const auto lib = builtin_material_library();
    fung_p = parameter_values(*fung, lib.find("fung-wall/table-5.1.1/mean").material.parameters);
    const auto& a = lib.find("artery-logpoly/table-4.1.4/circumferential");
    artery_mean = parameter_values(*artery, a.material.parameters);
    artery_sd = parameter_values(*artery, a.spreads.at("imvfosm_sd"));
    data = fung_data(*fung, fung_p);
    for (double s : lib.table("table-4.1.2").stretch) stages.push_back({s, 1.0, LoadCase::uniaxial_circumferential});
  }
};

Setup& setup() {
  static Setup s;
  return s;
}

void BM_GaFit(benchmark::State& state) {
  auto& s = setup();
  FitOptions o;
  o.ga.population = 200;
  o.ga.generations = 200;
  o.ga.parallel = state.range(0) != 0;
  double sse = 0;
  for (auto _ : state) {
    const FitResult r = calibrate(*s.fung, s.data, o);
    sse = r.stats.sse;
    benchmark::DoNotOptimize(sse);
  }
}
BENCHMARK(BM_GaFit)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->ArgName("parallel");

void BM_MultistartLm(benchmark::State& state) {
  auto& s = setup();
  std::vector<double> lo, hi;
  double sse = 0;
  for (auto _ : state) {
    const FitResult r = multistart_least_squares(*s.fung, s.data, static_cast<int>(state.range(0)), 7, lo, hi);
    sse = r.stats.sse;
    benchmark::DoNotOptimize(sse);
  }
}
BENCHMARK(BM_MultistartLm)->Arg(10)->Arg(50)->Unit(benchmark::kMillisecond)->ArgName("starts");

void BM_MonteCarlo(benchmark::State& state) {
  auto& s = setup();
  MonteCarloOptions o;
  o.samples = 10000;
  for (auto _ : state) {
    const auto mc = monte_carlo(*s.artery, s.stages, s.artery_mean, s.artery_sd, o);
    benchmark::DoNotOptimize(mc.moments.mean_Pa.data());
  }
}
BENCHMARK(BM_MonteCarlo)->Unit(benchmark::kMillisecond);

// Wall times of `reps` runs: {min, median}, plus the median CPU time of the calling thread (the
// machine is shared; the minimum and the thread CPU time are the figures least disturbed by other
// processes, the median is what a user would see on a busy machine).
struct Timing {
  double min_ms, median_ms, cpu_ms;
};

double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

template <class F>
Timing time_it(int reps, F&& f) {
  std::vector<double> wall, cpu;
  for (int i = 0; i < reps; ++i) {
    const double c0 = thread_cpu_ms();
    const auto t0 = std::chrono::steady_clock::now();
    f();
    wall.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    cpu.push_back(thread_cpu_ms() - c0);
  }
  std::sort(wall.begin(), wall.end());
  std::sort(cpu.begin(), cpu.end());
  return {wall.front(), wall[wall.size() / 2], cpu[cpu.size() / 2]};
}

void summary() {
  auto& s = setup();
  FitOptions o;
  o.ga.parallel = false;
  FitResult ga;
  const Timing serial = time_it(15, [&] { ga = calibrate(*s.fung, s.data, o); });
  o.ga.parallel = true;
  const Timing par = time_it(15, [&] { calibrate(*s.fung, s.data, o); });
  std::vector<double> lo, hi;
  std::vector<double> pred(s.data.points.size());
  s.fung->respond(s.data.points, s.fung_p, pred);
  const double sse_true = fit_statistics(s.data.measured, pred).sse;
  std::printf("\nSummary: 60 points, fung-wall Table 5.1.1 means, 2 %% noise. Wall min / median, thread CPU median.\n");
  std::printf("  GA 200 x 200 + LM, serial         : %6.2f / %6.2f ms, CPU %6.2f ms  SSE %.2f Pa^2 R2 %.5f  (target <= 50 ms: %s)\n",
              serial.min_ms, serial.median_ms, serial.cpu_ms, ga.stats.sse, ga.stats.r2,
              serial.median_ms <= 50 ? "met" : (serial.min_ms <= 50 ? "met on min, not on median" : "MISSED"));
  std::printf("  GA 200 x 200 + LM, parallel option: %6.2f / %6.2f ms\n", par.min_ms, par.median_ms);
  std::printf("  SSE at the generating parameters  : %.2f Pa^2\n", sse_true);
  for (int starts : {5, 10, 20, 50, 100}) {
    FitResult r;
    const Timing t = time_it(7, [&] { r = multistart_least_squares(*s.fung, s.data, starts, 7, lo, hi); });
    std::printf("  multi-start LM, %3d starts        : %6.2f / %6.2f ms, CPU %6.2f ms  SSE %.2f Pa^2\n", starts, t.min_ms,
                t.median_ms, t.cpu_ms, r.stats.sse);
  }
  MonteCarloOptions mo;
  const Timing mc = time_it(21, [&] { monte_carlo(*s.artery, s.stages, s.artery_mean, s.artery_sd, mo); });
  std::printf("  Monte Carlo 10 000 x 7 stretches  : %6.2f / %6.2f ms, CPU %6.2f ms  (target <= 20 ms: %s)\n", mc.min_ms,
              mc.median_ms, mc.cpu_ms, mc.median_ms <= 20 ? "met" : "MISSED");
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  summary();
  benchmark::Shutdown();
  return 0;
}
