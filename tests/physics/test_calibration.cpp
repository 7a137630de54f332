// Calibration: CSV validation, determinism, and round trips of the thesis parameter sets
// (Tables 5.1.1, 5.1.2, 4.2.2) through 2 %-noise synthetic curves.

#include "physics/materials/calibration.h"
#include "physics/materials/presets.h"
#include "synthetic.h"

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <cstdio>
#include <string>

using namespace organsmith::physics;
using namespace organsmith::physics::testing;

namespace {

std::vector<double> preset_values(const Model& m, const std::string& id) {
  return parameter_values(m, builtin_material_library().find(id).material.parameters);
}

double rel(double got, double want) { return std::abs(got - want) / std::abs(want); }

template <class F>
std::string csv_error(const std::string& text, F&& check, bool displacement = false, std::size_t min_points = 3) {
  try {
    parse_calibration_csv(text, "curves.csv", displacement, min_points);
  } catch (const CalibrationDataError& e) {
    check(e);
    return e.what();
  }
  ADD_FAILURE() << "no error for:\n" << text;
  return {};
}

// Smallest / largest singular value of the Jacobian (columns scaled by the parameter values) —
// ~0 when some direction in parameter space does not change the curve at all.
double jacobian_conditioning(const Model& m, const CalibrationData& d, const std::vector<double>& p) {
  const std::size_t n = p.size(), N = d.points.size();
  std::vector<double> f(N), jac(N * n);
  m.respond(d.points, p, f, jac);
  Eigen::MatrixXd J(N, n);
  for (std::size_t i = 0; i < N; ++i)
    for (std::size_t j = 0; j < n; ++j) J(i, j) = jac[i * n + j] * p[j];
  const Eigen::VectorXd s = J.jacobiSvd().singularValues();
  return s[s.size() - 1] / s[0];
}

}  // namespace

// ---- CSV ---------------------------------------------------------------------------------------

TEST(PhysicsCsv, ReadsStretchStrainDirectionAndSpecimen) {
  const auto d = parse_calibration_csv(
      "# comment\nspecimen,direction,strain,stress_pa\nA,circumferential,0.1,10\nA,circumferential,0.2,30\n"
      "A,longitudinal,0.1,8\nB,circumferential,0.05,4\n",
      "x.csv", false, 3);
  ASSERT_EQ(d.points.size(), 4u);
  EXPECT_DOUBLE_EQ(d.points[0].x, 1.1);
  EXPECT_EQ(d.points[2].load, LoadCase::uniaxial_longitudinal);
  EXPECT_EQ(d.specimen[3], "B");
}

TEST(PhysicsCsv, QuotedSpecimenNamesKeepTheirCommas) {
  // One CSV reader for the project: quoted fields (RFC 4180) hold commas, as fit.csv writes them.
  const auto d = parse_calibration_csv(
      "specimen,stretch,stress_pa\n\"GB 3, fundus\",1.1,10\n\"GB 3, fundus\",1.2,30\nB,1.05,4\n", "q.csv", false, 3);
  ASSERT_EQ(d.points.size(), 3u);
  EXPECT_EQ(d.specimen[0], "GB 3, fundus");
  EXPECT_EQ(d.specimen[2], "B");
}

