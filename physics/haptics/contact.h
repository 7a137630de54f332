#pragma once
// Tool–tissue reaction force (thesis §5.1.6): the tool tip is a sphere; its contact with organ
// surfaces is found with Embree (closest-point queries against a scene committed once, inside/
// outside from angle-weighted pseudo-normals); the penetration depth gives a strain, the organ's
// calibrated law gives the stress through a precomputed table (as the thesis did), and the force
// acts along the surface normal. Also the local surface deformation drawn around the contact.
// Derivations and units are in physics/haptics/HAPTICS.md. No Embree type crosses this header.
//
// Units: LPS mm, N, Pa.

#include "core/geometry.h"
#include "core/material.h"
#include "physics/materials/models.h"

#include <Eigen/Core>

#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace organsmith::physics {

/// The surface point nearest to a query point.
struct ClosestPoint {
  bool found = false;                 ///< false when no surface lies within the query's reach
  std::int32_t surface = -1;          ///< index of the surface in the SurfaceIndex
  std::int32_t triangle = -1;
  Eigen::Vector3d point_lps_mm = Eigen::Vector3d::Zero();
  /// Unit vector at the closest point pointing out of the surface (angle-weighted pseudo-normal
  /// of the face, edge or vertex the point lies on).
  Eigen::Vector3d outward_normal = Eigen::Vector3d::Zero();
  /// Distance to the surface, positive outside the closed surface, negative inside, mm.
  double signed_distance_mm = std::numeric_limits<double>::infinity();
};

/// A ray's first hit.
struct RayHit {
  std::int32_t surface = -1, triangle = -1;
  double t_mm = 0.0;  ///< distance along the (unit) direction
  Eigen::Vector3d point_lps_mm = Eigen::Vector3d::Zero();
};

/// Closed triangle surfaces in one Embree scene, built and committed once in the constructor,
/// then only queried (queries are const, allocation-free, and safe from several threads).
/// Surfaces must be closed and outward-oriented for the inside/outside sign to mean anything.
class SurfaceIndex {
 public:
  /// Throws InputError (exit code 18) for an empty surface, an out-of-range vertex index or a
  /// non-finite coordinate; Error (internal) when Embree cannot be initialised.
  explicit SurfaceIndex(std::vector<SurfaceMesh> surfaces);
  ~SurfaceIndex();
  SurfaceIndex(SurfaceIndex&&) noexcept;
  SurfaceIndex& operator=(SurfaceIndex&&) noexcept;
  SurfaceIndex(const SurfaceIndex&) = delete;
  SurfaceIndex& operator=(const SurfaceIndex&) = delete;

  /// Nearest surface point to q among all surfaces within `max_distance_mm` (Embree point query
  /// with a callback that shrinks the search radius).
  ClosestPoint closest(const Eigen::Vector3d& q_lps_mm,
                       double max_distance_mm = std::numeric_limits<double>::infinity()) const noexcept;
  /// The same by testing every triangle (reference for tests).
  ClosestPoint closest_brute_force(const Eigen::Vector3d& q_lps_mm) const noexcept;
  /// First hit of the ray origin + t·direction, 0 < t ≤ max_t_mm (direction need not be unit).
  std::optional<RayHit> first_hit(const Eigen::Vector3d& origin_lps_mm, const Eigen::Vector3d& direction,
                                  double max_t_mm = std::numeric_limits<double>::infinity()) const noexcept;
  /// Number of surface crossings along the ray (inside/outside by parity, for tests).
  /// `first_hit_mm`, when given, receives the distance to the first crossing (infinity without
  /// one): an upper bound of the distance from the origin to the surfaces.
  int crossings(const Eigen::Vector3d& origin_lps_mm, const Eigen::Vector3d& direction,
                double* first_hit_mm = nullptr) const noexcept;

  std::size_t surface_count() const;
  const SurfaceMesh& surface(std::size_t i) const;
  std::size_t triangle_count() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Nominal stress against compressive strain of an organ's calibrated law, tabulated once so that
/// the force loop only interpolates (thesis §5.1.6: "the stress-strain relationship ... was
/// utilized as pre-calculation data set"). The strain ε is mapped to the stretch λ = 1 + ε of the
/// law's uniaxial curve (HAPTICS.md: the laws were calibrated in tension).
class StressTable {
 public:
  StressTable() = default;
  /// Samples `model` with parameters `p` at `samples` strains evenly spaced on [0, max_strain]
  /// along `load`. Throws UsageError when the law is not finite, negative or decreasing there.
  StressTable(const Model& model, std::span<const double> p, double max_strain = 1.0, int samples = 1025,
              LoadCase load = LoadCase::uniaxial_circumferential);
  /// From a Material (model name and parameters; `options` for constants such as the bulk modulus).
  static StressTable from_material(const Material& material, const ModelOptions& options = {},
                                   double max_strain = 1.0, int samples = 1025);

