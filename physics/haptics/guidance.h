#pragma once
// Haptic guidance toward a predefined path (thesis §5.2.2–5.2.3, eqs 5.2.3–5.2.8): the nearest
// point of the path, the staged potential field and its force, and the gradient-descent pull.
// Derivations, units and the departures from the print are in physics/haptics/HAPTICS.md.
//
// Units: positions in LPS mm, stiffness ξ in N/mm, forces in N, energies in mJ (N·mm).

#include "core/geometry.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <vector>

namespace organsmith::physics {

/// The point of a path nearest to a query point.
struct NearestPoint {
  Eigen::Vector3d point_lps_mm = Eigen::Vector3d::Zero();  ///< q_goal
  double distance_mm = 0.0;                                ///< d(q, q_goal), eq. 5.2.4
  std::int32_t segment = -1;                               ///< segment index (i → i+1; closing segment last)
  double t = 0.0;                                          ///< position on that segment, [0, 1]
  double arc_length_mm = 0.0;                              ///< arc length of q_goal from the first point
};

/// A polyline prepared for nearest-point queries: an axis-aligned bounding-box tree over its
/// segments, searched nearest box first. Queries allocate nothing and are safe from several
/// threads at once. Built once; the polyline is copied.
class PathIndex {
 public:
  /// Throws InputError (exit code 18) when the path has no point or a non-finite coordinate.
  explicit PathIndex(Polyline path);

  /// Nearest point of the path to q (ties: the lower segment index). q must be finite.
  NearestPoint nearest(const Eigen::Vector3d& q_lps_mm) const noexcept;
  /// The same by testing every segment: the reference the tree is checked against.
  NearestPoint nearest_brute_force(const Eigen::Vector3d& q_lps_mm) const noexcept;

  const Polyline& path() const { return path_; }
  double length_mm() const { return cumulative_mm_.empty() ? 0.0 : cumulative_mm_.back(); }
  std::size_t segment_count() const { return seg_a_.size(); }

 private:
  struct Node {
    Eigen::Vector3d lo, hi;
    std::int32_t first = 0, count = 0;  ///< leaf: segments [first, first + count) of order_
    std::int32_t left = -1, right = -1; ///< inner node children
  };
  std::int32_t build(std::int32_t first, std::int32_t count, int depth);
  void test_segment(std::int32_t s, const Eigen::Vector3d& q, NearestPoint& best, double& best_d2) const noexcept;

  Polyline path_;
  std::vector<Eigen::Vector3d> seg_a_, seg_b_;
  std::vector<double> cumulative_mm_;   ///< arc length at the start of each segment, plus the total
  std::vector<std::int32_t> order_;     ///< segment ids in tree-leaf order
  std::vector<Node> nodes_;
  int depth_ = 0;
};

/// The staged potential field (§5.2.2: "three energy intensity stages (ξ = 3, 6, 9) with a
/// decreasing order as the manipulation point gets closer"): ξ = xi_N_per_mm[b] in band b, where
/// band 0 is d < band_edges_mm[0], band 1 is band_edges_mm[0] ≤ d < band_edges_mm[1], band 2 is
/// d ≥ band_edges_mm[1]. The thesis prints ξ without a unit; organsmith reads 3, 6, 9 in units of
/// 0.1 N/mm (HAPTICS.md explains the choice).
struct GuidanceOptions {
  std::array<double, 3> xi_N_per_mm = {0.3, 0.6, 0.9};  ///< ξ of each band, N/mm (default 0.3, 0.6, 0.9)
  std::array<double, 2> band_edges_mm = {2.0, 5.0};     ///< band boundaries, mm (default 2, 5)
};

/// Throws UsageError when ξ are not positive and finite or the edges not increasing and positive.
void validate(const GuidanceOptions& options);

/// Band index (0, 1, 2) of a distance to the path.
int xi_band(double distance_mm, const GuidanceOptions& options) noexcept;

/// Potential of the staged field at distance d, mJ: U(d) = ∫₀^d ξ(s) s ds, which equals the printed
/// ½ ξ d² (5.2.3) in the innermost band and is continuous across band edges (the printed form
/// jumps there); its gradient is exactly the printed force 5.2.5 in every band.
double staged_potential_mJ(double distance_mm, const GuidanceOptions& options) noexcept;

/// Guidance at one tool point.
struct GuidanceSample {
  NearestPoint goal;                                  ///< q_goal and d(q, q_goal)
  int band = 0;                                       ///< ξ band
  double xi_N_per_mm = 0.0;                           ///< ξ in force
  double potential_mJ = 0.0;                          ///< staged_potential_mJ(d)
  Eigen::Vector3d force_N = Eigen::Vector3d::Zero();  ///< G = −ξ (q − q_goal), eq. 5.2.5
};

/// G = −ξ(d) (q − q_goal) with q_goal the nearest path point (§5.2.3). Allocation-free.
GuidanceSample guidance_force(const PathIndex& path, const Eigen::Vector3d& q_lps_mm,
                              const GuidanceOptions& options) noexcept;

/// One gradient-descent step on U (eqs 5.2.6–5.2.8, in all three coordinates):
/// q_new = q − α ∇U(q) = q + α G(q). α in mm/N; the step converges monotonically toward the path
/// when α ξ < 1 (α ξ = 1 lands on q_goal in one step). Returns q_new.
Eigen::Vector3d gradient_descent_step(const PathIndex& path, const Eigen::Vector3d& q_lps_mm,
                                      double alpha_mm_per_N, const GuidanceOptions& options) noexcept;

}  // namespace organsmith::physics
