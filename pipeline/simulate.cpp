// Over 400 lines: the INP reader, the CalculiX run and the readers of its .sta, .dat and .frd
// belong together (each reads what the one before wrote); each part is short.
// simulate: CalculiX runs of the exported load cases (see simulate.h).

#include "pipeline/simulate.h"

#include "core/file_io.h"
#include "core/format.h"
#include "core/grid.h"
#include "core/process.h"
#include "pipeline/runner.h"
#include "meshing/export.h"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
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
  while (std::getline(in, line)) {
    ++lineno;
    if (line.rfind("**", 0) == 0) {
      if (line.find("Coordinates RAS") != std::string::npos) r.ras = true;
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
    } else if (block == "*MODEL CHANGE") {
      r.inactive_regions.push_back(cells[0]);
    } else if (block == "*BOUNDARY") {
      if (cells[0].find("_inactive_only_nodes") == std::string::npos && r.fixed_node_set.empty()) r.fixed_node_set = cells[0];
    } else if (block == "*DSLOAD") {
      if (cells.size() != 3) throw bad("a *DSLOAD line needs surface, P, value");
      r.pressure_surface = cells[0];
      r.pressure_MPa = number(cells[2]);
    }
  }
  if (m.nodes_lps_mm.empty() || m.elements.empty()) throw bad("no nodes or elements");
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
  for (const auto& f : m.surfaces.at(in.pressure_surface))
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
  // Principal stretches per active element from its corners: F = ∂x/∂X of the linear tet.
  std::map<std::string, std::vector<double>> stretches;
  for (std::size_t e = 0; e < m.elements.size(); ++e) {
    const std::string& region = m.region_names.at(m.region_ids[e]);
    if (std::find(in.inactive_regions.begin(), in.inactive_regions.end(), region) != in.inactive_regions.end()) continue;
    const auto& el = m.elements[e];
    Eigen::Matrix3d dX, dx;
    for (int k = 0; k < 3; ++k) {
      dX.col(k) = m.nodes_lps_mm[std::size_t(el[k + 1])] - m.nodes_lps_mm[std::size_t(el[0])];
      dx.col(k) = deformed(el[k + 1]) - deformed(el[0]);
    }
    if (std::abs(dX.determinant()) < 1e-12) continue;
    const Eigen::Matrix3d F = dx * dX.inverse();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(F.transpose() * F, Eigen::EigenvaluesOnly);
    stretches[region].push_back(std::sqrt(std::max(0.0, eig.eigenvalues()(2))));
  }
  for (auto& [region, v] : stretches) {
    std::sort(v.begin(), v.end());
    auto& s = r.principal_stretch[region];
    s.max = v.back();
    s.p99 = v[std::size_t(0.99 * double(v.size() - 1))];
  }
  // Lumen volume by the divergence theorem with the field (x_a, 0, 0), a an axis no cut face is
  // normal to, so that the open ends of a tube add nothing: V = ∫ x_a n_a da over the lumen
  // (n out of the lumen = into the wall element).
  int axis = 0;
  for (const auto& [name, faces] : m.surfaces) {
    if (name.find("_left") != std::string::npos || name.find("_right") != std::string::npos) axis = axis == 0 ? 1 : axis;
  }
  auto volume = [&](bool def) {
    double V = 0;
    const auto undeformed = [&](std::int32_t v) { return m.nodes_lps_mm[std::size_t(v)]; };
    for (const auto& f : m.surfaces.at(in.pressure_surface)) {
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

}  // namespace

Simulation simulate_inp(const fs::path& inp, const fs::path& work_dir, const SimulateOptions& o, Progress& progress) {
  const fs::path exe = find_on_path(o.solver);
  if (exe.empty())
    throw SimulationError(ExitCode::solver_not_found, "the finite-element solver '" + o.solver + "' is not on PATH", {},
                          "install CalculiX: apt-get install calculix-ccx (or scripts/install-deps)");
  Simulation sim;
  sim.input = read_solver_inp(inp);
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
  for (;;) {
    if (auto code = child.poll()) {
      exit_code = *code;
      break;
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    SimulationResult partial;
    read_sta(work_dir / (job + ".sta"), partial);
    const bool timed_out = o.timeout_s > 0 && seconds > o.timeout_s;
    if (progress.cancelled() || timed_out) {
      child.signal(SIGTERM);
      child.wait();
      if (timed_out)
        throw SimulationError(ExitCode::solver_failed,
                              r.organ + ": the solver did not finish within " + format_g(o.timeout_s, 4) + " s (load " +
                                  format_g(100 * partial.load_factor, 3) + " % reached)",
                              work_dir, "coarsen the mesh ([stages.mesh] edge_mm) or raise the time limit");
      throw Cancelled();
    }
    progress.report(partial.load_factor, what);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  r.solver_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  read_sta(work_dir / (job + ".sta"), r);
  const std::string text = read_file(log).value_or("");
  const bool finished = exit_code == 0 && text.find("Job finished") != std::string::npos;
  r.converged = finished && r.load_factor >= 1.0 - 1e-9;
  if (!r.converged) {
    r.solver_message = solver_errors(log);
    throw SimulationError(ExitCode::solver_failed,
                          r.organ + ": CalculiX stopped at " + format_g(100 * r.load_factor, 3) + " % of the load after " +
                              std::to_string(r.increments) + " increments and " + std::to_string(r.cutbacks) +
                              " cutbacks" + (r.solver_message.empty() ? "" : ": " + r.solver_message),
                          work_dir / "solver.log",
                          "lower the pressure ([stages.mesh] pressure_kPa) or coarsen the mesh; the log has the solver's account");
  }
  sim.frd = read_frd(work_dir / (job + ".frd"), sim.input.model.nodes_lps_mm.size());
  if (sim.input.ras)  // the solver worked in the file's RAS frame; figures are taken in LPS
    for (auto& u : sim.frd.displacement_mm) u[0] = -u[0], u[1] = -u[1];
  r.reaction_N = read_dat_totals(work_dir / (job + ".dat"), sim.input.fixed_node_set);
  evaluate_simulation(sim.input, sim.frd, r);
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
  write_text_atomic(dir / (r.organ + ".json"), r.to_json().dump(2) + "\n");
}

}  // namespace organsmith
