// Over 400 lines: the genetic algorithm, the Levenberg–Marquardt polish and the calibration CSV
// reader (with its line and column errors) of one calibration.
#include "physics/materials/calibration.h"
#include "core/csv.h"
#include "core/file_io.h"
#include "core/format.h"

#include <Eigen/Dense>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <sstream>

namespace organsmith::physics {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::string where(const std::filesystem::path& source, std::size_t line, const std::string& column) {
  return source.string() + ":" + std::to_string(line) + ", column '" + column + "'";
}

std::string fmt(double v) { return format_g(v, 10); }

}  // namespace

// ---- CSV -----------------------------------------------------------------------------------------

CalibrationData parse_calibration_csv(const std::string& text, const std::filesystem::path& source,
                                      bool displacement, std::size_t min_points) {
  CalibrationData d;
  d.source = source;
  std::vector<CsvRow> rows = parse_csv_rows(text, source, ExitCode::calibration_data);
  if (rows.empty())
    throw CalibrationDataError("the file has no header line", source,
                               displacement ? "expected columns displacement_m,force_n"
                                            : "expected columns stretch,stress_pa[,direction,specimen]");
  lowercase_fields(rows.front());
  const std::vector<std::string>& header = rows.front().fields;
  auto column = [&](std::string_view name) -> int {
    for (std::size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return static_cast<int>(i);
    return -1;
  };
  int cx = -1, cy = -1;
  bool strain = false;
  std::string x_name, y_name;
  if (displacement) {
    cx = column("displacement_m"), cy = column("force_n");
    x_name = "displacement_m", y_name = "force_n";
  } else {
    cx = column("stretch");
    x_name = "stretch";
    if (cx < 0) {
      cx = column("strain");
      strain = cx >= 0;
      x_name = "strain";
    }
    cy = column("stress_pa");
    y_name = "stress_pa";
  }
  if (cx < 0 || cy < 0)
    throw CalibrationDataError(
        "missing column '" + std::string(cx < 0 ? x_name : y_name) + "' in the header", source,
        displacement ? "a cutting test needs displacement_m and force_n"
                     : "a stress test needs stretch (or strain) and stress_pa");
  const int cdir = displacement ? -1 : column("direction");
  const int cspec = column("specimen");
  const int clat = displacement ? -1 : column("lateral_stretch");

  std::size_t line_no = 0;
  auto number = [&](const std::vector<std::string>& f, int col, const std::string& name) {
    const std::string& s = f[static_cast<std::size_t>(col)];
    const std::optional<double> parsed = csv_number(s);
    if (!parsed)
      throw CalibrationDataError(where(source, line_no, name) + ": '" + s + "' is not a number",
                                 source, "every data cell must be a plain decimal number");
    const double v = *parsed;
    if (!std::isfinite(v))
      throw CalibrationDataError(where(source, line_no, name) + ": '" + s + "' is not finite",
                                 source, "remove or repair rows with NaN or infinite values");
    return v;
  };

  // Last x per (specimen, direction) for the monotonicity check.
  std::map<std::pair<std::string, int>, std::pair<double, std::size_t>> last;
  for (std::size_t r = 1; r < rows.size(); ++r) {
    line_no = static_cast<std::size_t>(rows[r].line);
    const std::vector<std::string>& f = rows[r].fields;
    if (f.size() != header.size())
      throw CalibrationDataError(source.string() + ":" + std::to_string(line_no) + ": " +
                                     std::to_string(f.size()) + " fields, the header has " +
                                     std::to_string(header.size()),
                                 source, "check for missing or extra commas");
    LoadPoint p;
    double x = number(f, cx, x_name);
    const double y = number(f, cy, y_name);
    if (strain) x += 1.0;
    if (displacement) {
      p.load = LoadCase::displacement;
      if (x < 0)
        throw CalibrationDataError(where(source, line_no, x_name) + ": displacement " + fmt(x) +
                                       " m is negative", source, "displacements are measured from first contact");
    } else {
      if (!(x > 0))
        throw CalibrationDataError(where(source, line_no, x_name) + ": stretch " + fmt(x) +
                                       " is not positive", source,
                                   "stretch is current/original length (strain = stretch − 1)");
      std::string dir = cdir >= 0 ? f[static_cast<std::size_t>(cdir)] : "circumferential";
      for (char& ch : dir) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
      bool circ;
      if (dir == "circumferential" || dir == "circ" || dir.empty()) circ = true;
      else if (dir == "longitudinal" || dir == "long" || dir == "axial") circ = false;
      else
        throw CalibrationDataError(where(source, line_no, "direction") + ": '" + dir +
                                       "' is not a direction", source,
                                   "use circumferential or longitudinal");
      if (clat >= 0 && !f[static_cast<std::size_t>(clat)].empty()) {
        p.lateral_stretch = number(f, clat, "lateral_stretch");
        if (!(p.lateral_stretch > 0))
          throw CalibrationDataError(where(source, line_no, "lateral_stretch") +
                                         ": stretch is not positive", source);
        p.load = circ ? LoadCase::biaxial_circumferential : LoadCase::biaxial_longitudinal;
      } else {
        p.load = circ ? LoadCase::uniaxial_circumferential : LoadCase::uniaxial_longitudinal;
      }
    }
    p.x = x;
    const std::string spec = cspec >= 0 ? f[static_cast<std::size_t>(cspec)] : std::string();
    // Biaxial protocols may hold one stretch while the other moves, so only uniaxial and cutting
    // curves are required to be monotone.
    if (p.load != LoadCase::biaxial_circumferential && p.load != LoadCase::biaxial_longitudinal) {
      const auto key = std::make_pair(spec, static_cast<int>(p.load));
      const auto it = last.find(key);
      if (it != last.end() && !(x > it->second.first))
        throw CalibrationDataError(
            where(source, line_no, x_name) + ": " + x_name + " " + fmt(strain ? x - 1 : x) +
                " does not increase (line " + std::to_string(it->second.second) + " has " +
                fmt(strain ? it->second.first - 1 : it->second.first) + ")" +
                (spec.empty() ? std::string() : " within specimen '" + spec + "'"),
            source,
            "each specimen's loading curve must be strictly increasing; give unloading or repeated "
            "cycles their own specimen label");
      last[key] = {x, line_no};
    }
    d.points.push_back(p);
    d.measured.push_back(y);
    d.specimen.push_back(spec);
  }
  if (d.points.size() < min_points)
    throw CalibrationDataError("only " + std::to_string(d.points.size()) +
                                   " data rows; at least " + std::to_string(min_points) +
                                   " are needed", source,
                               "a fit needs more points than the model has parameters");
  return d;
}

CalibrationData read_calibration_csv(const std::filesystem::path& path, bool displacement,
                                     std::size_t min_points) {
  // Tests of a tissue are hundreds to thousands of rows; a log or an image given by mistake is
  // refused by its size before it is read.
  const std::string text = read_input_file(path, "the calibration data", ExitCode::calibration_data,
                                           "give the CSV of the tests (stretch and stress per row) with --data");
  return parse_calibration_csv(text, path, displacement, min_points);
}

// ---- statistics ----------------------------------------------------------------------------------

FitStatistics fit_statistics(std::span<const double> measured, std::span<const double> predicted) {
  FitStatistics s;
  const std::size_t n = measured.size();
  if (n == 0) return s;
  double mean = 0;
  for (double y : measured) mean += y;
  mean /= static_cast<double>(n);
  double sst = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double r = predicted[i] - measured[i];
    s.sse += r * r;
    sst += (measured[i] - mean) * (measured[i] - mean);
  }
  if (!std::isfinite(s.sse)) s.sse = kInf;
  s.r2 = sst > 0 ? 1.0 - s.sse / sst : 0.0;
  s.rmse = std::sqrt(s.sse / static_cast<double>(n));
  return s;
}

