// Over 400 lines: the constitutive models of the thesis (Fung wall and organ, artery
// log-polynomial, Mooney–Rivlin, Ogden, Kelvin cutting), each with its analytic Jacobian, behind
// one interface.
#include "physics/materials/models.h"

#include "core/errors.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <numeric>

namespace organsmith::physics {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

bool is_uniaxial(LoadCase l) {
  return l == LoadCase::uniaxial_circumferential || l == LoadCase::uniaxial_longitudinal;
}

// ---- Fung membrane ------------------------------------------------------------------------------
// Everything below is written for a "loaded" Green strain x and a "lateral" one y, with a1 the
// coefficient of the loaded axis and a2 that of the lateral axis. Q and W_vol are symmetric under
// (a1, x) ↔ (a2, y), so the longitudinal cases reuse the same code with a1 and a2 swapped.

struct FungLocal {
  double c, a1, a2, a4, t, K;
};

// Volumetric energy g(J) = K t⁻² [(J−1)² + t (ln J)²]/4 and its J-derivatives; g_t = ∂g'/∂t.
struct VolTerms {
  double g = 0, g1 = 0, g2 = 0, g1_t = 0;
};

VolTerms vol_terms(const FungLocal& f, double J) {
  VolTerms v;
  if (f.K == 0.0) return v;
  const double lnJ = std::log(J);
  const double t = f.t;
  v.g = f.K / (t * t) * ((J - 1) * (J - 1) + t * lnJ * lnJ) / 4.0;
  v.g1 = 0.5 * f.K * ((J - 1) / (t * t) + lnJ / (J * t));
  v.g2 = 0.5 * f.K * (1.0 / (t * t) + (1.0 - lnJ) / (J * J * t));
  v.g1_t = 0.5 * f.K * (-2.0 * (J - 1) / (t * t * t) - lnJ / (J * t * t));
  return v;
}

double fung_local_energy(const FungLocal& f, double x, double y) {
  const double Q = f.a1 * x * x + f.a2 * y * y + 2 * f.a4 * x * y;
  double W = 0.5 * f.c * std::expm1(Q);
  if (f.K != 0.0) {
    const double J = std::sqrt((2 * x + 1) * (2 * y + 1));
    W += vol_terms(f, J).g;
  }
  return W;
}

// First and second derivatives of W(x, y) that the uniaxial solve and its Jacobian need.
struct FungDerivs {
  double Wx, Wy, Wyy, Wxy;
  double eQ, A, B;          // e^Q, a1 x + a4 y, a4 x + a2 y
  double Jx, Jy, g1_t;      // for the t-derivatives
};

FungDerivs fung_derivs(const FungLocal& f, double x, double y) {
  FungDerivs d{};
  const double Q = f.a1 * x * x + f.a2 * y * y + 2 * f.a4 * x * y;
  d.eQ = std::exp(Q);
  d.A = f.a1 * x + f.a4 * y;
  d.B = f.a4 * x + f.a2 * y;
  // ∂/∂x [c/2 (e^Q − 1)] = c e^Q A because ∂Q/∂x = 2A; likewise for y.
  d.Wx = f.c * d.eQ * d.A;
  d.Wy = f.c * d.eQ * d.B;
  d.Wyy = f.c * d.eQ * (2 * d.B * d.B + f.a2);
  d.Wxy = f.c * d.eQ * (2 * d.A * d.B + f.a4);
  if (f.K != 0.0) {
    const double px = 2 * x + 1, py = 2 * y + 1;  // λ_x², λ_y²
    const double J = std::sqrt(px * py);
    const VolTerms v = vol_terms(f, J);
    d.Jx = J / px;
    d.Jy = J / py;
    const double Jyy = -J / (py * py);
    const double Jxy = J / (px * py);
    d.Wx += v.g1 * d.Jx;
    d.Wy += v.g1 * d.Jy;
    d.Wyy += v.g2 * d.Jy * d.Jy + v.g1 * Jyy;
    d.Wxy += v.g2 * d.Jx * d.Jy + v.g1 * Jxy;
    d.g1_t = v.g1_t;
  }
  return d;
}

// ∂W_x/∂p and ∂W_y/∂p for p = (c, a1, a2, a4, t) in the local (loaded/lateral) frame.
void fung_param_derivs(const FungLocal& f, const FungDerivs& d, double x, double y, double Wx_p[5],
                       double Wy_p[5]) {
  const double ce = f.c * d.eQ;
  Wx_p[0] = d.eQ * d.A;
  Wx_p[1] = ce * (x * x * d.A + x);
  Wx_p[2] = ce * (y * y * d.A);
  Wx_p[3] = ce * (2 * x * y * d.A + y);
  Wx_p[4] = f.K != 0.0 ? d.g1_t * d.Jx : 0.0;
  Wy_p[0] = d.eQ * d.B;
  Wy_p[1] = ce * (x * x * d.B);
  Wy_p[2] = ce * (y * y * d.B + y);
  Wy_p[3] = ce * (2 * x * y * d.B + x);
  Wy_p[4] = f.K != 0.0 ? d.g1_t * d.Jy : 0.0;
}

// Lateral Green strain y with W_y(x, y) = 0.
double lateral_strain(const FungLocal& f, double x) {
  if (f.K == 0.0) {
    // W_y = c e^Q (a4 x + a2 y) vanishes at y = −a4 x / a2.
    if (f.a2 <= 0.0) return kNaN;
    const double y = -f.a4 * x / f.a2;
    return y > -0.5 ? y : kNaN;
  }
  // W_y → −∞ as y → −1/2 (J → 0, ln J → −∞) and grows without bound for large y, so a root is
  // bracketed; Newton steps that leave the bracket are replaced by bisection.
  double lo = -0.5, hi = 0.0;
  auto Wy = [&](double y) { return fung_derivs(f, x, y).Wy; };
  for (int i = 0; i < 60 && !(Wy(hi) > 0.0); ++i) hi = 2 * hi + 0.5;
  if (!(Wy(hi) > 0.0)) return kNaN;
  // Start from the incompressible membrane guess J = 1, i.e. (2y+1) = 1/(2x+1).
  double y = std::clamp(0.5 * (1.0 / (2 * x + 1) - 1.0), lo + 1e-12, hi);
  for (int it = 0; it < 100; ++it) {
    const FungDerivs d = fung_derivs(f, x, y);
    if (!std::isfinite(d.Wy)) return kNaN;
    if (d.Wy > 0) hi = y; else lo = y;
    double next = (d.Wyy > 0) ? y - d.Wy / d.Wyy : kNaN;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::abs(next - y) <= 1e-15 * (1.0 + std::abs(y))) return next;
    y = next;
    if (hi - lo <= 1e-15) return y;
  }
  return y;
}