TEST(PhysicsCsv, RejectsBadDataWithFileLineAndColumn) {
  std::string m = csv_error("stretch,stress_pa\n1.1,10\n1.2,nan\n1.3,40\n", [](auto&) {});
  EXPECT_NE(m.find("curves.csv:3, column 'stress_pa'"), std::string::npos) << m;
  EXPECT_NE(m.find("not finite"), std::string::npos) << m;
  m = csv_error("stretch,stress_pa\n1.1,10\n1.2,abc\n1.3,40\n", [](auto&) {});
  EXPECT_NE(m.find("'abc' is not a number"), std::string::npos) << m;
  m = csv_error("stretch,stress_pa\n1.1,10\n1.2,20\n", [](auto&) {});
  EXPECT_NE(m.find("only 2 data rows; at least 3"), std::string::npos) << m;
  m = csv_error("specimen,stretch,stress_pa\nA,1.1,10\nA,1.3,20\nB,1.0,1\nA,1.2,30\n", [](auto&) {});
  EXPECT_NE(m.find("curves.csv:5, column 'stretch'"), std::string::npos) << m;
  EXPECT_NE(m.find("does not increase (line 3 has 1.3) within specimen 'A'"), std::string::npos) << m;
  m = csv_error("stretch,force\n1.1,10\n", [](auto&) {});
  EXPECT_NE(m.find("missing column 'stress_pa'"), std::string::npos) << m;
  m = csv_error("stretch,stress_pa,direction\n1.1,10,radial\n1.2,1,circ\n1.3,2,circ\n", [](auto&) {});
  EXPECT_NE(m.find("'radial' is not a direction"), std::string::npos) << m;
  m = csv_error("displacement_m,force_n\n0.001,1\n0.002\n", [](auto&) {}, true);
  EXPECT_NE(m.find(":3: 1 fields, the header has 2"), std::string::npos) << m;
  m = csv_error("stretch,stress_pa\n-1.1,10\n", [](auto&) {});
  EXPECT_NE(m.find("not positive"), std::string::npos) << m;
  csv_error("stretch,stress_pa\n1.1,inf\n", [](const CalibrationDataError& e) {
    EXPECT_EQ(e.code(), organsmith::ExitCode::calibration_data);
  });
}

TEST(PhysicsCsv, InvertedOrMismatchedBoundsAreUsageErrors) {
  const auto m = make_model("fung-wall");
  std::vector<double> lo = {1, 1, 1, 0}, hi = {100, 50, 0.5, 20};
  try {
    resolve_bounds(*m, lo, hi);
    ADD_FAILURE() << "inverted bounds accepted";
  } catch (const organsmith::UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("inverted bounds for a2: lower 1 is not below upper 0.5"), std::string::npos)
        << e.what();
  }
  std::vector<double> lo2 = {1, 1}, hi2 = {2, 2};
  EXPECT_THROW(resolve_bounds(*m, lo2, hi2), organsmith::UsageError);
}

// ---- determinism -------------------------------------------------------------------------------

// fung-organ (a Newton solve per point) makes a generation slow enough for the GA to evaluate it
// with TBB; the result must not depend on that.
TEST(PhysicsCalibration, SameSeedSameResultSerialOrParallel) {
  const auto m = make_model("fung-organ");
  const auto p = preset_values(*m, "fung-organ/table-5.1.2/mean");
  const auto d = uniaxial_curves(*m, p, {LoadCase::uniaxial_circumferential, LoadCase::uniaxial_longitudinal},
                                 30, 1.3, 0.02, 7);
  FitOptions o;
  o.ga.seed = 42;
  o.ga.population = 64;
  o.ga.generations = 15;
  const FitResult a = calibrate(*m, d, o);
  const FitResult b = calibrate(*m, d, o);
  o.ga.parallel = false;
  const FitResult c = calibrate(*m, d, o);
  EXPECT_EQ(a.parameters, b.parameters);
  EXPECT_EQ(a.parameters, c.parameters);
  EXPECT_EQ(a.predicted, c.predicted);
  o.ga.seed = 43;
  o.polish = false;
  const FitResult e = calibrate(*m, d, o);
  EXPECT_NE(a.parameters, e.parameters) << "a different seed explores differently";
}

// ---- round trips -------------------------------------------------------------------------------
//
// Criterion (issue 5): every parameter within 5 % and R² ≥ 0.98, from several seeds, with 2 %
// noise. Whether 5 % is reachable at all is a property of the data, not of the optimiser, so each
// quantity's standard error under the noise model (σ_i = 2 % of the stress) is computed for the
// estimator used (unweighted least squares, sandwich covariance) from the noise-free Jacobian:
//   * not identifiable (its gradient has a component along the Jacobian's null space): reported,
//     no accuracy asserted;
//   * identifiable with 2·SE ≤ 5 %: the 5 % criterion is asserted for every seed;
//   * identifiable but 2·SE > 5 % (2 % noise cannot pin it to 5 %): reported, and the error must
//     stay within 4·SE (a consistency check that still fails on a wrong fit);
//   * SE > 25 % (practically not identifiable): reported only.
// Independently of that, the optimiser must reach an SSE no worse than the true parameters'.

