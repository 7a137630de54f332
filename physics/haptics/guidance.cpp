#include "physics/haptics/guidance.h"

#include "core/errors.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace organsmith::physics {

namespace {

constexpr int kLeafSize = 4;
constexpr int kMaxStack = 128;

/// Closest point of segment [a, b] to q: parameter t in [0, 1].
inline double segment_parameter(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& q) {
  const Eigen::Vector3d ab = b - a;
  const double l2 = ab.squaredNorm();
  if (!(l2 > 0.0)) return 0.0;
  return std::clamp((q - a).dot(ab) / l2, 0.0, 1.0);
}

inline double box_distance2(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Vector3d& q) {
  const Eigen::Vector3d d = (lo - q).cwiseMax(q - hi).cwiseMax(0.0);
  return d.squaredNorm();
}

}  // namespace

PathIndex::PathIndex(Polyline path) : path_(std::move(path)) {
  const auto& p = path_.points_lps_mm;
  if (p.empty())
    throw InputError(ExitCode::unsupported_input, "the guidance path '" + path_.name + "' has no point", {},
                     "give a path with at least one point (LPS mm)");
  for (const auto& v : p)
    if (!v.allFinite())
      throw InputError(ExitCode::unsupported_input, "the guidance path '" + path_.name + "' has a non-finite coordinate",
                       {}, "every coordinate must be a finite number of millimetres");
  if (p.size() == 1) {
    seg_a_.push_back(p[0]);
    seg_b_.push_back(p[0]);
  } else {
    for (std::size_t i = 0; i + 1 < p.size(); ++i) seg_a_.push_back(p[i]), seg_b_.push_back(p[i + 1]);
    if (path_.closed && p.size() > 2) seg_a_.push_back(p.back()), seg_b_.push_back(p.front());
  }
  cumulative_mm_.resize(seg_a_.size() + 1, 0.0);
  for (std::size_t s = 0; s < seg_a_.size(); ++s) cumulative_mm_[s + 1] = cumulative_mm_[s] + (seg_b_[s] - seg_a_[s]).norm();
  order_.resize(seg_a_.size());
  std::iota(order_.begin(), order_.end(), 0);
  nodes_.reserve(2 * seg_a_.size() / kLeafSize + 2);
  build(0, std::int32_t(order_.size()), 0);
  // Median splits keep the depth near log2(segments / 4); the query stack holds depth + 1 nodes.
  if (depth_ + 2 > kMaxStack) throw InputError(ExitCode::unsupported_input, "the guidance path is too long", {});
}

std::int32_t PathIndex::build(std::int32_t first, std::int32_t count, int depth) {
  depth_ = std::max(depth_, depth);
  Node n;
  n.lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  n.hi = -n.lo;
  for (std::int32_t i = first; i < first + count; ++i) {
    const auto s = std::size_t(order_[std::size_t(i)]);
    n.lo = n.lo.cwiseMin(seg_a_[s]).cwiseMin(seg_b_[s]);
    n.hi = n.hi.cwiseMax(seg_a_[s]).cwiseMax(seg_b_[s]);
  }
  const std::int32_t id = std::int32_t(nodes_.size());
  nodes_.push_back(n);
  // The tree depth stays logarithmic (median splits), far below the query stack size.
  if (count <= kLeafSize) {
    nodes_[std::size_t(id)].first = first;
    nodes_[std::size_t(id)].count = count;
    return id;
  }
  int axis = 0;
  (n.hi - n.lo).maxCoeff(&axis);
  const auto mid = order_.begin() + first + count / 2;
  std::nth_element(order_.begin() + first, mid, order_.begin() + first + count, [&](std::int32_t a, std::int32_t b) {
    const double ca = seg_a_[std::size_t(a)][axis] + seg_b_[std::size_t(a)][axis];
    const double cb = seg_a_[std::size_t(b)][axis] + seg_b_[std::size_t(b)][axis];
    return ca < cb || (ca == cb && a < b);
  });
  const std::int32_t left = build(first, count / 2, depth + 1);
  const std::int32_t right = build(first + count / 2, count - count / 2, depth + 1);
  nodes_[std::size_t(id)].left = left;
  nodes_[std::size_t(id)].right = right;
  return id;
}

void PathIndex::test_segment(std::int32_t s, const Eigen::Vector3d& q, NearestPoint& best, double& best_d2) const noexcept {
  const auto& a = seg_a_[std::size_t(s)];
  const auto& b = seg_b_[std::size_t(s)];
  const double t = segment_parameter(a, b, q);
  const Eigen::Vector3d c = a + t * (b - a);
  const double d2 = (q - c).squaredNorm();
  if (d2 < best_d2 || (d2 == best_d2 && s < best.segment)) {
    best_d2 = d2;
    best.point_lps_mm = c;
    best.segment = s;
    best.t = t;
  }
}

