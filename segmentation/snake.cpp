#include "segmentation/snake.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <map>
#include <numbers>
#include <tuple>

namespace organsmith::seg {

double polygon_area(const std::vector<Point2>& p) {
  double a = 0;
  const std::size_t n = p.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Point2& q = p[i];
    const Point2& r = p[(i + 1) % n];
    a += q.x * r.y - r.x * q.y;
  }
  return 0.5 * a;
}

double polygon_length(const std::vector<Point2>& p) {
  double l = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Point2& q = p[i];
    const Point2& r = p[(i + 1) % p.size()];
    l += std::hypot(r.x - q.x, r.y - q.y);
  }
  return l;
}

std::vector<Point2> resample_closed(const std::vector<Point2>& p, int n) {
  const std::size_t m = p.size();
  std::vector<double> cum(m + 1, 0.0);
  for (std::size_t i = 0; i < m; ++i) {
    const Point2& q = p[i];
    const Point2& r = p[(i + 1) % m];
    cum[i + 1] = cum[i] + std::hypot(r.x - q.x, r.y - q.y);
  }
  const double total = cum[m];
  std::vector<Point2> out;
  out.reserve(std::size_t(n));
  if (total <= 0) {
    out.assign(std::size_t(n), p.front());
    return out;
  }
  std::size_t seg = 0;
  for (int k = 0; k < n; ++k) {
    const double s = total * k / n;
    while (seg + 1 < m && cum[seg + 1] < s) ++seg;
    const double len = cum[seg + 1] - cum[seg];
    const double t = len > 0 ? (s - cum[seg]) / len : 0.0;
    const Point2& q = p[seg];
    const Point2& r = p[(seg + 1) % m];
    out.push_back({q.x + t * (r.x - q.x), q.y + t * (r.y - q.y)});
  }
  return out;
}

namespace {

// Proper crossing of segments ab and cd; returns the parameter along ab.
bool cross(const Point2& a, const Point2& b, const Point2& c, const Point2& d, double& t) {
  const double rx = b.x - a.x, ry = b.y - a.y, sx = d.x - c.x, sy = d.y - c.y;
  const double den = rx * sy - ry * sx;
  if (std::abs(den) < 1e-15) return false;
  const double qx = c.x - a.x, qy = c.y - a.y;
  t = (qx * sy - qy * sx) / den;
  const double u = (qx * ry - qy * rx) / den;
  return t > 0 && t < 1 && u > 0 && u < 1;
}

bool find_crossing(const std::vector<Point2>& p, std::size_t& i_out, std::size_t& j_out, double& t_out) {
  const std::size_t n = p.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Point2& a = p[i];
    const Point2& b = p[(i + 1) % n];
    const double xmin = std::min(a.x, b.x), xmax = std::max(a.x, b.x);
    const double ymin = std::min(a.y, b.y), ymax = std::max(a.y, b.y);
    for (std::size_t j = i + 2; j < n; ++j) {
      if (i == 0 && j == n - 1) continue;  // adjacent through the closing edge
      const Point2& c = p[j];
      const Point2& d = p[(j + 1) % n];
      if (std::max(c.x, d.x) < xmin || std::min(c.x, d.x) > xmax || std::max(c.y, d.y) < ymin ||
          std::min(c.y, d.y) > ymax)
        continue;
      double t;
      if (cross(a, b, c, d, t)) {
        i_out = i;
        j_out = j;
        t_out = t;
        return true;
      }
    }
  }
  return false;
}

}  // namespace

bool self_intersects(const std::vector<Point2>& p) {
  std::size_t i, j;
  double t;
  return find_crossing(p, i, j, t);
}

void remove_loops(std::vector<Point2>& p) {
  std::size_t i, j;
  double t;
  while (p.size() >= 4 && find_crossing(p, i, j, t)) {
    const std::size_t n = p.size();
    const Point2 x{p[i].x + t * (p[(i + 1) % n].x - p[i].x), p[i].y + t * (p[(i + 1) % n].y - p[i].y)};
    // Loop A: x, p[i+1..j]; loop B: x, p[j+1..n-1], p[0..i].
    std::vector<Point2> a{x}, b{x};
    for (std::size_t k = i + 1; k <= j; ++k) a.push_back(p[k]);
    for (std::size_t k = j + 1; k < n; ++k) b.push_back(p[k]);
    for (std::size_t k = 0; k <= i; ++k) b.push_back(p[k]);
    p = std::abs(polygon_area(a)) >= std::abs(polygon_area(b)) ? std::move(a) : std::move(b);
  }
}

std::vector<Point2> circle(Point2 c, double r, int n) {
  std::vector<Point2> out;
  for (int k = 0; k < n; ++k) {
    const double t = 2 * std::numbers::pi * k / n;
    out.push_back({c.x + r * std::cos(t), c.y + r * std::sin(t)});
  }
  return out;
}

