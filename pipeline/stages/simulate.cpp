// Over 400 lines: the INP reader, the CalculiX run and the readers of its .sta, .dat and .frd
// belong together (each reads what the one before wrote); each part is short.
// simulate: CalculiX runs of the exported load cases (see simulate.h).

#include "pipeline/stages/simulate.h"

#include "core/file_io.h"
#include "core/format.h"
#include "core/grid.h"
#include "core/process.h"
#include "meshing/export.h"
#include "physics/materials/solver_fit.h"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

namespace organsmith {
namespace fs = std::filesystem;

namespace {

std::string trim(std::string s) {
  const auto a = s.find_first_not_of(" \t\r");
  const auto b = s.find_last_not_of(" \t\r");
  return a == std::string::npos ? std::string() : s.substr(a, b - a + 1);
}

std::vector<std::string> split_commas(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string cell;
  while (std::getline(ss, cell, ',')) out.push_back(trim(cell));
  return out;
}

std::string upper(std::string s) {
  for (char& c : s) c = char(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

/// Value of PARAM= on a keyword line ("" when absent).
std::string param(const std::string& keyword_line, const std::string& name) {
  for (const auto& part : split_commas(keyword_line)) {
    const auto eq = part.find('=');
    if (eq != std::string::npos && upper(trim(part.substr(0, eq))) == name) return trim(part.substr(eq + 1));
  }
  return {};
}

}  // namespace

// ---- INP reader ----------------------------------------------------------------------------------

SolverInput read_solver_inp(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw InputError(ExitCode::input_not_found, "cannot read the solver input", path,
                            "run the mesh stage first (`organsmith run`), which writes meshes/<organ>/<organ>.inp");
  SolverInput r;
  SolverModel& m = r.model;
  std::string line, block;
  std::string elset, nset, surface;
  std::int32_t region = 0;
  int lineno = 0;
  auto bad = [&](const std::string& what) {
    return InputError(ExitCode::unsupported_input, "line " + std::to_string(lineno) + ": " + what, path,
                      "give an INP that organsmith wrote (meshes/<organ>/<organ>.inp)");
  };
  auto number = [&](const std::string& s) {
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (end == s.c_str() || !std::isfinite(v)) throw bad("not a number: '" + s + "'");
    return v;
  };
  bool heading = false;
  std::string material, hyper;
  std::map<std::string, std::pair<std::string, std::vector<double>>> material_numbers;  // name → (kind, numbers)
  std::map<std::string, std::string> section;  // elset → material
  while (std::getline(in, line)) {
    ++lineno;
    if (line.rfind("**", 0) == 0) {
      if (line.find("Coordinates RAS") != std::string::npos) r.ras = true;
      if (line.rfind("** organsmith probe:", 0) == 0) {
        // point x y z; direction x y z; diameter d; depth D; area A; thickness T (the file's frame)
        std::string text = line.substr(20);
        for (char& ch : text)
          if (ch == ';') ch = ' ';
        std::stringstream ss(text);
        std::string word;
        SolverProbe& p = r.probe;
        while (ss >> word) {
          if (word == "point") ss >> p.point_lps_mm.x() >> p.point_lps_mm.y() >> p.point_lps_mm.z();
          else if (word == "direction") ss >> p.direction_lps.x() >> p.direction_lps.y() >> p.direction_lps.z();
          else if (word == "diameter") ss >> p.diameter_mm;
          else if (word == "depth") ss >> r.probe_depth_mm;
          else if (word == "area") ss >> p.contact_area_mm2;
          else if (word == "thickness") ss >> p.thickness_mm;
        }
        if (!ss.eof() && ss.fail()) throw bad("the probe comment is not 'point x y z; direction x y z; diameter d; depth D; …'");
      }
      continue;
    }
    if (trim(line).empty()) continue;
    if (line[0] == '*') {
      const std::string key = upper(trim(split_commas(line)[0]));
      block = key;
      if (key == "*HEADING") {
        heading = true;
        continue;
      }
      if (key == "*ELEMENT") {
        const std::string type = upper(param(line, "TYPE"));
        if (type != "C3D10" && type != "C3D4") throw bad("element type " + type + " (organsmith writes C3D10 or C3D4)");
        m.quadratic = type == "C3D10";
        elset = param(line, "ELSET");
        m.region_names[++region] = elset;
      } else if (key == "*NSET") {
        nset = param(line, "NSET");
        m.node_sets[nset];
      } else if (key == "*SURFACE") {
        surface = param(line, "NAME");
        m.surfaces[surface];
      } else if (key == "*MATERIAL") {
        material = param(line, "NAME");
      } else if (key == "*HYPERELASTIC") {
        const auto words = split_commas(line);
        hyper = words.size() > 1 ? upper(trim(words[1])) : "";
        if (hyper == "OGDEN") hyper += " " + param(line, "N");
        material_numbers[material] = {hyper, {}};
      } else if (key == "*SOLID SECTION") {
        section[param(line, "ELSET")] = param(line, "MATERIAL");
      }
      continue;
    }
    if (heading) {
      const std::string t = trim(line);
      if (t.rfind("organsmith ", 0) == 0) m.organ = t.substr(11);
      heading = false;
      continue;
    }
    const auto cells = split_commas(line);
    if (block == "*NODE") {
      if (cells.size() != 4) throw bad("a node line needs id, x, y, z");
      if (long(number(cells[0])) != long(m.nodes_lps_mm.size()) + 1) throw bad("node ids are not 1, 2, 3, …");
      Eigen::Vector3d p(number(cells[1]), number(cells[2]), number(cells[3]));
      m.nodes_lps_mm.push_back(r.ras ? lps_to_ras(p) : p);  // the same flip both ways
    } else if (block == "*ELEMENT") {
      const std::size_t npe = m.quadratic ? 10 : 4;
      if (cells.size() != npe + 1) throw bad("an element line needs its id and " + std::to_string(npe) + " nodes");
      if (long(number(cells[0])) != long(m.elements.size()) + 1) throw bad("element ids are not 1, 2, 3, …");
      std::array<std::int32_t, 10> e;
      e.fill(-1);
      for (std::size_t k = 0; k < npe; ++k) {
        const long v = long(number(cells[k + 1])) - 1;
        if (v < 0 || v >= long(m.nodes_lps_mm.size())) throw bad("element node out of range");
        e[k] = std::int32_t(v);
      }
      m.elements.push_back(e);
      m.region_ids.push_back(region);
    } else if (block == "*NSET") {
      for (const auto& c : cells)
        if (!c.empty()) m.node_sets[nset].push_back(std::int32_t(number(c)) - 1);
    } else if (block == "*SURFACE") {
      if (cells.size() != 2 || cells[1].size() != 2 || upper(cells[1])[0] != 'S') throw bad("a surface line needs element, S1–S4");
      const long e = long(number(cells[0])) - 1;
      const int f = cells[1][1] - '1';
      if (e < 0 || e >= long(m.elements.size()) || f < 0 || f > 3) throw bad("surface face out of range");
      m.surfaces[surface].push_back({std::int32_t(e), f});
    } else if (block == "*HYPERELASTIC") {
      for (const auto& c : cells)
        if (!trim(c).empty()) material_numbers[material].second.push_back(number(trim(c)));
    } else if (block == "*MODEL CHANGE") {
      r.inactive_regions.push_back(cells[0]);
    } else if (block == "*BOUNDARY") {
      if (cells.size() >= 4 && number(cells[3]) != 0.0) r.probe_node_set = cells[0];  // a prescribed motion
      else if (cells[0].find("_inactive_only_nodes") == std::string::npos && r.fixed_node_set.empty()) r.fixed_node_set = cells[0];
    } else if (block == "*DSLOAD") {
      if (cells.size() != 3) throw bad("a *DSLOAD line needs surface, P, value");
      r.pressure_surface = cells[0];
      r.pressure_MPa = number(cells[2]);
    }
  }
  if (m.nodes_lps_mm.empty() || m.elements.empty()) throw bad("no nodes or elements");
  for (const auto& [elset, mat] : section) {
    const auto it = material_numbers.find(mat);
    if (it == material_numbers.end()) continue;
    const auto& [kind, v] = it->second;
    physics::OgdenSolid law;
    auto need = [&](std::size_t k) {
      if (v.size() < k) throw bad("material " + mat + ": *HYPERELASTIC, " + kind + " needs " + std::to_string(k) + " numbers");
    };
    if (kind.rfind("OGDEN ", 0) == 0) {
      const int n = std::atoi(kind.substr(6).c_str());
      if (n < 1 || n > 6) throw bad("material " + mat + ": OGDEN N must be 1 to 6");
      need(std::size_t(3 * n));
      for (int k = 0; k < n; ++k) law.mu.push_back(v[2 * k]), law.alpha.push_back(v[2 * k + 1]);
      law.bulk = v[2 * n] > 0 ? 2.0 / v[2 * n] : 0.0;
    } else if (kind == "MOONEY-RIVLIN") {
      need(3);
      law.mu = {2 * v[0], 2 * v[1]};
      law.alpha = {2.0, -2.0};
      law.bulk = v[2] > 0 ? 2.0 / v[2] : 0.0;
    } else if (kind == "NEO HOOKE") {
      need(2);
      law.mu = {2 * v[0]};
      law.alpha = {2.0};
      law.bulk = v[1] > 0 ? 2.0 / v[1] : 0.0;
    } else {
      continue;
    }
    // A law the solver cannot hold (a sign flipped, a constant lost): refused here, not left to
    // CalculiX, which would stall and have the mesh blamed. Needed: a positive initial shear modulus,
    // a finite positive bulk modulus, and a uniaxial nominal stress rising with stretch from 0.8 to
    // 1.3 (Drucker stability where organsmith's laws are calibrated).
    const std::string hint = "the material block of the INP is not one organsmith wrote; write it again with "
                             "`organsmith mesh` or fix the constants";
    if (!(law.initial_shear() > 0))
      throw InputError(ExitCode::unsupported_input,
                       "material " + mat + ": the initial shear modulus Σμ = " + format_g(law.initial_shear(), 4) +
                           " MPa is not positive",
                       path, hint);
    if (!(law.bulk > 0) || !std::isfinite(law.bulk))
      throw InputError(ExitCode::unsupported_input,
                       "material " + mat + ": D1 must be positive (a finite bulk modulus K = 2/D1)", path, hint);
    SolverMaterial form;
    form.ogden_mu_Pa = law.mu;  // the file's units: only the sign of the slope matters here
    form.ogden_alpha = law.alpha;
    for (int k = 0; k < 50; ++k) {
      const double l = 0.8 + 0.5 * k / 50.0;
      if (!(physics::ogden_nominal_Pa(form, l + 0.01, false) > physics::ogden_nominal_Pa(form, l, false)))
        throw InputError(ExitCode::unsupported_input,
                         "material " + mat + ": the law is unstable (its uniaxial stress falls at stretch " +
                             format_g(l, 3) + ")",
                         path, hint);
    }
    r.region_laws[elset] = law;
  }
  if (r.ras) {  // the probe comment is in the file's frame
    r.probe.point_lps_mm = lps_to_ras(r.probe.point_lps_mm);
    r.probe.direction_lps = lps_to_ras(r.probe.direction_lps);
  }
  if (r.indentation()) {
    if (r.fixed_node_set.empty() || !(r.probe_depth_mm > 0))
      throw bad("an indentation step needs a fixed *BOUNDARY and the probe comment with its depth");
    if (!m.node_sets.count(r.fixed_node_set) || !m.node_sets.count(r.probe_node_set))
      throw InputError(ExitCode::unsupported_input, "the load case names a set the INP does not define", path);
    return r;
  }
  if (r.fixed_node_set.empty() != r.pressure_surface.empty())
    throw bad("a load case needs both a *BOUNDARY and a *DSLOAD");
  if (!r.fixed_node_set.empty() && (!m.node_sets.count(r.fixed_node_set) || !m.surfaces.count(r.pressure_surface)))
    throw InputError(ExitCode::unsupported_input, "the load case names a set or surface the INP does not define", path);
  return r;
}

bool has_load_case(const SolverInput& in) { return !in.fixed_node_set.empty(); }

// ---- .frd reader ---------------------------------------------------------------------------------

FrdResult read_frd(const fs::path& path, std::size_t node_count) {
  std::ifstream in(path);
  if (!in) throw SimulationError(ExitCode::solver_failed, "the solver wrote no result file", path);
  FrdResult r;
  std::vector<std::array<double, 3>> disp;
  std::vector<std::array<double, 6>> stress;
  std::string line, block;
  double time = 0.0, block_time = 0.0;
  auto field = [&](const std::string& l, std::size_t col) { return std::strtod(l.substr(col, 12).c_str(), nullptr); };
  while (std::getline(in, line)) {
    if (line.rfind("  100CL", 0) == 0) {
      block_time = std::strtod(line.substr(12, 12).c_str(), nullptr);
      continue;
    }
    if (line.rfind(" -4", 0) == 0) {
      block = trim(line.substr(5, 8));
      if (block == "DISP") disp.assign(node_count, {0, 0, 0});
      if (block == "STRESS") stress.assign(node_count, {0, 0, 0, 0, 0, 0});
      continue;
    }
    if (line.rfind(" -3", 0) == 0) {
      if (block == "DISP") {
        r.displacement_mm = disp;
        time = block_time;
      }
      if (block == "STRESS") r.stress_MPa = stress;
      block.clear();
      continue;
    }
    if (line.rfind(" -1", 0) != 0 || (block != "DISP" && block != "STRESS") || line.size() < 13 + 36) continue;
    const long id = std::strtol(line.substr(3, 10).c_str(), nullptr, 10) - 1;
    if (id < 0 || std::size_t(id) >= node_count) continue;
    if (block == "DISP") {
      for (int k = 0; k < 3; ++k) disp[std::size_t(id)][k] = field(line, 13 + 12 * k);
    } else if (line.size() >= 13 + 72) {
      for (int k = 0; k < 6; ++k) stress[std::size_t(id)][k] = field(line, 13 + 12 * k);
    }
  }
  if (r.displacement_mm.empty()) throw SimulationError(ExitCode::solver_failed, "the result file holds no displacement", path);
  if (r.stress_MPa.empty()) r.stress_MPa.assign(node_count, {0, 0, 0, 0, 0, 0});
  r.time = time;
  return r;
}

// ---- figures -------------------------------------------------------------------------------------

namespace {

/// Below this much free space where the solver works, a failed run is put down to the disk.
constexpr std::uintmax_t kSolverMinFreeBytes = 4u << 20;
/// Degree-4 rule on the reference triangle (Dunavant, 6 points); weights sum to 1.
constexpr double kQa = 0.445948490915965, kQwa = 0.223381589678011;
constexpr double kQb = 0.091576213509771, kQwb = 0.109951743655322;
const double kQuad[6][3] = {{kQa, kQa, kQwa}, {1 - 2 * kQa, kQa, kQwa}, {kQa, 1 - 2 * kQa, kQwa},
                            {kQb, kQb, kQwb}, {1 - 2 * kQb, kQb, kQwb}, {kQb, 1 - 2 * kQb, kQwb}};

/// Shape functions of the 3- or 6-node triangle at (ξ, η) and their derivatives.
void tri_shape(bool quadratic, double xi, double eta, double N[6], double dxi[6], double deta[6]) {
  const double l1 = 1 - xi - eta, l2 = xi, l3 = eta;
  if (!quadratic) {
    N[0] = l1, N[1] = l2, N[2] = l3;
    dxi[0] = -1, dxi[1] = 1, dxi[2] = 0;
    deta[0] = -1, deta[1] = 0, deta[2] = 1;
    return;
  }
  N[0] = l1 * (2 * l1 - 1), N[1] = l2 * (2 * l2 - 1), N[2] = l3 * (2 * l3 - 1);
  N[3] = 4 * l1 * l2, N[4] = 4 * l2 * l3, N[5] = 4 * l3 * l1;
  dxi[0] = -(4 * l1 - 1), dxi[1] = 4 * l2 - 1, dxi[2] = 0, dxi[3] = 4 * (l1 - l2), dxi[4] = 4 * l3, dxi[5] = -4 * l3;
  deta[0] = -(4 * l1 - 1), deta[1] = 0, deta[2] = 4 * l3 - 1, deta[3] = -4 * l2, deta[4] = 4 * l2, deta[5] = 4 * (l1 - l3);
}


/// Visits the quadrature points of face `f` with positions from `at`: shape functions N, the point
/// x and the area vector n da (into the element, by the face's node order), weights included.
template <class At, class Visit>
void for_each_face_point(const SolverModel& m, const SolverFace& f, At&& at, Visit&& visit) {
  const auto ids = m.face_nodes(f);
  for (const auto& q : kQuad) {
    double N[6], dxi[6], deta[6];
    tri_shape(m.quadratic, q[0], q[1], N, dxi, deta);
    Eigen::Vector3d x = Eigen::Vector3d::Zero(), xxi = Eigen::Vector3d::Zero(), xeta = Eigen::Vector3d::Zero();
    for (std::size_t k = 0; k < ids.size(); ++k) {
      const Eigen::Vector3d p = at(ids[k]);
      x += N[k] * p;
      xxi += dxi[k] * p;
      xeta += deta[k] * p;
    }
    visit(ids, N, x, Eigen::Vector3d(0.5 * q[2] * xxi.cross(xeta)));
  }
}

}  // namespace

void evaluate_simulation(const SolverInput& in, const FrdResult& frd, SimulationResult& r) {
  const SolverModel& m = in.model;
  auto deformed = [&](std::int32_t v) {
    const auto& u = frd.displacement_mm[std::size_t(v)];
    return Eigen::Vector3d(m.nodes_lps_mm[std::size_t(v)] + Eigen::Vector3d(u[0], u[1], u[2]));
  };
  // Consistent nodal forces of the pressure on the deformed loaded faces: f_i = p ∫ N_i n da,
  // n pointing into the element (the direction the pressure pushes).
  const double p_N_per_mm2 = in.pressure_MPa;
  std::map<std::int32_t, Eigen::Vector3d> nodal;
  double magnitude = 0;
  static const std::vector<SolverFace> kNone;
  const auto& loaded = in.indentation() ? kNone : m.surfaces.at(in.pressure_surface);
  for (const auto& f : loaded)
    for_each_face_point(m, f, deformed, [&](const std::vector<std::int32_t>& ids, const double* N, const Eigen::Vector3d&,
                                            const Eigen::Vector3d& nda) {
      magnitude += p_N_per_mm2 * nda.norm();
      for (std::size_t k = 0; k < ids.size(); ++k) {
        auto [it, fresh] = nodal.emplace(ids[k], Eigen::Vector3d::Zero());
        it->second += p_N_per_mm2 * N[k] * nda;
      }
    });
  // CalculiX's RF at a node is the external force there (reaction plus any load on that node), so
  // at equilibrium the fixed set's RF balances the loads on the nodes that are not fixed.
  const auto& fixed = m.node_sets.at(in.fixed_node_set);
  Eigen::Vector3d applied_free = Eigen::Vector3d::Zero(), applied = Eigen::Vector3d::Zero();
  for (const auto& [v, f] : nodal) {
    applied += f;
    if (!std::binary_search(fixed.begin(), fixed.end(), v)) applied_free += f;
  }
  for (int k = 0; k < 3; ++k) r.applied_resultant_N[k] = applied[k];
  r.load_magnitude_N = magnitude;
  const Eigen::Vector3d reaction(r.reaction_N[0], r.reaction_N[1], r.reaction_N[2]);
  r.balance_error = magnitude > 0 ? (reaction + applied_free).norm() / magnitude : 0.0;
  if (r.indentation) r.balance_error = r.indentation->balance_error;

  r.max_displacement_mm = 0;
  for (const auto& u : frd.displacement_mm) r.max_displacement_mm = std::max(r.max_displacement_mm, std::hypot(u[0], u[1], u[2]));
  // Largest von Mises stress at the nodes of active elements.
  std::vector<char> active(m.nodes_lps_mm.size(), 0);
  for (std::size_t e = 0; e < m.elements.size(); ++e) {
    const std::string& region = m.region_names.at(m.region_ids[e]);
    if (std::find(in.inactive_regions.begin(), in.inactive_regions.end(), region) != in.inactive_regions.end()) continue;
    for (int k = 0; k < m.nodes_per_element(); ++k) active[std::size_t(m.elements[e][k])] = 1;
  }
  r.max_von_mises_Pa = 0;
  for (std::size_t v = 0; v < frd.stress_MPa.size(); ++v) {
    if (!active[v]) continue;
    r.max_von_mises_Pa = std::max(r.max_von_mises_Pa, von_mises(frd.stress_MPa[v]) * 1e6);
  }
  // Principal stretches per active element from its corners (the element's mean deformation).
  for (const auto& [region, mx_p99] : region_stretches(in, frd.displacement_mm)) {
    auto& st = r.principal_stretch[region];
    st.max = mx_p99.first;
    st.p99 = mx_p99.second;
  }
  // Lumen volume by the divergence theorem with the field (x_a, 0, 0), a an axis no cut face is
  // normal to, so that the open ends of a tube add nothing: V = ∫ x_a n_a da over the lumen
  // (n out of the lumen = into the wall element).
  int axis = 0;
  for (const auto& [name, faces] : m.surfaces) {
    if (name.find("_left") != std::string::npos || name.find("_right") != std::string::npos) axis = axis == 0 ? 1 : axis;
  }
  const std::string lumen = in.indentation() ? m.organ + "_lumen" : in.pressure_surface;
  if (!m.surfaces.count(lumen)) return;
  auto volume = [&](bool def) {
    double V = 0;
    const auto undeformed = [&](std::int32_t v) { return m.nodes_lps_mm[std::size_t(v)]; };
    for (const auto& f : m.surfaces.at(lumen)) {
      auto add = [&](const std::vector<std::int32_t>&, const double*, const Eigen::Vector3d& x, const Eigen::Vector3d& nda) {
        V += x[axis] * nda[axis];
      };
      if (def) for_each_face_point(m, f, deformed, add);
      else for_each_face_point(m, f, undeformed, add);
    }
    return V;
  };
  r.lumen_volume_mm3 = volume(false);
  r.lumen_volume_change_mm3 = volume(true) - r.lumen_volume_mm3;
}

double von_mises(const std::array<double, 6>& s) {
  return std::sqrt(0.5 * ((s[0] - s[1]) * (s[0] - s[1]) + (s[1] - s[2]) * (s[1] - s[2]) + (s[2] - s[0]) * (s[2] - s[0])) +
                   3 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]));
}

nlohmann::json SimulationResult::to_json() const {
  nlohmann::json j = {{"organ", organ},
          {"solver", "CalculiX ccx"},
          {"converged", converged},
          {"increments", increments},
          {"cutbacks", cutbacks},
          {"load_factor", load_factor},
          {"solver_seconds", solver_seconds},
          {"reaction_N", reaction_N},
          {"applied_pressure_resultant_N", applied_resultant_N},
          {"load_magnitude_N", load_magnitude_N},
          {"reaction_balance_error", balance_error},
          {"max_displacement_mm", max_displacement_mm},
          {"max_von_mises_Pa", max_von_mises_Pa},
          {"lumen_volume_mm3", lumen_volume_mm3},
          {"lumen_volume_change_mm3", lumen_volume_change_mm3},
          {"solver_message", solver_message}};
  nlohmann::json ps = nlohmann::json::object();
  for (const auto& [region, st] : principal_stretch) {
    ps[region] = {{"max", st.max}, {"p99", st.p99}};
    if (st.calibrated_max > 0) {
      ps[region]["calibrated_max"] = st.calibrated_max;
      ps[region]["beyond_calibrated_range"] = st.p99 > st.calibrated_max;
    }
  }
  j["principal_stretch"] = ps;
  if (indentation) j["indentation"] = indentation->to_json();
  if (!indentation && pressure_kPa > 0) {
    j["pressure_kPa"] = pressure_kPa;
    if (pressure_range) {
      // The pressure step went past a region's range: the largest pressure that keeps every
      // region's 99th-percentile stretch inside it.
      j["in_range_pressure_kPa"] = pressure_range->in_range_pressure_kPa;
      j["pressure_beyond_calibrated_range"] = true;
      j["range_reached_by"] = pressure_range->region;
    } else {
      j["pressure_beyond_calibrated_range"] = false;
    }
  }
  if (!band.is_null()) j["band"] = band;
  return j;
}

nlohmann::json band_summary(const std::map<std::string, SimulationResult>& variants) {
  nlohmann::json runs = nlohmann::json::object();
  double dmin = INFINITY, dmax = -INFINITY, vmin = INFINITY, vmax = -INFINITY;
  bool all = !variants.empty();
  for (const auto& [name, r] : variants) {
    runs[name] = {{"converged", r.converged},
                  {"load_factor", r.load_factor},
                  {"increments", r.increments},
                  {"solver_seconds", r.solver_seconds},
                  {"max_displacement_mm", r.max_displacement_mm},
                  {"max_von_mises_Pa", r.max_von_mises_Pa},
                  {"lumen_volume_change_mm3", r.lumen_volume_change_mm3},
                  {"reaction_balance_error", r.balance_error},
                  {"solver_message", r.solver_message}};
    all = all && r.converged;
    if (!r.converged) continue;
    dmin = std::min(dmin, r.max_displacement_mm), dmax = std::max(dmax, r.max_displacement_mm);
    vmin = std::min(vmin, r.lumen_volume_change_mm3), vmax = std::max(vmax, r.lumen_volume_change_mm3);
  }
  nlohmann::json b = {{"variants", runs}, {"all_converged", all}};
  if (all) {
    b["max_displacement_mm"] = {dmin, dmax};
    b["lumen_volume_change_mm3"] = {vmin, vmax};
  }
  return b;
}

// ---- running the solver --------------------------------------------------------------------------

namespace {

/// Converged increments, cutbacks and the step time reached, from jobname.sta.
void read_sta(const fs::path& sta, SimulationResult& r) {
  std::ifstream in(sta);
  std::string line;
  r.increments = r.cutbacks = 0;
  r.load_factor = 0;
  while (std::getline(in, line)) {
    if (line.size() < 60 || !std::isdigit(static_cast<unsigned char>(trim(line.substr(0, 6)).empty() ? 'x' : trim(line.substr(0, 6))[0])))
      continue;
    if (line.size() > 23 && line[23] == 'U') {
      ++r.cutbacks;
      continue;
    }
    ++r.increments;
    std::stringstream ss(line.substr(29));
    double total = 0, step = 0;
    ss >> total >> step;
    r.load_factor = step;
  }
}

/// The sum of RF over `set` in the last block of jobname.dat.
std::array<double, 3> read_dat_totals(const fs::path& dat, const std::string& set) {
  std::ifstream in(dat);
  std::string line;
  std::array<double, 3> out{0, 0, 0};
  const std::string want = upper("for set " + set);
  while (std::getline(in, line)) {
    if (line.find("total force") == std::string::npos || upper(line).find(want) == std::string::npos) continue;
    while (std::getline(in, line) && trim(line).empty()) {
    }
    if (in.eof()) break;  // a line the solver was still writing when it was stopped
    std::stringstream ss(line);
    ss >> out[0] >> out[1] >> out[2];
  }
  return out;
}

std::string solver_errors(const fs::path& log) {
  std::ifstream in(log);
  std::string line, out;
  int after = 0;
  while (std::getline(in, line)) {
    if (line.find("*ERROR") != std::string::npos || line.find("nonpositive jacobian") != std::string::npos) after = 3;
    if (after > 0) {
      out += trim(line) + " ";
      --after;
    }
  }
  return trim(out);
}

/// ", largest principal stretch X (region, 99th percentile) against its range Y[, beyond it]" at
/// the last converged increment, or "" when there is none.
std::string stall_state(const SolverInput& in, const fs::path& frd, const std::map<std::string, double>& range) {
  if (!fs::exists(frd)) return {};
  auto incs = read_frd_increments(frd, in.model.nodes_lps_mm.size());
  if (incs.empty()) return {};
  std::string worst;
  double worst_ratio = 0, p99 = 0, top = 0;
  for (const auto& [region, mx] : region_stretches(in, incs.back().displacement_mm)) {
    const auto it = range.find(region);
    const double ratio = it != range.end() && it->second > 1 ? (mx.second - 1) / (it->second - 1) : 0;
    if (worst.empty() || ratio > worst_ratio) worst = region, worst_ratio = ratio, p99 = mx.second, top = it != range.end() ? it->second : 0;
  }
  if (worst.empty()) return {};
  return "; largest principal stretch (99th percentile) " + format_g(p99, 3) + " in " + worst +
         (top > 1 ? " against its calibrated " + format_g(top, 3) + (p99 > top ? ", beyond it" : ", inside it") : std::string());
}

}  // namespace

Simulation simulate_inp(const fs::path& inp, const fs::path& work_dir, const SimulateOptions& o, Progress& progress) {
  return simulate_inp(inp, read_solver_inp(inp), work_dir, o, progress);
}

Simulation simulate_inp(const fs::path& inp, SolverInput input, const fs::path& work_dir, const SimulateOptions& o,
                        Progress& progress) {
  const fs::path exe = find_on_path(o.solver);
  if (exe.empty())
    throw SimulationError(ExitCode::solver_not_found, "the finite-element solver '" + o.solver + "' is not on PATH", {},
                          "install CalculiX: apt-get install calculix-ccx (or scripts/install-deps)");
  Simulation sim;
  sim.input = std::move(input);
  SimulationResult& r = sim.result;
  r.organ = sim.input.model.organ;
  if (!has_load_case(sim.input))
    throw InputError(ExitCode::unsupported_input, r.organ + ": the INP has no load step", inp,
                     "its comments say why (no lumen or fixed surface was found on the mesh)");
  fs::create_directories(work_dir);
  const std::string job = "job";
  fs::copy_file(inp, work_dir / (job + ".inp"), fs::copy_options::overwrite_existing);
  for (const char* ext : {".sta", ".frd", ".dat", ".cvg"}) fs::remove(work_dir / (job + ext));
  const fs::path log = work_dir / "solver.log";
  const int threads = o.threads > 0 ? o.threads : int(std::max(1u, std::thread::hardware_concurrency()));

  const auto t0 = std::chrono::steady_clock::now();
  ChildSpec spec;
  spec.exe = exe;
  spec.args = {"-i", job};
  spec.cwd = work_dir;
  spec.log = log;
  spec.env = {{"OMP_NUM_THREADS", std::to_string(threads)}};
  fs::remove(log);
  ChildProcess child(spec);
  int exit_code = -1;
  const std::string what = "simulate " + r.organ + " (CalculiX)";
  // An indentation step is stopped where its curve ends: once a region's 99th-percentile stretch
  // has passed the top of its calibrated range, the rest of the depth is the fitted solid's
  // extrapolation and costs the most iterations.
  int increments_checked = 0;
  double stopped_at_range = -1.0;
  for (;;) {
    if (auto code = child.poll()) {
      exit_code = *code;
      break;
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    SimulationResult partial;
    read_sta(work_dir / (job + ".sta"), partial);
    if (sim.input.indentation() && partial.increments > increments_checked) {
      increments_checked = partial.increments;
      stopped_at_range = indentation_range_time(sim.input, work_dir / (job + ".frd"), work_dir / (job + ".dat"),
                                                o.calibrated_stretch_max);
      if (stopped_at_range >= 0) {
        child.signal(SIGTERM);
        child.wait();
        break;
      }
    }
    const bool timed_out = o.timeout_s > 0 && seconds > o.timeout_s;
    if (progress.cancelled() || timed_out) {
      child.signal(SIGTERM);
      child.wait();
      if (timed_out) {
        const std::string state = stall_state(sim.input, work_dir / (job + ".frd"), o.calibrated_stretch_max);
        const double rate = partial.load_factor / std::max(seconds, 1e-9);
        throw SimulationError(ExitCode::solver_failed,
                              r.organ + ": the solver did not finish within " + format_g(o.timeout_s, 4) + " s (load " +
                                  format_g(100 * partial.load_factor, 3) + " % reached" + state + ")",
                              work_dir,
                              partial.load_factor > 0.05
                                  ? "raise the time limit ([stages.simulate] timeout_s): at this rate the step needs about " +
                                        format_g((1.0 - partial.load_factor) / rate + seconds, 2) + " s"
                                  : "raise the time limit, or coarsen the solver mesh ([stages.mesh] tet_edge_mm): the step "
                                    "has barely started");
      }
      throw Cancelled();
    }
    progress.report(partial.load_factor, what);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  r.solver_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  read_sta(work_dir / (job + ".sta"), r);
  const std::string text = read_file(log).value_or("");
  const bool finished = exit_code == 0 && text.find("Job finished") != std::string::npos;
  if (stopped_at_range < 0 && !finished) {
    // Causes outside the mechanics first: a full disk (ccx may even exit 0 when its last writes
    // fail), or the solver ended by a signal.
    std::error_code space_ec;
    const fs::space_info space = fs::space(work_dir, space_ec);
    if (!space_ec && space.available < kSolverMinFreeBytes)
      throw OutputError("the disk is full: CalculiX could not write its results for " + r.organ + " (" +
                            std::to_string(space.available / 1024) + " KiB free)",
                        work_dir, "free some space (a solver run writes tens of MB) and run simulate again");
    if (const int sig = child.end_signal(); sig != 0)
      throw SimulationError(ExitCode::solver_failed,
                            r.organ + ": CalculiX was ended by signal " + std::to_string(sig) + " (" + strsignal(sig) +
                                ") at " + format_g(100 * r.load_factor, 3) + " % of the load",
                            work_dir / "solver.log",
                            sig == SIGKILL ? "something outside organsmith killed the solver (the system's out-of-memory "
                                             "killer, an operator or a scheduler's limit); run simulate again"
                                           : "the solver crashed: check the INP it was given (" + inp.string() +
                                                 "), or run simulate again");
  }
  r.converged = finished && r.load_factor >= 1.0 - 1e-9;
  const std::size_t nodes = sim.input.model.nodes_lps_mm.size();
  std::vector<SolverIncrement> incs;
  if (fs::exists(work_dir / (job + ".frd"))) incs = read_frd_increments(work_dir / (job + ".frd"), nodes);
  if (sim.input.ras)  // the solver worked in the file's RAS frame; figures are taken in LPS
    for (auto& inc : incs)
      for (auto& u : inc.displacement_mm) u[0] = -u[0], u[1] = -u[1];
  if (sim.input.indentation()) {
    r.indentation = evaluate_indentation(sim.input, incs, read_dat_series(work_dir / (job + ".dat"), sim.input.probe_node_set),
                                         read_dat_series(work_dir / (job + ".dat"), sim.input.fixed_node_set),
                                         o.calibrated_stretch_max);
    // A step that stalls after the wall reached its range has given the whole answer: the curve
    // ends at the range either way.
    if (!r.converged && !r.indentation->range_region.empty() && r.increments > 0) {
      r.solver_message = (stopped_at_range >= 0 ? "organsmith stopped the step at " : "the step stopped at ") +
                         format_g(100 * r.load_factor, 3) + " % of its depth, after " + r.indentation->range_region +
                         " reached its calibrated range at " + format_g(r.indentation->range_depth_mm, 3) + " mm";
      r.converged = true;
    }
  } else {
    r.pressure_kPa = sim.input.pressure_MPa * 1e3;
    const PressureRange pr = evaluate_pressure_range(sim.input, incs, o.calibrated_stretch_max);
    if (!pr.region.empty()) r.pressure_range = pr;
  }
  if (!r.converged) {
    if (r.solver_message.empty()) r.solver_message = solver_errors(log);
    const std::string state = stall_state(sim.input, work_dir / (job + ".frd"), o.calibrated_stretch_max);
    const bool beyond = state.find("beyond") != std::string::npos;
    const std::string load = sim.input.indentation() ? "depth ([stages.simulate] probe_depth_mm)" : "pressure ([stages.mesh] pressure_kPa)";
    throw SimulationError(ExitCode::solver_failed,
                          r.organ + ": CalculiX stopped at " + format_g(100 * r.load_factor, 3) + " % of the load after " +
                              std::to_string(r.increments) + " increments and " + std::to_string(r.cutbacks) +
                              " cutbacks" + state + (r.solver_message.empty() ? "" : ": " + r.solver_message),
                          work_dir / "solver.log",
                          beyond ? "lower the " + load + ": the tissue is past the range its law was calibrated over, where "
                                   "the fitted solid stiffens without data behind it"
                                 : "coarsen the solver mesh ([stages.mesh] tet_edge_mm): the step stalled with every region "
                                   "inside its calibrated range, which points at distorted elements; the log has the solver's account");
  }
  if (incs.empty()) throw SimulationError(ExitCode::solver_failed, "the result file holds no displacement", work_dir / (job + ".frd"));
  sim.frd = read_frd(work_dir / (job + ".frd"), nodes);
  if (sim.input.ras)
    for (auto& u : sim.frd.displacement_mm) u[0] = -u[0], u[1] = -u[1];
  if (sim.input.indentation() && !r.indentation->range_region.empty()) {
    // The picture and the figures at the curve's end: the last increment within the range.
    for (const auto& inc : incs)
      if (inc.time * sim.input.probe_depth_mm <= r.indentation->range_depth_mm + 1e-9) sim.frd.displacement_mm = inc.displacement_mm;
  }
  r.reaction_N = read_dat_totals(work_dir / (job + ".dat"), sim.input.fixed_node_set);
  evaluate_simulation(sim.input, sim.frd, r);
  for (auto& [region, st] : r.principal_stretch)
    if (const auto it = o.calibrated_stretch_max.find(region); it != o.calibrated_stretch_max.end()) st.calibrated_max = it->second;
  return sim;
}

void write_simulation_files(const SolverInput& in, const FrdResult& frd, const SimulationResult& r, const fs::path& dir) {
  fs::create_directories(dir);
  std::vector<PointField> fields;
  PointField u{"displacement_mm", 3, {}}, vm{"von_mises_Pa", 1, {}};
  for (std::size_t v = 0; v < in.model.nodes_lps_mm.size(); ++v) {
    const auto& d = frd.displacement_mm[v];
    const double flip = in.ras ? -1.0 : 1.0;  // the VTU is in the frame the INP was written in
    u.values.insert(u.values.end(), {flip * d[0], flip * d[1], d[2]});
    vm.values.push_back(1e6 * von_mises(frd.stress_MPa[v]));
  }
  fields.push_back(std::move(u));
  fields.push_back(std::move(vm));
  write_vtu(in.model, dir / (r.organ + ".vtu"), in.ras, fields);
  write_file_atomic(dir / (r.organ + ".json"), r.to_json().dump(2) + "\n");
}

}  // namespace organsmith
