// The organ's finite-element model from its solver file, and the two things done with it: the
// real-time press (`haptics --indent`: the probe pressed through the real-time threads and what
// the force loop gave the tool) and its comparison with CalculiX's curve. Over 400 lines because
// the press and its report share the model, the probe's nodes and the curve readers; the figures
// it writes are the ones TISSUE.md and issue 38's tables quote.

#include "pipeline/stages/organ_fe.h"

#include "core/errors.h"
#include "core/format.h"
#include "physics/tissue/realtime_tissue.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/stages/simulate.h"
#include "pipeline/stages/simulation_picture.h"
#include "viewer/display.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <thread>

#include <pthread.h>
#include <sched.h>

namespace organsmith {

namespace fs = std::filesystem;

OrganFe organ_fe(const fs::path& out, const std::string& organ, const OrganFeOptions& o) {
  OrganFe r;
  r.organ = organ;
  r.inp = OutputLayout{out}.volume(organ, "inp");
  SolverInput in = read_solver_inp(r.inp);
  SolverModel& m = in.model;
  if (o.probe_lps_mm) {
    // The bed the organ is held by: its surface <organ>_<bed organ>_bed (the gallbladder's liver bed).
    std::string bed;
    for (const auto& [name, _] : m.surfaces)
      if (name.rfind(organ + "_", 0) == 0 && name.size() > organ.size() + 4 && name.compare(name.size() - 4, 4, "_bed") == 0)
        bed = name.substr(organ.size() + 1);
    if (!m.surfaces.count(organ + "_outer") || bed.empty())
      throw InputError(ExitCode::unsupported_input, organ + " has no bed in its solver file, so no probe can be placed", r.inp,
                       "the probe presses organs held by a bed (the gallbladder's liver bed)");
    m.node_sets.erase(organ + "_probe_nodes");
    add_indentation_probe(m, o.probe_lps_mm, in.indentation() ? in.probe.diameter_mm : 5.0, bed);
    if (!m.probe) throw InputError(ExitCode::unsupported_input, "no free surface to place the probe on", r.inp);
    r.probe = *m.probe;
    r.probe->thickness_mm = m.probe->thickness_mm;
    in.probe_node_set = organ + "_probe_nodes";
    if (!(in.probe_depth_mm > 0)) in.probe_depth_mm = kProbeDepthFraction * m.probe->thickness_mm;
  } else if (in.indentation()) {
    r.probe = in.probe;
  }
  r.probe_depth_mm = in.probe_depth_mm;

  physics::TissueMesh q;
  q.nodes_per_element = m.quadratic ? 10 : 4;
  q.nodes_mm = m.nodes_lps_mm;
  q.elements = m.elements;
  std::map<std::int32_t, std::int32_t> law_of_region;
  for (const auto& [id, name] : m.region_names) {
    const auto it = in.region_laws.find(name);
    if (it == in.region_laws.end())
      throw InputError(ExitCode::unsupported_input, "region " + name + " has no hyperelastic law in the solver file", r.inp,
                       "re-run the mesh stage (`organsmith run`), which writes each region's law");
    law_of_region[id] = std::int32_t(q.laws.size());
    q.laws.push_back(it->second);
    r.region_names.push_back(name);
  }
  for (std::int32_t rid : m.region_ids) q.law_of_element.push_back(law_of_region.at(rid));
  std::vector<std::int32_t> id;
  r.mesh = o.quadratic ? q : physics::corner_mesh(q, &id);
  auto map_set = [&](const std::vector<std::int32_t>& s) {
    std::vector<std::int32_t> v;
    for (std::int32_t i : s)
      if (o.quadratic) v.push_back(i);
      else if (id[i] >= 0) v.push_back(id[i]);
    return v;
  };
  if (!in.fixed_node_set.empty()) r.fixed_nodes = map_set(m.node_sets.at(in.fixed_node_set));
  if (!in.probe_node_set.empty()) r.probe_nodes = map_set(m.node_sets.at(in.probe_node_set));
  if (const auto it = m.surfaces.find(organ + "_outer"); it != m.surfaces.end())
    for (const SolverFace& f : it->second) {
      const auto v = m.face_nodes(f);  // normal into the element: reversed for outward
      for (int k : {0, 2, 1}) r.surface_triangles.push_back(o.quadratic ? v[k] : id[v[k]]);
    }
  try {
    for (const auto& [region, law] : region_materials(registry_of_output(out))) r.stretch_max[region] = law.stretch_max;
  } catch (const Error&) {
  }
  return r;
}

namespace {

std::vector<std::array<double, 2>> read_curve(const fs::path& f) {
  std::vector<std::array<double, 2>> c;
  std::ifstream in(f);
  if (!in) return c;
  try {
    const nlohmann::json j = nlohmann::json::parse(in);
    if (j.contains("indentation") && j["indentation"].contains("curve"))
      for (const auto& p : j["indentation"]["curve"]) c.push_back({p[0].get<double>(), p[1].get<double>()});
  } catch (const nlohmann::json::exception&) {
    c.clear();
  }
  return c;
}

// A curve sampled during a press, at the reference's depths (linear between its samples, only
// within them), against the reference: rows of depth, reference, this, relative difference.
nlohmann::json against_reference(const nlohmann::json& samples, const std::vector<std::array<double, 2>>& reference, double deepest) {
  std::vector<std::array<double, 2>> c;
  for (const auto& p : samples) c.push_back({p[0].get<double>(), p[1].get<double>()});
  std::sort(c.begin(), c.end());
  nlohmann::json rows = nlohmann::json::array();
  double worst = 0.0;
  for (const auto& [d, ref] : reference) {
    if (c.empty() || d <= 0 || d < c.front()[0] || d > c.back()[0]) continue;
    const auto hi = std::lower_bound(c.begin(), c.end(), std::array<double, 2>{d, -1e300});
    const auto lo = hi == c.begin() ? hi : hi - 1;
    const double w = (*hi)[0] > (*lo)[0] ? (d - (*lo)[0]) / ((*hi)[0] - (*lo)[0]) : 1.0;
    const double f = (*lo)[1] + w * ((*hi)[1] - (*lo)[1]);
    const double rel = ref != 0.0 ? (f - ref) / ref : 0.0;
    rows.push_back({d, ref, f, rel});
    if (d >= 0.2 * deepest) worst = std::max(worst, std::abs(rel));
  }
  return {{"depth_mm_solver_N_press_N_relative_difference", rows},
          {"largest_relative_difference_past_20pct_depth", worst},
          {"deepest_sampled_mm", c.empty() ? 0.0 : c.back()[0]}};
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, std::size_t(p * double(v.size())))];
}

}  // namespace

