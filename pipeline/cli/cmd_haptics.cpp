// `guide` (guidance paths of a run's output directory: trachea centreline and incision,
// gallbladder dissection, or a user's recorded path) and `haptics` (replays a scripted trajectory
// through the 1 kHz force loop and reports path following, forces and loop timing).
// The science is in physics/haptics/HAPTICS.md. Just over 400 lines for a reason: the two
// commands share their readers of a run (labels, paths, laws) and their flags' checks; split,
// each half would carry a copy of them.

#include "core/errors.h"
#include "core/file_io.h"
#include "meshing/export.h"
#include "physics/haptics/contact.h"
#include "physics/haptics/guidance.h"
#include "physics/haptics/haptic_loop.h"
#include "physics/haptics/paths.h"
#include "physics/materials/presets.h"
#include "pipeline/cli/commands.h"
#include "pipeline/case/case_file.h"
#include "pipeline/stages/organ_fe.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/run/terminal_progress.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/review/output_scene.h"
#include "pipeline/stages/guide_stage.h"
#include "pipeline/io/image_io.h"
#include "pipeline/run/runner.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>

namespace organsmith {

namespace fs = std::filesystem;
using namespace organsmith::physics;

namespace {

void require_out_dir(const fs::path& out) {
  std::error_code ec;
  if (!fs::is_directory(out, ec))
    throw InputError(ExitCode::input_not_found, "no such output directory", out,
                     "give the directory `organsmith run --out` wrote (default: out)");
}

/// The label map of a run: the segmentation, else the phantom's ground truth.
LabelMap run_labels(const fs::path& out) {
  const OutputLayout layout{out};
  fs::path f = layout.labels();
  if (!fs::exists(f) && fs::exists(layout.phantom_truth())) f = layout.phantom_truth();
  if (!fs::exists(f))
    throw InputError(ExitCode::input_not_found, "no label map in the output directory", layout.labels(),
                     "run `organsmith run` into this directory first");
  return read_label_map(f);
}

/// The guidance paths the organ registry of the run in `out` defines (<organ>_<kind>).
std::vector<std::string> registry_paths(const fs::path& out) { return registry_of_output(out).path_names(); }

bool is_registry_path(const fs::path& out, const std::string& name) {
  const auto n = registry_paths(out);
  return std::find(n.begin(), n.end(), name) != n.end();
}

// ---- guide ---------------------------------------------------------------------------------------

struct GuideFlags {
  std::string out, path;
  bool force = false;
  GuideStageOptions options;
};

int run_guide(const GuideFlags& f) {
  const fs::path out = f.out;
  require_out_dir(out);
  GuideStageOptions options = f.options;
  std::optional<Polyline> user;
  if (!f.path.empty()) {
    if (is_registry_path(out, f.path)) {
      options.only = {f.path};
    } else if (fs::is_regular_file(f.path)) {
      user = read_path_file(f.path);
      check_path_within(*user, run_labels(out).grid, f.path);
    } else {
      std::string names;
      for (const auto& n : registry_paths(out)) names += (names.empty() ? "" : ", ") + n;
      throw UsageError("--path '" + f.path + "' is neither a path name nor a file", "names: " + names + "; or a CSV/JSON file");
    }
  }
  // Every built-in path of a run: the run's guide stage itself, with the flags given here.
  if (f.path.empty())
    if (std::optional<CaseFile> c = case_of_run(out)) {
      const GuideStageOptions defaults;
      GuideStageOptions& g = c->stages.guide;
      if (f.options.incision.first_ring != defaults.incision.first_ring) g.incision.first_ring = f.options.incision.first_ring;
      if (f.options.incision.ring_count != defaults.incision.ring_count) g.incision.ring_count = f.options.incision.ring_count;
      if (f.options.incision.ring_pitch_mm != defaults.incision.ring_pitch_mm)
        g.incision.ring_pitch_mm = f.options.incision.ring_pitch_mm;
      if (f.options.dissection.bed_distance_mm != defaults.dissection.bed_distance_mm)
        g.dissection.bed_distance_mm = f.options.dissection.bed_distance_mm;
      RunOptions ro;
      ro.from = ro.until = "guide";
      ro.force = f.force;
      NullProgress quiet;
      const RunSummary summary = run_case(*c, ro, quiet);
      for (const auto& o : summary.stages.back().outputs)
        std::cout << "wrote " << (summary.out_dir / o["path"].get<std::string>()).string() << "\n";
      return 0;
    }
  // Every file is staged, then moved into OUT_DIR/paths: a failure leaves nothing behind. Each
  // named path is its own stage, so that adding one keeps the others.
  OutputDir dir(out, OutputDirOptions{.in_place = true, .command = "guide"});
  const fs::path dest = OutputLayout{dir.path()}.paths_dir();
  std::vector<std::string> written;
  dir.commit(f.path.empty() ? "guide" : "guide-" + fs::path(f.path).stem().string(), [&](const fs::path& staging) {
    const fs::path paths = OutputLayout{staging}.paths_dir();
    fs::create_directories(paths);
    if (user) {
      user->name = fs::path(f.path).stem().string();
      write_file_atomic(paths / (user->name + ".json"),
                        path_json(*user, {{"recorded", 1.0}, {"length_mm", user->length_mm()}}));
      write_file_atomic(paths / (user->name + ".vtp"), path_vtp(*user));
      written = {user->name + ".json", user->name + ".vtp"};
    } else {
      const std::optional<CaseFile> run = case_of_run(out);
      const GuideFiles files = read_guide_inputs(out, run && run->stages.mesh.ras);
      written = write_guidance_paths(files.inputs(), paths, options, run ? run->registry : registry_of_output(out)).files;
    }
  });
  for (const auto& w : written) std::cout << "wrote " << (dest / w).string() << "\n";
  return 0;
}

// ---- haptics -------------------------------------------------------------------------------------

struct HapticsFlags {
  std::string out, trajectory, mode = "mixed", report, path;  // path: "" = the run's preferred
  LoopOptions loop;
  ContactOptions contact;
  std::vector<double> xi, bands, probe_lps;
  bool offline = false;
  std::string indent, fe_elements, fe;
  double press_speed_mm_per_s = IndentOptions{}.press_speed_mm_per_s;
};

int run_indent(const HapticsFlags& f) {
  const fs::path out = f.out;
  require_out_dir(out);
  IndentOptions o;
  o.fe.quadratic = f.fe_elements != "linear";
  o.press_speed_mm_per_s = f.press_speed_mm_per_s;
  if (!f.probe_lps.empty()) {
    if (f.probe_lps.size() != 3) throw UsageError("--probe-lps takes three coordinates (LPS mm)", "e.g. --probe-lps -20,-35,-368");
    o.fe.probe_lps_mm = Eigen::Vector3d(f.probe_lps[0], f.probe_lps[1], f.probe_lps[2]);
  }
  o.picture_png = fs::path(f.report).replace_extension(".png");
  TerminalProgress progress;
  const nlohmann::json r = haptics_indent(out, f.indent, o, progress);
  write_file_atomic(f.report, r.dump(2) + "\n");
  const auto& c = r["curve"];
  std::cout << "indent " << f.indent << " (" << r["curve_model"]["nodes"] << " nodes, " << r["curve_model"]["tets"] << " tets): "
            << c.back()[1].get<double>() * 1e3 << " mN at " << c.back()[0].get<double>() << " mm";
  if (r.contains("solver_curve"))
    std::cout << "; largest difference from CalculiX past 20 % of the depth "
              << 100 * r["solver_curve"]["largest_relative_difference_past_20pct_depth"].get<double>() << " %";
  const auto& fe = r["fe"];
  std::cout << "\nreal-time model (" << fe["nodes"] << " nodes): equilibria " << fe["equilibrium_hz"].get<double>() << " Hz (p50 "
            << fe["equilibrium_ms_p50"].get<double>() << " ms), display update p99 " << fe["update_ms_p99"].get<double>()
            << " ms; force loop " << fe["force_rate_hz"].get<double>() << " Hz, tick p99 " << fe["force_tick_us_p99"].get<double>()
            << " us; at rest 1 s after the tool left: " << 100 * fe["press"]["rest_fraction_of_depth"].get<double>() << " % of the depth";
  if (fe["press"].contains("felt_curve_against_solver"))
    std::cout << "\nforce felt at " << fe["press"]["speed_mm_per_s"].get<double>() << " mm/s against CalculiX past 20 % of the depth: "
              << 100 * fe["press"]["felt_curve_against_solver"]["largest_relative_difference_past_20pct_depth"].get<double>() << " %";
  std::cout << "\nwrote " << f.report << "\n";
  return 0;
}

/// The organ region's law (OUT_DIR/materials.json as `materials` holds it, else the built-in
/// preset) as a stress lookup table (the same law the preview and snapshots use).
StressTable region_table(const MaterialsFile* materials, const fs::path& out, const OrganInfo& organ,
                         const OrganRegistry& registry) {
  const fs::path file = OutputLayout{out}.materials();
  const OutputRegionLaw law = output_region_law(materials, organ.haptic_region, registry, file);
  if (!law.from_output)
    spdlog::warn("haptics: {} not in {}; using the built-in preset {}", organ.haptic_region, file.string(), law.preset_id);
  return StressTable::from_material(law.material, law.options, organ.haptic_max_strain);
}

nlohmann::json percentiles_json(const Percentiles& p) {
  return {{"p50", p.p50}, {"p99", p.p99}, {"p99_9", p.p999}, {"max", p.max}};
}

int run_haptics(HapticsFlags f) {
  if (!f.indent.empty() && !f.trajectory.empty()) throw UsageError("give --trajectory or --indent, not both");
  if (!f.indent.empty()) return run_indent(f);
  if (f.trajectory.empty()) throw UsageError("give --trajectory FILE (a replay) or --indent ORGAN (the probe's curve)");
  const fs::path out = f.out;
  require_out_dir(out);
  f.loop.mode = parse_force_mode(f.mode);
  if (!f.xi.empty()) {
    if (f.xi.size() != 3) throw UsageError("--xi takes three stiffnesses (N/mm)", "e.g. --xi 0.3,0.6,0.9");
    f.loop.guidance.xi_N_per_mm = {f.xi[0], f.xi[1], f.xi[2]};
  }
  if (!f.bands.empty()) {
    if (f.bands.size() != 2) throw UsageError("--bands takes two distances (mm)", "e.g. --bands 2,5");
    f.loop.guidance.band_edges_mm = {f.bands[0], f.bands[1]};
  }
  validate(f.loop);
  validate(f.contact);
  ScriptedDevice device = ScriptedDevice::read_csv(f.trajectory);
  const LabelMap labels = run_labels(out);

  // The path: the one named, else the first of the registry's preferred the run made.
  Polyline path;
  if (f.path.empty()) {
    const OrganRegistry registry = registry_of_output(out);
    for (const auto& name : registry.preferred_path_names())
      if (const fs::path pf = OutputLayout{out}.path(name, "json"); path.points_lps_mm.empty() && fs::exists(pf)) path = read_path_file(pf);
    if (path.points_lps_mm.empty())
      throw InputError(ExitCode::input_not_found, "no guidance path in " + OutputLayout{out}.paths_dir().string(),
                       OutputLayout{out}.paths_dir(), "run `organsmith guide " + out.string() + "` (or `organsmith run`) first");
  } else if (is_registry_path(out, f.path)) {
    const fs::path pf = OutputLayout{out}.path(f.path, "json");
    if (!fs::exists(pf))
      throw InputError(ExitCode::input_not_found, "no guidance path " + f.path, pf,
                       "run `organsmith guide " + out.string() + "` (or `organsmith run`) first");
    path = read_path_file(pf);
  } else if (fs::is_regular_file(f.path)) {
    path = read_path_file(f.path);
    check_path_within(path, labels.grid, f.path);
  } else {
    throw UsageError("--path '" + f.path + "' is neither a path name nor a file");
  }
  const PathIndex path_index(path);

  // The organs to touch: those in the label map, with their calibrated laws.
  std::vector<SurfaceMesh> surfaces;
  std::vector<StressTable> tables;
  nlohmann::json organs = nlohmann::json::array();
  const OrganRegistry registry = registry_of_output(out);
  // The organ felt through its real-time finite-element model (default: the gallbladder where its
  // solver file exists); the others through their surfaces and laws.
  std::unique_ptr<RealtimeOrgan> fe = fe_for_haptics(out, f.fe, f.contact.tool_radius_mm, f.fe_elements == "quadratic");
  const std::string fe_organ = fe ? fe->fe.organ : "none";
  const std::optional<MaterialsFile> materials = read_materials(out);
  for (const OrganInfo& o : registry.organs) {
    if (o.haptic_surface.empty() || labels.count(o.label) == 0 || o.name == fe_organ) continue;
    const fs::path sf = OutputLayout{out}.surface(o.name, o.haptic_surface, "stl");
    if (!fs::exists(sf))
      throw InputError(ExitCode::input_not_found, "missing organ surface " + o.haptic_surface + ".stl", sf,
                       "run the mesh stage (`organsmith run`) first");
    surfaces.push_back(read_stl(sf));
    tables.push_back(region_table(materials ? &*materials : nullptr, out, o, registry));
    organs.push_back({{"organ", o.name}, {"surface", fs::relative(sf, out).generic_string()}, {"law_region", o.haptic_region},
                      {"triangles", surfaces.back().triangles.size()}});
  }
  std::unique_ptr<ContactModel> contact;
  if (!surfaces.empty()) contact = std::make_unique<ContactModel>(SurfaceIndex(std::move(surfaces)), std::move(tables), f.contact);

  f.loop.trace_capacity = std::size_t(device.duration_s() * f.loop.rate_Hz * 1.25) + 2000;
  HapticLoop loop(device, &path_index, contact.get(), f.loop);
  loop.set_reaction_source(fe.get());
  if (f.offline) {
    // The FE model updated on the loop's clock, at its own rate (60 Hz).
    const double dt = 1.0 / f.loop.rate_Hz;
    double next_update_s = 0.0;
    for (std::int64_t i = 0; double(i) * dt <= device.duration_s(); ++i) {
      loop.tick(double(i) * dt);
      if (fe && double(i) * dt >= next_update_s - 1e-9) {
        fe->tissue->update_once();
        next_update_s += 1.0 / physics::RealtimeOptions{}.update_hz;
      }
    }
  } else {
    if (fe) fe->tissue->start();
    loop.start();
    loop.wait(device.duration_s() + 10.0);
    loop.stop();
    if (fe) fe->tissue->stop();
  }
  const LoopStats st = loop.stats();
  const std::vector<TraceSample> trace = loop.trace();
  if (trace.empty()) throw Error(ExitCode::internal, "the haptic loop produced no tick");

  double se = 0, emax = 0, dse = 0, dmax = 0, fsum = 0, fmax = 0, gsum = 0, gmax = 0, rsum = 0, rmax = 0, contact_s = 0;
  std::array<double, 3> band_s{0, 0, 0};
  for (std::size_t i = 0; i < trace.size(); ++i) {
    const TraceSample& t = trace[i];
    const double dt = i + 1 < trace.size() ? trace[i + 1].t_s - t.t_s : 1.0 / f.loop.rate_Hz;
    se += t.distance_mm * t.distance_mm;
    emax = std::max(emax, t.distance_mm);
    const double dd = path_index.nearest(to_eigen(t.device_lps_mm)).distance_mm;
    dse += dd * dd;
    dmax = std::max(dmax, dd);
    const double fm = to_eigen(t.force_N).norm();
    fsum += fm, fmax = std::max(fmax, fm);
    gsum += t.guidance_N, gmax = std::max(gmax, t.guidance_N);
    rsum += t.reaction_N, rmax = std::max(rmax, t.reaction_N);
    band_s[std::size_t(t.band)] += dt;
    if (t.contact) contact_s += dt;
  }
  const double n = double(trace.size());
  nlohmann::json r;
  r["mode"] = mode_name(f.loop.mode);
  r["weights"] = {{"guidance", weights(f.loop.mode).guidance}, {"reaction", weights(f.loop.mode).reaction}};
  r["path"] = {{"name", path.name}, {"length_mm", path.length_mm()}, {"points", path.points_lps_mm.size()}};
  r["trajectory"] = {{"file", f.trajectory}, {"duration_s", device.duration_s()}, {"samples", device.times_s().size()}};
  r["replay"] = f.offline ? "offline (ticks computed back to back at the nominal times)" : "real time (loop thread)";
  r["tool_path_error_mm"] = {{"rms", std::sqrt(se / n)}, {"max", emax}};
  r["device_path_error_mm"] = {{"rms", std::sqrt(dse / n)}, {"max", dmax}};
  r["guidance"] = {{"xi_N_per_mm", f.loop.guidance.xi_N_per_mm}, {"band_edges_mm", f.loop.guidance.band_edges_mm},
                   {"time_in_band_s", band_s}};
  r["force_N"] = {{"peak", fmax}, {"mean", fsum / n}, {"limit", f.loop.force_limit_N}};
  r["guidance_force_N"] = {{"peak", gmax}, {"mean", gsum / n}};
  r["reaction_force_N"] = {{"peak", rmax}, {"mean", rsum / n}};
  r["contact"] = {{"time_s", contact_s}, {"tool_radius_mm", f.contact.tool_radius_mm},
                  {"reference_length_mm", f.contact.reference_length_mm}, {"organs", organs}};
  r["loop"] = {{"rate_Hz_target", f.loop.rate_Hz}, {"rate_Hz_measured", st.rate_Hz}, {"ticks", st.ticks},
               {"overruns", st.overruns}, {"faults", st.faults}, {"realtime_priority", st.realtime_priority},
               {"compute_us", percentiles_json(st.compute_us)},
               {"jitter_us", percentiles_json(st.jitter_us)}};
  if (f.offline) r["loop"]["ticks"] = trace.size();
  if (fe) {
    r["fe"] = fe->figures();
    r["fe"]["force_rate_hz"] = st.rate_Hz;
    r["fe"]["force_tick_us_p99"] = st.compute_us.p99;
    r["fe"]["force_jitter_us_p99"] = st.jitter_us.p99;
    r["contact"]["organs"].push_back({{"organ", fe_organ}, {"finite_element_model", fe->fe.inp.string()}});
  }
  write_file_atomic(f.report, r.dump(2) + "\n");
  std::cout << "haptics (" << mode_name(f.loop.mode) << ", " << path.name << "): tool–path error RMS "
            << std::sqrt(se / n) << " mm, max " << emax << " mm (device " << std::sqrt(dse / n) << " mm); force peak "
            << fmax << " N, mean " << fsum / n << " N\n";
  if (!f.offline)
    std::cout << "loop: " << st.rate_Hz << " Hz, compute p50/p99/p99.9 " << st.compute_us.p50 << "/" << st.compute_us.p99
              << "/" << st.compute_us.p999 << " µs, jitter p50/p99/p99.9 " << st.jitter_us.p50 << "/" << st.jitter_us.p99
              << "/" << st.jitter_us.p999 << " µs\n";
  std::cout << "wrote " << f.report << "\n";
  return 0;
}

}  // namespace

std::vector<Command> haptics_commands(CLI::App& app) {
  std::vector<Command> commands;

  auto g = std::make_shared<GuideFlags>();
  auto* guide = app.add_subcommand(
      "guide",
      "Guidance paths of a run's output directory (thesis §5.2): the trachea centreline (reaching both\n"
      "lumen ends, 1 mm spacing), the incision line on the anterior trachea wall over a ring segment,\n"
      "and the gallbladder dissection line where the wall meets the liver bed; or a recorded path\n"
      "(CSV x,y,z or JSON, LPS mm). Writes OUT_DIR/paths/<name>.json and .vtp.");
  guide->add_option("out_dir", g->out, "output directory of `organsmith run`")->required();
  guide->add_option("--path", g->path, "one path: <organ>_<kind> of the run's registry (built in: " + [] {
                      std::string n;
                      for (const auto& p : builtin_organ_registry().path_names()) n += (n.empty() ? "" : ", ") + p;
                      return n;
                    }() + "), or a CSV/JSON file");
  guide->add_flag("--force", g->force, "redo the stage even when it is unchanged since the last run");
  guide->add_option("--first-ring", g->options.incision.first_ring, "incision: first ring from the cranial end (default 3)")
      ->check(CLI::Range(1, 100));
  guide->add_option("--ring-count", g->options.incision.ring_count, "incision: rings spanned (default 4)")->check(CLI::Range(1, 100));
  guide->add_option("--ring-pitch-mm", g->options.incision.ring_pitch_mm, "incision: ring period in mm (default 6)")
      ->check(CLI::PositiveNumber);
  guide->add_option("--bed-distance-mm", g->options.dissection.bed_distance_mm,
                    "dissection: liver within this distance marks the bed, mm (default 2)")
      ->check(CLI::PositiveNumber);
  commands.push_back({guide, [=] { return run_guide(*g); }});

  auto h = std::make_shared<HapticsFlags>();
  auto* haptics = app.add_subcommand(
      "haptics",
      "Replays a trajectory (CSV t_s,x,y,z; seconds, LPS mm) through the 1 kHz force loop: guidance\n"
      "toward the path (staged potential field, thesis 5.2.3–5.2.8), reaction from the organ surfaces\n"
      "and their calibrated laws, mixed F = w1 G + w2 R by mode. Writes REPORT.json: path-following\n"
      "error, time in each ξ band, peak and mean forces, loop rate, compute time and jitter.");
  haptics->add_option("out_dir", h->out, "output directory of `organsmith run`")->required();
  haptics->add_option("--trajectory", h->trajectory, "CSV with header t_s,x,y,z");
  haptics->add_option("--indent", h->indent,
                      "instead of a replay: press the simulate stage's probe into ORGAN's real-time finite-element model\n"
                      "quasi-statically and write its force–depth curve beside CalculiX's (simulation/ORGAN.json)");
  haptics->add_option("--probe-lps", h->probe_lps, "--indent: probe point X,Y,Z (LPS mm), snapped to the free surface")->delimiter(',');
  haptics->add_option("--fe-elements", h->fe_elements,
                      "the organ's finite-element model: quadratic (the solver file's 10-node tets, CalculiX's answer; the "
                      "default of --indent) or linear (their corner nodes: equilibria at the display rate, about twice as stiff; "
                      "the default of --trajectory)")
      ->check(CLI::IsMember({"linear", "quadratic"}));
  haptics->add_option("--press-speed", h->press_speed_mm_per_s,
                      "--indent: the real-time press's speed, mm/s (default 0.5: quasi-static for the 10-node model on two cores)")
      ->check(CLI::PositiveNumber);
  haptics->add_option("--mode", h->mode, "guidance (w1=1), mixed (0.5/0.5, default) or reaction (w2=1)")
      ->check(CLI::IsMember({"guidance", "mixed", "reaction"}));
  haptics->add_option("--out", h->report, "report JSON")->required();
  haptics->add_option("--path", h->path, "guidance path name in OUT_DIR/paths or a CSV/JSON file (default: the first the run made of "
                    "an incision, a dissection, a centreline)");
  haptics->add_option("--fe", h->fe,
                      "--trajectory: organ felt through its real-time finite-element model (meshes/<organ>/<organ>.inp); "
                      "none: every organ through its surface and law (default: the gallbladder where its solver file exists)");
  haptics->add_option("--tool-radius-mm", h->contact.tool_radius_mm, "tool tip sphere radius, mm (default 2)")
      ->check(CLI::PositiveNumber);
  haptics->add_option("--reference-length-mm", h->contact.reference_length_mm,
                      "strain = penetration / this length, mm (default 5)")
      ->check(CLI::PositiveNumber);
  haptics->add_option("--force-limit-n", h->loop.force_limit_N, "force clamp, N (default 3)")->check(CLI::PositiveNumber);
  haptics->add_option("--rate-hz", h->loop.rate_Hz, "loop rate, Hz (default 1000)")->check(CLI::Range(1.0, 100000.0));
  haptics->add_option("--xi", h->xi, "the three ξ stiffnesses, N/mm (default 0.3,0.6,0.9)")->delimiter(',');
  haptics->add_option("--bands", h->bands, "the two band edges, mm (default 2,5)")->delimiter(',');
  haptics->add_option("--hand-stiffness", h->loop.hand_stiffness_N_per_mm,
                      "stiffness of the simulated hand holding the tool, N/mm (default 0.5)")
      ->check(CLI::NonNegativeNumber);
  haptics->add_flag("--offline", h->offline,
                    "compute the ticks back to back at their nominal times instead of in real time (deterministic; no timing figures)");
  commands.push_back({haptics, [=] { return run_haptics(*h); }});
  return commands;
}

}  // namespace organsmith
