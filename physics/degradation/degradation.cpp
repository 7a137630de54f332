// Over 400 lines: one simulation loop (strain energy per element, degradation law,
// re-minimisation, fracture) and the τ_D fit that runs it.
#include "physics/degradation/degradation.h"
#include "core/csv.h"
#include "core/file_io.h"
#include "core/format.h"

#include "physics/materials/calibration.h"

#include <Eigen/SparseCholesky>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <limits>

namespace organsmith::physics {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::string fmt(double v) { return format_g(v); }

double max_abs(const Eigen::VectorXd& v) { return v.size() ? v.cwiseAbs().maxCoeff() : 0.0; }

/// Stiffness factors f_e = 1 − d_e of 6.14–6.15 (a broken element keeps a tiny fraction).
std::vector<double> stiffness_factors(const ClipModel& m, const std::vector<double>& d, const std::vector<bool>& broken) {
  std::vector<double> f(d.size());
  for (std::size_t e = 0; e < d.size(); ++e)
    f[e] = broken[e] ? m.preset().fractured_stiffness_fraction
                     : std::max(1.0 - d[e], m.preset().fractured_stiffness_fraction);
  return f;
}

/// True when one run of intact elements contains embedded elements of both legs: only then can
/// the clip hold the wound tension. (A node just above the surface that carries a sliver of a
/// broken element's embedded length does not count.)
bool load_path_intact(const ClipModel& m, const std::vector<bool>& broken) {
  const ClipGeometry& g = m.geometry();
  bool left = false, right = false;
  for (int e = 0; e < g.elements(); ++e) {
    if (broken[e]) {
      left = right = false;  // the run ends here
      continue;
    }
    if (g.embedded_mm[e] > 0) (g.side[e] < 0 && g.side[e + 1] < 0 ? left : right) = true;
    if (left && right) return true;
  }
  return false;
}

}  // namespace

// ---- 6.2–6.3 ------------------------------------------------------------------------------------

double beam_deflection_6_2(double F, double E, double I, double L, double x) {
  if (x > L / 2) x = L - x;
  return F * x * (0.75 * L * L - x * x) / (12 * E * I);
}

double bending_energy_6_2(double F, double E, double I, double L) {
  // d(s) = F L³ s (3/4 − s²)/(12EI) on s ≤ ½ → ∂²d/∂s² = −F L³ s/(2EI); ∫₀¹ = 2∫₀^½ gives
  // (F L³/(2EI))²/12, times β = EI/(2L³).
  return F * F * L * L * L / (96 * E * I);
}

// ---- energy map ---------------------------------------------------------------------------------