namespace {

struct Quantity {
  std::string name;
  std::function<double(const std::vector<double>&)> value;
};

std::vector<Quantity> plain(const Model& m) {
  std::vector<Quantity> q;
  for (std::size_t j = 0; j < m.parameter_count(); ++j)
    q.push_back({m.parameters()[j].name, [j](const std::vector<double>& p) { return p[j]; }});
  return q;
}

struct RelSe {
  bool identifiable = true;
  double rel_se = 0;
};

// Standard error of each quantity for the estimator actually used — unweighted least squares
// (thesis 3.16) — under the noise model σ_i = noise·|f_i|: the sandwich covariance
// (JᵀJ)⁺ Jᵀ diag(σ²) J (JᵀJ)⁺ of the linearised problem, evaluated with J = U S Vᵀ as
// V S⁻¹ Uᵀ diag(σ²) U S⁻¹ Vᵀ on the range of J.
std::vector<RelSe> sampling_se(const Model& m, const CalibrationData& clean, const std::vector<double>& p,
                               double noise, const std::vector<Quantity>& qs, bool relative) {
  const std::size_t n = p.size(), N = clean.points.size();
  std::vector<double> f(N), jac(N * n);
  m.respond(clean.points, p, f, jac);
  Eigen::MatrixXd J(N, n);
  for (std::size_t i = 0; i < N; ++i)
    for (std::size_t j = 0; j < n; ++j)
      J(i, j) = jac[i * n + j] * std::abs(p[j]) / (relative ? std::abs(f[i]) : 1.0);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd s = svd.singularValues();
  const Eigen::MatrixXd U = svd.matrixU(), V = svd.matrixV();
  std::vector<RelSe> out;
  for (const auto& q : qs) {
    // Gradient of q in log-parameter coordinates (matching J's column scaling), by differences.
    Eigen::VectorXd g(n);
    for (std::size_t j = 0; j < n; ++j) {
      std::vector<double> a = p, b = p;
      const double h = 1e-6 * std::abs(p[j]);
      a[j] += h;
      b[j] -= h;
      g[static_cast<Eigen::Index>(j)] = (q.value(a) - q.value(b)) / (2 * h) * std::abs(p[j]);
    }
    RelSe r;
    Eigen::VectorXd w = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(N));  // Mᵀ Vᵀ g
    for (Eigen::Index k = 0; k < s.size(); ++k) {
      const double c = V.col(k).dot(g);
      if (s[k] <= 1e-9 * s[0]) {
        if (std::abs(c) > 1e-6 * g.norm()) r.identifiable = false;
      } else {
        w += U.col(k) * (c / s[k]);
      }
    }
    double var = 0;
    // Weighted residual noise: σ_i w_i = noise (relative) or noise·|f_i| (absolute).
    for (std::size_t i = 0; i < N; ++i)
      var += std::pow(w[static_cast<Eigen::Index>(i)] * noise * (relative ? 1.0 : f[i]), 2);
    r.rel_se = std::sqrt(var) / std::abs(q.value(p));
    out.push_back(r);
  }
  return out;
}

double sse_at(const Model& m, const CalibrationData& d, const std::vector<double>& p) {
  std::vector<double> f(d.points.size());
  m.respond(d.points, p, f);
  return fit_statistics(d.measured, f).sse;
}

