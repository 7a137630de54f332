// Over 400 lines: nine writers (STL, OBJ, PLY, VTP, VTU, MSH 4.1 and 2.2, INP, FEB) sharing one
// number format and one region/material table; each writer is short.
// Mesh file writers. Numbers are printed with std::to_chars (shortest round-trip form), so the
// same mesh always gives the same bytes and re-reading gives the same doubles.

#include "meshing/export.h"

#include "core/file_io.h"

#include "core/errors.h"

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <optional>
#include <fstream>
#include <set>
#include <sstream>
#include <unistd.h>

namespace organsmith {
namespace fs = std::filesystem;

std::vector<std::string> all_mesh_formats() { return {"stl", "obj", "ply", "vtp", "vtu", "msh", "msh22", "inp", "feb"}; }

namespace {

std::string num(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v == 0.0 ? 0.0 : v);  // no "-0"
  return std::string(buf, r.ptr);
}

Eigen::Vector3d out_point(const Eigen::Vector3d& p, bool ras) { return ras ? lps_to_ras(p) : p; }

/// Writes `bytes` to `path` atomically.
void write_atomic(const fs::path& path, const std::string& bytes) { write_file_atomic(path, bytes); }

template <class T>
void put(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));  // x86-64 and aarch64 are little-endian, as STL and PLY require
  s.append(b, sizeof(T));
}