void use_relative_residuals(CalibrationData& d, double floor_fraction) {
  double ymax = 0;
  for (double y : d.measured) ymax = std::max(ymax, std::abs(y));
  const double floor = std::max(floor_fraction * ymax, std::numeric_limits<double>::min());
  d.weight.clear();
  for (double y : d.measured) d.weight.push_back(1.0 / std::max(std::abs(y), floor));
}

// ---- random numbers ------------------------------------------------------------------------------

Rng::Rng(std::uint64_t seed) {
  std::uint64_t z = seed;
  for (auto& s : s_) {
    z += 0x9e3779b97f4a7c15ULL;
    std::uint64_t x = z;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    s = x ^ (x >> 31);
  }
}

std::uint64_t Rng::next() {
  auto rotl = [](std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); };
  const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
  const std::uint64_t t = s_[1] << 17;
  s_[2] ^= s_[0];
  s_[3] ^= s_[1];
  s_[1] ^= s_[2];
  s_[0] ^= s_[3];
  s_[2] ^= t;
  s_[3] = rotl(s_[3], 45);
  return result;
}

double Rng::uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

double Rng::normal() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  double u, v, s;
  do {
    u = 2 * uniform() - 1;
    v = 2 * uniform() - 1;
    s = u * u + v * v;
  } while (s >= 1 || s == 0);
  const double m = std::sqrt(-2 * std::log(s) / s);
  spare_ = v * m;
  has_spare_ = true;
  return u * m;
}