ElementEnergies element_energies(const ClipModel& m, const ClipState& q, const std::vector<double>& f, double F) {
  const ClipGeometry& g = m.geometry();
  const ClipPreset& p = m.preset();
  const int N = g.elements();
  ElementEnergies out;
  out.stretch_mJ.assign(N, 0.0);
  out.bend_mJ.assign(N, 0.0);
  out.local_mJ.assign(N, 0.0);
  out.external_mJ.assign(N, 0.0);
  out.e_star_mJ.assign(N, 0.0);
  out.density.assign(N, 0.0);
  const double E = p.youngs_modulus_MPa, A = p.area_mm2(), I = p.inertia_mm4();
  for (int e = 0; e < N; ++e) {
    const double L = g.length_mm[e];
    const double l = (q.segment<2>(2 * e + 2) - q.segment<2>(2 * e)).norm();
    out.stretch_mJ[e] = 0.5 * f[e] * E * A / L * (l - L) * (l - L);
  }
  for (int n = 1; n < N; ++n) {
    const double dphi = m.turning_angle(q, n) - g.turning_rad[n];
    const double Eb = 0.5 * m.joint_stiffness(n, f) * dphi * dphi;
    // Series springs share the joint's energy in proportion to their compliance.
    const double ca = g.length_mm[n - 1] / (2 * f[n - 1]), cb = g.length_mm[n] / (2 * f[n]);
    out.bend_mJ[n - 1] += Eb * ca / (ca + cb);
    out.bend_mJ[n] += Eb * cb / (ca + cb);
  }
  // Tissue forces: node n's force is shared by its elements in proportion to the embedded length
  // each lumped onto it.
  for (int e = 0; e < N; ++e) {
    if (g.embedded_mm[e] <= 0) continue;
    Eigen::Vector2d Fe = Eigen::Vector2d::Zero();
    double work = 0;
    for (int k = 0; k < 2; ++k) {
      const int n = e + k;
      if (g.element_tributary_mm[e][k] <= 0) continue;
      const double share = g.element_tributary_mm[e][k] / g.tributary_mm[n];
      const Eigen::Vector2d Fn = m.tissue_force(q, n);
      const Eigen::Vector2d vn = q.segment<2>(2 * n) - g.nodes_mm[n];
      Fe += share * Fn;
      work += share * Fn.dot(vn);
    }
    const Eigen::Vector2d t = (q.segment<2>(2 * e + 2) - q.segment<2>(2 * e)).normalized();
    const double F_normal = std::abs(Fe.dot(Eigen::Vector2d(-t.y(), t.x())));
    out.local_mJ[e] = bending_energy_6_2(F_normal, f[e] * E, I, g.length_mm[e]);
    out.external_mJ[e] = -work;
  }
  for (int e = 0; e < N; ++e) {
    out.e_star_mJ[e] = out.stretch_mJ[e] + out.bend_mJ[e] + out.local_mJ[e] + std::abs(out.external_mJ[e]);
    out.density[e] = out.e_star_mJ[e] / (g.length_mm[e] * A) / kEnergyDensityUnit_mJ_per_mm3;
  }
  out.total_potential_mJ = m.energy(q, f, F);
  return out;
}

double advance_degradation(double d, double e_star, double tau_d, double k0, double dt) {
  const double rate = k0 + std::sqrt(std::max(0.0, e_star)) / (tau_d * kTauTimeUnit_days);
  return 1.0 - (1.0 - d) * std::exp(-rate * dt);
}

// ---- minimisation -------------------------------------------------------------------------------

MinimiseRecord minimise_energy(const ClipModel& m, ClipState& q, const std::vector<double>& f, double F,
                               const MinimiseOptions& o) {
  MinimiseRecord rec;
  Eigen::VectorXd grad;
  Eigen::SparseMatrix<double> K;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;
  bool analysed = false;
  m.gradient_hessian(q, f, F, grad, &K);
  double energy = m.energy(q, f, F);
  rec.energy_mJ.push_back(energy);
  rec.residual_N.push_back(max_abs(grad));
  while (rec.iterations < o.max_iterations) {
    if (max_abs(grad) <= o.force_tolerance_N) {
      rec.converged = true;
      break;
    }
    const Eigen::VectorXd P = -grad;  // 6.10: the non-equilibrium force
    // 6.8: K u = P, with K shifted until positive definite.
    if (!analysed) {
      ldlt.analyzePattern(K);
      analysed = true;
    }
    ldlt.factorize(K);
    bool pd = ldlt.info() == Eigen::Success && ldlt.vectorD().minCoeff() > 0;
    if (!pd) {
      ++rec.non_pd_shifts;
      const Eigen::VectorXd diag = K.diagonal().cwiseAbs().cwiseMax(1e-12);
      Eigen::SparseMatrix<double> Ks;
      for (double mu = 1e-8; !pd && mu < 1e8; mu *= 10) {
        Ks = K;
        for (int i = 0; i < Ks.rows(); ++i) Ks.coeffRef(i, i) += mu * diag[i];
        ldlt.factorize(Ks);
        pd = ldlt.info() == Eigen::Success && ldlt.vectorD().minCoeff() > 0;
      }
    }
    Eigen::VectorXd u = pd ? Eigen::VectorXd(ldlt.solve(P)) : P;
    double pu = P.dot(u);
    if (!(pu > 0) || !u.allFinite()) {  // 6.13 violated: fall back to the steepest descent direction
      ++rec.steepest_descent_steps;
      u = P / std::max(1.0, K.diagonal().cwiseAbs().maxCoeff());
      pu = P.dot(u);
    }
    // 6.11–6.12 with a backtracking line search on Π.
    double s = 1.0, dE = kInf;
    int h = 0;
    for (; h <= o.max_halvings; ++h, s *= 0.5) {
      dE = m.energy_change(q, s * u, f, F);
      if (std::isfinite(dE) && dE <= -o.armijo * s * pu) break;
    }
    if (h > o.max_halvings) break;  // no decrease possible at this precision
    q += s * u;
    ++rec.iterations;
    m.gradient_hessian(q, f, F, grad, &K);
    energy = m.energy(q, f, F);
    rec.energy_mJ.push_back(energy);
    rec.energy_change_mJ.push_back(dE);
    rec.residual_N.push_back(max_abs(grad));
    rec.p_dot_u.push_back(s * pu);
  }
  if (!rec.converged && max_abs(grad) <= o.force_tolerance_N) rec.converged = true;
  rec.final_residual_N = max_abs(grad);
  return rec;
}