std::string xml_escape(const std::string& in) {
  std::string o;
  for (char c : in) {
    switch (c) {
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '&': o += "&amp;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

/// A material as the solvers take it, in MPa (meshes are in mm).
struct SolverMaterial {
  std::string febio_type;                             ///< "neo-Hookean", "Mooney-Rivlin"
  std::vector<std::pair<std::string, double>> febio;  ///< FEBio parameter → value
  std::string abaqus;                                 ///< lines after *MATERIAL
  std::string note;                                   ///< how it was derived (written as a comment)
};

double to_mpa(const MaterialParameter& p) {
  if (p.unit == "Pa") return p.value * 1e-6;
  if (p.unit == "kPa") return p.value * 1e-3;
  if (p.unit == "MPa") return p.value;
  return p.value;  // dimensionless
}

SolverMaterial neo_hooke(double E_mpa, double nu, std::string note) {
  SolverMaterial s;
  s.febio_type = "neo-Hookean";
  s.febio = {{"density", 1.0}, {"E", E_mpa}, {"v", nu}};
  const double c10 = E_mpa / (4.0 * (1.0 + nu));
  const double K = E_mpa / (3.0 * (1.0 - 2.0 * nu));
  s.abaqus = "*HYPERELASTIC, NEO HOOKE\n" + num(c10) + ", " + num(2.0 / K) + "\n";
  s.note = std::move(note);
  return s;
}

SolverMaterial solver_material(const std::string& region, const std::map<std::string, Material>& materials,
                               std::vector<std::string>* warnings) {
  const auto it = materials.find(region);
  if (it == materials.end()) {
    if (warnings) warnings->push_back(region + ": no material given; wrote a placeholder neo-Hookean solid (E = 10 kPa, ν = 0.45)");
    return neo_hooke(0.01, 0.45, "placeholder: no material was given for this region");
  }
  const Material& m = it->second;
  auto par = [&](const char* name) -> std::optional<double> {
    for (const auto& p : m.parameters)
      if (p.name == name) return to_mpa(p);
    return std::nullopt;
  };
  std::string original = m.model + " (";
  for (std::size_t i = 0; i < m.parameters.size(); ++i)
    original += (i ? ", " : "") + m.parameters[i].name + " = " + num(m.parameters[i].value) + " " + m.parameters[i].unit;
  original += "; " + m.source + ")";
  if (m.model == "mooney-rivlin" && par("c1") && par("c2")) {
    SolverMaterial s;
    const double k = par("k").value_or(1000.0 * (*par("c1") + *par("c2")));
    s.febio_type = "Mooney-Rivlin";
    s.febio = {{"density", 1.0}, {"c1", *par("c1")}, {"c2", *par("c2")}, {"k", k}};
    s.abaqus = "*HYPERELASTIC, MOONEY-RIVLIN\n" + num(*par("c1")) + ", " + num(*par("c2")) + ", " + num(2.0 / k) + "\n";
    s.note = "from " + original;
    return s;
  }
  if (m.model == "neo-hookean" && par("E")) return neo_hooke(*par("E"), par("v").value_or(par("nu").value_or(0.45)), "from " + original);
  if (m.model.rfind("fung", 0) == 0 && par("c") && par("a1") && par("a2")) {
    // Neither solver has the isotropic-in-plane Fung law of the thesis; its zero-strain
    // tangent (S = c·a·E for W = c/2 (e^Q − 1)) gives the initial stiffness of an equivalent
    // nearly incompressible neo-Hookean solid.
    const double E = *par("c") * 0.5 * (*par("a1") + *par("a2"));
    if (warnings) {
      char e_pa[32];
      std::snprintf(e_pa, sizeof e_pa, "%.4g", E * 1e6);
      warnings->push_back(region + ": " + m.model + " written as its zero-strain neo-Hookean equivalent (E = " + e_pa +
                          " Pa); the solvers have no matching Fung form");
    }
    return neo_hooke(E, 0.49, "zero-strain neo-Hookean equivalent of " + original);
  }
  if (par("E")) return neo_hooke(*par("E"), par("v").value_or(0.45), "from " + original);
  if (warnings) warnings->push_back(region + ": material model '" + m.model + "' has no solver form; wrote a placeholder neo-Hookean solid (E = 10 kPa, ν = 0.45)");
  return neo_hooke(0.01, 0.45, "placeholder for " + original);
}

/// Region ids present in the mesh, ascending, with names.
std::vector<std::pair<std::int32_t, std::string>> regions_of(const TetMesh& m, const std::map<std::int32_t, std::string>& names) {
  std::set<std::int32_t> ids(m.region_ids.begin(), m.region_ids.end());
  std::vector<std::pair<std::int32_t, std::string>> out;
  for (auto id : ids) {
    const auto it = names.find(id);
    out.emplace_back(id, it != names.end() ? it->second : "region" + std::to_string(id));
  }
  return out;
}

}  // namespace

void write_stl(const SurfaceMesh& m, const fs::path& path, bool ras) {
  std::string s;
  std::string header = "organsmith binary STL, " + std::string(ras ? "RAS" : "LPS") + " mm";
  header.resize(80, ' ');
  s += header;
  put<std::uint32_t>(s, std::uint32_t(m.triangles.size()));
  for (const auto& t : m.triangles) {
    const Eigen::Vector3d a = out_point(m.vertices_lps_mm[t[0]], ras), b = out_point(m.vertices_lps_mm[t[1]], ras),
                          c = out_point(m.vertices_lps_mm[t[2]], ras);
    Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() > 0) n.normalize();
    for (const Eigen::Vector3d& v : {n, a, b, c})
      for (int i = 0; i < 3; ++i) put<float>(s, float(v[i]));
    put<std::uint16_t>(s, 0);
  }
  write_atomic(path, s);
}

SurfaceMesh read_stl(const fs::path& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(ExitCode::input_not_found, "cannot open the STL file", path);
  std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (bytes.size() < 84) throw InputError(ExitCode::unsupported_input, "not a binary STL file", path);
  std::uint32_t n = 0;
  std::memcpy(&n, bytes.data() + 80, 4);
  if (bytes.size() != 84 + std::size_t(n) * 50) throw InputError(ExitCode::unsupported_input, "truncated binary STL", path);
  SurfaceMesh m;
  std::map<std::array<float, 3>, std::int32_t> index;
  for (std::uint32_t t = 0; t < n; ++t) {
    std::array<std::int32_t, 3> tri{};
    for (int v = 0; v < 3; ++v) {
      std::array<float, 3> p{};
      std::memcpy(p.data(), bytes.data() + 84 + std::size_t(t) * 50 + 12 + v * 12, 12);
      auto [it, fresh] = index.emplace(p, std::int32_t(m.vertices_lps_mm.size()));
      if (fresh) m.vertices_lps_mm.emplace_back(p[0], p[1], p[2]);
      tri[v] = it->second;
    }
    m.triangles.push_back(tri);
  }
  return m;
}

void write_obj(const SurfaceMesh& m, const fs::path& path, bool ras) {
  std::string s = "# organsmith surface, " + std::string(ras ? "RAS" : "LPS") + " mm, counter-clockwise seen from outside\n";
  for (const auto& v : m.vertices_lps_mm) {
    const Eigen::Vector3d p = out_point(v, ras);
    s += "v " + num(p.x()) + " " + num(p.y()) + " " + num(p.z()) + "\n";
  }
  for (const auto& t : m.triangles)
    s += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " + std::to_string(t[2] + 1) + "\n";
  write_atomic(path, s);
}

void write_ply(const SurfaceMesh& m, const fs::path& path, bool ras) {
  std::string s = "ply\nformat binary_little_endian 1.0\ncomment organsmith surface, " + std::string(ras ? "RAS" : "LPS") +
                  " mm\nelement vertex " + std::to_string(m.vertices_lps_mm.size()) +
                  "\nproperty double x\nproperty double y\nproperty double z\nelement face " +
                  std::to_string(m.triangles.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  for (const auto& v : m.vertices_lps_mm) {
    const Eigen::Vector3d p = out_point(v, ras);
    for (int i = 0; i < 3; ++i) put<double>(s, p[i]);
  }
  for (const auto& t : m.triangles) {
    put<std::uint8_t>(s, 3);
    for (int i = 0; i < 3; ++i) put<std::int32_t>(s, t[i]);
  }
  write_atomic(path, s);
}

namespace {
std::string vtk_points(const std::vector<Eigen::Vector3d>& pts, bool ras) {
  std::string s = "      <Points>\n        <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (const auto& v : pts) {
    const Eigen::Vector3d p = out_point(v, ras);
    s += "          " + num(p.x()) + " " + num(p.y()) + " " + num(p.z()) + "\n";
  }
  return s + "        </DataArray>\n      </Points>\n";
}
}  // namespace

void write_vtp(const SurfaceMesh& m, const fs::path& path, bool ras) {
  std::string s = "<?xml version=\"1.0\"?>\n<!-- organsmith surface, " + std::string(ras ? "RAS" : "LPS") +
                  " mm -->\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
                  "  <PolyData>\n    <Piece NumberOfPoints=\"" + std::to_string(m.vertices_lps_mm.size()) +
                  "\" NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"" +
                  std::to_string(m.triangles.size()) + "\">\n";
  s += vtk_points(m.vertices_lps_mm, ras);
  s += "      <Polys>\n        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
  for (const auto& t : m.triangles) s += "          " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + "\n";
  s += "        </DataArray>\n        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
  for (std::size_t i = 0; i < m.triangles.size(); ++i) s += "          " + std::to_string(3 * (i + 1)) + "\n";
  s += "        </DataArray>\n      </Polys>\n";
  if (!m.region_ids.empty()) {
    s += "      <CellData Scalars=\"region_id\">\n        <DataArray type=\"Int32\" Name=\"region_id\" format=\"ascii\">\n";
    for (auto r : m.region_ids) s += "          " + std::to_string(r) + "\n";
    s += "        </DataArray>\n      </CellData>\n";
  }
  s += "    </Piece>\n  </PolyData>\n</VTKFile>\n";
  write_atomic(path, s);
}

void write_vtu(const TetMesh& m, const fs::path& path, bool ras) {
  std::string s = "<?xml version=\"1.0\"?>\n<!-- organsmith tetrahedra, " + std::string(ras ? "RAS" : "LPS") +
                  " mm; region_id per cell -->\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
                  "  <UnstructuredGrid>\n    <Piece NumberOfPoints=\"" + std::to_string(m.vertices_lps_mm.size()) +
                  "\" NumberOfCells=\"" + std::to_string(m.tets.size()) + "\">\n";
  s += vtk_points(m.vertices_lps_mm, ras);
  s += "      <Cells>\n        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
  for (const auto& t : m.tets)
    s += "          " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + " " + std::to_string(t[3]) + "\n";
  s += "        </DataArray>\n        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
  for (std::size_t i = 0; i < m.tets.size(); ++i) s += "          " + std::to_string(4 * (i + 1)) + "\n";
  s += "        </DataArray>\n        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (std::size_t i = 0; i < m.tets.size(); ++i) s += "          10\n";  // VTK_TETRA
  s += "        </DataArray>\n      </Cells>\n      <CellData Scalars=\"region_id\">\n"
       "        <DataArray type=\"Int32\" Name=\"region_id\" format=\"ascii\">\n";
  for (auto r : m.region_ids) s += "          " + std::to_string(r) + "\n";
  s += "        </DataArray>\n      </CellData>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n";
  write_atomic(path, s);
}

void write_msh41(const TetMesh& m, const std::map<std::int32_t, std::string>& names, const fs::path& path, bool ras) {
  const auto regions = regions_of(m, names);
  std::string s = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n" + std::to_string(regions.size()) + "\n";
  for (const auto& [id, name] : regions) s += "3 " + std::to_string(id) + " \"" + name + "\"\n";
  s += "$EndPhysicalNames\n$Entities\n0 0 0 " + std::to_string(regions.size()) + "\n";
  // One volume entity per region (tag = region id), with its bounding box and physical group.
  for (const auto& [id, name] : regions) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = Eigen::Vector3d::Constant(-1e300);
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      if (m.region_ids[t] == id)
        for (auto v : m.tets[t]) {
          const Eigen::Vector3d p = out_point(m.vertices_lps_mm[v], ras);
          lo = lo.cwiseMin(p);
          hi = hi.cwiseMax(p);
        }
    s += std::to_string(id) + " " + num(lo.x()) + " " + num(lo.y()) + " " + num(lo.z()) + " " + num(hi.x()) + " " +
         num(hi.y()) + " " + num(hi.z()) + " 1 " + std::to_string(id) + " 0\n";
  }
  s += "$EndEntities\n$Nodes\n";
  const std::size_t nn = m.vertices_lps_mm.size();
  const std::int32_t first_entity = regions.empty() ? 1 : regions.front().first;
  s += "1 " + std::to_string(nn) + " 1 " + std::to_string(nn) + "\n3 " + std::to_string(first_entity) + " 0 " +
       std::to_string(nn) + "\n";
  for (std::size_t i = 0; i < nn; ++i) s += std::to_string(i + 1) + "\n";
  for (const auto& v : m.vertices_lps_mm) {
    const Eigen::Vector3d p = out_point(v, ras);
    s += num(p.x()) + " " + num(p.y()) + " " + num(p.z()) + "\n";
  }
  s += "$EndNodes\n$Elements\n" + std::to_string(regions.size()) + " " + std::to_string(m.tets.size()) + " 1 " +
       std::to_string(m.tets.size()) + "\n";
  std::size_t tag = 0;
  for (const auto& [id, name] : regions) {
    std::size_t count = 0;
    for (auto r : m.region_ids) count += r == id;
    s += "3 " + std::to_string(id) + " 4 " + std::to_string(count) + "\n";
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      if (m.region_ids[t] == id) {
        const auto& T = m.tets[t];
        s += std::to_string(++tag) + " " + std::to_string(T[0] + 1) + " " + std::to_string(T[1] + 1) + " " +
             std::to_string(T[2] + 1) + " " + std::to_string(T[3] + 1) + "\n";
      }
  }
  s += "$EndElements\n";
  write_atomic(path, s);
}