// ---- fitting -------------------------------------------------------------------------------------

void resolve_bounds(const Model& model, std::vector<double>& lo, std::vector<double>& hi) {
  const auto& info = model.parameters();
  if (lo.empty() && hi.empty()) {
    for (const auto& p : info) {
      lo.push_back(p.lower);
      hi.push_back(p.upper);
    }
    return;
  }
  if (lo.size() != info.size() || hi.size() != info.size())
    throw UsageError(std::string(model.name()) + " has " + std::to_string(info.size()) +
                         " parameters; the bounds give " + std::to_string(lo.size()) + " lower and " +
                         std::to_string(hi.size()) + " upper values",
                     "give one lower and one upper bound per parameter, in the model's order");
  for (std::size_t i = 0; i < info.size(); ++i) {
    if (!std::isfinite(lo[i]) || !std::isfinite(hi[i]))
      throw UsageError("bound of " + info[i].name + " is not finite");
    if (!(lo[i] < hi[i]))
      throw UsageError("inverted bounds for " + info[i].name + ": lower " + fmt(lo[i]) +
                           " is not below upper " + fmt(hi[i]) + " " + info[i].unit,
                       "swap them or widen the interval");
  }
}

namespace {

// SSE of parameters p on the data; +∞ when the model is undefined anywhere.
double sse_of(const Model& m, const CalibrationData& d, std::span<const double> p,
              std::vector<double>& scratch) {
  scratch.resize(d.points.size());
  m.respond(d.points, p, scratch);
  double s = 0;
  const bool w = !d.weight.empty();
  for (std::size_t i = 0; i < scratch.size(); ++i) {
    const double r = (scratch[i] - d.measured[i]) * (w ? d.weight[i] : 1.0);
    s += r * r;
  }
  return std::isfinite(s) ? s : kInf;
}

void check_inputs(const Model& m, const CalibrationData& d) {
  if (!d.weight.empty() && d.weight.size() != d.points.size())
    throw CalibrationDataError("weights and points differ in number", d.source);
  if (d.points.size() != d.measured.size())
    throw CalibrationDataError("points and measurements differ in number", d.source);
  if (d.points.size() < m.parameter_count() + 1)
    throw CalibrationDataError("only " + std::to_string(d.points.size()) + " points for " +
                                   std::to_string(m.parameter_count()) + " parameters of " +
                                   std::string(m.name()), d.source,
                               "a fit needs more points than parameters");
}

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Levenberg–Marquardt in box-scaled coordinates z = (p − lo)/(hi − lo), projected onto [0, 1].
// Marquardt's diagonal scaling keeps steps sensible when columns differ by orders of magnitude;
// a floor on the diagonal keeps the system solvable when a parameter is not identifiable.
int lm_run(const Model& m, const CalibrationData& d, std::vector<double>& p,
           const std::vector<double>& lo, const std::vector<double>& hi, const LmOptions& o,
           double& sse) {
  const std::size_t n = p.size(), N = d.points.size();
  Eigen::VectorXd scale(n);
  for (std::size_t j = 0; j < n; ++j) scale[j] = hi[j] - lo[j];
  std::vector<double> f(N), jac(N * n), trial(n), scratch;
  sse = sse_of(m, d, p, scratch);
  if (!std::isfinite(sse)) return 0;
  double mu = 1e-3;
  int it = 0;
  for (; it < o.max_iterations; ++it) {
    m.respond(d.points, p, f, jac);
    Eigen::MatrixXd J(N, n);
    Eigen::VectorXd r(N);
    for (std::size_t i = 0; i < N; ++i) {
      const double w = d.weight.empty() ? 1.0 : d.weight[i];
      r[i] = w * (f[i] - d.measured[i]);
      for (std::size_t j = 0; j < n; ++j) J(i, j) = w * jac[i * n + j] * scale[j];
    }
    if (!J.allFinite()) break;
    const Eigen::MatrixXd A = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * r;
    Eigen::VectorXd diag = A.diagonal();
    const double dmax = diag.maxCoeff();
    for (std::size_t j = 0; j < n; ++j) diag[j] = std::max(diag[j], 1e-12 * dmax + 1e-300);
    bool improved = false;
    for (int tries = 0; tries < 30; ++tries) {
      Eigen::MatrixXd Am = A;
      Am.diagonal() += mu * diag;
      const Eigen::VectorXd step = Am.ldlt().solve(-g);
      for (std::size_t j = 0; j < n; ++j) {
        const double z = std::clamp((p[j] - lo[j]) / scale[j] + step[j], 0.0, 1.0);
        trial[j] = lo[j] + z * scale[j];
      }
      const double s = sse_of(m, d, trial, scratch);
      if (s < sse) {
        const double gain = (sse - s) / std::max(sse, 1e-300);
        p = trial;
        sse = s;
        mu = std::max(mu / 3.0, 1e-15);
        improved = true;
        if (gain < o.relative_tolerance) return it + 1;
        break;
      }
      mu *= 4.0;
      if (mu > 1e16) break;
    }
    if (!improved) break;
  }
  return it;
}

}  // namespace