NearestPoint PathIndex::nearest(const Eigen::Vector3d& q) const noexcept {
  NearestPoint best;
  double best_d2 = std::numeric_limits<double>::infinity();
  std::int32_t stack[kMaxStack];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[std::size_t(stack[--top])];
    if (box_distance2(n.lo, n.hi, q) > best_d2) continue;
    if (n.left < 0) {
      for (std::int32_t i = n.first; i < n.first + n.count; ++i) test_segment(order_[std::size_t(i)], q, best, best_d2);
      continue;
    }
    const double dl = box_distance2(nodes_[std::size_t(n.left)].lo, nodes_[std::size_t(n.left)].hi, q);
    const double dr = box_distance2(nodes_[std::size_t(n.right)].lo, nodes_[std::size_t(n.right)].hi, q);
    // Push the farther child first so that the nearer one is searched first.
    if (dl <= dr) {
      stack[top++] = n.right;
      stack[top++] = n.left;
    } else {
      stack[top++] = n.left;
      stack[top++] = n.right;
    }
  }
  best.distance_mm = std::sqrt(best_d2);
  const auto s = std::size_t(best.segment);
  best.arc_length_mm = cumulative_mm_[s] + best.t * (cumulative_mm_[s + 1] - cumulative_mm_[s]);
  return best;
}

NearestPoint PathIndex::nearest_brute_force(const Eigen::Vector3d& q) const noexcept {
  NearestPoint best;
  double best_d2 = std::numeric_limits<double>::infinity();
  for (std::int32_t s = 0; s < std::int32_t(seg_a_.size()); ++s) test_segment(s, q, best, best_d2);
  best.distance_mm = std::sqrt(best_d2);
  const auto s = std::size_t(best.segment);
  best.arc_length_mm = cumulative_mm_[s] + best.t * (cumulative_mm_[s + 1] - cumulative_mm_[s]);
  return best;
}

void validate(const GuidanceOptions& o) {
  for (double xi : o.xi_N_per_mm)
    if (!(xi > 0.0) || !std::isfinite(xi))
      throw UsageError("guidance stiffness ξ must be positive and finite (N/mm)", "e.g. 0.3, 0.6, 0.9");
  if (!(o.band_edges_mm[0] > 0.0) || !(o.band_edges_mm[1] > o.band_edges_mm[0]) || !std::isfinite(o.band_edges_mm[1]))
    throw UsageError("guidance band edges must be positive, finite and increasing (mm)", "e.g. 2, 5");
}

int xi_band(double d, const GuidanceOptions& o) noexcept {
  if (d < o.band_edges_mm[0]) return 0;
  if (d < o.band_edges_mm[1]) return 1;
  return 2;
}

double staged_potential_mJ(double d, const GuidanceOptions& o) noexcept {
  // ∫₀^d ξ(s) s ds, band by band.
  const double e0 = o.band_edges_mm[0], e1 = o.band_edges_mm[1];
  const auto& xi = o.xi_N_per_mm;
  if (d < e0) return 0.5 * xi[0] * d * d;
  double u = 0.5 * xi[0] * e0 * e0;
  if (d < e1) return u + 0.5 * xi[1] * (d * d - e0 * e0);
  u += 0.5 * xi[1] * (e1 * e1 - e0 * e0);
  return u + 0.5 * xi[2] * (d * d - e1 * e1);
}

GuidanceSample guidance_force(const PathIndex& path, const Eigen::Vector3d& q, const GuidanceOptions& o) noexcept {
  GuidanceSample g;
  g.goal = path.nearest(q);
  g.band = xi_band(g.goal.distance_mm, o);
  g.xi_N_per_mm = o.xi_N_per_mm[std::size_t(g.band)];
  g.potential_mJ = staged_potential_mJ(g.goal.distance_mm, o);
  g.force_N = -g.xi_N_per_mm * (q - g.goal.point_lps_mm);
  return g;
}

Eigen::Vector3d gradient_descent_step(const PathIndex& path, const Eigen::Vector3d& q, double alpha_mm_per_N,
                                      const GuidanceOptions& o) noexcept {
  const GuidanceSample g = guidance_force(path, q, o);
  return q + alpha_mm_per_N * g.force_N;
}

}  // namespace organsmith::physics
