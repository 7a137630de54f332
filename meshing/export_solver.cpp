// Over 400 lines: the five volume writers (VTU, MSH 4.1 and 2.2, INP, FEB) share one solver model,
// one region/surface grouping and the load-step resolution; each writer is short.
// Volume writers on the solver model: VTU, Gmsh 4.1 and 2.2, CalculiX/Abaqus INP and FEBio 4.0
// FEB. One model, one numbering: element ids are 1-based in region order, node ids 1-based with
// mid-edge nodes after the corners, and the sets and surfaces carry the same names everywhere.

#include "meshing/export.h"
#include "meshing/material_axes.h"
#include "meshing/export_text.h"

#include "core/errors.h"
#include "core/format.h"
#include "core/vtk_xml.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <span>

namespace organsmith {
namespace fs = std::filesystem;
using namespace export_text;

namespace {

/// Region ids present, ascending, with names.
std::vector<std::pair<std::int32_t, std::string>> regions_of(const SolverModel& m) {
  std::set<std::int32_t> ids(m.region_ids.begin(), m.region_ids.end());
  std::vector<std::pair<std::int32_t, std::string>> out;
  for (auto id : ids) {
    const auto it = m.region_names.find(id);
    out.emplace_back(id, it != m.region_names.end() ? it->second : "region" + std::to_string(id));
  }
  return out;
}

std::string id_list(const std::vector<std::int32_t>& ids, int per_line, const char* sep_line_end) {
  std::string s;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    s += std::to_string(ids[i] + 1);
    s += (i + 1 == ids.size()) ? "\n" : ((i + 1) % std::size_t(per_line) == 0 ? sep_line_end : ", ");
  }
  return s;
}

const char* kUnits = "mm, N, MPa (N/mm2), s";

/// Gmsh numbers the last two mid-edge nodes of a tet10 the other way round (edges 2-3 then 1-3).
std::array<std::int32_t, 10> gmsh_order(const std::array<std::int32_t, 10>& e) {
  auto g = e;
  std::swap(g[8], g[9]);
  return g;
}

double mpa(double pa) { return pa * 1e-6; }

/// The scenario's surface names, resolved against the model (empty when it has none).
struct ResolvedScenario {
  std::string fixed_nodes, pressure_surface;
  double pressure_MPa = 0.0;
  std::vector<std::string> inactive;
  // Indentation: the probe's node set and its displacement at the end of the step (LPS mm).
  std::string probe_nodes;
  Eigen::Vector3d probe_u_mm{0, 0, 0};
  double probe_depth_mm = 0.0;
};
ResolvedScenario resolve(const SolverModel& m, const SolverScenario& s) {
  ResolvedScenario r;
  if (s.fixed_surface.empty()) return r;
  const std::string fixed = m.organ + "_" + s.fixed_surface, loaded = m.organ + "_" + s.pressure_surface;
  // A model whose surfaces could not be found (its notes say why) is written without a load step.
  if (!m.surfaces.count(fixed)) return r;
  if (s.indentation) {
    if (!m.probe || !m.surfaces.count(m.organ + "_probe")) return r;
    r.fixed_nodes = fixed + "_nodes";
    r.probe_nodes = m.organ + "_probe_nodes";
    // Depth to 0.1 mm: the file states it as a reader would.
    double depth = s.probe_depth_mm > 0 ? s.probe_depth_mm : kProbeDepthFraction * m.probe->thickness_mm;
    if (!(depth > 0)) depth = m.probe->diameter_mm;
    r.probe_depth_mm = std::max(0.1, std::round(depth * 10.0) / 10.0);
    r.probe_u_mm = r.probe_depth_mm * m.probe->direction_lps;
    return r;
  }
  if (!m.surfaces.count(loaded)) return r;
  r.fixed_nodes = fixed + "_nodes";
  r.pressure_surface = loaded;
  r.pressure_MPa = s.pressure_kPa * 1e-3;
  for (const auto& reg : s.inactive_regions)
    for (const auto& [id, name] : m.region_names)
      if (name == reg) r.inactive.push_back(reg);
  return r;
}

/// Nodes that only elements of `inactive` regions use (sorted, 0-based).
std::vector<std::int32_t> inactive_only_nodes(const SolverModel& m, const std::vector<std::string>& inactive) {
  std::vector<char> active(m.nodes_lps_mm.size(), 0), used(m.nodes_lps_mm.size(), 0);
  for (std::size_t e = 0; e < m.elements.size(); ++e) {
    const auto it = m.region_names.find(m.region_ids[e]);
    const bool off = it != m.region_names.end() && std::find(inactive.begin(), inactive.end(), it->second) != inactive.end();
    for (int k = 0; k < m.nodes_per_element(); ++k) (off ? used : active)[std::size_t(m.elements[e][k])] = 1;
  }
  std::vector<std::int32_t> out;
  for (std::size_t v = 0; v < used.size(); ++v)
    if (used[v] && !active[v]) out.push_back(std::int32_t(v));
  return out;
}

}  // namespace

