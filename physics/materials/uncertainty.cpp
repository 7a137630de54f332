#include "physics/materials/uncertainty.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <map>

namespace organsmith::physics {

namespace {

Eigen::MatrixXd jacobian_at(const Model& m, std::span<const LoadPoint> pts, std::span<const double> p,
                            std::vector<double>* values = nullptr) {
  const std::size_t n = m.parameter_count(), N = pts.size();
  std::vector<double> f(N), jac(N * n);
  m.respond(pts, p, f, jac);
  if (values) *values = f;
  Eigen::MatrixXd J(N, n);
  for (std::size_t i = 0; i < N; ++i)
    for (std::size_t j = 0; j < n; ++j) J(i, j) = jac[i * n + j];
  return J;
}

// Lawson–Hanson active-set non-negative least squares: min ‖A x − b‖, x ≥ 0.
Eigen::VectorXd nnls(const Eigen::MatrixXd& A, const Eigen::VectorXd& b) {
  const Eigen::Index n = A.cols();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
  std::vector<bool> passive(static_cast<std::size_t>(n), false);
  const double tol = 1e-12 * A.norm() * b.norm();
  for (int outer = 0; outer < 3 * n + 10; ++outer) {
    const Eigen::VectorXd w = A.transpose() * (b - A * x);
    Eigen::Index t = -1;
    double wmax = tol;
    for (Eigen::Index j = 0; j < n; ++j)
      if (!passive[static_cast<std::size_t>(j)] && w[j] > wmax) wmax = w[j], t = j;
    if (t < 0) break;
    passive[static_cast<std::size_t>(t)] = true;
    for (int inner = 0; inner < 3 * n + 10; ++inner) {
      std::vector<Eigen::Index> idx;
      for (Eigen::Index j = 0; j < n; ++j)
        if (passive[static_cast<std::size_t>(j)]) idx.push_back(j);
      Eigen::MatrixXd Ap(A.rows(), static_cast<Eigen::Index>(idx.size()));
      for (std::size_t k = 0; k < idx.size(); ++k) Ap.col(static_cast<Eigen::Index>(k)) = A.col(idx[k]);
      const Eigen::VectorXd zp = Ap.colPivHouseholderQr().solve(b);
      Eigen::VectorXd z = Eigen::VectorXd::Zero(n);
      for (std::size_t k = 0; k < idx.size(); ++k) z[idx[k]] = zp[static_cast<Eigen::Index>(k)];
      bool feasible = true;
      for (auto j : idx) feasible = feasible && z[j] > 0;
      if (feasible) {
        x = z;
        break;
      }
      double alpha = 1.0;
      for (auto j : idx)
        if (z[j] <= 0) alpha = std::min(alpha, x[j] / (x[j] - z[j]));
      x += alpha * (z - x);
      for (auto j : idx)
        if (x[j] <= 1e-15 * (1 + std::abs(x.maxCoeff()))) passive[static_cast<std::size_t>(j)] = false, x[j] = 0;
    }
  }
  return x;
}

}  // namespace

StressMoments linearised_moments(const Model& m, std::span<const LoadPoint> pts,
                                 std::span<const double> mean, std::span<const double> sd) {
  std::vector<double> f;
  const Eigen::MatrixXd J = jacobian_at(m, pts, mean, &f);
  StressMoments s;
  s.mean_Pa = f;
  for (Eigen::Index i = 0; i < J.rows(); ++i) {
    double v = 0;
    for (Eigen::Index j = 0; j < J.cols(); ++j) v += std::pow(J(i, j) * sd[static_cast<std::size_t>(j)], 2);
    s.sd_Pa.push_back(std::sqrt(v));
  }
  return s;
}

StressMoments second_order_moments(const Model& m, std::span<const LoadPoint> pts,
                                   std::span<const double> mean, std::span<const double> sd,
                                   double rel_step) {
  const std::size_t n = m.parameter_count(), N = pts.size();
  std::vector<double> f;
  const Eigen::MatrixXd J = jacobian_at(m, pts, mean, &f);
  // H[k](i, j) = ∂²f_k/∂Ci∂Cj by central differences of the analytic gradient.
  std::vector<Eigen::MatrixXd> H(N, Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n)));
  std::vector<double> p(mean.begin(), mean.end());
  for (std::size_t j = 0; j < n; ++j) {
    const double h = rel_step * std::max({std::abs(mean[j]), sd[j], 1e-12});
    p[j] = mean[j] + h;
    const Eigen::MatrixXd Jp = jacobian_at(m, pts, p);
    p[j] = mean[j] - h;
    const Eigen::MatrixXd Jm = jacobian_at(m, pts, p);
    p[j] = mean[j];
    for (std::size_t k = 0; k < N; ++k)
      H[k].col(static_cast<Eigen::Index>(j)) = (Jp.row(static_cast<Eigen::Index>(k)) - Jm.row(static_cast<Eigen::Index>(k))).transpose() / (2 * h);
  }
  StressMoments s;
  for (std::size_t k = 0; k < N; ++k) {
    const Eigen::MatrixXd Hs = 0.5 * (H[k] + H[k].transpose());
    double mu = f[k], var = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const auto ii = static_cast<Eigen::Index>(i);
      mu += 0.5 * Hs(ii, ii) * sd[i] * sd[i];
      var += std::pow(J(static_cast<Eigen::Index>(k), ii) * sd[i], 2);
      for (std::size_t j = 0; j < n; ++j)
        var += 0.5 * std::pow(Hs(ii, static_cast<Eigen::Index>(j)) * sd[i] * sd[j], 2);
    }
    s.mean_Pa.push_back(mu);
    s.sd_Pa.push_back(std::sqrt(var));
  }
  return s;
}