std::unique_ptr<RealtimeOrgan> realtime_organ(const fs::path& out, const std::string& organ, double tool_radius_mm, bool quadratic) {
  auto r = std::make_unique<RealtimeOrgan>();
  OrganFeOptions fo;
  fo.quadratic = quadratic;
  r->fe = organ_fe(out, organ, fo);
  r->model = std::make_unique<physics::TissueModel>(r->fe.mesh);
  physics::RealtimeOptions ro;
  ro.tool_radius_mm = tool_radius_mm;
  r->tissue = std::make_unique<physics::RealtimeTissue>(*r->model, r->fe.fixed_nodes, r->fe.surface_triangles, ro);
  return r;
}

std::unique_ptr<RealtimeOrgan> fe_for_haptics(const fs::path& out, const std::string& flag, double tool_radius_mm, bool quadratic) {
  if (flag == "none") return nullptr;
  if (!flag.empty()) return realtime_organ(out, flag, tool_radius_mm, quadratic);
  // By default the first organ of the run's registry pressed by the probe (its load case; the
  // gallbladder) whose solver file exists.
  std::string organ;
  for (const OrganInfo& o : registry_of_output(out).organs)
    if (organ.empty() && o.mesh == OrganMeshModel::wall_body && o.load_case == "indentation" &&
        fs::exists(OutputLayout{out}.volume(o.name, "inp")))
      organ = o.name;
  if (organ.empty()) return nullptr;
  try {
    return realtime_organ(out, organ, tool_radius_mm, quadratic);
  } catch (const Error& e) {
    spdlog::warn("the {} is felt through its surface: no finite-element model from its solver file ({})", organ, e.what());
    return nullptr;
  }
}

