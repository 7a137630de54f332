// Surface and tetrahedral quality figures. Topology, orientation, self-intersection and
// distances are computed with CGAL (Polygon Mesh Processing, AABB trees); tetrahedral shape
// measures are closed-form.

#include "meshing/quality.h"
#include "core/format.h"

#include <Eigen/Geometry>

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/connected_components.h>
#include <CGAL/Polygon_mesh_processing/manifoldness.h>
#include <CGAL/Polygon_mesh_processing/measure.h>
#include <CGAL/Polygon_mesh_processing/orientation.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Polygon_mesh_processing/shape_predicates.h>
#include <CGAL/Surface_mesh.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <sstream>

namespace organsmith {
namespace {

namespace PMP = CGAL::Polygon_mesh_processing;
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using Triangles = std::vector<K::Triangle_3>;
using Primitive = CGAL::AABB_triangle_primitive<K, Triangles::const_iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;

std::string fmt(double v, int digits = 3) { return format_g(v, digits); }

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  const std::size_t k = std::min(v.size() - 1, std::size_t(std::ceil(p * double(v.size()))) - (p > 0 ? 1 : 0));
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
  return v[k];
}

Point P(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d u = b - a, v = c - a;
  const double d = u.norm() * v.norm();
  return d > 0 ? std::acos(std::clamp(u.dot(v) / d, -1.0, 1.0)) * 180.0 / M_PI : 0.0;
}

}  // namespace

