#pragma once
// Parametric closed snake (Kass, Witkin & Terzopoulos 1988) driven by a GVF field and a region
// pressure, as in Xu & Prince 1998, §II: x_t = α x'' − β x'''' + F_ext. Internal forces are
// implicit, external forces explicit:
//     (I + γA) x^{n+1} = x^n + γ F_ext(x^n),
// with A the cyclic pentadiagonal matrix of −α ∂² + β ∂⁴ on a contour of uniformly spaced points.
// (I + γA) is symmetric positive definite and fixed while the number of points is; it is
// factorised once per (N, α, β, γ, spacing) and reused.

#include "segmentation/image2d.h"

#include <vector>

namespace organsmith::seg {

/// A point in the plane of a slice, mm: x = i · spacing_x, y = j · spacing_y.
struct Point2 {
  double x = 0, y = 0;
};

struct SnakeOptions {
  double alpha = 0.6;            ///< elasticity α, mm²/step (default 0.6)
  double beta = 0.3;             ///< rigidity β, mm⁴/step (default 0.3)
  double gamma = 1.0;            ///< time step γ of the semi-implicit update (default 1)
  double kappa = 0.6;            ///< GVF force at full edge strength, mm/step (default 0.6)
  double balloon = 0.5;          ///< region pressure at |p| = 1, mm/step along the normal (default 0.5)
  double max_step_mm = 0.5;      ///< cap of the explicit force per step, mm (default 0.5; keeps it stable)
  double point_spacing_mm = 1.0; ///< reparametrised point spacing, mm (default 1)
  int min_points = 12;           ///< fewest points of a contour (default 12)
  int max_iterations = 400;      ///< steps at most (default 400)
  int reparametrise_every = 4;   ///< steps between uniform resamplings (default 4)
  double converged_mm = 0.02;    ///< stop when the mean point motion per step stays below this for 10 steps
};

/// External forces of one slice. `gvf_u`/`gvf_v` are in pixel units (normalised by the caller so
/// |(u, v)| ≤ 1 at the strongest edge); `pressure` is in [−1, 1]: positive where the pixel looks
/// like the organ (push outward), negative where it does not.
struct SnakeForces {
  const Image2f* gvf_u = nullptr;
  const Image2f* gvf_v = nullptr;
  const Image2f* pressure = nullptr;  ///< may be null (no balloon)
  double spacing_x_mm = 1.0;
  double spacing_y_mm = 1.0;
};

struct SnakeResult {
  std::vector<Point2> points;  ///< counter-clockwise (positive signed area), uniformly spaced
  int iterations = 0;
  bool converged = false;
};

/// Evolves a closed snake from `initial` (≥ 3 points, any orientation) until it converges or
/// reaches max_iterations. The contour never self-intersects: a loop that forms is cut off,
/// keeping the part of largest area.
SnakeResult evolve_snake(const std::vector<Point2>& initial, const SnakeForces& forces, const SnakeOptions& options);

/// Signed area (mm²) of a closed polygon: positive when counter-clockwise in (x, y).
double polygon_area(const std::vector<Point2>& p);
/// Perimeter of a closed polygon, mm.
double polygon_length(const std::vector<Point2>& p);
/// Resamples a closed polygon to n points uniformly spaced by arc length.
std::vector<Point2> resample_closed(const std::vector<Point2>& p, int n);
/// True when two non-adjacent edges of the closed polygon cross.
bool self_intersects(const std::vector<Point2>& p);
/// Removes loops until the polygon is simple, keeping the part of largest |area| at each cut.
void remove_loops(std::vector<Point2>& p);
/// True when `q` lies inside the closed polygon `p` (even–odd rule).
bool point_in_polygon(const std::vector<Point2>& p, Point2 q);
/// Distance (mm) from q to the closed polygon's boundary.
double distance_to_boundary(const std::vector<Point2>& p, Point2 q);

struct NeckOptions {
  double max_neck_ratio = 0.8;  ///< cut when the neck is narrower than this × the smaller lobe's equivalent diameter (default 0.8)
  double min_depth_mm = 2.0;    ///< a neck needs at least one end this deep inside the convex hull, mm (default 2)
  double min_lobe_fraction = 0.08;  ///< each lobe holds at least this fraction of the area (default 0.08)
  int max_cuts = 3;             ///< cuts at most (default 3)
};

/// Cuts a closed contour (counter-clockwise, roughly uniform spacing) at its narrowest neck while
/// one exists: a chord inside the contour, with at least one end in a concavity `min_depth_mm`
/// deep, that is shorter than `max_neck_ratio` × the equivalent diameter 2√(A/π) of the smaller
/// of the two lobes it separates. Keeps the lobe holding more of the points `keep` (ties: the
/// larger lobe). A convex contour, or a contour with only shallow dents, is returned unchanged.
/// This is how a contour that passed through a narrow gap into a neighbour of the same HU is
/// brought back to its organ.
std::vector<Point2> cut_necks(const std::vector<Point2>& p, const std::vector<Point2>& keep,
                              const NeckOptions& options = {});

/// A circle of `n` points, counter-clockwise.
std::vector<Point2> circle(Point2 centre, double radius_mm, int n);

}  // namespace organsmith::seg