// ---- degradation --------------------------------------------------------------------------------

double mass_fraction(const ClipModel& m, const std::vector<double>& d) {
  double total = 0, left = 0;
  for (int e = 0; e < m.geometry().elements(); ++e) {
    total += m.geometry().length_mm[e];
    left += m.geometry().length_mm[e] * (1.0 - d[e]);
  }
  return left / total;
}

DegradationResult simulate_degradation(const ClipModel& m, const DegradationOptions& o, Progress* progress) {
  if (!(o.tau_d > 0) || !std::isfinite(o.tau_d))
    throw UsageError("τ_D must be positive (got " + fmt(o.tau_d) + ")",
                     "τ_D is the characteristic time of 6.16 in week·(kJ/m³)^½; Table 6.1 gives 241.41 and 245.31");
  if (!(o.load_N >= 0) || !std::isfinite(o.load_N))
    throw UsageError("the load must be ≥ 0 N (got " + fmt(o.load_N) + ")");
  if (!(o.dt_days > 0) || !(o.end_days >= 0) || !std::isfinite(o.end_days))
    throw UsageError("the time step must be positive and the end time ≥ 0 days");
  const ClipGeometry& g = m.geometry();
  const ClipPreset& p = m.preset();
  const int N = g.elements();
  DegradationResult r;
  std::vector<double> d(N, 0.0);
  std::vector<bool> broken(N, false);
  std::vector<double> f = stiffness_factors(m, d, broken);
  r.fracture_day.assign(N, -1.0);
  ClipState q = m.reference_state();

  // Deployment: the wound tension is raised in steps (the tissue law stiffens exponentially).
  const int S = std::max(1, o.deployment_load_steps);
  for (int s = 1; s <= S; ++s) {
    r.deployment_steps.push_back(minimise_energy(m, q, f, o.load_N * s / S, o.minimise));
    r.total_iterations += r.deployment_steps.back().iterations;
    r.all_converged = r.all_converged && r.deployment_steps.back().converged;
  }
  r.deployment = r.deployment_steps.back();
  for (int n = 0; n < g.nodes(); ++n)
    r.max_displacement_mm = std::max(r.max_displacement_mm, (q.segment<2>(2 * n) - g.nodes_mm[n]).norm());
  for (int n = 1; n < N; ++n) {
    const double kappa = (m.turning_angle(q, n) - g.turning_rad[n]) / ((g.length_mm[n - 1] + g.length_mm[n]) / 2);
    r.max_bending_stress_MPa = std::max(r.max_bending_stress_MPa, std::abs(p.youngs_modulus_MPa * kappa * p.width_mm / 2));
  }

  bool load_carried = o.load_N > 0;
  double load = o.load_N;
  auto snapshot = [&](double t, const ElementEnergies& en) {
    ClipSnapshot s;
    s.t_days = t;
    s.q = q;
    s.d = d;
    s.fractured = broken;
    s.energies = en;
    s.load_carried = load_carried;
    return s;
  };
  ElementEnergies en = element_energies(m, q, f, load);
  r.initial = snapshot(0.0, en);
  auto row = [&](double t, const MinimiseRecord& rec) {
    DegradationStep st;
    st.t_days = t;
    st.mass_fraction = mass_fraction(m, d);
    st.fractured = static_cast<int>(std::count(broken.begin(), broken.end(), true));
    st.load_carried = load_carried;
    st.potential_mJ = en.total_potential_mJ;
    for (double v : en.e_star_mJ) st.stored_mJ += v;
    st.iterations = rec.iterations;
    st.residual_N = rec.final_residual_N;
    r.steps.push_back(st);
  };
  row(0.0, r.deployment);

  const long steps = std::lround(o.end_days / o.dt_days);
  std::vector<long> stage_step;
  for (double sd : o.stage_days) stage_step.push_back(std::lround(sd / o.dt_days));
  for (long k = 1; k <= steps; ++k) {
    if (progress) {
      progress->check_cancelled();
      if (k % 20 == 0) progress->report(static_cast<double>(k) / steps, "degrading the clip");
    }
    const double t = k * o.dt_days;
    // 6.16 over [t − Δt, t] with E* of the equilibrium at t − Δt.
    for (int e = 0; e < N; ++e) {
      d[e] = advance_degradation(d[e], en.density[e], o.tau_d, p.baseline_rate_per_day, o.dt_days);
      if (!broken[e] && d[e] >= p.fracture_threshold) {
        broken[e] = true;
        r.fracture_day[e] = t;
      }
    }
    if (load_carried && !load_path_intact(m, broken)) {
      load_carried = false;
      r.load_released_day = t;
    }
    load = load_carried ? o.load_N : 0.0;
    f = stiffness_factors(m, d, broken);
    const MinimiseRecord rec = minimise_energy(m, q, f, load, o.minimise);
    r.total_iterations += rec.iterations;
    r.all_converged = r.all_converged && rec.converged;
    en = element_energies(m, q, f, load);
    row(t, rec);
    if (o.keep_stages && std::find(stage_step.begin(), stage_step.end(), k) != stage_step.end())
      r.stages.push_back(snapshot(t, en));
  }
  r.final_state = snapshot(steps * o.dt_days, en);
  return r;
}