void write_vtu(const SolverModel& m, const fs::path& path, bool ras, const std::vector<PointField>& point_fields) {
  const int npe = m.nodes_per_element();
  VtkPiece piece;
  piece.points.reserve(m.nodes_lps_mm.size());
  for (const auto& v : m.nodes_lps_mm) piece.points.push_back(out_point(v, ras));
  for (const auto& e : m.elements) piece.add_cell(std::span(e.data(), std::size_t(npe)));  // VTK's quadratic tetra uses the same order
  piece.cell_types.assign(m.elements.size(), m.quadratic ? 24 : 10);  // VTK_QUADRATIC_TETRA, VTK_TETRA
  piece.cell_data.push_back({"region_id", "Int32", 1, std::vector<double>(m.region_ids.begin(), m.region_ids.end())});
  for (const auto& f : point_fields) piece.point_data.push_back({f.name, "Float64", f.components, f.values});
  write_atomic(path, vtk_unstructured_xml(piece, std::string("organsmith tetrahedra (") + (m.quadratic ? "quadratic" : "linear") +
                                                     "), " + (ras ? "RAS" : "LPS") + " mm; region_id per cell"));
}

namespace {

/// Gmsh element lines of a tet (type 4 or 11) and of a boundary face (type 2 or 9).
std::string msh_tet(const SolverModel& m, std::size_t e) {
  const auto g = gmsh_order(m.elements[e]);
  std::string s;
  for (int k = 0; k < m.nodes_per_element(); ++k) s += " " + std::to_string((m.quadratic ? g[k] : m.elements[e][k]) + 1);
  return s;
}
std::string msh_face(const SolverModel& m, const SolverFace& f) {
  std::string s;
  for (auto v : m.face_nodes(f)) s += " " + std::to_string(v + 1);
  return s;
}

/// The named surfaces overlap (the liver bed lies in the outer surface, the cuts are the cranial
/// and caudal faces together). Gmsh wants each face once: faces are grouped by the set of surfaces
/// they belong to, one entity per group, tagged with every surface of its set (MSH 4.1); MSH 2.2
/// has one physical tag per element, so a face carries its smallest surface's.
struct FaceGroup {
  std::vector<int> tags;   ///< physical tags (1-based, in m.surfaces order)
  std::vector<SolverFace> faces;
};
std::vector<FaceGroup> face_groups(const SolverModel& m) {
  std::map<std::pair<std::int32_t, std::int32_t>, std::vector<int>> member;
  std::vector<std::pair<std::int32_t, std::int32_t>> order;
  int tag = 0;
  for (const auto& [name, faces] : m.surfaces) {
    ++tag;
    for (const auto& f : faces) {
      auto [it, fresh] = member.emplace(std::make_pair(f.tet, f.face), std::vector<int>{});
      if (fresh) order.push_back(it->first);
      it->second.push_back(tag);
    }
  }
  std::map<std::vector<int>, std::size_t> index;
  std::vector<FaceGroup> groups;
  for (const auto& key : order) {
    const auto& tags = member[key];
    auto [it, fresh] = index.emplace(tags, groups.size());
    if (fresh) groups.push_back({tags, {}});
    groups[it->second].faces.push_back({key.first, key.second});
  }
  return groups;
}

}  // namespace