nlohmann::json RealtimeOrgan::figures() const {
  return {{"organ", fe.organ},
          {"nodes", fe.mesh.nodes_mm.size()},
          {"tets", fe.mesh.elements.size()},
          {"update_ms_p50", tissue->update_ms_percentile(0.5)},
          {"update_ms_p99", tissue->update_ms_percentile(0.99)},
          {"update_hz", tissue->achieved_update_hz()},
          {"updates", tissue->updates()},
          {"equilibrium_hz", tissue->achieved_equilibrium_hz()},
          {"equilibrium_ms_p50", tissue->equilibrium_ms_percentile(0.5)},
          {"equilibrium_ms_p99", tissue->equilibrium_ms_percentile(0.99)},
          {"equilibria", tissue->equilibria()}};
}

nlohmann::json realtime_press(physics::TissueModel& model, const OrganFe& fe, double depth_mm, double speed, Progress& progress) {
  using clock = std::chrono::steady_clock;
  model.reset();
  physics::RealtimeOptions ro;
  physics::RealtimeTissue rt(model, fe.fixed_nodes, fe.surface_triangles, ro);
  rt.hold_on_contact(fe.probe_nodes);  // the tool is the simulate stage's probe: it holds the probe's faces
  const Eigen::Vector3d dir = fe.probe->direction_lps.normalized();
  const Eigen::Vector3d p0 = fe.probe->point_lps_mm - dir * (ro.tool_radius_mm + 1.0);
  // The sphere's front reaches the probe point after 1 mm; the grip then goes `depth_mm` in.
  const double travel = 1.0 + depth_mm;
  // The hold lasts at least t_hold and until the equilibrium is where the tool is (at most
  // kMaxHoldS): its force is then the settled answer, compared with the same grip pressed
  // statically, whatever else the machine is doing (a busy machine made equilibria late).
  constexpr double kMaxHoldS = 10.0;
  const double t_in = travel / speed, t_hold = 0.5, t_rest = 1.0;
  std::atomic<double> hold_end{-1.0};  // set by the force loop when the hold ends
  auto tool_at = [&](double t) {
    const double he = hold_end.load();
    double s = t < t_in ? speed * t : he < 0 ? travel : std::max(0.0, travel - speed * (t - he));
    return Eigen::Vector3d(p0 + dir * s);
  };
  std::atomic<double> total{2 * t_in + kMaxHoldS + t_rest};  // until the hold's end is known
  rt.set_tool(tool_at(0));
  rt.start();
  std::vector<double> tick_us, jitter_us;
  tick_us.reserve(std::size_t((2 * t_in + t_hold + t_rest) * 1000) + 100);
  jitter_us.reserve(tick_us.capacity());
  double fmax = 0.0, hold_force = 0.0, hold_fe_force = 0.0, hold_lag = 0.0;
  Eigen::Vector3d hold_held = Eigen::Vector3d::Zero();
  std::vector<std::int32_t> hold_grip;
  // The press's force–depth curves while the tool goes in: what the force loop gave the tool
  // against the depth the tool asked of the grip (felt), and each equilibrium's (solved).
  std::vector<std::array<double, 2>> felt, solved;
  std::uint64_t last_equilibrium = 0;
  double gap_max = 0.0;
  const auto start = clock::now();
  auto next = start;
  std::int64_t ticks = 0;
  double end_s = 0.0;
  // The force loop as the haptic loop runs it: its own thread, real-time priority where the
  // system grants it (SCHED_FIFO; refused without the privilege, then normal and said so).
  bool realtime = false;
  std::atomic<bool> done{false};
  std::thread force_loop([&] {
  sched_param sp{};
  sp.sched_priority = 20;
  realtime = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0;
  while (true) {
    const auto wake = clock::now();
    jitter_us.push_back(std::chrono::duration<double, std::micro>(wake - next).count());
    const double t = std::chrono::duration<double>(wake - start).count();
    if (t > total.load()) {
      end_s = t;
      break;
    }
    const Eigen::Vector3d x = tool_at(t);
    rt.set_tool(x);
    const Eigen::Vector3d F = rt.tool_force_N(x);
    fmax = std::max(fmax, F.norm());
    if (t <= t_in) {
      const physics::ToolContact c = rt.contact();
      if (c.in_contact && Eigen::Vector3d(c.held_mm.data()).norm() > 0) {
        const Eigen::Vector3d grip = x + Eigen::Vector3d(c.held_mm.data()) - Eigen::Vector3d(c.tool_mm.data());
        felt.push_back({grip.dot(dir), -F.dot(dir)});
        if (c.update != last_equilibrium)
          solved.push_back({Eigen::Vector3d(c.held_mm.data()).dot(dir), -Eigen::Vector3d(c.force_on_tool_N.data()).dot(dir)});
        last_equilibrium = c.update;
      }
    }
    if (t > t_in && hold_end.load() < 0) {
      const physics::ToolContact c = rt.contact();
      const bool settled = c.in_contact && (x - Eigen::Vector3d(c.tool_mm.data())).norm() < 1e-4;
      if (t - t_in >= kMaxHoldS || (t - t_in >= t_hold && settled)) {
        hold_end.store(t);
        total.store(t + t_in + t_rest);
      }
    }
    if (hold_end.load() < 0 || t <= hold_end.load()) {  // the last one: the end of the hold
      hold_force = F.norm();
      const physics::ToolContact c = rt.contact();
      hold_fe_force = Eigen::Vector3d(c.force_on_tool_N.data()).norm();
      hold_lag = c.in_contact ? (x - Eigen::Vector3d(c.tool_mm.data())).norm() : -1.0;
      hold_held = Eigen::Vector3d(c.held_mm.data());
    }
    tick_us.push_back(std::chrono::duration<double, std::micro>(clock::now() - wake).count());
    ++ticks;
    next += std::chrono::microseconds(1000);
    if (next < clock::now()) next = clock::now();
    std::this_thread::sleep_until(next);
  }
  done.store(true);
  });
  while (!done.load()) {  // progress from this thread; the grip near the end of the hold
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const double t = std::chrono::duration<double>(clock::now() - start).count();
    const double he = hold_end.load();
    if (he < 0) gap_max = std::max(gap_max, rt.last_gap_mm());
    if (t > t_in + 0.5 * t_hold && he < 0) hold_grip = rt.grip_nodes();
    progress.report(std::min(1.0, t / total.load()), "real-time press");
  }
  force_loop.join();
  rt.stop();
  // The same grip pressed quasi-statically to where the tool held it: what the hold should feel.
  // An independent static solve (full Newton from rest, its own model): in 0.6 mm increments
  // (the trachea's 14 682-node wall: 8 increments, 32 Newton iterations, 27 s, where 0.15 mm took
  // 31 increments, 63 iterations, 70 s, for the same force to 2·10⁻⁶); again at 0.15 mm where
  // the larger increments do not converge.
  double static_force = -1.0;
  if (!hold_grip.empty()) {
    auto press_statically = [&](double step_mm) {
      physics::TissueModel ref(model.mesh(), model.options());
      ref.set_boundary(fe.fixed_nodes, hold_grip);
      const int steps = std::max(1, int(std::ceil(hold_held.norm() / step_mm)));
      for (int k = 1; k <= steps; ++k)
        if (!ref.solve_static(hold_held * double(k) / steps).converged) return -1.0;
      return ref.held_force_N().norm();
    };
    static_force = press_statically(0.6);
    if (static_force < 0) static_force = press_statically(0.15);
  }

  const Eigen::VectorXd u = rt.displacement_mm();
  double umax = 0.0;
  for (Eigen::Index i = 0; i + 2 < u.size(); i += 3) umax = std::max(umax, u.segment<3>(i).norm());
  auto to_json = [](const std::vector<std::array<double, 2>>& c) {
    nlohmann::json a = nlohmann::json::array();
    for (const auto& p : c) a.push_back({p[0], p[1]});
    return a;
  };
  return {{"felt_curve", to_json(felt)},
          {"solved_curve", to_json(solved)},
          {"update_ms_p50", rt.update_ms_percentile(0.5)},
          {"update_ms_p99", rt.update_ms_percentile(0.99)},
          {"update_hz", rt.achieved_update_hz()},
          {"updates", rt.updates()},
          {"equilibrium_hz", rt.achieved_equilibrium_hz()},
          {"equilibrium_ms_p50", rt.equilibrium_ms_percentile(0.5)},
          {"equilibrium_ms_p99", rt.equilibrium_ms_percentile(0.99)},
          {"equilibria", rt.equilibria()},
          {"largest_travel_ahead_of_equilibrium_mm", gap_max},
          {"force_rate_hz", double(ticks) / end_s},
          {"force_tick_us_p99", percentile(tick_us, 0.99)},
          {"force_jitter_us_p99", percentile(jitter_us, 0.99)},
          {"force_loop_realtime_priority", realtime},
          {"press", {{"speed_mm_per_s", speed}, {"depth_mm", depth_mm}, {"hold_s", hold_end.load() - t_in}, {"rest_after_s", t_rest},
                     {"peak_force_N", fmax}, {"force_at_end_of_hold_N", hold_force}, {"tissue_force_at_end_of_hold_N", hold_fe_force},
                     {"tissue_behind_tool_at_end_of_hold_mm", hold_lag}, {"held_nodes_at_end_of_hold", hold_grip.size()},
                     {"static_force_same_grip_N", static_force}, {"largest_displacement_after_rest_mm", umax},
                     {"rest_fraction_of_depth", umax / depth_mm}}}};
}