void write_msh22(const TetMesh& m, const std::map<std::int32_t, std::string>& names, const fs::path& path, bool ras) {
  const auto regions = regions_of(m, names);
  std::string s = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n" + std::to_string(regions.size()) + "\n";
  for (const auto& [id, name] : regions) s += "3 " + std::to_string(id) + " \"" + name + "\"\n";
  s += "$EndPhysicalNames\n$Nodes\n" + std::to_string(m.vertices_lps_mm.size()) + "\n";
  for (std::size_t i = 0; i < m.vertices_lps_mm.size(); ++i) {
    const Eigen::Vector3d p = out_point(m.vertices_lps_mm[i], ras);
    s += std::to_string(i + 1) + " " + num(p.x()) + " " + num(p.y()) + " " + num(p.z()) + "\n";
  }
  s += "$EndNodes\n$Elements\n" + std::to_string(m.tets.size()) + "\n";
  std::size_t tag = 0;
  for (const auto& [id, name] : regions)
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      if (m.region_ids[t] == id) {
        const auto& T = m.tets[t];
        s += std::to_string(++tag) + " 4 2 " + std::to_string(id) + " " + std::to_string(id) + " " +
             std::to_string(T[0] + 1) + " " + std::to_string(T[1] + 1) + " " + std::to_string(T[2] + 1) + " " +
             std::to_string(T[3] + 1) + "\n";
      }
  s += "$EndElements\n";
  write_atomic(path, s);
}