std::vector<double> standard_errors(const Model& m, const CalibrationData& d, std::span<const double> p) {
  const std::size_t n = p.size(), N = d.points.size();
  std::vector<double> f(N), jac(N * n);
  m.respond(d.points, p, f, jac);
  Eigen::MatrixXd J(N, n);
  double sse = 0;
  for (std::size_t i = 0; i < N; ++i) {
    sse += (f[i] - d.measured[i]) * (f[i] - d.measured[i]);
    for (std::size_t j = 0; j < n; ++j) J(i, j) = jac[i * n + j];
  }
  std::vector<double> se(n, kInf);
  if (N <= n || !J.allFinite()) return se;
  const double s2 = sse / static_cast<double>(N - n);
  // Columns scaled to unit norm so that the rank decision does not depend on parameter units.
  Eigen::VectorXd norm = J.colwise().norm().transpose();
  for (std::size_t j = 0; j < n; ++j)
    if (norm[j] > 0) J.col(j) /= norm[j];
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeThinV);
  const Eigen::VectorXd s = svd.singularValues();
  if (s[s.size() - 1] <= 1e-10 * s[0]) return se;   // a direction the data do not see
  const Eigen::MatrixXd V = svd.matrixV();
  for (std::size_t j = 0; j < n; ++j) {
    double v = 0;
    for (Eigen::Index k = 0; k < s.size(); ++k) v += std::pow(V(static_cast<Eigen::Index>(j), k) / s[k], 2);
    se[j] = norm[j] > 0 ? std::sqrt(s2 * v) / norm[j] : kInf;
  }
  return se;
}