  /// Nominal stress at compressive strain ε, Pa: linear interpolation; 0 for ε ≤ 0; beyond
  /// max_strain linear extrapolation with the last slope (finite and increasing).
  double stress_Pa(double strain) const noexcept;
  double max_strain() const { return max_strain_; }
  bool empty() const { return stress_.empty(); }

 private:
  std::vector<double> stress_;
  double max_strain_ = 0.0, step_ = 0.0, inv_step_ = 0.0;
};

/// The tool and how a penetration becomes a strain.
struct ContactOptions {
  double tool_radius_mm = 2.0;         ///< radius of the spherical tool tip, mm (default 2)
  /// Length over which the penetration is taken as a strain, ε = δ / L, mm (default 5). The
  /// thesis divided the surface point's displacement by its spring rest length; see HAPTICS.md.
  double reference_length_mm = 5.0;
  /// A tool sunk deeper than its radius is found by searching balls of radius 2r + this margin,
  /// then 4× wider until a surface is found, mm (default 10).
  double search_margin_mm = 10.0;
};

/// Throws UsageError for non-positive or non-finite values.
void validate(const ContactOptions& options);

/// Contact of the tool sphere at one tip position.
struct ContactSample {
  bool contact = false;
  std::int32_t surface = -1;
  double penetration_mm = 0.0;         ///< δ = r − signed distance of the centre (> 0 in contact)
  double strain = 0.0;                 ///< δ / L
  double stress_Pa = 0.0;              ///< law at that strain
  double area_mm2 = 0.0;               ///< contact area π a², a² = 2 r δ − δ² (δ ≤ r), π r² beyond
  Eigen::Vector3d point_lps_mm = Eigen::Vector3d::Zero();  ///< closest surface point
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();        ///< unit, from the surface toward the tool
  Eigen::Vector3d force_N = Eigen::Vector3d::Zero();       ///< R = stress · area · normal
};

/// Force magnitude for a penetration, N: stress(δ / L) · area(δ) · 1e-6 (mm² → m²). Zero for δ ≤ 0,
/// non-decreasing in δ.
double indentation_force_N(const StressTable& table, double penetration_mm, const ContactOptions& options) noexcept;

/// The reaction force model: a SurfaceIndex and one StressTable per surface.
class ContactModel {
 public:
  /// Throws UsageError when the number of tables differs from the number of surfaces.
  ContactModel(SurfaceIndex index, std::vector<StressTable> tables, const ContactOptions& options = {});
  /// Contact at tool tip q (the sphere's centre). Allocation-free.
  ContactSample evaluate(const Eigen::Vector3d& q_lps_mm) const noexcept;
  const SurfaceIndex& index() const { return index_; }
  const ContactOptions& options() const { return options_; }

 private:
  SurfaceIndex index_;
  std::vector<StressTable> tables_;
  ContactOptions options_;
};

/// Displays the local surface deformation around a contact: vertices within `falloff_radius_mm`
/// of the contact point move against the normal by δ · w(r / R), w(x) = (1 − x²)², which is 1 at
/// the contact, smooth, and 0 with zero slope at R. Meant for the display thread (≥ 60 fps): only
/// the vertices near the contact are touched, found through a uniform grid.
class SurfaceDeformer {
 public:
  SurfaceDeformer(SurfaceMesh rest, double falloff_radius_mm = 8.0);
  /// Applies the deformation of `contact` (none when contact.contact is false) and returns the
  /// deformed vertices (same order as the rest mesh).
  const std::vector<Eigen::Vector3d>& update(const ContactSample& contact);
  const SurfaceMesh& rest() const { return rest_; }
  /// Vertices moved by the last update.
  std::size_t moved_count() const { return moved_.size(); }

 private:
  SurfaceMesh rest_;
  double radius_mm_;
  std::vector<Eigen::Vector3d> current_;
  std::vector<std::int32_t> moved_;
  Eigen::Vector3d grid_lo_;
  double cell_mm_ = 1.0;
  Eigen::Vector3i dims_;
  std::vector<std::int32_t> cell_start_, cell_vertices_;
};

}  // namespace organsmith::physics