void write_msh41(const SolverModel& m, const fs::path& path, bool ras) {
  const auto regions = regions_of(m);
  const int tet_type = m.quadratic ? 11 : 4, tri_type = m.quadratic ? 9 : 2;
  std::string s = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n" +
                  std::to_string(regions.size() + m.surfaces.size()) + "\n";
  int sid = 0;
  for (const auto& [name, fs_] : m.surfaces) s += "2 " + std::to_string(++sid) + " \"" + name + "\"\n";
  for (const auto& [id, name] : regions) s += "3 " + std::to_string(id) + " \"" + name + "\"\n";
  const auto groups = face_groups(m);
  s += "$EndPhysicalNames\n$Entities\n0 0 " + std::to_string(groups.size()) + " " + std::to_string(regions.size()) + "\n";
  auto box = [&](auto&& nodes_of) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = Eigen::Vector3d::Constant(-1e300);
    nodes_of([&](std::int32_t v) {
      const Eigen::Vector3d p = out_point(m.nodes_lps_mm[v], ras);
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    });
    return num(lo.x()) + " " + num(lo.y()) + " " + num(lo.z()) + " " + num(hi.x()) + " " + num(hi.y()) + " " + num(hi.z());
  };
  // One surface entity per group of faces (tagged with each surface it belongs to), one volume
  // entity per region.
  sid = 0;
  for (const auto& g : groups) {
    ++sid;
    s += std::to_string(sid) + " " + box([&](auto&& f) {
           for (const auto& x : g.faces)
             for (auto v : m.face_nodes(x)) f(v);
         }) + " " + std::to_string(g.tags.size());
    for (int t : g.tags) s += " " + std::to_string(t);
    s += " 0\n";
  }
  for (const auto& [id, name] : regions)
    s += std::to_string(id) + " " + box([&](auto&& f) {
           for (std::size_t e = 0; e < m.elements.size(); ++e)
             if (m.region_ids[e] == id)
               for (int k = 0; k < m.nodes_per_element(); ++k) f(m.elements[e][k]);
         }) + " 1 " + std::to_string(id) + " 0\n";
  s += "$EndEntities\n$Nodes\n";
  const std::size_t nn = m.nodes_lps_mm.size();
  const std::int32_t first_entity = regions.empty() ? 1 : regions.front().first;
  s += "1 " + std::to_string(nn) + " 1 " + std::to_string(nn) + "\n3 " + std::to_string(first_entity) + " 0 " +
       std::to_string(nn) + "\n";
  for (std::size_t i = 0; i < nn; ++i) s += std::to_string(i + 1) + "\n";
  for (const auto& v : m.nodes_lps_mm) {
    const Eigen::Vector3d p = out_point(v, ras);
    s += num(p.x()) + " " + num(p.y()) + " " + num(p.z()) + "\n";
  }
  std::size_t faces_total = 0;
  for (const auto& g : groups) faces_total += g.faces.size();
  const std::size_t total = m.elements.size() + faces_total;
  s += "$EndNodes\n$Elements\n" + std::to_string(regions.size() + groups.size()) + " " + std::to_string(total) +
       " 1 " + std::to_string(total) + "\n";
  std::size_t tag = 0;
  sid = 0;
  for (const auto& g : groups) {
    s += "2 " + std::to_string(++sid) + " " + std::to_string(tri_type) + " " + std::to_string(g.faces.size()) + "\n";
    for (const auto& f : g.faces) s += std::to_string(++tag) + msh_face(m, f) + "\n";
  }
  for (const auto& [id, name] : regions) {
    std::size_t count = 0;
    for (auto r : m.region_ids) count += r == id;
    s += "3 " + std::to_string(id) + " " + std::to_string(tet_type) + " " + std::to_string(count) + "\n";
    for (std::size_t e = 0; e < m.elements.size(); ++e)
      if (m.region_ids[e] == id) s += std::to_string(++tag) + msh_tet(m, e) + "\n";
  }
  s += "$EndElements\n";
  write_atomic(path, s);
}

void write_msh22(const SolverModel& m, const fs::path& path, bool ras) {
  const auto regions = regions_of(m);
  const int tet_type = m.quadratic ? 11 : 4, tri_type = m.quadratic ? 9 : 2;
  std::string s = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n" +
                  std::to_string(regions.size() + m.surfaces.size()) + "\n";
  int sid = 0;
  for (const auto& [name, fs_] : m.surfaces) s += "2 " + std::to_string(++sid) + " \"" + name + "\"\n";
  for (const auto& [id, name] : regions) s += "3 " + std::to_string(id) + " \"" + name + "\"\n";
  s += "$EndPhysicalNames\n$Nodes\n" + std::to_string(m.nodes_lps_mm.size()) + "\n";
  for (std::size_t i = 0; i < m.nodes_lps_mm.size(); ++i) {
    const Eigen::Vector3d p = out_point(m.nodes_lps_mm[i], ras);
    s += std::to_string(i + 1) + " " + num(p.x()) + " " + num(p.y()) + " " + num(p.z()) + "\n";
  }
  const auto groups = face_groups(m);
  std::vector<std::size_t> surface_size;
  for (const auto& [name, faces] : m.surfaces) surface_size.push_back(faces.size());
  std::size_t faces_total = 0;
  for (const auto& g : groups) faces_total += g.faces.size();
  s += "$EndNodes\n$Elements\n" + std::to_string(m.elements.size() + faces_total) + "\n";
  std::size_t tag = 0;
  for (const auto& g : groups) {
    const int smallest = *std::min_element(g.tags.begin(), g.tags.end(), [&](int a, int b) {
      return surface_size[std::size_t(a - 1)] < surface_size[std::size_t(b - 1)];
    });
    const std::string t = std::to_string(smallest);
    for (const auto& f : g.faces)
      s += std::to_string(++tag) + " " + std::to_string(tri_type) + " 2 " + t + " " + t + msh_face(m, f) + "\n";
  }
  for (const auto& [id, name] : regions)
    for (std::size_t e = 0; e < m.elements.size(); ++e)
      if (m.region_ids[e] == id)
        s += std::to_string(++tag) + " " + std::to_string(tet_type) + " 2 " + std::to_string(id) + " " +
             std::to_string(id) + msh_tet(m, e) + "\n";
  s += "$EndElements\n";
  write_atomic(path, s);
}