namespace {

// Factorisation of (I + γA) for one (N, h) — the rest of the key is fixed per evolve call.
class ImplicitSolver {
 public:
  ImplicitSolver(int n, double h, const SnakeOptions& o) {
    const double a = o.alpha / (h * h), b = o.beta / (h * h * h * h);
    // Rows of −α∂² + β∂⁴ on a closed contour: [β, −α−4β, 2α+6β, −α−4β, β], cyclic.
    Eigen::MatrixXd m = Eigen::MatrixXd::Identity(n, n);
    const double c[5] = {b, -a - 4 * b, 2 * a + 6 * b, -a - 4 * b, b};
    for (int i = 0; i < n; ++i)
      for (int d = -2; d <= 2; ++d) m(i, ((i + d) % n + n) % n) += o.gamma * c[d + 2];
    llt_.compute(m);
    assert(llt_.info() == Eigen::Success);
  }
  void solve(Eigen::VectorXd& x) const { llt_.solveInPlace(x); }

 private:
  Eigen::LLT<Eigen::MatrixXd> llt_;
};

void orient_ccw(std::vector<Point2>& p) {
  if (polygon_area(p) < 0) std::reverse(p.begin(), p.end());
}

}  // namespace

SnakeResult evolve_snake(const std::vector<Point2>& initial, const SnakeForces& f, const SnakeOptions& o) {
  assert(initial.size() >= 3);
  SnakeResult res;
  std::map<std::pair<int, long long>, ImplicitSolver> solvers;
  auto resample = [&](std::vector<Point2>& p, double& h) {
    const double len = polygon_length(p);
    const int n = std::max(o.min_points, int(std::lround(len / o.point_spacing_mm)));
    p = resample_closed(p, n);
    h = len / n;
  };
  std::vector<Point2> p = initial;
  orient_ccw(p);
  double h = 1.0;
  resample(p, h);
  int quiet = 0;
  Eigen::VectorXd bx, by;
  for (int it = 0; it < o.max_iterations; ++it) {
    const int n = int(p.size());
    // The factorisation is keyed by N and h quantised to 1 %: h changes only through the
    // resampling, and a 1 % change in h alters the stiffness by a few per cent at most.
    const long long hq = std::llround(std::log(h) * 100.0);
    auto key = std::make_pair(n, hq);
    auto sit = solvers.find(key);
    if (sit == solvers.end()) sit = solvers.emplace(key, ImplicitSolver(n, std::exp(hq / 100.0), o)).first;
    bx.resize(n);
    by.resize(n);
    for (int i = 0; i < n; ++i) {
      const Point2& q = p[std::size_t(i)];
      const double px = q.x / f.spacing_x_mm, py = q.y / f.spacing_y_mm;
      double fx = o.kappa * f.gvf_u->sample(px, py);
      double fy = o.kappa * f.gvf_v->sample(px, py);
      if (f.pressure) {
        const Point2& prev = p[std::size_t((i + n - 1) % n)];
        const Point2& next = p[std::size_t((i + 1) % n)];
        double tx = next.x - prev.x, ty = next.y - prev.y;
        const double tl = std::hypot(tx, ty);
        if (tl > 0) {
          tx /= tl;
          ty /= tl;
          const double pr = o.balloon * f.pressure->sample(px, py);
          fx += pr * ty;  // outward normal of a counter-clockwise contour
          fy -= pr * tx;
        }
      }
      const double fl = std::hypot(fx, fy) * o.gamma;
      const double s = fl > o.max_step_mm ? o.max_step_mm / fl : 1.0;
      bx[i] = q.x + o.gamma * fx * s;
      by[i] = q.y + o.gamma * fy * s;
    }
    sit->second.solve(bx);
    sit->second.solve(by);
    double motion = 0;
    for (int i = 0; i < n; ++i) {
      Point2& q = p[std::size_t(i)];
      motion += std::hypot(bx[i] - q.x, by[i] - q.y);
      q = {bx[i], by[i]};
    }
    motion /= n;
    remove_loops(p);
    orient_ccw(p);
    if (p.size() < 3 || std::abs(polygon_area(p)) < 1e-6) {
      res.points = p;
      res.iterations = it + 1;
      return res;  // collapsed; the caller treats a tiny area as "organ not here"
    }
    if ((it + 1) % o.reparametrise_every == 0 || int(p.size()) != n) resample(p, h);
    res.iterations = it + 1;
    quiet = motion < o.converged_mm ? quiet + 1 : 0;
    if (quiet >= 10) {
      res.converged = true;
      break;
    }
  }
  resample(p, h);
  remove_loops(p);
  orient_ccw(p);
  res.points = std::move(p);
  return res;
}

}  // namespace organsmith::seg