// Runs the round trip for `seeds`; `make(seed, noise)` builds the data. Returns how many
// (seed, quantity) pairs missed 5 %.
int round_trip(const std::string& label, const Model& m, const std::vector<double>& p,
               const std::function<CalibrationData(std::uint64_t, double)>& make,
               const std::vector<Quantity>& qs, std::initializer_list<std::uint64_t> seeds,
               bool relative) {
  const auto se = sampling_se(m, make(0, 0.0), p, 0.02, qs, relative);
  std::printf("%s, %s residuals: standard error at 2 %% noise:", label.c_str(), relative ? "relative" : "absolute");
  for (std::size_t k = 0; k < qs.size(); ++k)
    std::printf(" %s %s", qs[k].name.c_str(),
                se[k].identifiable ? (std::to_string(100 * se[k].rel_se).substr(0, 5) + "%").c_str() : "not-identifiable");
  std::printf("\n");
  int misses = 0;
  for (std::uint64_t seed : seeds) {
    auto d = make(seed, 0.02);
    if (relative) use_relative_residuals(d);
    FitOptions o;
    o.ga.seed = seed;
    const FitResult r = calibrate(m, d, o);
    std::printf("  seed %llu:", static_cast<unsigned long long>(seed));
    for (std::size_t k = 0; k < qs.size(); ++k) {
      const double want = qs[k].value(p), got = qs[k].value(r.parameters);
      const double err = rel(got, want);
      std::printf(" %s %.4g (%+.2f%%)", qs[k].name.c_str(), got, 100 * (got - want) / std::abs(want));
      if (!se[k].identifiable) continue;
      if (err > 0.05) ++misses;
      if (se[k].rel_se > 0.25) continue;  // practically not identifiable: a 4·SE bound would be vacuous
      if (2 * se[k].rel_se <= 0.05)
        EXPECT_LT(err, 0.05) << label << " seed " << seed << ": " << qs[k].name;
      else
        EXPECT_LT(err, 4 * se[k].rel_se) << label << " seed " << seed << ": " << qs[k].name;
    }
    auto wsse = [&](const std::vector<double>& q) {
      std::vector<double> f(d.points.size());
      m.respond(d.points, q, f);
      double s = 0;
      for (std::size_t i = 0; i < f.size(); ++i) s += std::pow((f[i] - d.measured[i]) * (d.weight.empty() ? 1.0 : d.weight[i]), 2);
      return s;
    };
    const double sse_true = sse_at(m, d, p);
    std::printf(" | R2 %.4f RMSE %.3g SSE %.4g (true params %.4g) %.3f s\n", r.stats.r2, r.stats.rmse,
                r.stats.sse, sse_true, r.seconds);
    EXPECT_GE(r.stats.r2, 0.98) << label << " seed " << seed;
    EXPECT_LE(wsse(r.parameters), wsse(p) * (1 + 1e-9)) << label << " seed " << seed << ": optimiser stopped short";
  }
  return misses;
}

const std::vector<LoadCase> kBothDirections = {LoadCase::uniaxial_circumferential, LoadCase::uniaxial_longitudinal};

}  // namespace

// Table 5.1.1 means, uniaxial curves in both directions (lateral axis stress-free), stretch up to
// 1.3, 30 points per direction. The curves depend on c, A1 = a1 − a4²/a2 and A2 = a2 − a4²/a1 only
// (PhysicsModels.UniaxialFungWallDependsOnlyOnReducedModuli): a1, a2, a4 are not identifiable.
TEST(PhysicsRoundTrip, FungWallUniaxial) {
  const auto m = make_model("fung-wall");
  const auto p = preset_values(*m, "fung-wall/table-5.1.1/mean");
  auto qs = plain(*m);
  qs.push_back({"A1", [](const std::vector<double>& q) { return q[1] - q[3] * q[3] / q[2]; }});
  qs.push_back({"A2", [](const std::vector<double>& q) { return q[2] - q[3] * q[3] / q[1]; }});
  qs.push_back({"c*A1", [](const std::vector<double>& q) { return q[0] * (q[1] - q[3] * q[3] / q[2]); }});
  const int misses = round_trip("fung-wall uniaxial", *m, p, [&](std::uint64_t s, double noise) {
    return uniaxial_curves(*m, p, kBothDirections, 30, 1.3, noise, 100 + s);
  }, qs, {1, 2, 3, 4, 5}, false);
  std::printf("fung-wall uniaxial, absolute residuals: %d identifiable (seed, quantity) pairs outside 5 %%\n", misses);
  const int misses_rel = round_trip("fung-wall uniaxial", *m, p, [&](std::uint64_t s, double noise) {
    return uniaxial_curves(*m, p, kBothDirections, 30, 1.3, noise, 100 + s);
  }, qs, {1, 2, 3, 4, 5}, true);
  EXPECT_EQ(misses_rel, 0);
  const auto se = sampling_se(*m, uniaxial_curves(*m, p, kBothDirections, 30, 1.3, 0.0, 0), p, 0.02, qs, true);
  EXPECT_FALSE(se[1].identifiable);
  EXPECT_FALSE(se[2].identifiable);
  EXPECT_FALSE(se[3].identifiable);
  EXPECT_TRUE(se[0].identifiable && se[4].identifiable && se[5].identifiable);
}