FitResult least_squares(const Model& m, const CalibrationData& d, std::vector<double> start,
                        const std::vector<double>& lo_in, const std::vector<double>& hi_in,
                        const LmOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  check_inputs(m, d);
  std::vector<double> lo = lo_in, hi = hi_in;
  resolve_bounds(m, lo, hi);
  for (std::size_t j = 0; j < start.size(); ++j) start[j] = std::clamp(start[j], lo[j], hi[j]);
  FitResult r;
  double sse = 0;
  r.lm_iterations = lm_run(m, d, start, lo, hi, o, sse);
  r.parameters = start;
  r.lower = lo;
  r.upper = hi;
  r.predicted.resize(d.points.size());
  m.respond(d.points, r.parameters, r.predicted);
  r.stats = fit_statistics(d.measured, r.predicted);
  r.standard_errors = standard_errors(m, d, r.parameters);
  r.ga_sse = r.stats.sse;
  r.seconds = since(t0);
  return r;
}

FitResult multistart_least_squares(const Model& m, const CalibrationData& d, int starts,
                                   std::uint64_t seed, const std::vector<double>& lo_in,
                                   const std::vector<double>& hi_in, const LmOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<double> lo = lo_in, hi = hi_in;
  resolve_bounds(m, lo, hi);
  Rng rng(seed);
  FitResult best;
  best.stats.sse = kInf;
  for (int s = 0; s < starts; ++s) {
    std::vector<double> p(lo.size());
    for (std::size_t j = 0; j < p.size(); ++j) p[j] = lo[j] + rng.uniform() * (hi[j] - lo[j]);
    FitResult r = least_squares(m, d, p, lo, hi, o);
    if (r.stats.sse < best.stats.sse) best = std::move(r);
  }
  best.seed = seed;
  best.seconds = since(t0);
  return best;
}

