// Over 400 lines: the CGAL Polygon Mesh Processing steps share one Surface_mesh type and its
// property maps, kept in one translation unit because each CGAL unit costs minutes to compile.
// CGAL Polygon Mesh Processing on the sampled organ surfaces: repair (largest component, holes),
// isotropic remeshing to the target edge length, angle improvement, outward orientation, and
// flat cuts with caps.

#include "meshing/detail.h"
#include "meshing/mesh.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/angle_and_area_smoothing.h>
#include <CGAL/Polygon_mesh_processing/border.h>
#include <CGAL/Polygon_mesh_processing/clip.h>
#include <CGAL/Polygon_mesh_processing/connected_components.h>
#include <CGAL/Polygon_mesh_processing/detect_features.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/orientation.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Polygon_mesh_processing/remesh.h>
#include <CGAL/Polygon_mesh_processing/repair_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/tangential_relaxation.h>
#include <CGAL/Polygon_mesh_processing/triangulate_hole.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>
#include <CGAL/boost/graph/Euler_operations.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <unordered_map>
#include <stdexcept>

namespace organsmith::meshing_detail {
namespace {

namespace PMP = CGAL::Polygon_mesh_processing;
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using V = Mesh::Vertex_index;
using F = Mesh::Face_index;
using E = Mesh::Edge_index;
using H = Mesh::Halfedge_index;

/// Welds points closer than `tol_mm` (to the first of them): `points` receives the kept points,
/// the result maps each input index to its kept point.
std::vector<std::size_t> weld_points(const std::vector<Eigen::Vector3d>& in, double tol_mm, std::vector<Point>& points) {
  struct CellHash {
    std::size_t operator()(const std::array<std::int64_t, 3>& c) const {
      return std::hash<std::int64_t>()(c[0] * 73856093 ^ c[1] * 19349663 ^ c[2] * 83492791);
    }
  };
  std::unordered_map<std::array<std::int64_t, 3>, std::vector<std::size_t>, CellHash> cells;  // cell -> kept points
  std::vector<std::size_t> to_kept(in.size());
  points.clear();
  points.reserve(in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    const Point q(in[i].x(), in[i].y(), in[i].z());
    const std::array<std::int64_t, 3> c{std::int64_t(std::floor(q.x() / tol_mm)), std::int64_t(std::floor(q.y() / tol_mm)),
                                        std::int64_t(std::floor(q.z() / tol_mm))};
    std::size_t found = points.size();
    for (int d = 0; d < 27 && found == points.size(); ++d) {
      const auto it = cells.find({c[0] + d % 3 - 1, c[1] + d / 3 % 3 - 1, c[2] + d / 9 - 1});
      if (it == cells.end()) continue;
      for (std::size_t j : it->second)
        if (CGAL::squared_distance(points[j], q) <= tol_mm * tol_mm) {
          found = j;
          break;
        }
    }
    if (found == points.size()) {
      points.push_back(q);
      cells[c].push_back(found);
    }
    to_kept[i] = found;
  }
  return to_kept;
}

Mesh to_cgal(const SurfaceMesh& s) {
  // Points closer than 1e-6 mm are one point: a flat cut computes the same intersection twice
  // with round-off (1e-14 mm apart), and such a zero-length edge survives remeshing (it lies on
  // a protected rim) and sends the tetrahedral mesher's feature protection off the mesh.
  std::vector<Point> points;
  const std::vector<std::size_t> weld = weld_points(s.vertices_lps_mm, 1e-6, points);
  // Resizable polygons: CGAL's soup repair then also drops triangles left with a repeated point.
  std::vector<std::vector<std::size_t>> polys;
  polys.reserve(s.triangles.size());
  for (const auto& t : s.triangles) polys.push_back({weld[std::size_t(t[0])], weld[std::size_t(t[1])], weld[std::size_t(t[2])]});
  PMP::repair_polygon_soup(points, polys);
  PMP::orient_polygon_soup(points, polys);  // duplicates non-manifold vertices if any
  Mesh m;
  PMP::polygon_soup_to_polygon_mesh(points, polys, m);
  return m;
}

SurfaceMesh from_cgal(Mesh m) {
  m.collect_garbage();
  SurfaceMesh s;
  s.vertices_lps_mm.reserve(m.number_of_vertices());
  for (V v : m.vertices()) {
    const Point& p = m.point(v);
    s.vertices_lps_mm.emplace_back(p.x(), p.y(), p.z());
  }
  for (F f : m.faces()) {
    std::array<std::int32_t, 3> t{};
    int i = 0;
    for (V v : CGAL::vertices_around_face(m.halfedge(f), m)) t[i++] = std::int32_t(v.idx());
    s.triangles.push_back(t);
  }
  return s;
}

double angle_at(const Point& a, const Point& b, const Point& c) {  // angle at a, degrees
  const K::Vector_3 u = b - a, v = c - a;
  const double d = std::sqrt(u.squared_length() * v.squared_length());
  if (d <= 0) return 0.0;
  return std::acos(std::clamp(u * v / d, -1.0, 1.0)) * 180.0 / M_PI;
}

double min_angle(const Point& a, const Point& b, const Point& c) {
  return std::min({angle_at(a, b, c), angle_at(b, c, a), angle_at(c, a, b)});
}

double face_min_angle(const Mesh& m, F f) {
  const H h = m.halfedge(f);
  return min_angle(m.point(m.source(h)), m.point(m.target(h)), m.point(m.target(m.next(h))));
}

/// Flips edges whose flip raises the smaller of the two triangles' minimum angles, when the two
/// triangles are nearly coplanar (so the surface shape does not change). Returns flips made.
int improving_flips(Mesh& m, const Mesh::Property_map<E, bool>& constrained, double max_dihedral_deg) {
  int flips = 0;
  const double cos_limit = std::cos(max_dihedral_deg * M_PI / 180.0);
  for (E e : m.edges()) {
    if (m.is_border(e) || constrained[e]) continue;
    const H h = m.halfedge(e), o = m.opposite(h);
    const V a = m.source(h), b = m.target(h), c = m.target(m.next(h)), d = m.target(m.next(o));
    if (c == d || m.degree(a) <= 3 || m.degree(b) <= 3) continue;
    if (CGAL::halfedge(c, d, m).second) continue;  // the flipped edge already exists
    const Point &pa = m.point(a), &pb = m.point(b), &pc = m.point(c), &pd = m.point(d);
    const K::Vector_3 n1 = CGAL::cross_product(pb - pa, pc - pa), n2 = CGAL::cross_product(pa - pb, pd - pb);
    const double l = std::sqrt(n1.squared_length() * n2.squared_length());
    if (l <= 0 || n1 * n2 / l < cos_limit) continue;
    const double before = std::min(min_angle(pa, pb, pc), min_angle(pb, pa, pd));
    // After the flip: triangles (c, d, b)… keep orientation consistent: (a, d, c) and (b, c, d).
    const K::Vector_3 m1 = CGAL::cross_product(pd - pa, pc - pa), m2 = CGAL::cross_product(pc - pb, pd - pb);
    if (m1 * n1 <= 0 || m2 * n1 <= 0) continue;  // would fold
    const double after = std::min(min_angle(pa, pd, pc), min_angle(pb, pc, pd));
    if (after > before + 1e-3) {
      CGAL::Euler::flip_edge(h, m);
      ++flips;
    }
  }
  return flips;
}

/// Collapses the shortest edge of triangles whose smallest angle is below `min_deg` and whose
/// shortest edge is much shorter than the target (needles). Returns collapses made.
int collapse_needles(Mesh& m, const Mesh::Property_map<E, bool>& constrained, double min_deg, double short_mm) {
  int collapsed = 0;
  std::vector<F> bad;
  for (F f : m.faces())
    if (face_min_angle(m, f) < min_deg) bad.push_back(f);
  for (F f : bad) {
    if (m.is_removed(f)) continue;
    H best = m.halfedge(f);
    double best_len = std::numeric_limits<double>::max();
    for (H h : CGAL::halfedges_around_face(m.halfedge(f), m)) {
      const double len = std::sqrt(CGAL::squared_distance(m.point(m.source(h)), m.point(m.target(h))));
      if (len < best_len) best_len = len, best = h;
    }
    if (best_len > short_mm || constrained[m.edge(best)]) continue;
    // Do not move vertices that sit on a constrained (feature) edge.
    bool on_feature = false;
    for (V v : {m.source(best), m.target(best)})
      for (H h : CGAL::halfedges_around_target(v, m))
        if (constrained[m.edge(h)]) on_feature = true;
    if (on_feature) continue;
    if (!CGAL::Euler::does_satisfy_link_condition(m.edge(best), m)) continue;
    const Point mid = CGAL::midpoint(m.point(m.source(best)), m.point(m.target(best)));
    const V kept = CGAL::Euler::collapse_edge(m.edge(best), m);
    m.point(kept) = mid;
    ++collapsed;
  }
  return collapsed;
}

/// Merges two rim vertices (vertices on constrained edges: the rims of flat cuts) that are closer
/// than `short_mm` and joined by an edge on the cut's plane. The remesher leaves such edges where
/// it relaxes rim vertices along the rim (a 1 mm-slice trachea's carina cut: 0.34 and 0.02 mm,
/// without the constrained flag), and every triangle on one has a needle angle opposite it that
/// no flip or smoothing can open, since rim vertices stay put. The vertex kept is the one where
/// the rim bends more (its place unchanged), so the rim stays on the plane and on the surface.
int merge_close_rim_vertices(Mesh& m, const Mesh::Property_map<E, bool>& constrained, double short_mm) {
  auto rim_turn_deg = [&](V v) {  // the rim's turn at v; -1 where v is on no rim
    std::vector<V> nb;
    for (H h : CGAL::halfedges_around_target(v, m))
      if (constrained[m.edge(h)]) nb.push_back(m.source(h));
    if (nb.empty()) return -1.0;
    if (nb.size() != 2) return 180.0;
    const auto u = m.point(v) - m.point(nb[0]), w = m.point(nb[1]) - m.point(v);
    const double c = (u * w) / std::sqrt(u.squared_length() * w.squared_length() + 1e-300);
    return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / M_PI;
  };
  auto on_one_axis_plane = [&](V a, V b) {
    for (int ax = 0; ax < 3; ++ax)
      if (std::abs(m.point(a)[ax] - m.point(b)[ax]) < 1e-6) return true;
    return false;
  };
  int merged = 0;
  std::vector<E> candidates;
  for (E e : m.edges())
    if (std::sqrt(CGAL::squared_distance(m.point(m.vertex(e, 0)), m.point(m.vertex(e, 1)))) < short_mm)
      candidates.push_back(e);
  for (E e : candidates) {
    if (m.is_removed(e) || m.is_border(e)) continue;
    const H h = m.halfedge(e);
    const V s = m.source(h), t = m.target(h);
    if (std::sqrt(CGAL::squared_distance(m.point(s), m.point(t))) >= short_mm || !on_one_axis_plane(s, t)) continue;
    const double ts = rim_turn_deg(s), tt = rim_turn_deg(t);
    if (ts < 0 || tt < 0) continue;
    if (!CGAL::Euler::does_satisfy_link_condition(e, m)) continue;
    const Point keep = ts > tt ? m.point(s) : m.point(t);
    const V kept = CGAL::Euler::collapse_edge(e, m);
    m.point(kept) = keep;
    ++merged;
  }
  return merged;
}

/// `PMP::angle_and_area_smoothing` (angles only, no flips) for `iterations` rounds, each moved
/// vertex projected back onto the triangles of `faces` as they were before. CGAL's own
/// projection (`do_project`) does the same but first runs `does_self_intersect` on the whole
/// mesh, sequentially, every round: on the phantom that was most of the time of the angle
/// passes (trachea wall join 0.30 s, lumen 0.16 s, outer offset 0.17 s per surface, one run).
/// That check does not undo a move; it only skips the projection of a mesh that already
/// self-intersects. The result is the same whenever CGAL's check would pass (always, on the
/// reference inputs: the exports did not change by a byte), and the surfaces' own
/// self-intersection test in `measure_surface` still guards the output.
void smooth_angles_projected(Mesh& m, const std::vector<F>& faces, const Mesh::Property_map<V, bool>& vconstrained,
                             int iterations) {
  using Triangle = K::Triangle_3;
  using Primitive = CGAL::AABB_triangle_primitive<K, std::vector<Triangle>::iterator>;
  using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;
  // The same triangles, order, vertex range and tree as inside angle_and_area_smoothing.
  std::vector<Triangle> triangles;
  triangles.reserve(faces.size());
  std::vector<V> moved;
  moved.reserve(3 * faces.size());
  for (F f : faces) {
    const H h = m.halfedge(f);
    for (V v : CGAL::vertices_around_face(h, m)) moved.push_back(v);
    if (m.is_border(h)) continue;
    triangles.emplace_back(m.point(m.source(h)), m.point(m.target(h)), m.point(m.target(m.next(h))));
  }
  std::sort(moved.begin(), moved.end());
  moved.erase(std::unique(moved.begin(), moved.end()), moved.end());
  Tree tree(triangles.begin(), triangles.end());
  for (int it = 0; it < iterations; ++it) {
    PMP::angle_and_area_smoothing(faces, m, CGAL::parameters::number_of_iterations(1)
                                                .use_area_smoothing(false)
                                                .use_Delaunay_flips(false)
                                                .do_project(false)
                                                .vertex_is_constrained_map(vconstrained));
    for (V v : moved) {
      if (m.is_border(v) || vconstrained[v]) continue;
      m.point(v) = tree.closest_point(m.point(v));
    }
  }
}

/// Isotropic remeshing leaves a few triangles with small angles where the sizing meets
/// curvature; this improves them without moving the surface: flips between nearly coplanar
/// triangles, collapses of needles, and angle-based smoothing projected back on the surface.
/// Edges in the "e:constrained" map (and their vertices) are left alone.
void improve_angles(Mesh& m, double min_angle_deg, double target_edge_mm, bool skip_fixed_faces = false) {
  auto constrained = m.property_map<E, bool>("e:constrained").first;
  // A flip between triangles that meet at up to 25° moves the surface by at most
  // ≈ edge · tan(12.5°) / 4 ≈ 0.08 · edge where they meet: only in kinks of the field (thick
  // slices), where the surface is no better defined than that.
  for (int pass = 0; pass < 8; ++pass) {
    int changes = improving_flips(m, constrained, pass < 2 ? 12.0 : 25.0);
    changes += collapse_needles(m, constrained, min_angle_deg, 0.6 * target_edge_mm);
    m.collect_garbage();
    constrained = m.property_map<E, bool>("e:constrained").first;
    auto vconstrained = m.add_property_map<V, bool>("v:constrained", false).first;
    for (E e : m.edges())
      if (constrained[e]) vconstrained[m.vertex(e, 0)] = vconstrained[m.vertex(e, 1)] = true;
    // Angle smoothing: the whole surface once (it evens out the edge lengths too), then only
    // around triangles near the angle bound (two rings of faces) — smoothing all of it every
    // pass cost most of this function's time.
    std::vector<F> near_bad;
    if (pass == 0) {
      for (F f : m.faces()) {
        bool fixed = skip_fixed_faces;
        for (V v : CGAL::vertices_around_face(m.halfedge(f), m)) fixed &= vconstrained[v];
        if (!fixed) near_bad.push_back(f);
      }
    } else {
      auto mark = m.add_property_map<F, bool>("f:near_bad", false).first;
      std::vector<F> ring;
      for (F f : m.faces())
        if (face_min_angle(m, f) < min_angle_deg + 5.0) ring.push_back(f), mark[f] = true;
      for (int r = 0; r < 2; ++r) {
        std::vector<F> next;
        for (F f : ring)
          for (H h : CGAL::halfedges_around_face(m.halfedge(f), m))
            for (F g : CGAL::faces_around_target(h, m))
              if (g != Mesh::null_face() && !mark[g]) mark[g] = true, next.push_back(g);
        ring.swap(next);
      }
      for (F f : m.faces())
        if (mark[f]) near_bad.push_back(f);
      m.remove_property_map(mark);
    }
    if (skip_fixed_faces) {
      std::vector<F> movable;
      for (F f : near_bad) {
        bool fixed = true;
        for (V v : CGAL::vertices_around_face(m.halfedge(f), m)) fixed &= vconstrained[v];
        if (!fixed) movable.push_back(f);
      }
      near_bad.swap(movable);
    }
    if (!near_bad.empty()) smooth_angles_projected(m, near_bad, vconstrained, 2);
    if (changes == 0) break;
  }
}

}  // namespace

namespace {

/// Reports the wall time of each phase to `p.on_step` (when set).
class PhaseClock {
 public:
  explicit PhaseClock(const RemeshParams& p) : p_(p) {}
  void done(const char* phase) {
    const auto now = std::chrono::steady_clock::now();
    if (p_.on_step) p_.on_step(phase, std::chrono::duration<double>(now - t_).count());
    t_ = now;
  }

