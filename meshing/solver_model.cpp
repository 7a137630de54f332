// Over 400 lines: quadratic nodes, boundary faces and the per-model surface rules (tube cut faces,
// lumen by distance to the lumen surface, liver bed) build one model and share its face helpers.
// Solver models: quadratic tetrahedra, boundary surfaces and node sets (see solver_model.h).

#include "meshing/solver_model.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <set>

namespace organsmith {
namespace {

constexpr int kFace[4][3] = {{0, 1, 2}, {0, 3, 1}, {1, 3, 2}, {2, 3, 0}};
/// Mid-edge slot (4–9) of the edge between corners i and j.
int mid_slot(int i, int j) {
  if (i > j) std::swap(i, j);
  static const int slot[4][4] = {{-1, 4, 6, 7}, {4, -1, 5, 8}, {6, 5, -1, 9}, {7, 8, 9, -1}};
  return slot[i][j];
}

using Key3 = std::array<std::int32_t, 3>;
using Key2 = std::pair<std::int32_t, std::int32_t>;

Key3 sorted3(std::int32_t a, std::int32_t b, std::int32_t c) {
  Key3 k{a, b, c};
  std::sort(k.begin(), k.end());
  return k;
}

/// Edge-connected components of a face list; returns component id per face.
std::vector<int> components(const SolverModel& m, const std::vector<SolverFace>& faces, int& count) {
  std::map<Key2, std::vector<int>> by_edge;
  for (std::size_t f = 0; f < faces.size(); ++f) {
    const auto& e = m.elements[faces[f].tet];
    for (int k = 0; k < 3; ++k) {
      std::int32_t a = e[kFace[faces[f].face][k]], b = e[kFace[faces[f].face][(k + 1) % 3]];
      by_edge[{std::min(a, b), std::max(a, b)}].push_back(int(f));
    }
  }
  std::vector<int> comp(faces.size(), -1);
  count = 0;
  for (std::size_t s = 0; s < faces.size(); ++s) {
    if (comp[s] >= 0) continue;
    std::vector<int> stack{int(s)};
    comp[s] = count;
    while (!stack.empty()) {
      const int f = stack.back();
      stack.pop_back();
      const auto& e = m.elements[faces[f].tet];
      for (int k = 0; k < 3; ++k) {
        std::int32_t a = e[kFace[faces[f].face][k]], b = e[kFace[faces[f].face][(k + 1) % 3]];
        for (int g : by_edge[{std::min(a, b), std::max(a, b)}])
          if (comp[g] < 0) {
            comp[g] = count;
            stack.push_back(g);
          }
      }
    }
    ++count;
  }
  return comp;
}

/// Distance from p to triangle abc (closest point by region tests on the barycentric coordinates).
double point_triangle_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                               const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return ap.norm();
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return bp.norm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (p - (a + d1 / (d1 - d3) * ab)).norm();
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return cp.norm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (p - (a + d2 / (d2 - d6) * ac)).norm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return (p - (b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b))).norm();
  const double denom = 1.0 / (va + vb + vc);
  return (p - (a + ab * (vb * denom) + ac * (vc * denom))).norm();
}

Eigen::Vector3d centroid(const SolverModel& m, const SolverFace& f) {
  const auto& e = m.elements[f.tet];
  return (m.nodes_lps_mm[e[kFace[f.face][0]]] + m.nodes_lps_mm[e[kFace[f.face][1]]] + m.nodes_lps_mm[e[kFace[f.face][2]]]) / 3.0;
}

}  // namespace

std::vector<std::int32_t> SolverModel::face_nodes(const SolverFace& f) const {
  const auto& e = elements[f.tet];
  const int* c = kFace[f.face];
  std::vector<std::int32_t> out{e[c[0]], e[c[1]], e[c[2]]};
  if (quadratic)
    for (int k = 0; k < 3; ++k) out.push_back(e[mid_slot(c[k], c[(k + 1) % 3])]);
  return out;
}

Eigen::Vector3d SolverModel::face_area_out_mm2(const SolverFace& f) const {
  const auto& e = elements[f.tet];
  const Eigen::Vector3d& a = nodes_lps_mm[e[kFace[f.face][0]]];
  const Eigen::Vector3d& b = nodes_lps_mm[e[kFace[f.face][1]]];
  const Eigen::Vector3d& c = nodes_lps_mm[e[kFace[f.face][2]]];
  return -0.5 * (b - a).cross(c - a);  // the face's node order makes (b−a)×(c−a) point inward
}