SurfaceQuality measure_surface(const SurfaceMesh& s, double target, const SurfaceGuarantees& g) {
  SurfaceQuality q;
  q.vertices = std::int64_t(s.vertices_lps_mm.size());
  q.triangles = std::int64_t(s.triangles.size());
  q.target_edge_mm = target;

  std::vector<Point> points;
  for (const auto& p : s.vertices_lps_mm) points.push_back(P(p));
  std::vector<std::vector<std::size_t>> polys;
  for (const auto& t : s.triangles) polys.push_back({std::size_t(t[0]), std::size_t(t[1]), std::size_t(t[2])});
  Mesh m;
  const bool is_mesh = !polys.empty() && PMP::is_polygon_soup_a_polygon_mesh(polys);
  if (is_mesh) {
    PMP::polygon_soup_to_polygon_mesh(points, polys, m);
    std::vector<Mesh::Halfedge_index> nm;
    PMP::non_manifold_vertices(m, std::back_inserter(nm));
    q.manifold = nm.empty();
    q.closed = CGAL::is_closed(m);
    auto fcc = m.add_property_map<Mesh::Face_index, std::size_t>("f:cc", 0).first;
    q.components = std::int64_t(PMP::connected_components(m, fcc));
    q.self_intersecting = PMP::does_self_intersect<CGAL::Parallel_if_available_tag>(m);
    for (auto f : m.faces())
      if (PMP::is_degenerate_triangle_face(f, m)) ++q.degenerate_faces;
    q.area_mm2 = PMP::area(m);
    if (q.closed) {
      q.volume_mm3 = PMP::volume(m);
      q.outward = q.volume_mm3 > 0 && PMP::is_outward_oriented(m);
    }
  }

  // Edge lengths (each undirected edge once) and angles.
  std::vector<double> lengths, angles;
  std::vector<std::pair<std::int32_t, std::int32_t>> edges;
  for (const auto& t : s.triangles)
    for (int e = 0; e < 3; ++e) {
      const std::int32_t a = t[e], b = t[(e + 1) % 3];
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::int64_t within = 0;
  for (const auto& [a, b] : edges) {
    const double l = (s.vertices_lps_mm[a] - s.vertices_lps_mm[b]).norm();
    lengths.push_back(l);
    if (target > 0 && std::abs(l - target) <= g.edge_tolerance * target) ++within;
  }
  for (const auto& t : s.triangles) {
    const auto &a = s.vertices_lps_mm[t[0]], &b = s.vertices_lps_mm[t[1]], &c = s.vertices_lps_mm[t[2]];
    angles.push_back(std::min({angle_deg(a, b, c), angle_deg(b, c, a), angle_deg(c, a, b)}));
  }
  if (!lengths.empty()) {
    q.edge_min_mm = *std::min_element(lengths.begin(), lengths.end());
    q.edge_max_mm = *std::max_element(lengths.begin(), lengths.end());
    double sum = 0;
    for (double l : lengths) sum += l;
    q.edge_mean_mm = sum / double(lengths.size());
    q.edge_within_tolerance = double(within) / double(lengths.size());
  }
  // Folds: the angle between the normals of the two triangles on each interior edge.
  {
    std::vector<std::array<std::int32_t, 3>> he;  // (min vertex, max vertex, triangle)
    he.reserve(3 * s.triangles.size());
    for (std::size_t t = 0; t < s.triangles.size(); ++t)
      for (int e = 0; e < 3; ++e) {
        const std::int32_t a = s.triangles[t][e], b = s.triangles[t][(e + 1) % 3];
        he.push_back({std::min(a, b), std::max(a, b), std::int32_t(t)});
      }
    std::sort(he.begin(), he.end());
    auto normal = [&](std::int32_t t) {
      const auto& tri = s.triangles[std::size_t(t)];
      const auto &a = s.vertices_lps_mm[tri[0]], &b = s.vertices_lps_mm[tri[1]], &c = s.vertices_lps_mm[tri[2]];
      return Eigen::Vector3d((b - a).cross(c - a).normalized());
    };
    std::vector<double> folds;
    for (std::size_t i = 0; i + 1 < he.size(); ++i) {
      if (he[i][0] != he[i + 1][0] || he[i][1] != he[i + 1][1]) continue;
      if (i + 2 < he.size() && he[i + 2][0] == he[i][0] && he[i + 2][1] == he[i][1]) continue;  // non-manifold edge
      const double c = std::clamp(normal(he[i][2]).dot(normal(he[i + 1][2])), -1.0, 1.0);
      folds.push_back(std::acos(c) * 180.0 / M_PI);
      if (g.max_fold_deg > 0 && folds.back() > g.max_fold_deg) ++q.folds_above_limit;
    }
    if (!folds.empty()) {
      q.fold_max_deg = *std::max_element(folds.begin(), folds.end());
      q.fold_p99_deg = percentile(folds, 0.99);
    }
  }
  if (!angles.empty()) {
    q.angle_min_deg = *std::min_element(angles.begin(), angles.end());
    q.angle_p1_deg = percentile(angles, 0.01);
  }

  auto fail = [&](std::string w) { q.failures.push_back(std::move(w)); };
  if (s.triangles.empty()) fail("empty surface");
  if (!is_mesh || !q.manifold) fail("not 2-manifold");
  if (!q.closed) fail("not closed");
  if (q.closed && !q.outward) fail("not oriented outward");
  if (q.self_intersecting) fail("self-intersecting");
  if (q.degenerate_faces > 0) fail(std::to_string(q.degenerate_faces) + " degenerate faces");
  if (target > 0 && q.edge_within_tolerance < g.edge_fraction)
    fail("only " + fmt(100 * q.edge_within_tolerance) + " % of edges within ±" + fmt(100 * g.edge_tolerance) +
         " % of " + fmt(target) + " mm (need " + fmt(100 * g.edge_fraction) + " %)");
  if (q.angle_min_deg < g.min_angle_deg)
    fail("smallest angle " + fmt(q.angle_min_deg) + "° < " + fmt(g.min_angle_deg) + "°");
  if (q.folds_above_limit > 0)
    fail(std::to_string(q.folds_above_limit) + " edges folded beyond " + fmt(g.max_fold_deg) + "° (largest " +
         fmt(q.fold_max_deg) + "°): a staircase sharper than the edge length can carry");
  return q;
}

void compare_with_label(SurfaceQuality& q, const SurfaceMesh& mesh, const LabelMap& labels, std::uint8_t value,
                        double reference_volume_mm3, const SurfaceGuarantees& g, std::int64_t k0, std::int64_t k1) {
  const ImageGrid& grid = labels.grid;
  const auto n = grid.size_vox;
  if (k0 < 0) k0 = 0;
  if (k1 < 0 || k1 >= n[2]) k1 = n[2] - 1;
  auto in = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    return i >= 0 && j >= 0 && k >= k0 && i < n[0] && j < n[1] && k <= k1 && labels.at(i, j, k) == value;
  };
  // The label boundary: faces between a voxel of the label and one that is not.
  Triangles boundary;
  std::vector<Point> face_centres;
  for (std::int64_t k = k0; k <= k1; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i) {
        if (labels.at(i, j, k) != value) continue;
        for (int a = 0; a < 3; ++a)
          for (int sgn : {-1, 1}) {
            std::array<std::int64_t, 3> nb{i, j, k};
            nb[a] += sgn;
            if (in(nb[0], nb[1], nb[2])) continue;
            const int b = (a + 1) % 3, c = (a + 2) % 3;
            Eigen::Vector3d corner[4];
            for (int m = 0; m < 4; ++m) {
              Eigen::Vector3d ijk{double(i), double(j), double(k)};
              ijk[a] += 0.5 * sgn;
              ijk[b] += (m == 1 || m == 2) ? 0.5 : -0.5;
              ijk[c] += (m >= 2) ? 0.5 : -0.5;
              corner[m] = grid.index_to_lps_mm(ijk);
            }
            boundary.emplace_back(P(corner[0]), P(corner[1]), P(corner[2]));
            boundary.emplace_back(P(corner[0]), P(corner[2]), P(corner[3]));
            face_centres.push_back(P(0.25 * (corner[0] + corner[1] + corner[2] + corner[3])));
          }
      }
  const Eigen::Vector3d s = grid.spacing_mm;
  q.hd_tolerance_mm = s.norm();
  q.reference_volume_mm3 = reference_volume_mm3;
  if (reference_volume_mm3 > 0) q.volume_error = (q.volume_mm3 - reference_volume_mm3) / reference_volume_mm3;
  if (boundary.empty() || mesh.triangles.empty()) {
    q.failures.push_back("no label boundary or no mesh to compare");
    return;
  }
  Tree label_tree(boundary.begin(), boundary.end());
  label_tree.accelerate_distance_queries();
  Triangles mesh_triangles;
  for (const auto& t : mesh.triangles)
    mesh_triangles.emplace_back(P(mesh.vertices_lps_mm[t[0]]), P(mesh.vertices_lps_mm[t[1]]),
                                P(mesh.vertices_lps_mm[t[2]]));
  Tree mesh_tree(mesh_triangles.begin(), mesh_triangles.end());
  mesh_tree.accelerate_distance_queries();

  // Mesh → label: vertices and triangle centroids; label → mesh: voxel face centres.
  std::vector<double> d_mesh, d_label;
  for (const auto& v : mesh.vertices_lps_mm) d_mesh.push_back(std::sqrt(label_tree.squared_distance(P(v))));
  for (const auto& t : mesh_triangles) d_mesh.push_back(std::sqrt(label_tree.squared_distance(CGAL::centroid(t))));
  for (const auto& c : face_centres) d_label.push_back(std::sqrt(mesh_tree.squared_distance(c)));
  q.hd95_mesh_to_label_mm = percentile(d_mesh, 0.95);
  q.hd95_label_to_mesh_mm = percentile(d_label, 0.95);
  q.hd95_mm = std::max(q.hd95_mesh_to_label_mm, q.hd95_label_to_mesh_mm);

  if (reference_volume_mm3 > 0 && std::abs(q.volume_error) > g.volume_tolerance)
    q.failures.push_back("volume " + fmt(q.volume_mm3 / 1000, 4) + " ml differs from the label's " +
                         fmt(reference_volume_mm3 / 1000, 4) + " ml by " + fmt(100 * q.volume_error) + " % (limit ±" +
                         fmt(100 * g.volume_tolerance) + " %)");
  if (q.hd95_mm > q.hd_tolerance_mm)
    q.failures.push_back("HD95 to the label boundary " + fmt(q.hd95_mm) + " mm exceeds one voxel diagonal (" +
                         fmt(q.hd_tolerance_mm) + " mm)");
}