 private:
  const RemeshParams& p_;
  std::chrono::steady_clock::time_point t_ = std::chrono::steady_clock::now();
};

}  // namespace

SurfaceMesh repair_and_remesh(const SurfaceMesh& in, const RemeshParams& p, std::vector<std::string>& notes) {
  PhaseClock clock(p);
  Mesh m = to_cgal(in);
  if (m.number_of_faces() == 0) throw MeshInputError("the sampled surface is empty",
      "check the label map (a mask a few voxels thin cannot be closed), or try another edge length (--edge-mm, [stages.mesh] edge_mm)");

  const std::size_t components = PMP::connected_components(
      m, m.add_property_map<F, std::size_t>("f:cc", 0).first);
  if (components > 1) {
    PMP::keep_largest_connected_components(m, 1);
    notes.push_back("kept the largest of " + std::to_string(components) + " surface components");
  }

  // Fill holes (the sampler returns closed surfaces; this guards against a stray border).
  std::vector<H> borders;
  PMP::extract_boundary_cycles(m, std::back_inserter(borders));
  for (H h : borders) {
    std::vector<F> nf;
    std::vector<V> nv;
    PMP::triangulate_refine_and_fair_hole(m, h, std::back_inserter(nf), std::back_inserter(nv));
  }
  if (!borders.empty()) notes.push_back("filled " + std::to_string(borders.size()) + " hole(s)");
  m.collect_garbage();

  auto constrained = m.add_property_map<E, bool>("e:constrained", false).first;
  if (p.feature_angle_deg > 0) {
    // Only the rims of flat cuts are features. Creases of the field between thick slices can be
    // as sharp, but protecting them would keep the needles that form along them.
    PMP::detect_sharp_edges(m, p.feature_angle_deg, constrained);
    auto on_axis_plane = [&](F f) {
      const H h = m.halfedge(f);
      const Point &a = m.point(m.source(h)), &b = m.point(m.target(h)), &c = m.point(m.target(m.next(h)));
      for (int ax = 0; ax < 3; ++ax)
        if (std::abs(a[ax] - b[ax]) < 1e-6 && std::abs(b[ax] - c[ax]) < 1e-6) return true;
      return false;
    };
    for (E e : m.edges())
      if (constrained[e] && !m.is_border(e)) {
        const H h = m.halfedge(e);
        constrained[e] = on_axis_plane(m.face(h)) || on_axis_plane(m.face(m.opposite(h)));
      }
  }

  clock.done("repair");
  try {
    PMP::isotropic_remeshing(faces(m), p.target_edge_mm, m,
                             CGAL::parameters::number_of_iterations(p.iterations)
                                 .edge_is_constrained_map(constrained)
                                 .protect_constraints(false)
                                 .relax_constraints(true));
  } catch (const std::out_of_range& e) {
    // CGAL's remesher looks up a normal it never stored on some all-flat boxes (a label
    // filling the image): an input it cannot mesh, not an internal error of ours.
    throw MeshInputError(std::string("the surface could not be remeshed (CGAL: ") + e.what() + ")",
                         "check the label map: a label that is only flat faces cut by the image border has no organ "
                         "surface to mesh");
  }
  merge_close_rim_vertices(m, constrained, 0.4 * p.target_edge_mm);
  m.collect_garbage();
  clock.done("isotropic remeshing");

  improve_angles(m, p.min_angle_deg, p.target_edge_mm);
  clock.done("angles");

  if (CGAL::is_closed(m) && !PMP::is_outward_oriented(m)) PMP::reverse_face_orientations(m);
  SurfaceMesh out = from_cgal(std::move(m));
  clock.done("orient");
  return out;
}

namespace {

/// Puts a surface in a canonical order: vertices sorted by coordinates, each triangle starting
/// at its smallest index (orientation kept), triangles sorted. PMP::clip returns the same
/// geometry in an order that varies from call to call (its intersection search depends on
/// where the heap placed things); everything after it must not see that.
SurfaceMesh canonical_order(const SurfaceMesh& in) {
  const auto& v = in.vertices_lps_mm;
  std::vector<std::int32_t> order(v.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = std::int32_t(i);
  std::sort(order.begin(), order.end(), [&](std::int32_t a, std::int32_t b) {
    return std::lexicographical_compare(v[a].data(), v[a].data() + 3, v[b].data(), v[b].data() + 3);
  });
  std::vector<std::int32_t> rank(v.size());
  SurfaceMesh out;
  out.vertices_lps_mm.reserve(v.size());
  for (std::size_t r = 0; r < order.size(); ++r) {
    rank[order[r]] = std::int32_t(r);
    out.vertices_lps_mm.push_back(v[order[r]]);
  }
  out.triangles.reserve(in.triangles.size());
  for (const auto& t : in.triangles) {
    std::array<std::int32_t, 3> u{rank[t[0]], rank[t[1]], rank[t[2]]};
    const auto first = std::min_element(u.begin(), u.end()) - u.begin();
    std::rotate(u.begin(), u.begin() + first, u.end());
    out.triangles.push_back(u);
  }
  std::sort(out.triangles.begin(), out.triangles.end());
  return out;
}

}  // namespace

SurfaceMesh clip_slab(const SurfaceMesh& in, int axis, double lo, double hi) {
  Mesh m = to_cgal(in);
  std::array<double, 3> n{0, 0, 0};
  n[axis] = -1;
  // CGAL keeps the negative side of the plane: −q[axis] + lo < 0  ⇔  q[axis] > lo.
  bool ok = PMP::clip(m, K::Plane_3(n[0], n[1], n[2], lo), CGAL::parameters::clip_volume(true));
  n[axis] = 1;
  ok = ok && PMP::clip(m, K::Plane_3(n[0], n[1], n[2], -hi), CGAL::parameters::clip_volume(true));
  if (!ok || !CGAL::is_closed(m))
    throw MeshInputError("the flat cut of the surface did not close (the sampled surface self-intersects)",
      "check the label map (a mask a few voxels thin cannot be closed), or try another edge length (--edge-mm, [stages.mesh] edge_mm)");
  return canonical_order(from_cgal(std::move(m)));
}

SurfaceMesh tube_wall_from_surfaces(const SurfaceMesh& outer, const SurfaceMesh& lumen,
                                    const std::vector<std::pair<int, double>>& planes, const RemeshParams& p) {
  PhaseClock clock(p);
  constexpr double kOnPlane = 1e-6;  // mm; clip_slab and the rim-constrained remeshing keep caps flat to this
  auto on_plane = [&](const Eigen::Vector3d& q) {
    for (std::size_t i = 0; i < planes.size(); ++i)
      if (std::abs(q[planes[i].first] - planes[i].second) < kOnPlane) return int(i);
    return -1;
  };
  auto cap_of = [&](const SurfaceMesh& s, const std::array<std::int32_t, 3>& t) {
    const int a = on_plane(s.vertices_lps_mm[t[0]]);
    return a >= 0 && on_plane(s.vertices_lps_mm[t[1]]) == a && on_plane(s.vertices_lps_mm[t[2]]) == a ? a : -1;
  };
  // The two tubes without their caps; the lumen turned inside out (its outside is the wall).
  SurfaceMesh soup;
  soup.vertices_lps_mm = outer.vertices_lps_mm;
  soup.vertices_lps_mm.insert(soup.vertices_lps_mm.end(), lumen.vertices_lps_mm.begin(), lumen.vertices_lps_mm.end());
  const auto shift = std::int32_t(outer.vertices_lps_mm.size());
  std::size_t outer_caps = 0, lumen_caps = 0;
  for (const auto& t : outer.triangles)
    if (cap_of(outer, t) < 0) soup.triangles.push_back(t);
    else ++outer_caps;
  for (const auto& t : lumen.triangles)
    if (cap_of(lumen, t) < 0) soup.triangles.push_back({t[0] + shift, t[2] + shift, t[1] + shift});
    else ++lumen_caps;
  if (outer_caps == 0 || lumen_caps == 0) throw MeshInputError("tube wall: the surfaces have no flat caps to join",
      "check the label map (a mask a few voxels thin cannot be closed), or try another edge length (--edge-mm, [stages.mesh] edge_mm)");

  // Per cut plane: the rims are the border edges on it; the annulus between them is their
  // constrained Delaunay triangulation, faces at odd nesting depth (inside the outer rim,
  // outside the lumen's).
  // Rim edges: directed edges of the tubes whose reverse is not there, in (from, to) order
  // (a sorted vector, same order as the std::map of every directed edge it replaces; the
  // join's set-up went from 0.12–0.17 s to 0.07–0.11 s on the phantom).
  std::vector<std::pair<std::int32_t, std::int32_t>> directed;
  directed.reserve(3 * soup.triangles.size());
  for (const auto& t : soup.triangles)
    for (int e = 0; e < 3; ++e) directed.emplace_back(t[e], t[(e + 1) % 3]);
  std::sort(directed.begin(), directed.end());
  directed.erase(std::unique(directed.begin(), directed.end()), directed.end());
  std::vector<std::pair<std::int32_t, std::int32_t>> rims;
  for (const auto& e : directed)
    if (!std::binary_search(directed.begin(), directed.end(), std::make_pair(e.second, e.first))) rims.push_back(e);
  using Vb = CGAL::Triangulation_vertex_base_with_info_2<std::int32_t, K>;
  using Fb = CGAL::Constrained_triangulation_face_base_2<K, CGAL::Triangulation_face_base_with_info_2<int, K>>;
  using CDT = CGAL::Constrained_Delaunay_triangulation_2<K, CGAL::Triangulation_data_structure_2<Vb, Fb>,
                                                         CGAL::Exact_predicates_tag>;
  const std::size_t tube_triangles = soup.triangles.size();
  for (std::size_t pi = 0; pi < planes.size(); ++pi) {
    const int axis = planes[pi].first, u = (axis + 1) % 3, w = (axis + 2) % 3;
    CDT cdt;
    std::map<std::int32_t, CDT::Vertex_handle> handle;
    auto vh = [&](std::int32_t i) {
      auto it = handle.find(i);
      if (it != handle.end()) return it->second;
      const auto& q = soup.vertices_lps_mm[i];
      auto h = cdt.insert(K::Point_2(q[u], q[w]));
      h->info() = i;
      return handle[i] = h;
    };
    // The rim edges on this plane, checked before any constraint is inserted: coincident rim
    // vertices or crossing rim edges would break the constrained triangulation (it needs simple,
    // disjoint rims), so they end the join here and the caller samples the wall on its own.
    std::vector<std::pair<std::int32_t, std::int32_t>> here;
    for (const auto& e : rims)
      if (on_plane(soup.vertices_lps_mm[e.first]) == int(pi) && on_plane(soup.vertices_lps_mm[e.second]) == int(pi))
        here.push_back(e);
    if (here.empty()) continue;
    for (const auto& e : here) vh(e.first), vh(e.second);
    if (cdt.number_of_vertices() != handle.size())
      throw MeshInputError("tube wall: rim vertices coincide in the cap plane",
      "check the label map (a mask a few voxels thin cannot be closed), or try another edge length (--edge-mm, [stages.mesh] edge_mm)");
    auto p2 = [&](std::int32_t i) { return K::Point_2(soup.vertices_lps_mm[i][u], soup.vertices_lps_mm[i][w]); };
    for (std::size_t a = 0; a < here.size(); ++a)
      for (std::size_t b = a + 1; b < here.size(); ++b) {
        const auto& ea = here[a];
        const auto& eb = here[b];
        if (ea.first == eb.first || ea.first == eb.second || ea.second == eb.first || ea.second == eb.second) continue;
        if (CGAL::do_intersect(K::Segment_2(p2(ea.first), p2(ea.second)), K::Segment_2(p2(eb.first), p2(eb.second))))
          throw MeshInputError("tube wall: rim edges cross in the cap plane",
                               "check the label map, or try another edge length (--edge-mm, [stages.mesh] edge_mm)");
      }
    for (const auto& e : here) cdt.insert_constraint(vh(e.first), vh(e.second));
    for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->info() = -1;
    std::vector<CDT::Face_handle> front{cdt.infinite_face()};
    cdt.infinite_face()->info() = 0;
    // Breadth-first by depth: a face's depth grows by one across each constrained edge.
    for (int depth = 0; !front.empty(); ++depth) {
      std::vector<CDT::Face_handle> next, queue = front;
      while (!queue.empty()) {
        const auto f = queue.back();
        queue.pop_back();
        for (int i = 0; i < 3; ++i) {
          const auto g = f->neighbor(i);
          if (g->info() != -1) continue;
          if (cdt.is_constrained(CDT::Edge(f, i))) {
            next.push_back(g);
          } else {
            g->info() = depth;
            queue.push_back(g);
          }
        }
      }
      front.clear();
      for (auto g : next)
        if (g->info() == -1) g->info() = depth + 1, front.push_back(g);
    }
    // Faces at depth 1 lie between the rims; outward on this cap is ±axis, away from the wall.
    double mid = 0;
    for (const auto& q : soup.vertices_lps_mm) mid += q[axis];
    mid /= double(soup.vertices_lps_mm.size());
    const double out_sign = planes[pi].second < mid ? -1.0 : 1.0;
    for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
      if (f->info() % 2 != 1) continue;
      std::array<std::int32_t, 3> t{f->vertex(0)->info(), f->vertex(1)->info(), f->vertex(2)->info()};
      const auto &a = soup.vertices_lps_mm[t[0]], &b = soup.vertices_lps_mm[t[1]], &c = soup.vertices_lps_mm[t[2]];
      if ((b - a).cross(c - a)[axis] * out_sign < 0) std::swap(t[1], t[2]);
      soup.triangles.push_back(t);
    }
  }
  if (soup.triangles.size() == tube_triangles) throw MeshInputError("tube wall: no annular cap was made",
      "check the label map (a mask a few voxels thin cannot be closed), or try another edge length (--edge-mm, [stages.mesh] edge_mm)");