void write_inp(const TetMesh& m, const std::map<std::int32_t, std::string>& names,
               const std::map<std::string, Material>& materials, const fs::path& path, bool ras,
               std::vector<std::string>* warnings) {
  const auto regions = regions_of(m, names);
  std::string s = "*HEADING\norgansmith tetrahedral mesh; coordinates " + std::string(ras ? "RAS" : "LPS") +
                  " mm, stresses MPa\n*NODE, NSET=ALLNODES\n";
  for (std::size_t i = 0; i < m.vertices_lps_mm.size(); ++i) {
    const Eigen::Vector3d p = out_point(m.vertices_lps_mm[i], ras);
    s += std::to_string(i + 1) + ", " + num(p.x()) + ", " + num(p.y()) + ", " + num(p.z()) + "\n";
  }
  std::size_t tag = 0;
  for (const auto& [id, name] : regions) {
    s += "*ELEMENT, TYPE=C3D4, ELSET=" + name + "\n";
    std::set<std::int32_t> nodes;
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      if (m.region_ids[t] == id) {
        const auto& T = m.tets[t];
        s += std::to_string(++tag) + ", " + std::to_string(T[0] + 1) + ", " + std::to_string(T[1] + 1) + ", " +
             std::to_string(T[2] + 1) + ", " + std::to_string(T[3] + 1) + "\n";
        nodes.insert(T.begin(), T.end());
      }
    s += "*NSET, NSET=" + name + "_NODES\n";
    std::size_t col = 0;
    for (auto v : nodes) {
      s += std::to_string(v + 1);
      s += (++col % 16 == 0 || col == nodes.size()) ? "\n" : ", ";
    }
  }
  for (const auto& [id, name] : regions) {
    const SolverMaterial sm = solver_material(name, materials, warnings);
    s += "** " + name + ": " + sm.note + "\n";
    s += "*SOLID SECTION, ELSET=" + name + ", MATERIAL=" + name + "_MAT\n,\n";
    s += "*MATERIAL, NAME=" + name + "_MAT\n" + sm.abaqus;
  }
  write_atomic(path, s);
}