FungLocal local_frame(std::span<const double> p, bool organ, double K, bool loaded_is_theta) {
  FungLocal f{p[0], p[1], p[2], p[3], organ ? p[4] : 1.0, organ ? K : 0.0};
  if (!loaded_is_theta) std::swap(f.a1, f.a2);
  return f;
}

class FungModel final : public Model {
 public:
  FungModel(bool organ, double K) : organ_(organ), K_(K) {
    // Search intervals bracket Tables 5.1.1/5.1.2 (c 14.6–25.7 Pa, a 4.5–23.6, t 8.3–9.3).
    info_ = {{"c", "Pa", 1.0, 100.0}, {"a1", "1", 1.0, 50.0}, {"a2", "1", 1.0, 50.0},
             {"a4", "1", 0.0, 20.0}};
    if (organ_) info_.push_back({"t", "1", 1.0, 30.0});
  }
  std::string_view name() const override { return organ_ ? "fung-organ" : "fung-wall"; }
  const std::vector<ParameterInfo>& parameters() const override { return info_; }

  void respond(std::span<const LoadPoint> points, std::span<const double> p, std::span<double> out,
               std::span<double> jac) const override {
    const std::size_t n = info_.size();
    assert(p.size() == n && out.size() == points.size());
    assert(jac.empty() || jac.size() == points.size() * n);
    const FungLocal frames[2] = {local_frame(p, organ_, K_, false), local_frame(p, organ_, K_, true)};
    // Uniaxial wall, lateral axis free: W_x = c A1 x e^(A1 x²) with A1 = a1 − a4²/a2 in the local
    // frame — the GA's hot path (no lateral solve, one exponential per point). Per frame:
    // A1, c·A1 and a4/a2 (the lateral strain is −(a4/a2) x, physical while 1 − 2(a4/a2) x > 0).
    struct Reduced {
      double A, cA, ratio;
      bool ok;
    } reduced[2];
    for (int k = 0; k < 2; ++k) {
      const FungLocal& f = frames[k];
      reduced[k].ratio = f.a4 / f.a2;
      reduced[k].A = f.a1 - f.a4 * reduced[k].ratio;
      reduced[k].cA = f.c * reduced[k].A;
      reduced[k].ok = f.a2 > 0;
    }
    for (std::size_t i = 0; i < points.size(); ++i) {
      const LoadPoint& pt = points[i];
      const bool theta = pt.load == LoadCase::uniaxial_circumferential ||
                         pt.load == LoadCase::biaxial_circumferential;
      const FungLocal& f = frames[theta ? 1 : 0];
      if (!organ_ && jac.empty() && is_uniaxial(pt.load)) {
        const double lam = pt.x, x = 0.5 * (lam * lam - 1);
        const Reduced& r = reduced[theta ? 1 : 0];
        const bool ok = r.ok && 1.0 - 2.0 * r.ratio * x > 0 && lam > 0;
        out[i] = ok ? lam * r.cA * x * std::exp(r.A * x * x) : kNaN;
        continue;
      }
      const double lam = pt.x;
      const double x = 0.5 * (lam * lam - 1);
      double y;
      const bool uni = is_uniaxial(pt.load);
      if (uni) {
        y = lateral_strain(f, x);
      } else if (pt.load == LoadCase::displacement) {
        y = kNaN;
      } else {
        y = 0.5 * (pt.lateral_stretch * pt.lateral_stretch - 1);
      }
      if (!std::isfinite(y) || lam <= 0) {
        out[i] = kNaN;
        if (!jac.empty()) std::fill_n(jac.begin() + i * n, n, kNaN);
        continue;
      }
      if (jac.empty()) {
        // Hot path of the GA: only W_x. Nominal stress P = ∂W/∂λ = (∂W/∂E)(dE/dλ) = λ S
        // (thesis 5.1.8 with 5.1.16: T = σ/λ = λ S).
        const double Q = f.a1 * x * x + f.a2 * y * y + 2 * f.a4 * x * y;
        double Wx = f.c * std::exp(Q) * (f.a1 * x + f.a4 * y);
        if (f.K != 0.0) {
          const double px = 2 * x + 1, J = std::sqrt(px * (2 * y + 1));
          Wx += vol_terms(f, J).g1 * J / px;
        }
        out[i] = lam * Wx;
        continue;
      }
      const FungDerivs d = fung_derivs(f, x, y);
      out[i] = lam * d.Wx;
      double Wx_p[5], Wy_p[5];
      fung_param_derivs(f, d, x, y, Wx_p, Wy_p);
      double g[5];
      for (std::size_t k = 0; k < 5; ++k) {
        // Uniaxial: the lateral strain moves with p; by the implicit function theorem on
        // W_y(x, y(p); p) = 0, dy/dp = −W_y,p / W_yy.
        g[k] = uni ? lam * (Wx_p[k] - d.Wxy * Wy_p[k] / d.Wyy) : lam * Wx_p[k];
      }
      if (!theta) std::swap(g[1], g[2]);  // local a1/a2 are the global a2/a1
      std::copy_n(g, n, jac.begin() + i * n);
    }
  }