TetQuality measure_tets(const TetMesh& mesh, const TetGuarantees& g) {
  TetQuality q;
  q.vertices = std::int64_t(mesh.vertices_lps_mm.size());
  q.tets = std::int64_t(mesh.tets.size());
  q.dihedral_min_deg = 180.0;
  std::map<std::int32_t, double> regions;
  double re_sum = 0;
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
    const auto& T = mesh.tets[t];
    const Eigen::Vector3d p[4] = {mesh.vertices_lps_mm[T[0]], mesh.vertices_lps_mm[T[1]], mesh.vertices_lps_mm[T[2]],
                                  mesh.vertices_lps_mm[T[3]]};
    const double vol = (p[1] - p[0]).dot((p[2] - p[0]).cross(p[3] - p[0])) / 6.0;
    double lmin = 1e300, lmax = 0;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        const double l = (p[a] - p[b]).norm();
        lmin = std::min(lmin, l);
        lmax = std::max(lmax, l);
      }
    q.volume_mm3 += vol;
    regions[mesh.region_ids.empty() ? 0 : mesh.region_ids[t]] += vol;
    if (vol <= 1e-12 * lmax * lmax * lmax) {
      ++q.inverted_or_flat;
      continue;
    }
    // Dihedral angles along the 6 edges from the face normals.
    const int faces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};  // face i opposite vertex i, outward
    Eigen::Vector3d nrm[4];
    for (int f = 0; f < 4; ++f)
      nrm[f] = (p[faces[f][1]] - p[faces[f][0]]).cross(p[faces[f][2]] - p[faces[f][0]]).normalized();
    double dmin = 180, dmax = 0;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        const double d = 180.0 - std::acos(std::clamp(nrm[a].dot(nrm[b]), -1.0, 1.0)) * 180.0 / M_PI;
        dmin = std::min(dmin, d);
        dmax = std::max(dmax, d);
      }
    q.dihedral_min_deg = std::min(q.dihedral_min_deg, dmin);
    q.dihedral_max_deg = std::max(q.dihedral_max_deg, dmax);
    if (dmin < g.min_dihedral_deg) ++q.below_min_dihedral;
    // Circumradius: |a|²(b×c) + |b|²(c×a) + |c|²(a×b) over 12 V, with a, b, c from p0.
    const Eigen::Vector3d a = p[1] - p[0], b = p[2] - p[0], c = p[3] - p[0];
    const Eigen::Vector3d num = a.squaredNorm() * b.cross(c) + b.squaredNorm() * c.cross(a) + c.squaredNorm() * a.cross(b);
    const double radius = num.norm() / (12.0 * vol);
    const double re = radius / lmin;
    q.radius_edge_max = std::max(q.radius_edge_max, re);
    re_sum += re;
    if (re > g.max_radius_edge) ++q.above_max_radius_edge;
  }
  if (q.tets > 0) q.radius_edge_mean = re_sum / double(q.tets);
  for (const auto& [id, v] : regions) q.region_volumes_mm3.emplace_back(id, v);
  if (q.tets == 0) q.failures.push_back("no tetrahedra");
  if (q.inverted_or_flat > 0) q.failures.push_back(std::to_string(q.inverted_or_flat) + " inverted or zero-volume tets");
  if (q.below_min_dihedral > 0)
    q.failures.push_back(std::to_string(q.below_min_dihedral) + " tets with a dihedral angle below " +
                         fmt(g.min_dihedral_deg) + "° (smallest " + fmt(q.dihedral_min_deg) + "°)");
  if (q.above_max_radius_edge > 0)
    q.failures.push_back(std::to_string(q.above_max_radius_edge) + " tets with radius-edge ratio above " +
                         fmt(g.max_radius_edge) + " (largest " + fmt(q.radius_edge_max) + ")");
  return q;
}