namespace {
/// A number for an INP data line. CalculiX reads at most 20 characters per field (a node line with
/// -1.3633504295285093E-05, the shortest round trip of a coordinate, stops it with "*ERROR reading
/// *NODE"): 12 significant digits take at most 18, and 1e-10 mm is far below any mesh's precision.
std::string inp_num(double v) { return format_g(v, 12); }
}  // namespace

void write_inp(const SolverModel& m, const std::map<std::string, SolverMaterial>& materials,
               const SolverScenario& scenario, const fs::path& path, bool ras, std::vector<std::string>* warnings) {
  const auto regions = regions_of(m);
  const ResolvedScenario sc = resolve(m, scenario);
  const std::string type = m.quadratic ? "C3D10" : "C3D4";
  std::string s = "** organsmith solver model of " + m.organ + "; runs unedited in CalculiX (ccx) and Abaqus.\n";
  s += "** Units: " + std::string(kUnits) + ". Coordinates " + (ras ? "RAS" : "LPS") + " mm.\n";
  s += "** Elements: " + type + (m.quadratic ? " (quadratic tetrahedra; mid-edge nodes at edge midpoints)" : " (linear tetrahedra)") +
       ", one element set per region.\n";
  s += "** Surfaces (element faces; a positive pressure pushes into the element):";
  for (const auto& [name, faces] : m.surfaces) s += " " + name;
  s += ".\n** Node sets: <surface>_nodes, <region>_nodes.\n";
  for (const auto& n : m.notes) s += "** " + n + ".\n";
  s += "*HEADING\norgansmith " + m.organ + "\n*NODE, NSET=ALLNODES\n";
  for (std::size_t i = 0; i < m.nodes_lps_mm.size(); ++i) {
    const Eigen::Vector3d p = out_point(m.nodes_lps_mm[i], ras);
    s += std::to_string(i + 1) + ", " + inp_num(p.x()) + ", " + inp_num(p.y()) + ", " + inp_num(p.z()) + "\n";
  }
  for (const auto& [id, name] : regions) {
    s += "*ELEMENT, TYPE=" + type + ", ELSET=" + name + "\n";
    for (std::size_t e = 0; e < m.elements.size(); ++e)
      if (m.region_ids[e] == id) {
        s += std::to_string(e + 1);
        for (int k = 0; k < m.nodes_per_element(); ++k) s += ", " + std::to_string(m.elements[e][k] + 1);
        s += "\n";
      }
  }
  for (const auto& [name, ids] : m.node_sets) s += "*NSET, NSET=" + name + "\n" + id_list(ids, 16, "\n");
  if (!sc.inactive.empty()) {
    // Nodes only the inactive regions use have no stiffness once those are removed; the step
    // holds them (they move nothing).
    const auto loose = inactive_only_nodes(m, sc.inactive);
    if (!loose.empty()) s += "*NSET, NSET=" + m.organ + "_inactive_only_nodes\n" + id_list(loose, 16, "\n");
  }
  for (const auto& [name, faces] : m.surfaces) {
    s += "*SURFACE, NAME=" + name + ", TYPE=ELEMENT\n";
    for (const auto& f : faces) s += std::to_string(f.tet + 1) + ", S" + std::to_string(f.face + 1) + "\n";
  }
  for (const auto& [id, name] : regions) {
    const auto it = materials.find(name);
    s += "*MATERIAL, NAME=" + name + "_MAT\n";
    if (it == materials.end()) {
      if (warnings) warnings->push_back(name + ": no material given; wrote a placeholder neo-Hookean solid (E = 10 kPa, ν = 0.45)");
      const double E = 0.01, nu = 0.45;
      s += "** placeholder: no material was given for this region (E = 10 kPa, nu = 0.45)\n";
      s += "*HYPERELASTIC, NEO HOOKE\n" + inp_num(E / (4 * (1 + nu))) + ", " + inp_num(2.0 / (E / (3 * (1 - 2 * nu)))) + "\n";
    } else {
      const SolverMaterial& sm = it->second;
      s += "** " + sm.note + "\n** bulk modulus " + num(sm.bulk_modulus_Pa) + " Pa: " + sm.bulk_source + "\n";
      if (sm.mooney_rivlin_Pa) {
        s += "** the law itself: Mooney-Rivlin C10, C01, D1 = 2/K\n*HYPERELASTIC, MOONEY-RIVLIN\n" +
             format_g(mpa((*sm.mooney_rivlin_Pa)[0]), 9) + "," + format_g(mpa((*sm.mooney_rivlin_Pa)[1]), 9) + "," +
             format_g(2.0 / mpa(sm.bulk_modulus_Pa), 9) + "\n";
        s += "*SOLID SECTION, ELSET=" + name + ", MATERIAL=" + name + "_MAT\n";
        continue;
      }
      s += "** D2, D3 = 1e20: no higher-order volumetric terms\n";
      s += "*HYPERELASTIC, OGDEN, N=" + std::to_string(sm.ogden_mu_Pa.size()) + "\n";
      // Nine significant digits: CalculiX reads at most 132 characters and 8 values per line.
      std::vector<std::string> v;
      for (std::size_t k = 0; k < sm.ogden_mu_Pa.size(); ++k) {
        v.push_back(format_g(mpa(sm.ogden_mu_Pa[k]), 9));
        v.push_back(format_g(sm.ogden_alpha[k], 9));
      }
      v.push_back(format_g(2.0 / mpa(sm.bulk_modulus_Pa), 9));
      for (std::size_t k = 1; k < sm.ogden_mu_Pa.size(); ++k) v.push_back("1e20");
      for (std::size_t i = 0; i < v.size(); ++i) s += v[i] + ((i + 1 == v.size() || (i + 1) % 8 == 0) ? "\n" : ",");
    }
    s += "*SOLID SECTION, ELSET=" + name + ", MATERIAL=" + name + "_MAT\n";
  }
  if (!sc.probe_nodes.empty()) {
    const SolverProbe& p = *m.probe;
    const Eigen::Vector3d at = out_point(p.point_lps_mm, ras), dir = out_point(p.direction_lps, ras),
                          u = out_point(sc.probe_u_mm, ras);  // out_point flips x, y for RAS: a rotation
    s += "** Load case: " + sc.fixed_nodes.substr(0, sc.fixed_nodes.size() - 6) + " fixed; the thesis' indentation test "
         "(section 5.1.2): a rigid " + num(p.diameter_mm) + " mm probe bonded to " + m.organ + "_probe pressed " +
         num(sc.probe_depth_mm) + " mm along the inward normal, displacement-controlled, both regions active.\n";
    // Read back by organsmith simulate (read_solver_inp); the frame is the file's.
    s += "** organsmith probe: point " + inp_num(at.x()) + " " + inp_num(at.y()) + " " + inp_num(at.z()) + "; direction " +
         inp_num(dir.x()) + " " + inp_num(dir.y()) + " " + inp_num(dir.z()) + "; diameter " + num(p.diameter_mm) +
         "; depth " + num(sc.probe_depth_mm) + "; area " + num(p.contact_area_mm2) + "; thickness " + num(p.thickness_mm) + "\n";
    // Even steps of about 0.15 mm of probe travel (4 % of the depth at most, 0.5 % at least),
    // cut back only where an increment fails. On tetrahedra that fill the organ's gated surface
    // (mesh.cpp), steps of 0.15 and 0.18 mm converged without a cutback on the phantom's
    // gallbladder (3 950 C3D10 nodes, 5.6 mm) and on the 3 mm abdomen's from three seeds, two
    // iterations each; 0.22 mm cut back three times on the phantom. (On the earlier meshes with
    // clusters of tiny tetrahedra, 0.19 mm already diverged.) A bonded flat probe's rim distorts
    // the elements beside it by the step's travel over their size, whatever the depth; 0.15 mm
    // keeps a margin of about 1.5 below the first step seen to fail.
    const double step = std::clamp(kProbeIncrementMm / std::max(sc.probe_depth_mm, 1e-9), 0.005, 0.04);
    s += "*STEP, NLGEOM, INC=1000\n*STATIC\n" + num(step) + ", 1.0, 1e-06, " + num(step) + "\n";
    s += "*CONTROLS, PARAMETERS=TIME INCREMENTATION\n4, 8, 9, 16, 10, 4, 0, 20\n";
    s += "*BOUNDARY\n" + sc.fixed_nodes + ", 1, 3\n";
    s += "*BOUNDARY\n";
    for (int k = 0; k < 3; ++k)
      s += sc.probe_nodes + ", " + std::to_string(k + 1) + ", " + std::to_string(k + 1) + ", " + inp_num(u[k]) + "\n";
    s += "*NODE FILE\nU\n*EL FILE\nS\n";
    s += "*NODE PRINT, NSET=" + sc.fixed_nodes + ", TOTALS=ONLY\nRF\n";
    s += "*NODE PRINT, NSET=" + sc.probe_nodes + ", TOTALS=ONLY\nRF\n*END STEP\n";
  } else if (!sc.fixed_nodes.empty()) {
    s += "** Load case: " + sc.fixed_nodes.substr(0, sc.fixed_nodes.size() - 6) + " fixed; uniform pressure " +
         num(scenario.pressure_kPa) + " kPa on " + sc.pressure_surface + " (ramped over the step).\n";
    // Laws that stiffen steeply (fitted Ogden exponents near 40: the gallbladder's) take a small
    // first increment and up to 20 cutbacks per increment, so the load path has room to adapt.
    // Neo-Hookean and Mooney–Rivlin tissue (the trachea's) is nearly linear at these loads: 5 %
    // first, up to 20 % per increment (phantom trachea, 19 000 nodes: 34 iterations and 50 s
    // from 0.5 %, NN from 5 %).
    bool steep = false;
    for (const auto& [id, name] : regions) {
      if (std::find(sc.inactive.begin(), sc.inactive.end(), name) != sc.inactive.end()) continue;
      const auto it = materials.find(name);
      if (it == materials.end() || it->second.mooney_rivlin_Pa) continue;
      for (double a : it->second.ogden_alpha) steep = steep || std::abs(a) > 4.0;
    }
    s += steep ? "*STEP, NLGEOM, INC=2000\n*STATIC\n0.005, 1.0, 1e-08, 0.1\n" : "*STEP, NLGEOM, INC=2000\n*STATIC\n0.05, 1.0, 1e-08, 0.2\n";
    s += "*CONTROLS, PARAMETERS=TIME INCREMENTATION\n4, 8, 9, 16, 10, 4, 0, 20\n";
    std::vector<std::int32_t> loose;
    if (!sc.inactive.empty()) {
      s += "** The pressure is the lumen's content acting on the wall: these regions carry no load.\n";
      s += "*MODEL CHANGE, TYPE=ELEMENT, REMOVE\n";
      for (const auto& r : sc.inactive) s += r + "\n";
      loose = inactive_only_nodes(m, sc.inactive);
    }
    s += "*BOUNDARY\n" + sc.fixed_nodes + ", 1, 3\n";
    if (!loose.empty()) s += m.organ + "_inactive_only_nodes, 1, 3\n";
    s += "*DSLOAD\n" + sc.pressure_surface + ", P, " + inp_num(sc.pressure_MPa) + "\n";
    s += "*NODE FILE\nU\n*EL FILE\nS\n";
    s += "*NODE PRINT, NSET=" + sc.fixed_nodes + ", TOTALS=ONLY\nRF\n*END STEP\n";
  }
  write_atomic(path, s);
}

