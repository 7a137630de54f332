#include "segmentation/snake.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <algorithm>
#include <limits>
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

bool point_in_polygon(const std::vector<Point2>& p, Point2 q) {
  bool in = false;
  const std::size_t n = p.size();
  for (std::size_t i = 0, j = n - 1; i < n; j = i++) {
    const Point2& a = p[i];
    const Point2& b = p[j];
    if ((a.y > q.y) != (b.y > q.y) && q.x < (b.x - a.x) * (q.y - a.y) / (b.y - a.y) + a.x) in = !in;
  }
  return in;
}

namespace {

/// Convex hull (Andrew's monotone chain), counter-clockwise.
std::vector<Point2> convex_hull(std::vector<Point2> p) {
  std::sort(p.begin(), p.end(), [](const Point2& a, const Point2& b) { return a.x < b.x || (a.x == b.x && a.y < b.y); });
  auto turn = [](const Point2& o, const Point2& a, const Point2& b) {
    return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
  };
  std::vector<Point2> h(2 * p.size());
  std::size_t k = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && turn(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (std::size_t i = p.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && turn(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  h.resize(k > 1 ? k - 1 : k);
  return h;
}

double segment_distance(Point2 q, Point2 a, Point2 b) {
  const double dx = b.x - a.x, dy = b.y - a.y, l2 = dx * dx + dy * dy;
  const double t = l2 > 0 ? std::clamp(((q.x - a.x) * dx + (q.y - a.y) * dy) / l2, 0.0, 1.0) : 0.0;
  return std::hypot(q.x - a.x - t * dx, q.y - a.y - t * dy);
}

/// True when the chord p[i]–p[j] runs inside the polygon: its midpoint is inside and it crosses
/// no edge.
bool chord_inside(const std::vector<Point2>& p, std::size_t i, std::size_t j) {
  const Point2 a = p[i], b = p[j];
  if (!point_in_polygon(p, {0.5 * (a.x + b.x), 0.5 * (a.y + b.y)})) return false;
  const std::size_t n = p.size();
  for (std::size_t e = 0; e < n; ++e) {
    const std::size_t f = (e + 1) % n;
    if (e == i || f == i || e == j || f == j) continue;
    double t;
    if (cross(a, b, p[e], p[f], t)) return false;
  }
  return true;
}

}  // namespace

double distance_to_boundary(const std::vector<Point2>& p, Point2 q) {
  double d = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < p.size(); ++i) d = std::min(d, segment_distance(q, p[i], p[(i + 1) % p.size()]));
  return d;
}

std::vector<Point2> cut_necks(const std::vector<Point2>& input, const std::vector<Point2>& keep, const NeckOptions& o) {
  std::vector<Point2> p = input;
  if (polygon_area(p) < 0) std::reverse(p.begin(), p.end());
  for (int cut = 0; cut < o.max_cuts && p.size() >= 8; ++cut) {
    const std::size_t n = p.size();
    const std::vector<Point2> hull = convex_hull(p);
    if (hull.size() < 3) break;
    // Depth of each point inside the hull.
    std::vector<double> depth(n, 0.0);
    for (std::size_t i = 0; i < n; ++i) {
      double d = 1e300;
      for (std::size_t h = 0; h < hull.size(); ++h) d = std::min(d, segment_distance(p[i], hull[h], hull[(h + 1) % hull.size()]));
      depth[i] = d;
    }
    // Prefix sums of the shoelace terms: the area of the lobe p[i..j] closed by the chord in O(1).
    std::vector<double> pre(n + 1, 0.0);
    for (std::size_t i = 0; i < n; ++i) {
      const Point2& a = p[i];
      const Point2& b = p[(i + 1) % n];
      pre[i + 1] = pre[i] + (a.x * b.y - b.x * a.y);
    }
    const double total = 0.5 * pre[n];
    if (total <= 0) break;
    struct Cand {
      double ratio;
      std::size_t i, j;
    };
    std::vector<Cand> cands;
    for (std::size_t i = 0; i < n; ++i) {
      // Concavity bottoms only: deep enough, and the deepest among their neighbours.
      if (depth[i] < o.min_depth_mm || depth[i] < depth[(i + n - 1) % n] || depth[i] < depth[(i + 1) % n]) continue;
      for (std::size_t j = 0; j < n; ++j) {
        const std::size_t gap = (j + n - i) % n;
        if (gap < 3 || gap > n - 3) continue;
        const std::size_t lo = std::min(i, j), hi = std::max(i, j);
        const double a1 = 0.5 * (pre[hi] - pre[lo] + (p[hi].x * p[lo].y - p[lo].x * p[hi].y));
        const double a2 = total - a1;
        const double amin = std::min(a1, a2);
        if (amin < o.min_lobe_fraction * total || amin <= 0) continue;
        const double d = std::hypot(p[i].x - p[j].x, p[i].y - p[j].y);
        const double ratio = d / (2.0 * std::sqrt(amin / std::numbers::pi));
        if (ratio < o.max_neck_ratio) cands.push_back({ratio, i, j});
      }
    }
    std::sort(cands.begin(), cands.end(), [](const Cand& a, const Cand& b) {
      return a.ratio < b.ratio || (a.ratio == b.ratio && (a.i < b.i || (a.i == b.i && a.j < b.j)));
    });
    bool done = true;
    for (const Cand& c : cands) {
      if (!chord_inside(p, c.i, c.j)) continue;
      const std::size_t lo = std::min(c.i, c.j), hi = std::max(c.i, c.j);
      std::vector<Point2> a(p.begin() + std::ptrdiff_t(lo), p.begin() + std::ptrdiff_t(hi) + 1);
      std::vector<Point2> b(p.begin() + std::ptrdiff_t(hi), p.end());
      b.insert(b.end(), p.begin(), p.begin() + std::ptrdiff_t(lo) + 1);
      int ka = 0, kb = 0;
      for (const Point2& q : keep) ka += point_in_polygon(a, q), kb += point_in_polygon(b, q);
      const bool take_a = ka != kb ? ka > kb : std::abs(polygon_area(a)) >= std::abs(polygon_area(b));
      std::vector<Point2> kept = take_a ? std::move(a) : std::move(b);
      // Re-space the chord (it is one long edge) like the rest of the contour.
      const double len = polygon_length(kept);
      const double spacing = polygon_length(p) / double(n);
      p = resample_closed(kept, std::max(8, int(std::lround(len / spacing))));
      done = false;
      break;
    }
    if (done) break;
  }
  return p;
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