  double energy(const LoadPoint& pt, std::span<const double> p) const override {
    const bool theta = pt.load == LoadCase::uniaxial_circumferential ||
                       pt.load == LoadCase::biaxial_circumferential;
    const FungLocal f = local_frame(p, organ_, K_, theta);
    const double x = 0.5 * (pt.x * pt.x - 1);
    const double y = is_uniaxial(pt.load) ? lateral_strain(f, x)
                                          : 0.5 * (pt.lateral_stretch * pt.lateral_stretch - 1);
    return std::isfinite(y) ? fung_local_energy(f, x, y) : kNaN;
  }

 private:
  bool organ_;
  double K_;
  std::vector<ParameterInfo> info_;
};

// ---- Combined logarithmic and polynomial artery model (thesis 4.1.3–4.1.5) ----------------------
// Incompressible uniaxial extension along the fibre axis: I1 = λ² + 2/λ, I4 = λ², with
// a = I1 − 3, b = I4 − 1, a' = 2(λ − 1/λ²), b' = 2λ. W = −C1/2 ln(1 − u) + q/2 and the nominal
// stress is T = dW/dλ = C1 u' / (2(1 − u)) + q'/2.
class ArteryLogPoly final : public Model {
 public:
  ArteryLogPoly() {
    // Units: C1 and C5–C7 multiply energies (Pa); C2–C4 sit inside u, which the logarithm needs
    // dimensionless, so they are pure numbers although the thesis tables head every column "Pa".
    // Search intervals bracket Tables 4.1.1/4.1.4/4.1.5 with roughly ×3 margin.
    info_ = {{"C1", "Pa", -200.0, 200.0},     {"C2", "1", -5000.0, 5000.0},
             {"C3", "1", -2000.0, 2000.0},    {"C4", "1", -3000.0, 3000.0},
             {"C5", "Pa", 0.0, 2.0e6},        {"C6", "Pa", 0.0, 3.0e5},
             {"C7", "Pa", -7.0e5, 0.0}};
  }
  std::string_view name() const override { return "artery-logpoly"; }
  const std::vector<ParameterInfo>& parameters() const override { return info_; }