// ---- mass series --------------------------------------------------------------------------------

MassSeries parse_mass_csv(const std::string& text, const std::filesystem::path& source, double max_increase) {
  MassSeries s;
  s.source = source;
  const std::string hint = "a mass series is a CSV with columns t_days and mass_fraction (1 = initial mass)";
  std::vector<CsvRow> rows = parse_csv_rows(text, source, ExitCode::calibration_data);
  if (rows.empty()) throw CalibrationDataError("the file is empty", source, hint);
  lowercase_fields(rows.front());
  const std::vector<std::string>& header = rows.front().fields;
  int col_t = -1, col_m = -1;
  for (std::size_t c = 0; c < header.size(); ++c) {
    if (header[c] == "t_days") col_t = static_cast<int>(c);
    if (header[c] == "mass_fraction") col_m = static_cast<int>(c);
  }
  if (col_t < 0 || col_m < 0)
    throw CalibrationDataError("line " + std::to_string(rows.front().line) + ": the header lacks " +
                                   std::string(col_t < 0 ? "'t_days'" : "'mass_fraction'"),
                               source, hint);
  std::size_t lowest = 0;
  for (std::size_t r = 1; r < rows.size(); ++r) {
    const int lineno = rows[r].line;
    const std::vector<std::string>& cells = rows[r].fields;
    if (cells.size() != header.size())
      throw CalibrationDataError("line " + std::to_string(lineno) + ": " + std::to_string(cells.size()) +
                                     " fields, the header has " + std::to_string(header.size()),
                                 source, hint);
    auto number = [&](int c, const char* name) {
      const std::string& cell = cells[static_cast<std::size_t>(c)];
      const std::optional<double> v = csv_number(cell);
      if (!v || !std::isfinite(*v))
        throw CalibrationDataError("line " + std::to_string(lineno) + ", column '" + name + "': '" + cell +
                                       "' is not a finite number",
                                   source, hint);
      return *v;
    };
    const double t = number(col_t, "t_days"), mf = number(col_m, "mass_fraction");
    if (t < 0)
      throw CalibrationDataError("line " + std::to_string(lineno) + ", column 't_days': negative time " + fmt(t),
                                 source, hint);
    if (!s.t_days.empty() && !(t > s.t_days.back()))
      throw CalibrationDataError("line " + std::to_string(lineno) + ", column 't_days': " + fmt(t) +
                                     " does not follow " + fmt(s.t_days.back()) + " (line " +
                                     std::to_string(s.line.back()) + "); times must increase strictly",
                                 source, hint);
    if (!(mf > 0) || mf > 1 + max_increase)
      throw CalibrationDataError("line " + std::to_string(lineno) + ", column 'mass_fraction': " + fmt(mf) +
                                     " lies outside (0, " + fmt(1 + max_increase) + "]",
                                 source, "give the mass remaining as a fraction of the initial mass (1 = 100 %)");
    // A rise is measured from the lowest mass so far (one comparison per row).
    const std::size_t i = lowest;
    if (!s.mass_fraction.empty() && mf > s.mass_fraction[i] + max_increase)
        throw CalibrationDataError("line " + std::to_string(lineno) + ", column 'mass_fraction': the mass rises from " +
                                       fmt(s.mass_fraction[i]) + " (line " + std::to_string(s.line[i]) + ") to " +
                                       fmt(mf) + ", more than " + fmt(max_increase) +
                                       " above an earlier value; a degrading clip does not gain mass",
                                   source, "check the column order and the units (fraction of the initial mass)");
    if (!s.mass_fraction.empty() && mf < s.mass_fraction[lowest]) lowest = s.mass_fraction.size();
    s.t_days.push_back(t);
    s.mass_fraction.push_back(mf);
    s.line.push_back(lineno);
  }
  if (s.t_days.size() < 3)
    throw CalibrationDataError("only " + std::to_string(s.t_days.size()) + " rows; τ_D needs at least 3 points",
                               source, hint);
  return s;
}