std::vector<double> imvfosm_forward(const Eigen::MatrixXd& D, std::span<const double> sigma_C) {
  std::vector<double> out;
  for (Eigen::Index k = 0; k < D.rows(); ++k) {
    double v = 0;
    for (Eigen::Index i = 0; i < D.cols(); ++i) v += std::pow(D(k, i) * sigma_C[static_cast<std::size_t>(i)], 2);
    out.push_back(std::sqrt(v));
  }
  return out;
}

ImvfosmResult imvfosm_solve(const Eigen::MatrixXd& D, std::span<const double> sigma_T, bool relative) {
  if (static_cast<std::size_t>(D.rows()) != sigma_T.size())
    throw CalibrationDataError("IMVFOSM: " + std::to_string(D.rows()) + " derivative rows but " +
                               std::to_string(sigma_T.size()) + " stress standard deviations");
  for (double s : sigma_T)
    if (!(s > 0) || !std::isfinite(s))
      throw CalibrationDataError("IMVFOSM: stress standard deviations must be positive and finite");
  // Equation k: Σ_i D_ki² s_i = σ_Tk² with s_i = σ_Ci² ≥ 0. Columns are scaled to unit norm for
  // conditioning (the derivatives differ by up to 10⁵ between parameters).
  Eigen::MatrixXd A = D.array().square();
  Eigen::VectorXd b(D.rows());
  for (Eigen::Index k = 0; k < D.rows(); ++k) {
    b[k] = sigma_T[static_cast<std::size_t>(k)] * sigma_T[static_cast<std::size_t>(k)];
    if (relative) {
      A.row(k) /= b[k];
      b[k] = 1.0;
    }
  }
  Eigen::VectorXd colscale(A.cols());
  for (Eigen::Index j = 0; j < A.cols(); ++j) {
    colscale[j] = A.col(j).norm() > 0 ? A.col(j).norm() : 1.0;
    A.col(j) /= colscale[j];
  }
  const Eigen::VectorXd s = nnls(A, b).cwiseQuotient(colscale);
  ImvfosmResult r;
  for (Eigen::Index j = 0; j < s.size(); ++j) r.sigma.push_back(std::sqrt(std::max(0.0, s[j])));
  r.predicted_sd_Pa = imvfosm_forward(D, r.sigma);
  double e = 0;
  for (std::size_t k = 0; k < sigma_T.size(); ++k)
    e += std::pow((r.predicted_sd_Pa[k] - sigma_T[k]) / sigma_T[k], 2);
  r.rms_relative_error = std::sqrt(e / static_cast<double>(sigma_T.size()));
  return r;
}