std::string bed_surface_suffix(const MeshOrganSpec& spec) { return spec.bed_organ.empty() ? "bed" : spec.bed_organ + "_bed"; }

SolverScenario default_scenario(const MeshOrganSpec& spec) {
  SolverScenario s;
  if (spec.load_case.empty()) return s;
  s.pressure_surface = "lumen";
  s.pressure_kPa = spec.pressure_kPa;
  if (spec.model == OrganModel::wall_body) {
    s.fixed_surface = bed_surface_suffix(spec);
    s.indentation = spec.load_case == "indentation";
    if (!s.indentation) s.inactive_regions = {spec.name + "_body"};
  } else if (spec.model == OrganModel::tube) {
    s.fixed_surface = "cuts";
    s.indentation = spec.load_case == "indentation";  // the probe on the anterior wall, both cuts held
  }
  return s;
}

SolverModel build_solver_model(const OrganMesh& organ, const SolverModelOptions& o) {
  const TetMesh& t = organ.volume;
  if (t.tets.empty()) throw MeshInputError(organ.spec.name + ": no tetrahedra to export to a solver");
  SolverModel m;
  m.organ = organ.spec.name;
  m.quadratic = o.quadratic;
  m.region_names = organ.region_names;
  m.nodes_lps_mm = t.vertices_lps_mm;
  // Elements grouped by region (stable), so that each region is one block of consecutive ids.
  std::vector<std::size_t> order(t.tets.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return t.region_ids[a] < t.region_ids[b]; });
  m.elements.resize(t.tets.size());
  m.region_ids.resize(t.tets.size());
  for (std::size_t e = 0; e < t.tets.size(); ++e) {
    auto q = t.tets[order[e]];
    m.region_ids[e] = t.region_ids[order[e]];
    const auto& p = m.nodes_lps_mm;
    if ((p[q[1]] - p[q[0]]).cross(p[q[2]] - p[q[0]]).dot(p[q[3]] - p[q[0]]) < 0) std::swap(q[1], q[2]);
    m.elements[e].fill(-1);
    std::copy(q.begin(), q.end(), m.elements[e].begin());
  }
  if (m.quadratic) {
    // Mid-edge nodes at edge midpoints, numbered after the corners in order of first use. The
    // boundary of the tetrahedra is the organ's remeshed surface itself, so its edge midpoints
    // lie on that surface.
    std::map<Key2, std::int32_t> mid;
    for (auto& e : m.elements)
      for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) {
          const Key2 k{std::min(e[i], e[j]), std::max(e[i], e[j])};
          auto [it, fresh] = mid.emplace(k, std::int32_t(m.nodes_lps_mm.size()));
          if (fresh) m.nodes_lps_mm.push_back(0.5 * (m.nodes_lps_mm[e[i]] + m.nodes_lps_mm[e[j]]));
          e[mid_slot(i, j)] = it->second;
        }
  }

  // Boundary faces (one element) and region interfaces (two elements of different regions).
  std::map<Key3, std::vector<SolverFace>> faces;
  for (std::size_t e = 0; e < m.elements.size(); ++e)
    for (int f = 0; f < 4; ++f) {
      const auto& el = m.elements[e];
      faces[sorted3(el[kFace[f][0]], el[kFace[f][1]], el[kFace[f][2]])].push_back({std::int32_t(e), f});
    }
  std::vector<SolverFace> boundary, interface_wall_side;
  const std::string wall = organ.spec.name + "_wall";
  std::int32_t wall_id = -1;
  for (const auto& [id, name] : m.region_names)
    if (name == wall) wall_id = id;
  for (const auto& [k, list] : faces) {
    if (list.size() == 1) boundary.push_back(list[0]);
    else if (list.size() == 2 && m.region_ids[list[0].tet] != m.region_ids[list[1].tet])
      interface_wall_side.push_back(m.region_ids[list[0].tet] == wall_id ? list[0] : list[1]);
  }
  const std::string n = organ.spec.name;
  auto area = [&](const std::vector<SolverFace>& fs) {
    double a = 0;
    for (const auto& f : fs) a += m.face_area_out_mm2(f).norm();
    return a;
  };
  auto largest_component = [&](const std::vector<SolverFace>& fs) {
    int count = 0;
    const auto comp = components(m, fs, count);
    std::vector<double> a(std::size_t(count), 0.0);
    for (std::size_t f = 0; f < fs.size(); ++f) a[std::size_t(comp[f])] += m.face_area_out_mm2(fs[f]).norm();
    const int best = int(std::max_element(a.begin(), a.end()) - a.begin());
    std::vector<SolverFace> out;
    for (std::size_t f = 0; f < fs.size(); ++f)
      if (comp[f] == best) out.push_back(fs[f]);
    return out;
  };

  if (organ.spec.model == OrganModel::tube) {
    // Cut faces: boundary faces lying on a supporting plane of the whole mesh normal to an image
    // axis (the tube is cut flat where the label meets the image border).
    double lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = hi[a] = t.vertices_lps_mm[0][a];
      for (const auto& v : t.vertices_lps_mm) {
        lo[a] = std::min(lo[a], v[a]);
        hi[a] = std::max(hi[a], v[a]);
      }
    }
    double edge = 0;
    for (const auto& f : boundary) edge += std::sqrt(2.0 * m.face_area_out_mm2(f).norm());
    edge /= std::max<std::size_t>(boundary.size(), 1);
    const double tol = 0.1 * edge;
    std::map<std::string, std::vector<SolverFace>> caps;
    std::vector<SolverFace> rest;
    const char* axis_names[3][2] = {{"right", "left"}, {"anterior", "posterior"}, {"caudal", "cranial"}};
    for (const auto& f : boundary) {
      const Eigen::Vector3d nrm = m.face_area_out_mm2(f).normalized();
      const auto& el = m.elements[f.tet];
      std::string cap;
      for (int a = 0; a < 3 && cap.empty(); ++a)
        for (int side = 0; side < 2 && cap.empty(); ++side) {
          const double s = side ? 1.0 : -1.0, plane = side ? hi[a] : lo[a];
          if (s * nrm[a] < std::cos(25.0 * M_PI / 180.0)) continue;
          bool on = true;
          for (int k = 0; k < 3; ++k) on = on && std::abs(m.nodes_lps_mm[el[kFace[f.face][k]]][a] - plane) <= tol;
          if (on) cap = n + "_" + axis_names[a][side];
        }
      (cap.empty() ? rest : caps[cap]).push_back(f);
    }
    // A cut face spans the tube's whole cross-section on its plane: its extent across the plane
    // is at least half that of the mesh near the plane. A flat patch of the outer wall that happens
    // to touch a bounding plane (the trachea's membranous back wall) is small and stays outer.
    for (auto it = caps.begin(); it != caps.end();) {
      const auto& f0 = it->second.front();
      const Eigen::Vector3d nrm = m.face_area_out_mm2(f0).normalized();
      int a = 0;
      nrm.cwiseAbs().maxCoeff(&a);
      const double plane = m.nodes_lps_mm[m.elements[f0.tet][kFace[f0.face][0]]][a];
      Eigen::Vector3d clo = Eigen::Vector3d::Constant(1e300), chi = -clo, nlo = clo, nhi = -clo;
      for (const auto& f : it->second)
        for (int k = 0; k < 3; ++k) {
          const Eigen::Vector3d& p = m.nodes_lps_mm[m.elements[f.tet][kFace[f.face][k]]];
          clo = clo.cwiseMin(p);
          chi = chi.cwiseMax(p);
        }
      for (const auto& p : t.vertices_lps_mm)
        if (std::abs(p[a] - plane) <= 2 * edge) {
          nlo = nlo.cwiseMin(p);
          nhi = nhi.cwiseMax(p);
        }
      bool spans = true;
      for (int k = 0; k < 3; ++k)
        if (k != a) spans = spans && (chi[k] - clo[k]) >= 0.5 * (nhi[k] - nlo[k]);
      if (!spans) {
        rest.insert(rest.end(), it->second.begin(), it->second.end());
        it = caps.erase(it);
      } else {
        ++it;
      }
    }
    // Lumen or outside: the tube's inner side is the lumen surface itself (the wall reuses its
    // vertices), so a side face whose corners all lie on the lumen surface is lumen. Without that
    // surface, the two largest connected pieces of the side.
    const NamedSurface* lumen_surface = nullptr;
    for (const auto& ns : organ.surfaces)
      if (ns.name == n + "_lumen") lumen_surface = &ns;
    if (lumen_surface && !caps.empty()) {
      // Triangles of the lumen surface in a uniform grid; a side face is lumen when its centroid
      // lies within half a wall of that surface (the outside is a whole wall away).
      const SurfaceMesh& ls = lumen_surface->mesh;
      const double h = std::max({organ.spec.wall_mm, edge, 1e-3});
      auto key = [&](const Eigen::Vector3d& p) {
        return std::array<long, 3>{long(std::floor(p.x() / h)), long(std::floor(p.y() / h)), long(std::floor(p.z() / h))};
      };
      std::map<std::array<long, 3>, std::vector<std::size_t>> grid;
      for (std::size_t t = 0; t < ls.triangles.size(); ++t) {
        Eigen::Vector3d lo = ls.vertices_lps_mm[ls.triangles[t][0]], hi = lo;
        for (int k = 1; k < 3; ++k) {
          lo = lo.cwiseMin(ls.vertices_lps_mm[ls.triangles[t][k]]);
          hi = hi.cwiseMax(ls.vertices_lps_mm[ls.triangles[t][k]]);
        }
        const auto kl = key(lo), kh = key(hi);
        for (long x = kl[0]; x <= kh[0]; ++x)
          for (long y = kl[1]; y <= kh[1]; ++y)
            for (long z = kl[2]; z <= kh[2]; ++z) grid[{x, y, z}].push_back(t);
      }
      auto on_lumen = [&](const Eigen::Vector3d& p) {
        const auto k = key(p);
        for (long dx = -1; dx <= 1; ++dx)
          for (long dy = -1; dy <= 1; ++dy)
            for (long dz = -1; dz <= 1; ++dz) {
              const auto it = grid.find({k[0] + dx, k[1] + dy, k[2] + dz});
              if (it == grid.end()) continue;
              for (std::size_t t : it->second) {
                const auto& tri = ls.triangles[t];
                if (point_triangle_distance(p, ls.vertices_lps_mm[tri[0]], ls.vertices_lps_mm[tri[1]],
                                            ls.vertices_lps_mm[tri[2]]) <= 0.5 * organ.spec.wall_mm)
                  return true;
              }
            }
        return false;
      };
      std::vector<SolverFace> lumen, outer;
      for (const auto& f : rest) (on_lumen(centroid(m, f)) ? lumen : outer).push_back(f);
      if (!lumen.empty() && !outer.empty()) {
        std::vector<SolverFace> cuts;
        for (auto& [name, fs] : caps) {
          cuts.insert(cuts.end(), fs.begin(), fs.end());
          m.surfaces[name] = std::move(fs);
        }
        m.surfaces[n + "_lumen"] = std::move(lumen);
        m.surfaces[n + "_outer"] = std::move(outer);
        m.surfaces[n + "_cuts"] = std::move(cuts);
        m.notes.push_back(n + "_lumen: the side faces within half a wall of the lumen surface; _outer: the rest; cut faces on the planes "
                              "where the tube meets the image border");
        caps.clear();
        rest.clear();
      }
    }
    int count = 0;
    const auto comp = components(m, rest, count);
    if (rest.empty()) {
      // classified above
    } else if (caps.empty() || count < 2) {
      // Without cut faces the lumen and the outside are one surface: no load case can be set.
      m.surfaces[n + "_outer"] = boundary;
      m.notes.push_back(n + ": lumen and outer surface could not be told apart (" + std::to_string(caps.size()) +
                        " cut faces, " + std::to_string(count) + " side surfaces); no load case");
      caps.clear();
      rest.clear();
    }
    std::vector<double> a(std::size_t(count), 0.0);
    for (std::size_t f = 0; f < rest.size(); ++f) a[std::size_t(comp[f])] += m.face_area_out_mm2(rest[f]).norm();
    std::vector<int> order(static_cast<std::size_t>(count));
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](int x, int y) { return a[std::size_t(x)] > a[std::size_t(y)]; });
    for (std::size_t f = 0; f < rest.size(); ++f)
      m.surfaces[comp[f] == order[1] ? n + "_lumen" : n + "_outer"].push_back(rest[f]);
    std::vector<SolverFace> cuts;
    for (auto& [name, fs] : caps) {
      cuts.insert(cuts.end(), fs.begin(), fs.end());
      m.surfaces[name] = std::move(fs);
    }
    if (!cuts.empty()) {
      m.surfaces[n + "_cuts"] = std::move(cuts);
      m.notes.push_back(n + "_lumen and _outer: the inner and outer side of the tube; cut faces on the planes where the "
                            "tube meets the image border");
    }
  } else {
    m.surfaces[n + "_outer"] = boundary;
    if (organ.spec.model == OrganModel::wall_body) {
      if (!interface_wall_side.empty()) {
        m.surfaces[n + "_lumen"] = interface_wall_side;
      } else {
        // A wall without a body (an organ nowhere thicker than twice its wall): its boundary is
        // the outside and, as the second-largest piece, the inside of the wall.
        int count = 0;
        const auto comp = components(m, boundary, count);
        if (count >= 2) {
          std::vector<double> a(std::size_t(count), 0.0);
          for (std::size_t f = 0; f < boundary.size(); ++f) a[std::size_t(comp[f])] += m.face_area_out_mm2(boundary[f]).norm();
          std::vector<int> order(static_cast<std::size_t>(count));
          std::iota(order.begin(), order.end(), 0);
          std::sort(order.begin(), order.end(), [&](int x, int y) { return a[std::size_t(x)] > a[std::size_t(y)]; });
          std::vector<SolverFace> outer, lumen;
          for (std::size_t f = 0; f < boundary.size(); ++f) (comp[f] == order[1] ? lumen : outer).push_back(boundary[f]);
          m.surfaces[n + "_outer"] = outer;
          m.surfaces[n + "_lumen"] = lumen;
          boundary = outer;
        } else {
          m.notes.push_back(n + ": no lumen (the wall has no inside); no load case");
        }
      }
      // The bed: where the organ lies against its bed organ (the gallbladder's liver bed).
      const std::string suffix = bed_surface_suffix(organ.spec);
      std::string words = suffix;  // "liver_bed" → "liver bed"
      std::replace(words.begin(), words.end(), '_', ' ');
      const std::string bed_organ = organ.spec.bed_organ.empty() ? std::string("bed") : organ.spec.bed_organ;
      const auto score_it = o.bed_score.find(n);
      const auto source_it = o.bed_source.find(n);
      const bool has_score = score_it != o.bed_score.end() && score_it->second;
      std::vector<SolverFace> bed;
      const Eigen::Vector3d dir = o.bed_direction_lps.normalized();
      const double c = std::cos(o.bed_angle_deg * M_PI / 180.0);
      bool by_score = false;
      if (has_score) {
        for (const auto& f : boundary)
          if (score_it->second(centroid(m, f)) >= 0.5) bed.push_back(f);
        by_score = !bed.empty();
      }
      if (!by_score)
        for (const auto& f : boundary)
          if (m.face_area_out_mm2(f).normalized().dot(dir) >= c) bed.push_back(f);
      if (bed.empty()) {
        m.notes.push_back(n + ": no part of the surface faces the " + bed_organ + "; no " + words + ", no load case");
      } else {
        m.surfaces[n + "_" + suffix] = largest_component(bed);
        m.notes.push_back(n + "_" + suffix + ": " +
                          (by_score ? "the " + words + " from the " + (source_it != o.bed_source.end() ? source_it->second : std::string())
                           : has_score ? "surface facing superior-right (the " + words + " given lies off the mesh)"
                                       : "surface facing superior-right (the " + bed_organ + "'s side)") +
                          ", " + std::to_string(int(std::round(area(m.surfaces[n + "_" + suffix])))) + " mm2");
      }
    }
  }
  if (organ.spec.model == OrganModel::wall_body && m.surfaces.count(n + "_" + bed_surface_suffix(organ.spec)))
    add_indentation_probe(m, o.probe_lps_mm, organ.spec.probe_diameter_mm, bed_surface_suffix(organ.spec));
  if (organ.spec.model == OrganModel::tube && o.probe_on_tube && m.surfaces.count(n + "_cuts") && m.surfaces.count(n + "_outer"))
    add_indentation_probe(m, o.probe_lps_mm, organ.spec.probe_diameter_mm, "cuts");
  for (const auto& [name, fs] : m.surfaces) {
    std::set<std::int32_t> ids;
    for (const auto& f : fs)
      for (auto v : m.face_nodes(f)) ids.insert(v);
    m.node_sets[name + "_nodes"] = {ids.begin(), ids.end()};
  }
  for (const auto& [id, name] : m.region_names) {
    std::set<std::int32_t> ids;
    for (std::size_t e = 0; e < m.elements.size(); ++e)
      if (m.region_ids[e] == id)
        for (int k = 0; k < m.nodes_per_element(); ++k) ids.insert(m.elements[e][k]);
    if (!ids.empty()) m.node_sets[name + "_nodes"] = {ids.begin(), ids.end()};
  }
  return m;
}

}  // namespace organsmith