nlohmann::json to_json(const SurfaceQuality& q) {
  nlohmann::json j = {{"vertices", q.vertices}, {"triangles", q.triangles}, {"components", q.components},
                      {"closed", q.closed}, {"manifold", q.manifold}, {"outward_oriented", q.outward},
                      {"self_intersecting", q.self_intersecting}, {"degenerate_faces", q.degenerate_faces},
                      {"target_edge_mm", q.target_edge_mm},
                      {"edge_length_mm", {{"min", q.edge_min_mm}, {"mean", q.edge_mean_mm}, {"max", q.edge_max_mm}}},
                      {"edges_within_25pct_of_target", q.edge_within_tolerance},
                      {"min_angle_deg", q.angle_min_deg}, {"angle_p1_deg", q.angle_p1_deg},
                      {"fold_max_deg", q.fold_max_deg}, {"fold_p99_deg", q.fold_p99_deg},
                      {"area_mm2", q.area_mm2}, {"volume_mm3", q.volume_mm3}};
  if (q.reference_volume_mm3 > 0) {
    j["label_volume_mm3"] = q.reference_volume_mm3;
    j["volume_error"] = q.volume_error;
  }
  if (q.hd95_mm >= 0) {
    j["hd95_mm"] = q.hd95_mm;
    j["hd95_mesh_to_label_mm"] = q.hd95_mesh_to_label_mm;
    j["hd95_label_to_mesh_mm"] = q.hd95_label_to_mesh_mm;
    j["hd95_limit_mm"] = q.hd_tolerance_mm;
  }
  j["passed"] = q.ok();
  j["failures"] = q.failures;
  return j;
}

nlohmann::json to_json(const TetQuality& q) {
  nlohmann::json regions = nlohmann::json::object();
  for (const auto& [id, v] : q.region_volumes_mm3) regions[std::to_string(id)] = v;
  return {{"vertices", q.vertices}, {"tetrahedra", q.tets}, {"inverted_or_zero_volume", q.inverted_or_flat},
          {"volume_mm3", q.volume_mm3}, {"region_volume_mm3", regions},
          {"min_dihedral_deg", q.dihedral_min_deg}, {"max_dihedral_deg", q.dihedral_max_deg},
          {"max_radius_edge_ratio", q.radius_edge_max}, {"mean_radius_edge_ratio", q.radius_edge_mean},
          {"tets_below_min_dihedral", q.below_min_dihedral}, {"tets_above_max_radius_edge", q.above_max_radius_edge},
          {"passed", q.ok()}, {"failures", q.failures}};
}

}  // namespace organsmith