  void respond(std::span<const LoadPoint> points, std::span<const double> C, std::span<double> out,
               std::span<double> jac) const override {
    for (std::size_t i = 0; i < points.size(); ++i) {
      const double l = points[i].x;
      const double a = l * l + 2 / l - 3, b = l * l - 1;
      const double da = 2 * (l - 1 / (l * l)), db = 2 * l;
      const double u = 0.5 * C[1] * a * a + 0.5 * C[2] * b * b + C[3] * a * b;
      const double du = (C[1] * a + C[3] * b) * da + (C[2] * b + C[3] * a) * db;
      const double dq2 = (C[4] * a + C[6] * b) * da + (C[5] * b + C[6] * a) * db;
      const double one_u = 1 - u;
      const bool ok = one_u > 0 && l > 0;
      out[i] = ok ? C[0] * du / (2 * one_u) + dq2 : kNaN;
      if (jac.empty()) continue;
      double* g = jac.data() + i * 7;
      if (!ok) {
        std::fill_n(g, 7, kNaN);
        continue;
      }
      // ∂T/∂Ck for k = 2..4: C1/2 [∂u'/∂Ck /(1−u) + u' (∂u/∂Ck)/(1−u)²].
      const double u_k[3] = {0.5 * a * a, 0.5 * b * b, a * b};
      const double du_k[3] = {a * da, b * db, b * da + a * db};
      g[0] = du / (2 * one_u);
      for (int k = 0; k < 3; ++k)
        g[1 + k] = 0.5 * C[0] * (du_k[k] / one_u + du * u_k[k] / (one_u * one_u));
      g[4] = a * da;
      g[5] = b * db;
      g[6] = b * da + a * db;
    }
  }

  double energy(const LoadPoint& pt, std::span<const double> C) const override {
    const double l = pt.x;
    const double a = l * l + 2 / l - 3, b = l * l - 1;
    const double u = 0.5 * C[1] * a * a + 0.5 * C[2] * b * b + C[3] * a * b;
    const double q = C[4] * a * a + C[5] * b * b + 2 * C[6] * a * b;
    return 1 - u > 0 ? -0.5 * C[0] * std::log(1 - u) + 0.5 * q : kNaN;
  }

 private:
  std::vector<ParameterInfo> info_;
};

// ---- Mooney-Rivlin (thesis 2.2.5–2.2.7), incompressible uniaxial --------------------------------
// J = 1 so the isochoric invariants equal I1 = λ² + 2/λ and I2 = 2λ + 1/λ²;
// T = dW/dλ = 2 C1 (λ − 1/λ²) + 2 C2 (1 − 1/λ³).
class MooneyRivlin final : public Model {
 public:
  MooneyRivlin() { info_ = {{"C1", "Pa", -1.0e5, 1.0e5}, {"C2", "Pa", -1.0e5, 1.0e5}}; }
  std::string_view name() const override { return "mooney-rivlin"; }
  const std::vector<ParameterInfo>& parameters() const override { return info_; }
  void respond(std::span<const LoadPoint> points, std::span<const double> C, std::span<double> out,
               std::span<double> jac) const override {
    for (std::size_t i = 0; i < points.size(); ++i) {
      const double l = points[i].x;
      const double d1 = 2 * (l - 1 / (l * l)), d2 = 2 * (1 - 1 / (l * l * l));
      out[i] = l > 0 ? C[0] * d1 + C[1] * d2 : kNaN;
      if (!jac.empty()) {
        jac[2 * i] = d1;
        jac[2 * i + 1] = d2;
      }
    }
  }
  double energy(const LoadPoint& pt, std::span<const double> C) const override {
    const double l = pt.x;
    return C[0] * (l * l + 2 / l - 3) + C[1] * (2 * l + 1 / (l * l) - 3);
  }