nlohmann::json haptics_indent(const fs::path& out, const std::string& organ, const IndentOptions& o, Progress& progress) {
  const OrganFe fe = organ_fe(out, organ, o.fe);
  if (!fe.probe || fe.probe_nodes.empty())
    throw InputError(ExitCode::unsupported_input, organ + "'s solver file has no indentation probe", fe.inp,
                     "--indent presses organs whose load case is the probe (the gallbladder); give --probe-lps to place one");
  const fs::path sim = OutputLayout{out}.simulation(organ, "json");
  const std::vector<std::array<double, 2>> reference = o.fe.probe_lps_mm ? std::vector<std::array<double, 2>>{} : read_curve(sim);
  std::vector<double> depths;
  if (!reference.empty()) {
    for (const auto& p : reference)
      if (p[0] > 0) depths.push_back(p[0]);
  } else {
    const int n = std::max(1, int(std::ceil(fe.probe_depth_mm / o.max_step_mm - 1e-9)));
    for (int k = 1; k <= n; ++k) depths.push_back(fe.probe_depth_mm * k / n);
  }
  physics::TissueModelOptions mo;
  mo.solver_threads = 2;  // no display to share the cores with
  physics::TissueModel model(fe.mesh, mo);
  model.set_boundary(fe.fixed_nodes, fe.probe_nodes);
  const Eigen::Vector3d dir = fe.probe->direction_lps.normalized();
  nlohmann::json curve = nlohmann::json::array(), cmp = nlohmann::json::array();
  std::vector<double> solve_ms;
  int iterations = 0;
  double at = 0.0, worst = 0.0;
  const double deepest = depths.empty() ? 0.0 : depths.back();
  for (std::size_t k = 0; k < depths.size(); ++k) {
    progress.report(double(k) / double(depths.size()), "pressing the probe");
    progress.check_cancelled();
    const double target = depths[k];
    const int sub = std::max(1, int(std::ceil((target - at) / o.max_step_mm - 1e-9)));
    for (int s = 1; s <= sub; ++s) {
      const double d = at + (target - at) * s / sub;
      const auto t0 = std::chrono::steady_clock::now();
      const physics::NewtonReport rep = model.solve_static(dir * d);
      solve_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      iterations += rep.iterations;
      if (!rep.converged)
        throw SimulationError(ExitCode::solver_failed,
                              "the real-time model of " + organ + " did not reach equilibrium at " + std::to_string(d).substr(0, 5) +
                                  " mm (largest residual " + std::to_string(rep.residual_N) + " N)",
                              fe.inp);
    }
    at = target;
    const double force = model.held_force_N().dot(dir);
    curve.push_back({target, force});
    if (!reference.empty()) {
      double ref = 0.0;
      for (const auto& p : reference)
        if (std::abs(p[0] - target) < 1e-12) ref = p[1];
      const double rel = ref != 0.0 ? (force - ref) / ref : 0.0;
      cmp.push_back({target, ref, rel});
      if (target >= 0.2 * deepest) worst = std::max(worst, std::abs(rel));
    }
  }
  const auto stretch = model.element_max_stretch();
  nlohmann::json regions = nlohmann::json::object();
  for (std::size_t L = 0; L < fe.region_names.size(); ++L) {
    std::vector<double> s;
    for (std::size_t e = 0; e < stretch.size(); ++e)
      if (fe.mesh.law_of_element[e] == std::int32_t(L)) s.push_back(stretch[e]);
    std::sort(s.begin(), s.end());
    if (!s.empty()) regions[fe.region_names[L]] = {{"p99", s[std::min(s.size() - 1, std::size_t(0.99 * s.size()))]}, {"max", s.back()}};
  }
  nlohmann::json j;
  j["organ"] = organ;
  j["solver_input"] = fe.inp.string();
  j["probe"] = {{"point_lps_mm", {fe.probe->point_lps_mm.x(), fe.probe->point_lps_mm.y(), fe.probe->point_lps_mm.z()}},
                {"direction", {dir.x(), dir.y(), dir.z()}},
                {"diameter_mm", fe.probe->diameter_mm},
                {"held_nodes", fe.probe_nodes.size()}};
  j["curve"] = curve;
  if (!reference.empty()) {
    j["solver_curve"] = {{"file", sim.string()}, {"depth_mm_force_N_relative_difference", cmp},
                         {"largest_relative_difference_past_20pct_depth", worst}};
  }
  j["principal_stretch_at_deepest"] = regions;
  if (!o.picture_png.empty()) {
    // The organ at the deepest indentation, coloured by von Mises stress, over its rest outline.
    const Eigen::VectorXd& u = model.displacement_mm();
    std::vector<double> vm = model.element_von_mises();
    for (double& v : vm) v *= 1e6;  // N/mm² → Pa
    const std::string detail = format_g(fe.probe->diameter_mm, 3) + " mm probe pressed " + format_g(deepest, 3) + " mm, " +
                               format_g(1e3 * (curve.empty() ? 0.0 : curve.back()[1].get<double>()), 3) +
                               " mN  |  organsmith's model: " + std::to_string(fe.mesh.nodes_mm.size()) + " nodes, " +
                               std::to_string(fe.mesh.elements.size()) + " tetrahedra";
    try {
      draw_deformed_tets(organ, fe.mesh.nodes_mm, fe.mesh.elements, std::vector<double>(u.data(), u.data() + u.size()), vm,
                         "von Mises, Pa", detail, o.picture_png, o.picture_width_px, o.picture_height_px);
      j["picture"] = o.picture_png.string();
    } catch (const DisplayError& e) {
      spdlog::warn("indent: no picture ({})", e.what());
    }
  }
  auto describe = [](const OrganFe& m) {
    return nlohmann::json{{"nodes", m.mesh.nodes_mm.size()},
                          {"tets", m.mesh.elements.size()},
                          {"element", m.mesh.nodes_per_element == 10 ? "10-node tetrahedron (C3D10's)" : "4-node tetrahedron (the C3D10 corners)"},
                          {"law", "the solver file's Ogden solid per region"}};
  };
  j["curve_model"] = describe(fe);
  j["curve_model"]["static_increments"] = solve_ms.size();
  j["curve_model"]["newton_iterations"] = iterations;
  j["curve_model"]["static_solve_ms"] = {{"p50", percentile(solve_ms, 0.5)}, {"p99", percentile(solve_ms, 0.99)}};
  // The real-time press on the same model, through its threads.
  if (!o.realtime_press) return j;
  progress.report(1.0, "real-time press");
  j["fe"] = describe(fe);
  const nlohmann::json rt = realtime_press(model, fe, deepest, o.press_speed_mm_per_s, progress);
  for (const auto& [k, v] : rt.items())
    if (k != "felt_curve" && k != "solved_curve") j["fe"][k] = v;
  // The press's curves at the solver's depths (linear between samples) against its curve.
  if (!reference.empty()) {
    for (const char* which : {"felt_curve", "solved_curve"})
      j["fe"]["press"][std::string(which) + "_against_solver"] = against_reference(rt[which], reference, deepest);
  }
  return j;
}

}  // namespace organsmith
