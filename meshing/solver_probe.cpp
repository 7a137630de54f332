// The indentation probe of a solver model: a wall_body's opposite its bed (the liver bed), a tube's on its
// anterior wall (see solver_model.h, SolverProbe).
//
// Why a bonded rigid disc and not contact: the thesis' stick is a flat rigid cylinder pressed
// along the surface normal (§5.1.2). Prescribing the displacement of the wall under a 5 mm disc
// is that punch with no slip under it; a contact pair with a rigid surface would let the wall
// slide and lift off at the rim, which for a normal push changes the force by the rim's share
// only, at several times the solver's cost and with contact's own convergence failures.

#include "meshing/solver_model.h"

#include "core/format.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <set>

namespace organsmith {
namespace {

constexpr int kFace[4][3] = {{0, 1, 2}, {0, 3, 1}, {1, 3, 2}, {2, 3, 0}};

Eigen::Vector3d corner(const SolverModel& m, const SolverFace& f, int k) {
  return m.nodes_lps_mm[std::size_t(m.elements[std::size_t(f.tet)][kFace[f.face][k]])];
}
Eigen::Vector3d centroid(const SolverModel& m, const SolverFace& f) {
  return (corner(m, f, 0) + corner(m, f, 1) + corner(m, f, 2)) / 3.0;
}

/// Ray parameter t of o + t d through triangle abc (Möller–Trumbore), or −1.
double ray_hit(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
               const Eigen::Vector3d& c) {
  const Eigen::Vector3d e1 = b - a, e2 = c - a, p = d.cross(e2);
  const double det = e1.dot(p);
  if (std::abs(det) < 1e-12) return -1;
  const Eigen::Vector3d s = o - a;
  const double u = s.dot(p) / det;
  if (u < 0 || u > 1) return -1;
  const Eigen::Vector3d q = s.cross(e1);
  const double v = d.dot(q) / det;
  if (v < 0 || u + v > 1) return -1;
  return e2.dot(q) / det;
}

}  // namespace

void add_indentation_probe(SolverModel& m, const std::optional<Eigen::Vector3d>& requested, double diameter_mm,
                           const std::string& fixed) {
  const std::string n = m.organ;
  const bool tube = fixed == "cuts";
  std::string bed_words = fixed;  // "liver_bed" → "liver bed"
  std::replace(bed_words.begin(), bed_words.end(), '_', ' ');
  const auto& outer = m.surfaces.at(n + "_outer");
  const auto& bed = m.surfaces.at(n + "_" + fixed);
  std::set<std::pair<std::int32_t, std::int32_t>> in_bed;
  std::set<std::int32_t> bed_nodes;
  Eigen::Vector3d bed_normal = Eigen::Vector3d::Zero();
  for (const auto& f : bed) {
    in_bed.insert({f.tet, f.face});
    bed_normal += m.face_area_out_mm2(f);
    for (auto v : m.face_nodes(f)) bed_nodes.insert(v);
  }
  std::vector<SolverFace> free;
  for (const auto& f : outer)
    if (!in_bed.count({f.tet, f.face})) free.push_back(f);
  if (free.empty() || (!tube && bed_normal.norm() < 1e-12)) {
    m.notes.push_back(n + ": no free surface beside the " + (tube ? std::string("cut ends") : bed_words) + "; no indentation probe");
    return;
  }
  if (!tube) bed_normal.normalize();
  Eigen::Vector3d c0 = Eigen::Vector3d::Zero();
  for (const auto& p : m.nodes_lps_mm) c0 += p;
  c0 /= double(m.nodes_lps_mm.size());

  // The point: a requested one snapped to the nearest free face; else the centre of the free
  // surface opposite the bed (the faces within 2 mm of the farthest along −bed normal, averaged,
  // snapped), which on an organ lying along its bed is the middle of its free side.
  Eigen::Vector3d target;
  if (requested) {
    target = *requested;
  } else if (tube) {
    // Halfway between the cuts (along z, the airway's course), the most anterior (−y) outer face:
    // where a surgeon's instrument meets the trachea's front wall.
    double z_lo = 1e300, z_hi = -1e300;
    for (const auto& f : free) z_lo = std::min(z_lo, centroid(m, f).z()), z_hi = std::max(z_hi, centroid(m, f).z());
    const double z_mid = 0.5 * (z_lo + z_hi);
    double front = 1e300;
    for (const auto& f : free)
      if (std::abs(centroid(m, f).z() - z_mid) <= 3.0) front = std::min(front, centroid(m, f).y());
    target = Eigen::Vector3d(c0.x(), front, z_mid);
    for (const auto& f : free)
      if (std::abs(centroid(m, f).z() - z_mid) <= 3.0 && centroid(m, f).y() == front) target = centroid(m, f);
  } else {
    double best = -1e300;
    for (const auto& f : free) best = std::max(best, (centroid(m, f) - c0).dot(-bed_normal));
    Eigen::Vector3d acc = Eigen::Vector3d::Zero();
    int k = 0;
    for (const auto& f : free)
      if ((centroid(m, f) - c0).dot(-bed_normal) >= best - 2.0) acc += centroid(m, f), ++k;
    target = acc / k;
  }
  std::size_t nearest = 0;
  double dmin = 1e300;
  for (std::size_t i = 0; i < free.size(); ++i)
    if (const double d = (centroid(m, free[i]) - target).norm(); d < dmin) dmin = d, nearest = i;
  SolverProbe probe;
  probe.diameter_mm = diameter_mm;
  probe.point_lps_mm = centroid(m, free[nearest]);
  probe.requested_offset_mm = requested ? dmin : 0.0;
  const double R = 0.5 * diameter_mm;
  // Direction: the inward normal averaged over the free faces within the probe's radius.
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (const auto& f : free)
    if ((centroid(m, f) - probe.point_lps_mm).norm() <= std::max(R, 1e-3)) normal += m.face_area_out_mm2(f);
  if (normal.norm() < 1e-12) normal = m.face_area_out_mm2(free[nearest]);
  probe.direction_lps = -normal.normalized();
  // The faces under the disc: centroid within R of the axis and within R of the disc's plane
  // (the near side), none touching the fixed bed; at least the face under the point.
  std::vector<SolverFace> held;
  for (const auto& f : free) {
    const Eigen::Vector3d r = centroid(m, f) - probe.point_lps_mm;
    const double axial = r.dot(probe.direction_lps);
    if ((r - axial * probe.direction_lps).norm() > R || std::abs(axial) > R) continue;
    bool touches_bed = false;
    for (auto v : m.face_nodes(f)) touches_bed = touches_bed || bed_nodes.count(v);
    if (!touches_bed) held.push_back(f);
  }
  if (held.empty()) held.push_back(free[nearest]);
  for (const auto& f : held) probe.contact_area_mm2 += m.face_area_out_mm2(f).norm();
  // Thickness: where a ray from the point along the direction leaves the organ again.
  double exit = 0;
  const Eigen::Vector3d o = probe.point_lps_mm + 1e-3 * probe.direction_lps;
  for (const auto& f : outer) {
    const double t = ray_hit(o, probe.direction_lps, corner(m, f, 0), corner(m, f, 1), corner(m, f, 2));
    if (t > 0.5 && m.face_area_out_mm2(f).dot(probe.direction_lps) > 0 && (exit == 0 || t < exit)) exit = t;
  }
  probe.thickness_mm = exit;
  m.surfaces[n + "_probe"] = std::move(held);
  m.notes.push_back(n + "_probe: the faces under a rigid " + format_g(diameter_mm, 3) + " mm probe at (" +
                    format_g(probe.point_lps_mm.x(), 5) + ", " + format_g(probe.point_lps_mm.y(), 5) + ", " +
                    format_g(probe.point_lps_mm.z(), 5) + ") LPS mm, " +
                    (requested ? "the free surface nearest the point asked for (" + format_g(dmin, 3) + " mm from it)"
                     : tube    ? std::string("the front of the anterior wall halfway between the cuts")
                               : "the centre of the free surface opposite the " + bed_words) +
                    ", " + format_g(probe.contact_area_mm2, 3) + " mm2; the organ is " + format_g(exit, 3) +
                    " mm thick along its inward normal");
  m.probe = probe;
}

}  // namespace organsmith