void write_feb(const TetMesh& m, const std::map<std::int32_t, std::string>& names,
               const std::map<std::string, Material>& materials, const fs::path& path, bool ras,
               std::vector<std::string>* warnings) {
  const auto regions = regions_of(m, names);
  std::string s = "<?xml version=\"1.0\" encoding=\"ISO-8859-1\"?>\n<!-- organsmith tetrahedral mesh; coordinates " +
                  std::string(ras ? "RAS" : "LPS") + " mm, stresses MPa -->\n<febio_spec version=\"4.0\">\n"
                  "  <Module type=\"solid\"/>\n  <Material>\n";
  int mid = 0;
  for (const auto& [id, name] : regions) {
    const SolverMaterial sm = solver_material(name, materials, nullptr);
    s += "    <!-- " + xml_escape(sm.note) + " -->\n";
    s += "    <material id=\"" + std::to_string(++mid) + "\" name=\"" + xml_escape(name) + "\" type=\"" + sm.febio_type + "\">\n";
    for (const auto& [k, v] : sm.febio) s += "      <" + k + ">" + num(v) + "</" + k + ">\n";
    s += "    </material>\n";
  }
  (void)warnings;  // reported once by write_inp / export_meshes
  s += "  </Material>\n  <Mesh>\n    <Nodes name=\"AllNodes\">\n";
  for (std::size_t i = 0; i < m.vertices_lps_mm.size(); ++i) {
    const Eigen::Vector3d p = out_point(m.vertices_lps_mm[i], ras);
    s += "      <node id=\"" + std::to_string(i + 1) + "\">" + num(p.x()) + "," + num(p.y()) + "," + num(p.z()) + "</node>\n";
  }
  s += "    </Nodes>\n";
  std::size_t tag = 0;
  for (const auto& [id, name] : regions) {
    s += "    <Elements type=\"tet4\" name=\"" + xml_escape(name) + "\">\n";
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      if (m.region_ids[t] == id) {
        const auto& T = m.tets[t];
        s += "      <elem id=\"" + std::to_string(++tag) + "\">" + std::to_string(T[0] + 1) + "," + std::to_string(T[1] + 1) +
             "," + std::to_string(T[2] + 1) + "," + std::to_string(T[3] + 1) + "</elem>\n";
      }
    s += "    </Elements>\n";
  }
  s += "  </Mesh>\n  <MeshDomains>\n";
  for (const auto& [id, name] : regions)
    s += "    <SolidDomain name=\"" + xml_escape(name) + "\" mat=\"" + xml_escape(name) + "\"/>\n";
  s += "  </MeshDomains>\n</febio_spec>\n";
  write_atomic(path, s);
}