  // Remesh the caps only: every edge that is not between two cap triangles is held.
  // Only the vertices still used (the old caps' inner vertices are not).
  std::vector<std::int64_t> index(soup.vertices_lps_mm.size(), -1);
  std::vector<Point> points;
  std::vector<std::array<std::size_t, 3>> polys;
  for (const auto& t : soup.triangles) {
    std::array<std::size_t, 3> poly{};
    for (int j = 0; j < 3; ++j) {
      if (index[t[j]] < 0) {
        index[t[j]] = std::int64_t(points.size());
        const auto& q = soup.vertices_lps_mm[t[j]];
        points.emplace_back(q.x(), q.y(), q.z());
      }
      poly[j] = std::size_t(index[t[j]]);
    }
    polys.push_back(poly);
  }
  if (!PMP::is_polygon_soup_a_polygon_mesh(polys)) throw MeshInputError("tube wall: the joined surface is not a manifold",
      "check the label map (a mask a few voxels thin cannot be closed), or try another edge length (--edge-mm, [stages.mesh] edge_mm)");
  Mesh m;
  PMP::polygon_soup_to_polygon_mesh(points, polys, m);
  if (!CGAL::is_closed(m)) throw MeshInputError("tube wall: the joined surface is not closed",
      "check the label map (a mask a few voxels thin cannot be closed), or try another edge length (--edge-mm, [stages.mesh] edge_mm)");
  clock.done("join: soup and annuli");
  auto cap = m.add_property_map<F, bool>("f:cap", false).first;
  auto find_caps = [&] {
    std::vector<F> found;
    for (F f : m.faces()) {
      int plane = -2;
      for (V v : CGAL::vertices_around_face(m.halfedge(f), m)) {
        const Point& q = m.point(v);
        const int pl = on_plane(Eigen::Vector3d(q.x(), q.y(), q.z()));
        plane = plane == -2 || plane == pl ? pl : -1;
      }
      cap[f] = plane >= 0;
      if (cap[f]) found.push_back(f);
    }
    return found;
  };
  std::vector<F> caps = find_caps();
  auto is_rim = [&](E e) {
    const H h = m.halfedge(e);
    return cap[m.face(h)] != cap[m.face(m.opposite(h))];
  };
  // The rims stay as they are (protected), and CGAL's remesher requires protected edges no longer
  // than 4/3 of the target: split longer rim edges first. A split point lies on the straight rim
  // edge, so the caps stay flat and the wall keeps its shape; the faces either side are split in two.
  auto rim = m.add_property_map<E, bool>("e:rim", false).first;
  std::vector<E> long_rims;
  for (E e : m.edges()) {
    rim[e] = is_rim(e);
    if (rim[e] && std::sqrt(CGAL::squared_distance(m.point(m.vertex(e, 0)), m.point(m.vertex(e, 1)))) >
                      1.25 * p.target_edge_mm)
      long_rims.push_back(e);
  }
  if (!long_rims.empty()) {
    PMP::split_long_edges(long_rims, 1.25 * p.target_edge_mm, m, CGAL::parameters::edge_is_constrained_map(rim));
    caps = find_caps();
    for (E e : m.edges()) rim[e] = is_rim(e);
  }
  // Angle improvement afterwards must not touch the tubes: every edge not inside a cap is fixed.
  auto constrained = m.add_property_map<E, bool>("e:constrained", false).first;
  for (E e : m.edges()) {
    const H h = m.halfedge(e);
    constrained[e] = !cap[m.face(h)] || !cap[m.face(m.opposite(h))];
  }
  PMP::isotropic_remeshing(caps, p.target_edge_mm, m,
                           CGAL::parameters::number_of_iterations(p.iterations)
                               .edge_is_constrained_map(rim)
                               .protect_constraints(true));
  m.remove_property_map(rim);
  m.collect_garbage();
  clock.done("join: cap remeshing");
  improve_angles(m, p.min_angle_deg, p.target_edge_mm, true);
  clock.done("join: angles");
  if (!CGAL::is_closed(m)) throw MeshInputError("tube wall: remeshing the caps opened the surface",
      "check the label map (a mask a few voxels thin cannot be closed), or try another edge length (--edge-mm, [stages.mesh] edge_mm)");
  if (!PMP::is_outward_oriented(m)) PMP::reverse_face_orientations(m);
  SurfaceMesh out = from_cgal(std::move(m));
  clock.done("join: orient");
  return out;
}

}  // namespace organsmith::meshing_detail