MonteCarloResult monte_carlo(const Model& m, std::span<const LoadPoint> pts,
                             std::span<const double> mean, std::span<const double> sd,
                             const MonteCarloOptions& o) {
  const std::size_t n = m.parameter_count(), N = pts.size();
  if (o.samples < 2) throw UsageError("Monte Carlo needs at least 2 samples");
  Rng rng(o.seed);
  MonteCarloResult r;
  Eigen::MatrixXd S(o.samples, static_cast<Eigen::Index>(N));
  std::vector<double> p(n), f(N);
  Eigen::Index valid = 0;
  for (int s = 0; s < o.samples; ++s) {
    for (std::size_t j = 0; j < n; ++j) p[j] = mean[j] + sd[j] * rng.normal();
    m.respond(pts, p, f);
    bool ok = true;
    for (double v : f) ok = ok && std::isfinite(v);
    if (!ok) {
      ++r.invalid_draws;
      continue;
    }
    for (std::size_t k = 0; k < N; ++k) S(valid, static_cast<Eigen::Index>(k)) = f[k];
    ++valid;
  }
  r.stress_Pa = S.topRows(valid);
  const double levels[3] = {0.25, 0.5, 0.75};
  for (std::size_t k = 0; k < N; ++k) {
    const auto col = r.stress_Pa.col(static_cast<Eigen::Index>(k));
    const double mu = valid > 0 ? col.mean() : std::nan("");
    const double var = valid > 1 ? (col.array() - mu).square().sum() / static_cast<double>(valid - 1) : std::nan("");
    r.moments.mean_Pa.push_back(mu);
    r.moments.sd_Pa.push_back(std::sqrt(var));
    const auto q = stress_quantiles(r, static_cast<int>(k), levels);
    r.median_Pa.push_back(q[1]);
    r.robust_sd_Pa.push_back((q[2] - q[0]) / 1.3489795003921634);
  }
  return r;
}

std::vector<double> stress_quantiles(const MonteCarloResult& mc, int k, std::span<const double> levels) {
  std::vector<double> v(static_cast<std::size_t>(mc.stress_Pa.rows()));
  for (Eigen::Index s = 0; s < mc.stress_Pa.rows(); ++s) v[static_cast<std::size_t>(s)] = mc.stress_Pa(s, k);
  std::sort(v.begin(), v.end());
  std::vector<double> out;
  for (double L : levels) {
    if (v.empty()) {
      out.push_back(std::nan(""));
      continue;
    }
    const double pos = std::clamp(L, 0.0, 1.0) * static_cast<double>(v.size() - 1);
    const auto i = static_cast<std::size_t>(pos);
    const double frac = pos - static_cast<double>(i);
    out.push_back(i + 1 < v.size() ? v[i] + frac * (v[i + 1] - v[i]) : v[i]);
  }
  return out;
}

DirectCalculation direct_calculation(const Model& m, const CalibrationData& d, const FitOptions& o) {
  std::map<std::string, CalibrationData> groups;
  std::vector<std::string> order;
  for (std::size_t i = 0; i < d.points.size(); ++i) {
    auto [it, fresh] = groups.try_emplace(d.specimen[i]);
    if (fresh) order.push_back(d.specimen[i]);
    it->second.points.push_back(d.points[i]);
    it->second.measured.push_back(d.measured[i]);
    it->second.specimen.push_back(d.specimen[i]);
    it->second.source = d.source;
  }
  if (order.size() < 2)
    throw CalibrationDataError("the DC method needs at least two specimens; found " +
                                   std::to_string(order.size()), d.source,
                               "label each curve in a 'specimen' column");
  DirectCalculation dc;
  const std::size_t n = m.parameter_count();
  dc.mean.assign(n, 0.0);
  dc.sd.assign(n, 0.0);
  for (const auto& name : order) {
    dc.specimens.push_back(name);
    dc.fits.push_back(calibrate(m, groups[name], o));
  }
  const double K = static_cast<double>(dc.fits.size());
  for (const auto& f : dc.fits)
    for (std::size_t j = 0; j < n; ++j) dc.mean[j] += f.parameters[j] / K;
  for (const auto& f : dc.fits)
    for (std::size_t j = 0; j < n; ++j) dc.sd[j] += std::pow(f.parameters[j] - dc.mean[j], 2) / K;
  for (double& s : dc.sd) s = std::sqrt(s);
  return dc;
}

EnvelopeCheck three_sigma_check(const StressMoments& pred, std::span<const double> curve) {
  EnvelopeCheck e;
  std::size_t in = 0;
  for (std::size_t k = 0; k < curve.size(); ++k) {
    const bool ok = std::abs(curve[k] - pred.mean_Pa[k]) <= 3 * pred.sd_Pa[k];
    e.inside.push_back(ok);
    in += ok;
  }
  e.fraction_inside = curve.empty() ? 0.0 : static_cast<double>(in) / static_cast<double>(curve.size());
  return e;
}

}  // namespace organsmith::physics