std::string quality_json(const OrganMesh& organ) {
  nlohmann::json j;
  j["organ"] = organ.spec.name;
  j["label"] = organ.spec.label;
  j["model"] = organ.spec.model == OrganModel::tube ? "tube" : organ.spec.model == OrganModel::wall_body ? "wall_body" : "solid";
  j["wall_mm"] = organ.spec.wall_mm;
  j["label_volume_mm3"] = organ.label_volume_mm3;
  j["dropped_volume_mm3"] = organ.dropped_volume_mm3;
  j["voxel_diagonal_mm"] = organ.voxel_diagonal_mm;
  j["surfaces"] = nlohmann::json::object();
  for (const auto& s : organ.surfaces) j["surfaces"][s.name] = to_json(s.quality);
  if (!organ.volume.tets.empty()) {
    j["tetrahedra"] = to_json(organ.volume_quality);
    nlohmann::json regions = nlohmann::json::object();
    for (const auto& [id, name] : organ.region_names) regions[std::to_string(id)] = name;
    j["tetrahedra"]["regions"] = regions;
  }
  // No wall times here: the file is a result, byte-identical for the same input and options
  // (the manifest records how long each stage took).
  j["warnings"] = organ.warnings;
  bool ok = organ.volume_quality.ok() || organ.volume.tets.empty();
  for (const auto& s : organ.surfaces) ok = ok && s.quality.ok();
  j["passed"] = ok;
  return j.dump(2) + "\n";
}

std::vector<fs::path> export_meshes(const OrganMeshes& meshes, const fs::path& dir, const ExportOptions& o,
                                    std::vector<std::string>* warnings) {
  const auto formats = all_mesh_formats();
  const std::set<std::string> known(formats.begin(), formats.end());
  std::set<std::string> want;
  for (const auto& f : o.formats) {
    if (!known.count(f)) throw UsageError("unknown mesh format '" + f + "'", "choose from stl, obj, ply, vtp, vtu, msh, msh22, inp, feb");
    want.insert(f);
  }
  std::vector<fs::path> written;
  for (const auto& organ : meshes.organs) {
    const fs::path rel = organ.spec.name;
    std::error_code ec;
    fs::create_directories(dir / rel, ec);
    if (ec) throw OutputError("cannot create the output directory", dir / rel, ec.message());
    auto emit = [&](const std::string& file, auto&& writer) {
      writer(dir / rel / file);
      written.push_back(rel / file);
    };
    for (const auto& s : organ.surfaces) {
      if (want.count("stl")) emit(s.name + ".stl", [&](const fs::path& p) { write_stl(s.mesh, p, o.ras); });
      if (want.count("obj")) emit(s.name + ".obj", [&](const fs::path& p) { write_obj(s.mesh, p, o.ras); });
      if (want.count("ply")) emit(s.name + ".ply", [&](const fs::path& p) { write_ply(s.mesh, p, o.ras); });
      if (want.count("vtp")) emit(s.name + ".vtp", [&](const fs::path& p) { write_vtp(s.mesh, p, o.ras); });
    }
    if (!organ.volume.tets.empty()) {
      const auto& v = organ.volume;
      const std::string n = organ.spec.name;
      if (want.count("vtu")) emit(n + ".vtu", [&](const fs::path& p) { write_vtu(v, p, o.ras); });
      if (want.count("msh")) emit(n + ".msh", [&](const fs::path& p) { write_msh41(v, organ.region_names, p, o.ras); });
      if (want.count("msh22")) emit(n + ".v22.msh", [&](const fs::path& p) { write_msh22(v, organ.region_names, p, o.ras); });
      if (want.count("inp"))
        emit(n + ".inp", [&](const fs::path& p) { write_inp(v, organ.region_names, o.materials, p, o.ras, warnings); });
      if (want.count("feb"))
        emit(n + ".feb", [&](const fs::path& p) {
          write_feb(v, organ.region_names, o.materials, p, o.ras, want.count("inp") ? nullptr : warnings);
        });
    }
    emit("quality.json", [&](const fs::path& p) { write_atomic(p, quality_json(organ)); });
  }
  return written;
}

}  // namespace organsmith