 private:
  std::vector<ParameterInfo> info_;
};

// ---- Ogden (thesis 2.2.3–2.2.4), incompressible -------------------------------------------------
// W = Σ μp/αp (λ1^αp + λ2^αp + λ3^αp − 3) with λ3 = 1/(λ1 λ2). The loaded axis is 1 and axis 3
// (thickness) is stress-free, so the nominal stress along 1 is T = Σ μp (λ1^αp − λ3^αp)/λ1.
// Uniaxial: λ2 = λ3 = λ^(−1/2), T = Σ μp (λ^(αp−1) − λ^(−αp/2−1)); biaxial: λ2 is the prescribed
// lateral stretch (equibiaxial λ2 = λ gives T = Σ μp (λ^(αp−1) − λ^(−2αp−1))).
class Ogden final : public Model {
 public:
  explicit Ogden(int terms) {
    if (terms < 1 || terms > 6)
      throw UsageError("ogden: the number of terms must be 1..6, got " + std::to_string(terms));
    for (int k = 1; k <= terms; ++k) {
      info_.push_back({"mu" + std::to_string(k), "Pa", -1.0e5, 1.0e5});
      info_.push_back({"alpha" + std::to_string(k), "1", -30.0, 30.0});
    }
  }
  std::string_view name() const override { return "ogden"; }
  const std::vector<ParameterInfo>& parameters() const override { return info_; }
  void respond(std::span<const LoadPoint> points, std::span<const double> p, std::span<double> out,
               std::span<double> jac) const override {
    const std::size_t n = info_.size();
    for (std::size_t i = 0; i < points.size(); ++i) {
      const double l1 = points[i].x;
      const bool uni = is_uniaxial(points[i].load);
      const double l2 = uni ? 1.0 / std::sqrt(l1) : points[i].lateral_stretch;
      const double l3 = 1.0 / (l1 * l2);
      const double ln1 = std::log(l1), ln3 = std::log(l3);
      const bool ok = l1 > 0 && l2 > 0 && points[i].load != LoadCase::displacement;
      double T = 0;
      for (std::size_t k = 0; k < n; k += 2) {
        const double mu = p[k], al = p[k + 1];
        const double e1 = std::pow(l1, al) / l1, e3 = std::pow(l3, al) / l1;
        T += mu * (e1 - e3);
        if (!jac.empty()) {
          jac[i * n + k] = e1 - e3;
          jac[i * n + k + 1] = mu * (e1 * ln1 - e3 * ln3);
        }
      }
      out[i] = ok ? T : kNaN;
    }
  }
  double energy(const LoadPoint& pt, std::span<const double> p) const override {
    const double l1 = pt.x;
    const double l2 = is_uniaxial(pt.load) ? 1.0 / std::sqrt(l1) : pt.lateral_stretch;
    const double l3 = 1.0 / (l1 * l2);
    double W = 0;
    for (std::size_t k = 0; k < info_.size(); k += 2) {
      const double mu = p[k], al = p[k + 1];
      W += mu / al * (std::pow(l1, al) + std::pow(l2, al) + std::pow(l3, al) - 3);
    }
    return W;
  }

 private:
  std::vector<ParameterInfo> info_;
};

// ---- Modified Kelvin cutting law (thesis 4.2.8) -------------------------------------------------
// F(u) = μ0 u (1 − e^(−s)), s = u μ1/(v η1). μ1 and η1 enter only through their ratio, so a
// force–displacement curve determines μ0 and μ1/η1 but not μ1 and η1 separately.
class KelvinCutting final : public Model {
 public:
  explicit KelvinCutting(double v) : v_(v) {
    if (!(v > 0)) throw UsageError("kelvin-cutting: the blade speed must be > 0 m/s");
    // Intervals bracket Table 4.2.2 (both columns) by about a decade.
    info_ = {{"mu0", "N/m", 100.0, 1.0e5}, {"mu1", "N/m", 1.0, 1.0e5},
             {"eta1", "N*s/m", 10.0, 5.0e5}};
  }
  std::string_view name() const override { return "kelvin-cutting"; }
  const std::vector<ParameterInfo>& parameters() const override { return info_; }
  void respond(std::span<const LoadPoint> points, std::span<const double> p, std::span<double> out,
               std::span<double> jac) const override {
    const double mu0 = p[0], mu1 = p[1], eta1 = p[2];
    for (std::size_t i = 0; i < points.size(); ++i) {
      const double u = points[i].x;
      const double s = u * mu1 / (v_ * eta1);
      const double e = std::exp(-s), one_e = -std::expm1(-s);
      out[i] = mu0 * u * one_e;
      if (!jac.empty()) {
        // dF/ds = μ0 u e^(−s); ds/dμ1 = s/μ1, ds/dη1 = −s/η1.
        const double dFds = mu0 * u * e;
        jac[3 * i] = u * one_e;
        jac[3 * i + 1] = dFds * u / (v_ * eta1);
        jac[3 * i + 2] = -dFds * s / eta1;
      }
    }
  }
  double energy(const LoadPoint&, std::span<const double>) const override { return kNaN; }