FitResult calibrate(const Model& m, const CalibrationData& d, const FitOptions& o,
                    Progress* progress) {
  const auto t0 = std::chrono::steady_clock::now();
  check_inputs(m, d);
  std::vector<double> lo = o.lower, hi = o.upper;
  resolve_bounds(m, lo, hi);
  const GaOptions& ga = o.ga;
  if (ga.population < 4) throw UsageError("GA population must be at least 4");
  if (ga.generations < 1) throw UsageError("GA generations must be at least 1");
  if (!(ga.selection_fraction >= 0 && ga.selection_fraction < 1) ||
      !(ga.crossover_fraction >= 0 && ga.crossover_fraction <= 1))
    throw UsageError("GA selection and crossover fractions must lie in [0, 1)");

  const std::size_t n = lo.size();
  const int P = ga.population;
  Rng rng(ga.seed);
  // Individuals live in the unit box; row k of `pop` is individual k.
  std::vector<double> pop(static_cast<std::size_t>(P) * n), next(pop.size());
  std::vector<double> fitness(static_cast<std::size_t>(P));
  for (double& z : pop) z = rng.uniform();

  bool go_parallel = false;  // decided after timing the first generation (see below)
  auto evaluate = [&](const std::vector<double>& zs) {
    auto body = [&](int k, std::vector<double>& scratch, std::vector<double>& p) {
      for (std::size_t j = 0; j < n; ++j) p[j] = lo[j] + zs[k * n + j] * (hi[j] - lo[j]);
      fitness[static_cast<std::size_t>(k)] = sse_of(m, d, p, scratch);
    };
    if (go_parallel) {
      tbb::parallel_for(tbb::blocked_range<int>(0, P, 16), [&](const tbb::blocked_range<int>& r) {
        std::vector<double> scratch, p(n);
        for (int k = r.begin(); k < r.end(); ++k) body(k, scratch, p);
      });
    } else {
      std::vector<double> scratch, p(n);
      for (int k = 0; k < P; ++k) body(k, scratch, p);
    }
  };

  const int elite = std::max(1, static_cast<int>(std::lround(ga.selection_fraction * P)));
  const int children = P - elite;
  const int crossovers = static_cast<int>(std::lround(ga.crossover_fraction * children));
  std::vector<int> order(static_cast<std::size_t>(P)), rank(static_cast<std::size_t>(P));
  // Fork-join costs tens of microseconds per generation and more when the other core is busy, so
  // the population is evaluated in parallel only when a generation's work clearly exceeds that
  // (cheap closed forms on a few dozen points stay serial; the fung-organ lateral solve does not).
  // The choice never changes the result: every individual's fitness is computed the same way.
  const auto t_first = std::chrono::steady_clock::now();
  evaluate(pop);
  go_parallel = ga.parallel && P >= 32 && since(t_first) > 0.5e-3;
  for (int gen = 0; gen < ga.generations; ++gen) {
    if (progress) {
      progress->check_cancelled();
      progress->report(static_cast<double>(gen) / ga.generations, "genetic algorithm");
    }
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(),
                     [&](int a, int b) { return fitness[a] < fitness[b]; });
    for (int k = 0; k < P; ++k) rank[static_cast<std::size_t>(order[k])] = k;
    // Binary tournament on rank (ties cannot occur, so the choice is deterministic).
    auto tournament = [&]() {
      const int a = rng.below(P), b = rng.below(P);
      return rank[a] < rank[b] ? a : b;
    };
    for (int k = 0; k < elite; ++k)
      std::copy_n(pop.begin() + order[k] * n, n, next.begin() + k * n);
    const double sigma =
        ga.mutation_scale * (1.0 - static_cast<double>(gen) / ga.generations) + 1e-4;
    for (int c = 0; c < children; ++c) {
      double* child = next.data() + (elite + c) * n;
      if (c < crossovers) {
        // Blend crossover: each gene drawn on the segment through both parents, extended by a
        // quarter on each side so the population does not collapse onto its convex hull.
        const double* a = pop.data() + tournament() * n;
        const double* b = pop.data() + tournament() * n;
        for (std::size_t j = 0; j < n; ++j) {
          const double beta = -0.25 + 1.5 * rng.uniform();
          child[j] = std::clamp(a[j] + beta * (b[j] - a[j]), 0.0, 1.0);
        }
      } else {
        const double* a = pop.data() + tournament() * n;
        for (std::size_t j = 0; j < n; ++j) {
          double z = a[j] + sigma * rng.normal();
          if (z < 0) z = -z;        // reflect so the boundary is not over-sampled
          if (z > 1) z = 2 - z;
          child[j] = std::clamp(z, 0.0, 1.0);
        }
      }
    }
    pop.swap(next);
    evaluate(pop);
  }
  const int best = static_cast<int>(std::min_element(fitness.begin(), fitness.end()) - fitness.begin());
  std::vector<double> p(n);
  for (std::size_t j = 0; j < n; ++j) p[j] = lo[j] + pop[best * n + j] * (hi[j] - lo[j]);

  FitResult r;
  r.ga_sse = fitness[static_cast<std::size_t>(best)];
  if (!std::isfinite(r.ga_sse))
    throw CalibrationDataError(std::string(m.name()) + ": no parameter set in the search box "
                                   "gives finite stresses at all data points",
                               d.source, "check the data's units (Pa, stretch) and the bounds");
  if (o.polish) {
    double sse = 0;
    r.lm_iterations = lm_run(m, d, p, lo, hi, o.lm, sse);
  }
  r.parameters = p;
  r.lower = lo;
  r.upper = hi;
  r.predicted.resize(d.points.size());
  m.respond(d.points, r.parameters, r.predicted);
  r.stats = fit_statistics(d.measured, r.predicted);
  r.standard_errors = standard_errors(m, d, r.parameters);
  r.seed = ga.seed;
  r.seconds = since(t0);
  if (progress) progress->report(1.0, "genetic algorithm");
  return r;
}

}  // namespace organsmith::physics