void write_feb(const SolverModel& m, const std::map<std::string, SolverMaterial>& materials,
               const SolverScenario& scenario, const fs::path& path, bool ras) {
  const auto regions = regions_of(m);
  const ResolvedScenario sc = resolve(m, scenario);
  std::string s = "<?xml version=\"1.0\" encoding=\"ISO-8859-1\"?>\n<!-- organsmith solver model of " + m.organ +
                  " for FEBio 4.0. Units: " + kUnits + ". Coordinates " + (ras ? "RAS" : "LPS") + " mm. -->\n";
  for (const auto& n : m.notes) s += "<!-- " + xml_escape(n) + ". -->\n";
  s += "<febio_spec version=\"4.0\">\n  <Module type=\"solid\"/>\n";
  s += "  <Control>\n    <analysis>STATIC</analysis>\n    <time_steps>20</time_steps>\n    <step_size>0.05</step_size>\n"
       "    <solver type=\"solid\">\n      <symmetric_stiffness>1</symmetric_stiffness>\n      <max_refs>25</max_refs>\n"
       "      <dtol>0.001</dtol>\n      <etol>0.01</etol>\n      <rtol>0</rtol>\n      <lstol>0.9</lstol>\n"
       "      <qn_method type=\"BFGS\">\n        <max_ups>10</max_ups>\n      </qn_method>\n    </solver>\n"
       "    <time_stepper type=\"default\">\n      <dtmin>1e-05</dtmin>\n      <dtmax>0.25</dtmax>\n"
       "      <max_retries>10</max_retries>\n      <opt_iter>10</opt_iter>\n    </time_stepper>\n  </Control>\n";
  // Regions whose law FEBio takes as it is (membrane Fung laws) get per-element material axes.
  std::map<std::string, std::vector<MaterialAxes>> axes;
  for (const auto& [id, name] : regions)
    if (const auto it = materials.find(name); it != materials.end() && it->second.febio_fung)
      if (auto a = wall_material_axes(m, id); !a.empty()) axes[name] = std::move(a);
  s += "  <Material>\n";
  int mid = 0;
  for (const auto& [id, name] : regions) {
    const auto it = materials.find(name);
    if (it == materials.end()) {
      s += "    <!-- placeholder: no material was given for this region -->\n";
      s += "    <material id=\"" + std::to_string(++mid) + "\" name=\"" + xml_escape(name) +
           "\" type=\"neo-Hookean\">\n      <density>1e-09</density>\n      <E>0.01</E>\n      <v>0.45</v>\n    </material>\n";
      continue;
    }
    const SolverMaterial& sm = it->second;
    if (sm.febio_fung && axes.count(name)) {
      // The law itself (no fit): FEBio's Fung orthotropic form with per-element axes (MeshData).
      const FebioFungOrthotropic& f = *sm.febio_fung;
      s += "    <!-- " + xml_escape(sm.law_id) + ": " + xml_escape(f.note) + ". Axes per element in MeshData. -->\n";
      s += "    <material id=\"" + std::to_string(++mid) + "\" name=\"" + xml_escape(name) + "\" type=\"Fung-ortho-compressible\">\n";
      s += "      <density>1e-09</density>\n";
      const std::pair<const char*, double> params[] = {
          {"E1", mpa(f.E1_Pa)},   {"E2", mpa(f.E2_Pa)},   {"E3", mpa(f.E3_Pa)}, {"G12", mpa(f.G12_Pa)},
          {"G23", mpa(f.G23_Pa)}, {"G31", mpa(f.G31_Pa)}, {"v12", f.v12},       {"v23", f.v23},
          {"v31", f.v31},         {"c", mpa(f.c_Pa)},     {"k", mpa(f.k_Pa)}};
      for (const auto& [key, v] : params) s += "      <" + std::string(key) + ">" + num(v) + "</" + key + ">\n";
      s += "    </material>\n";
      continue;
    }
    s += "    <!-- " + xml_escape(sm.note) + "; bulk modulus " + num(sm.bulk_modulus_Pa) + " Pa: " + xml_escape(sm.bulk_source) +
         ". FEBio's Ogden: c_i = 2 mu_i, m_i = alpha_i, k = K (pressure_model 2: U = k/2 (J-1)^2). -->\n";
    s += "    <material id=\"" + std::to_string(++mid) + "\" name=\"" + xml_escape(name) + "\" type=\"Ogden\">\n";
    s += "      <density>1e-09</density>\n      <k>" + num(mpa(sm.bulk_modulus_Pa)) + "</k>\n      <pressure_model>2</pressure_model>\n";
    for (std::size_t k = 0; k < sm.ogden_mu_Pa.size(); ++k)
      s += "      <c" + std::to_string(k + 1) + ">" + num(2 * mpa(sm.ogden_mu_Pa[k])) + "</c" + std::to_string(k + 1) + ">\n";
    for (std::size_t k = 0; k < sm.ogden_mu_Pa.size(); ++k)
      s += "      <m" + std::to_string(k + 1) + ">" + num(sm.ogden_alpha[k]) + "</m" + std::to_string(k + 1) + ">\n";
    s += "    </material>\n";
  }
  s += "  </Material>\n  <Mesh>\n    <Nodes name=\"" + xml_escape(m.organ) + "_nodes_all\">\n";
  for (std::size_t i = 0; i < m.nodes_lps_mm.size(); ++i) {
    const Eigen::Vector3d p = out_point(m.nodes_lps_mm[i], ras);
    s += "      <node id=\"" + std::to_string(i + 1) + "\">" + num(p.x()) + "," + num(p.y()) + "," + num(p.z()) + "</node>\n";
  }
  s += "    </Nodes>\n";
  const std::string et = m.quadratic ? "tet10" : "tet4";
  for (const auto& [id, name] : regions) {
    s += "    <Elements type=\"" + et + "\" name=\"" + xml_escape(name) + "\">\n";
    for (std::size_t e = 0; e < m.elements.size(); ++e)
      if (m.region_ids[e] == id) {
        s += "      <elem id=\"" + std::to_string(e + 1) + "\">";
        for (int k = 0; k < m.nodes_per_element(); ++k) s += (k ? "," : "") + std::to_string(m.elements[e][k] + 1);
        s += "</elem>\n";
      }
    s += "    </Elements>\n";
  }
  for (const auto& [name, ids] : m.node_sets) s += "    <NodeSet name=\"" + xml_escape(name) + "\">" + id_list(ids, 16, ",\n").substr(0) + "    </NodeSet>\n";
  const std::string ft = m.quadratic ? "tri6" : "tri3";
  for (const auto& [name, faces] : m.surfaces) {
    // FEBio's pressure pushes against the facet normal of its node order, so the facets are
    // written reversed (normal out of the element): a positive pressure then pushes into the
    // element, as in the INP.
    s += "    <Surface name=\"" + xml_escape(name) + "\">\n";
    int fid = 0;
    for (const auto& f : faces) {
      const auto n = m.face_nodes(f);
      std::vector<std::int32_t> r = {n[0], n[2], n[1]};
      if (m.quadratic) r.insert(r.end(), {n[5], n[4], n[3]});
      s += "      <" + ft + " id=\"" + std::to_string(++fid) + "\">";
      for (std::size_t k = 0; k < r.size(); ++k) s += (k ? "," : "") + std::to_string(r[k] + 1);
      s += "</" + ft + ">\n";
    }
    s += "    </Surface>\n";
  }
  s += "  </Mesh>\n  <MeshDomains>\n";
  for (const auto& [id, name] : regions) {
    const bool inactive = std::find(sc.inactive.begin(), sc.inactive.end(), name) != sc.inactive.end();
    if (inactive) s += "    <!-- " + xml_escape(name) + " carries no load in this load case; kept as a part of the model -->\n";
    s += "    <SolidDomain name=\"" + xml_escape(name) + "\" mat=\"" + xml_escape(name) + "\"/>\n";
  }
  s += "  </MeshDomains>\n";
  if (!axes.empty()) {
    // After MeshDomains (FEBio refuses it before). a = longitudinal, d = circumferential; FEBio
    // takes e1 = a, e3 = a × d (the wall normal), e2 = e3 × e1.
    s += "  <MeshData>\n";
    for (const auto& [name, list] : axes) {
      s += "    <ElementData type=\"mat_axis\" elem_set=\"" + xml_escape(name) + "\">\n";
      auto vec = [&](const Eigen::Vector3d& v) {
        const Eigen::Vector3d o = out_point(v, ras);
        return format_g(o.x(), 6) + "," + format_g(o.y(), 6) + "," + format_g(o.z(), 6);
      };
      for (std::size_t i = 0; i < list.size(); ++i)
        s += "      <e lid=\"" + std::to_string(i + 1) + "\"><a>" + vec(list[i].longitudinal) + "</a><d>" +
             vec(list[i].circumferential) + "</d></e>\n";
      s += "    </ElementData>\n";
    }
    s += "  </MeshData>\n";
  }
  if (!sc.probe_nodes.empty()) {
    const Eigen::Vector3d u = out_point(sc.probe_u_mm, ras);
    s += "  <!-- the thesis' indentation test (section 5.1.2): a rigid " + num(m.probe->diameter_mm) + " mm probe bonded to " +
         xml_escape(m.organ) + "_probe, pressed " + num(sc.probe_depth_mm) + " mm along the inward normal -->\n";
    s += "  <Boundary>\n    <bc name=\"fixed\" type=\"zero displacement\" node_set=\"" + xml_escape(sc.fixed_nodes) +
         "\">\n      <x_dof>1</x_dof>\n      <y_dof>1</y_dof>\n      <z_dof>1</z_dof>\n    </bc>\n";
    const char* dof[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k)
      s += "    <bc name=\"probe_" + std::string(dof[k]) + "\" type=\"prescribed displacement\" node_set=\"" +
           xml_escape(sc.probe_nodes) + "\">\n      <dof>" + dof[k] + "</dof>\n      <value lc=\"1\">" + num(u[k]) +
           "</value>\n      <relative>0</relative>\n    </bc>\n";
    s += "  </Boundary>\n";
    s += "  <LoadData>\n    <load_controller id=\"1\" name=\"ramp\" type=\"loadcurve\">\n      <interpolate>LINEAR</interpolate>\n"
         "      <extend>CONSTANT</extend>\n      <points>\n        <point>0,0</point>\n        <point>1,1</point>\n"
         "      </points>\n    </load_controller>\n  </LoadData>\n";
  } else if (!sc.fixed_nodes.empty()) {
    s += "  <Boundary>\n    <bc name=\"fixed\" type=\"zero displacement\" node_set=\"" + xml_escape(sc.fixed_nodes) +
         "\">\n      <x_dof>1</x_dof>\n      <y_dof>1</y_dof>\n      <z_dof>1</z_dof>\n    </bc>\n  </Boundary>\n";
    s += "  <Loads>\n    <surface_load name=\"pressure\" type=\"pressure\" surface=\"" + xml_escape(sc.pressure_surface) +
         "\">\n      <pressure lc=\"1\">" + num(sc.pressure_MPa) +
         "</pressure>\n      <symmetric_stiffness>1</symmetric_stiffness>\n      <linear>0</linear>\n    </surface_load>\n  </Loads>\n";
    s += "  <LoadData>\n    <load_controller id=\"1\" name=\"ramp\" type=\"loadcurve\">\n      <interpolate>LINEAR</interpolate>\n"
         "      <extend>CONSTANT</extend>\n      <points>\n        <point>0,0</point>\n        <point>1,1</point>\n"
         "      </points>\n    </load_controller>\n  </LoadData>\n";
  }
  s += "  <Output>\n    <plotfile type=\"febio\">\n      <var type=\"displacement\"/>\n      <var type=\"stress\"/>\n"
       "      <var type=\"reaction forces\"/>\n    </plotfile>\n  </Output>\n</febio_spec>\n";
  write_atomic(path, s);
}

}  // namespace organsmith