MassSeries read_mass_csv(const std::filesystem::path& path, double max_increase) {
  return parse_mass_csv(
      read_input_file(path, "the mass series", ExitCode::calibration_data, "check the path given to --fit"), path,
      max_increase);
}

// ---- τ_D fit ------------------------------------------------------------------------------------

std::vector<double> model_mass_at(const ClipModel& m, const DegradationOptions& o, const std::vector<double>& times) {
  DegradationOptions so = o;
  so.keep_stages = false;
  so.end_days = 0;
  for (double t : times) so.end_days = std::max(so.end_days, t);
  so.end_days = std::ceil(so.end_days / so.dt_days - 1e-9) * so.dt_days;
  const DegradationResult r = simulate_degradation(m, so, nullptr);
  std::vector<double> out;
  for (double t : times) {
    const double x = t / so.dt_days;
    const auto k = std::min(static_cast<std::size_t>(std::floor(x)), r.steps.size() - 1);
    const std::size_t k1 = std::min(k + 1, r.steps.size() - 1);
    const double w = std::clamp(x - static_cast<double>(k), 0.0, 1.0);
    out.push_back((1 - w) * r.steps[k].mass_fraction + w * r.steps[k1].mass_fraction);
  }
  return out;
}

TauFit fit_tau_d(const ClipModel& m, const DegradationOptions& o, const MassSeries& data, const TauFitOptions& fo,
                 Progress* progress) {
  if (!(fo.tau_min > 0) || !(fo.tau_max > fo.tau_min) || fo.grid < 3)
    throw UsageError("the τ_D search interval must satisfy 0 < min < max (got [" + fmt(fo.tau_min) + ", " +
                     fmt(fo.tau_max) + "])");
  if (!(o.load_N > 0))
    throw UsageError("τ_D cannot be identified without load: at " + fmt(o.load_N) +
                         " N the clip stores no strain energy, so its mass curve is the baseline corrosion "
                         "exp(−k0 t) whatever τ_D is",
                     "give the load the clips carried (--load-n, 5 N in the thesis' loaded group)");
  TauFit best;
  auto sse_of = [&](double tau, std::vector<double>* pred) {
    DegradationOptions so = o;
    so.tau_d = tau;
    const auto y = model_mass_at(m, so, data.t_days);
    ++best.evaluations;
    double obj = 0;
    for (std::size_t i = 0; i < y.size(); ++i) {
      const double r = (y[i] - data.mass_fraction[i]) / (fo.relative_residuals ? data.mass_fraction[i] : 1.0);
      obj += r * r;
    }
    if (pred) *pred = y;
    return obj;
  };
  const double a = std::log(fo.tau_min), b = std::log(fo.tau_max);
  std::vector<double> grid_sse(fo.grid);
  std::vector<std::vector<double>> grid_pred(fo.grid);
  for (int k = 0; k < fo.grid; ++k) {
    if (progress) {
      progress->check_cancelled();
      progress->report(0.5 * k / fo.grid, "fitting τ_D");
    }
    grid_sse[k] = sse_of(std::exp(a + (b - a) * k / (fo.grid - 1)), &grid_pred[k]);
  }
  double spread = 0;
  for (std::size_t i = 0; i < data.t_days.size(); ++i)
    spread = std::max(spread, std::abs(grid_pred.front()[i] - grid_pred.back()[i]));
  if (spread < 1e-9)
    throw UsageError("τ_D cannot be identified: the model's mass curve at the series' times does not change "
                     "between τ_D = " + fmt(fo.tau_min) + " and " + fmt(fo.tau_max),
                     "the clip must carry load (--load-n) and the series must reach beyond t = 0");
  const int j = static_cast<int>(std::min_element(grid_sse.begin(), grid_sse.end()) - grid_sse.begin());
  // Golden-section search on log τ_D in the bracket around the best grid point.
  double lo = a + (b - a) * std::max(0, j - 1) / (fo.grid - 1);
  double hi = a + (b - a) * std::min(fo.grid - 1, j + 1) / (fo.grid - 1);
  const double phi = (std::sqrt(5.0) - 1) / 2;
  double x1 = hi - phi * (hi - lo), x2 = lo + phi * (hi - lo);
  double f1 = sse_of(std::exp(x1), nullptr), f2 = sse_of(std::exp(x2), nullptr);
  while (hi - lo > fo.relative_tolerance) {
    if (progress) {
      progress->check_cancelled();
      progress->report(0.75, "fitting τ_D");
    }
    if (f1 <= f2) {
      hi = x2;
      x2 = x1;
      f2 = f1;
      x1 = hi - phi * (hi - lo);
      f1 = sse_of(std::exp(x1), nullptr);
    } else {
      lo = x1;
      x1 = x2;
      f1 = f2;
      x2 = lo + phi * (hi - lo);
      f2 = sse_of(std::exp(x2), nullptr);
    }
  }
  double x = f1 <= f2 ? x1 : x2;
  double fx = std::min(f1, f2);
  if (grid_sse[j] < fx) {  // the objective is piecewise smooth (fracture steps): keep the best seen
    x = a + (b - a) * j / (fo.grid - 1);
    fx = grid_sse[j];
  }
  best.tau_d = std::exp(x);
  sse_of(best.tau_d, &best.predicted);
  best.sse = 0;
  for (std::size_t i = 0; i < best.predicted.size(); ++i)
    best.sse += (best.predicted[i] - data.mass_fraction[i]) * (best.predicted[i] - data.mass_fraction[i]);
  best.at_bound = (j == 0 || j == fo.grid - 1) && (std::abs(x - a) < 1e-3 || std::abs(x - b) < 1e-3);
  double mean = 0;
  for (double v : data.mass_fraction) mean += v;
  mean /= static_cast<double>(data.mass_fraction.size());
  double sst = 0;
  for (double v : data.mass_fraction) sst += (v - mean) * (v - mean);
  best.r2 = sst > 0 ? 1 - best.sse / sst : 0.0;
  best.rmse = std::sqrt(best.sse / static_cast<double>(data.mass_fraction.size()));
  return best;
}

}  // namespace organsmith::physics
