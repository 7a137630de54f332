// Mesh file writers: surfaces (STL, OBJ, PLY, VTP), quality.json and export_meshes; the volume
// writers on the solver model are in export_solver.cpp. Numbers are printed with std::to_chars (shortest round-trip form), so the
// same mesh always gives the same bytes and re-reading gives the same doubles.

#include "meshing/export.h"
#include "meshing/export_text.h"

#include "core/file_io.h"
#include "core/vtk_xml.h"

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


using namespace export_text;

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


void write_vtp(const SurfaceMesh& m, const fs::path& path, bool ras) {
  VtkPiece piece;
  piece.points.reserve(m.vertices_lps_mm.size());
  for (const auto& v : m.vertices_lps_mm) piece.points.push_back(out_point(v, ras));
  for (const auto& t : m.triangles) piece.add_cell(t);
  if (!m.region_ids.empty())
    piece.cell_data.push_back({"region_id", "Int32", 1, std::vector<double>(m.region_ids.begin(), m.region_ids.end())});
  write_atomic(path, vtk_polydata_xml(piece, VtkPolyCells::polys, std::string("organsmith surface, ") + (ras ? "RAS" : "LPS") + " mm"));
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
    if (!organ.volume.tets.empty() && (want.count("vtu") || want.count("msh") || want.count("msh22") || want.count("inp") ||
                                       want.count("feb"))) {
      const auto sc_it = o.scenarios.find(organ.spec.name);
      const SolverScenario sc = sc_it != o.scenarios.end() ? sc_it->second : default_scenario(organ.spec);
      SolverModelOptions bo = o.boundaries;
      bo.quadratic = o.quadratic;
      bo.probe_on_tube = sc.indentation;
      const SolverModel v = build_solver_model(organ, bo);
      if (warnings)
        for (const auto& note : v.notes)
          if (note.find("no load case") != std::string::npos || note.find("no indentation probe") != std::string::npos)
            warnings->push_back(note);
      const std::string n = organ.spec.name;
      if (want.count("vtu")) emit(n + ".vtu", [&](const fs::path& p) { write_vtu(v, p, o.ras); });
      if (want.count("msh")) emit(n + ".msh", [&](const fs::path& p) { write_msh41(v, p, o.ras); });
      if (want.count("msh22")) emit(n + ".v22.msh", [&](const fs::path& p) { write_msh22(v, p, o.ras); });
      if (want.count("inp")) emit(n + ".inp", [&](const fs::path& p) { write_inp(v, o.materials, sc, p, o.ras, warnings); });
      if (want.count("inp") && !o.material_band.empty()) {
        fs::create_directories(dir / rel / "band", ec);
        if (ec) throw OutputError("cannot create the output directory", dir / rel / "band", ec.message());
        for (const auto& [variant, regions] : o.material_band) {
          std::map<std::string, SolverMaterial> mats = o.materials;
          for (const auto& [region, m] : regions) mats[region] = m;
          emit("band/" + n + "." + variant + ".inp", [&](const fs::path& p) { write_inp(v, mats, sc, p, o.ras); });
        }
      }
      if (want.count("feb")) emit(n + ".feb", [&](const fs::path& p) { write_feb(v, o.materials, sc, p, o.ras); });
    }
    emit("quality.json", [&](const fs::path& p) { write_atomic(p, quality_json(organ)); });
  }
  return written;
}

}  // namespace organsmith