 private:
  double v_;
  std::vector<ParameterInfo> info_;
};

}  // namespace

double Model::respond_one(const LoadPoint& point, std::span<const double> p) const {
  double out = 0;
  respond(std::span<const LoadPoint>(&point, 1), p, std::span<double>(&out, 1));
  return out;
}

std::vector<std::string> model_names() {
  return {"fung-wall", "fung-organ", "artery-logpoly", "mooney-rivlin", "ogden", "kelvin-cutting"};
}

std::unique_ptr<Model> make_model(std::string_view name, const ModelOptions& o) {
  if (name == "fung-wall") return std::make_unique<FungModel>(false, 0.0);
  if (name == "fung-organ") {
    if (!(o.bulk_modulus_Pa > 0)) throw UsageError("fung-organ: the bulk modulus must be > 0 Pa");
    return std::make_unique<FungModel>(true, o.bulk_modulus_Pa);
  }
  if (name == "artery-logpoly") return std::make_unique<ArteryLogPoly>();
  if (name == "mooney-rivlin") return std::make_unique<MooneyRivlin>();
  if (name == "ogden") return std::make_unique<Ogden>(o.ogden_terms);
  if (name == "kelvin-cutting") return std::make_unique<KelvinCutting>(o.blade_speed_m_per_s);
  std::string known;
  for (const auto& m : model_names()) known += (known.empty() ? "" : ", ") + m;
  throw UsageError("unknown model '" + std::string(name) + "'", "use one of: " + known);
}

double fung_energy(const FungParameters& f, double E_theta, double E_z) {
  return fung_local_energy({f.c_Pa, f.a1, f.a2, f.a4, f.t, f.bulk_Pa}, E_theta, E_z);
}

void fung_pk2(const FungParameters& f, double E_theta, double E_z, double& S_theta, double& S_z) {
  const FungDerivs d = fung_derivs({f.c_Pa, f.a1, f.a2, f.a4, f.t, f.bulk_Pa}, E_theta, E_z);
  S_theta = d.Wx;
  S_z = d.Wy;
}

double fung_lateral_strain(const FungParameters& f, double E_loaded, bool loaded_is_theta) {
  FungLocal l{f.c_Pa, f.a1, f.a2, f.a4, f.t, f.bulk_Pa};
  if (!loaded_is_theta) std::swap(l.a1, l.a2);
  return lateral_strain(l, E_loaded);
}

double artery_logpoly_stress_as_printed(double l, std::span<const double> C) {
  const double a = l * l + 2 / l - 3, b = l * l - 1;
  const double G = C[1] * a - C[2] * b * b + 2 * C[3] * a * b;
  return (2 * C[0] * (C[1] * a + C[3] * b) / (1 - G / 2) + 2 * C[4] * a + 2 * C[6] * b) *
             (l - 1 / (l * l)) +
         (2 * C[0] * (C[2] * b + C[3] * a) / (1 - G / 2) + 2 * C[5] * b + 2 * C[6] * a) * l;
}

double kelvin_force_N(double u, double mu0, double mu1, double eta1, double v) {
  return -mu0 * u * std::expm1(-u * mu1 / (v * eta1));
}

double kelvin_modulus_Pa(double u, double mu0, double mu1, double eta1, double v,
                         const CuttingGeometry& g) {
  // k = F/u (4.2.12) and E = k L0/A0 (4.2.10).
  return -mu0 * g.length_m * std::expm1(-u * mu1 / (v * eta1)) / g.area_m2;
}

double kelvin_displacement_m(double E, double mu0, double mu1, double eta1, double v,
                             const CuttingGeometry& g) {
  const double r = E * g.area_m2 / (mu0 * g.length_m);
  if (!(r >= 0 && r < 1)) return kNaN;
  return -(v * eta1 / mu1) * std::log1p(-r);
}

}  // namespace organsmith::physics