// The same parameters from a planar biaxial protocol (each axis to 1.3 with the other held at
// 1.0, 1.15, 1.3): all four are identifiable.
TEST(PhysicsRoundTrip, FungWallBiaxial) {
  const auto m = make_model("fung-wall");
  const auto p = preset_values(*m, "fung-wall/table-5.1.1/mean");
  round_trip("fung-wall biaxial", *m, p, [&](std::uint64_t s, double noise) {
    return biaxial_curves(*m, p, 10, 1.3, noise, 200 + s);
  }, plain(*m), {1, 2, 3}, false);
  round_trip("fung-wall biaxial", *m, p, [&](std::uint64_t s, double noise) {
    return biaxial_curves(*m, p, 10, 1.3, noise, 200 + s);
  }, plain(*m), {1, 2, 3}, true);
}

// Table 5.1.2 means (t = 8.93, K = 39 kPa), uniaxial both directions.
TEST(PhysicsRoundTrip, FungOrganUniaxial) {
  const auto lib = builtin_material_library();
  const auto& preset = lib.find("fung-organ/table-5.1.2/mean");
  const auto m = make_model("fung-organ", model_options_for(preset));
  const auto p = parameter_values(*m, preset.material.parameters);
  round_trip("fung-organ uniaxial", *m, p, [&](std::uint64_t s, double noise) {
    return uniaxial_curves(*m, p, kBothDirections, 30, 1.3, noise, 300 + s);
  }, plain(*m), {1, 2, 3}, false);
  round_trip("fung-organ uniaxial", *m, p, [&](std::uint64_t s, double noise) {
    return uniaxial_curves(*m, p, kBothDirections, 30, 1.3, noise, 300 + s);
  }, plain(*m), {1, 2, 3}, true);
}

TEST(PhysicsRoundTrip, FungOrganBiaxial) {
  const auto lib = builtin_material_library();
  const auto& preset = lib.find("fung-organ/table-5.1.2/mean");
  const auto m = make_model("fung-organ", model_options_for(preset));
  const auto p = parameter_values(*m, preset.material.parameters);
  round_trip("fung-organ biaxial", *m, p, [&](std::uint64_t s, double noise) {
    return biaxial_curves(*m, p, 10, 1.3, noise, 400 + s);
  }, plain(*m), {1, 2, 3}, false);
  round_trip("fung-organ biaxial", *m, p, [&](std::uint64_t s, double noise) {
    return biaxial_curves(*m, p, 10, 1.3, noise, 400 + s);
  }, plain(*m), {1, 2, 3}, true);
}

// Table 4.2.2 GA column; F depends on μ1 and η1 only through μ1/η1
// (PhysicsModels.KelvinModulusAndInverse): μ0 and μ1/η1 are identifiable, μ1 and η1 are not.
TEST(PhysicsRoundTrip, KelvinCutting) {
  const auto lib = builtin_material_library();
  const auto& preset = lib.find("kelvin-cutting/table-4.2.2/ga");
  const auto m = make_model("kelvin-cutting", model_options_for(preset));
  const auto p = parameter_values(*m, preset.material.parameters);
  auto qs = plain(*m);
  qs.push_back({"mu1/eta1", [](const std::vector<double>& q) { return q[1] / q[2]; }});
  round_trip("kelvin-cutting", *m, p, [&](std::uint64_t s, double noise) {
    return cutting_curve(*m, p, 60, 3e-3, noise, 500 + s);
  }, qs, {1, 2, 3}, false);
  round_trip("kelvin-cutting", *m, p, [&](std::uint64_t s, double noise) {
    return cutting_curve(*m, p, 60, 3e-3, noise, 500 + s);
  }, qs, {1, 2, 3}, true);
  const auto se = sampling_se(*m, cutting_curve(*m, p, 60, 3e-3, 0.0, 0), p, 0.02, qs, true);
  EXPECT_TRUE(se[0].identifiable && se[3].identifiable);
  EXPECT_FALSE(se[1].identifiable);
  EXPECT_FALSE(se[2].identifiable);
}
