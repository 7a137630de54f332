// Over 400 lines: the command's two modes (simulate the clip; fit τ_D to a mass series), each
// with its outputs and Fig. 6.8 plots.
// `organsmith degrade`: strain-energy-driven degradation of the magnesium micro-clip (thesis ch. 6,
// physics/degradation/degradation.h). Simulates the deployed clip under the wound load and writes the Fig. 6.8
// stages as VTK XML polylines, the mass curve and a summary; with --fit, calibrates τ_D to a
// mass-remaining series (Table 6.1). Output formats: physics/degradation/DEGRADATION.md ("Outputs").

#include "core/errors.h"
#include "core/file_io.h"
#include "pipeline/output/tool_info.h"
#include "core/format.h"
#include "core/vtk_xml.h"
#include "physics/materials/calibration.h"
#include "physics/degradation/clip.h"
#include "physics/degradation/degradation.h"
#include "pipeline/cli/commands.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/run/terminal_progress.h"
#include "viewer/display.h"
#include "viewer/snapshot.h"

#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;
using namespace organsmith::physics;

namespace {

/// The most time steps a degradation run may take (≈ 70 years at the default 0.25 days).
constexpr double kMaxSteps = 100000;

std::string num(double v) { return format_g(v, 10); }

/// Four significant digits, for what the terminal shows (files keep full precision).
std::string show(double v) { return format_g(v, 4); }

struct DegradeFlags {
  std::string out, clip, fit;
  double load_n = 5.0;
  double tau_d = 241.41;
  double weeks = 4.0;
  double dt_days = 0.1;
  int elements = 0;
  double max_increase = 0.05;
  bool print_clip = false;
  bool snapshots = true;
};

/// One stage as VTK XML PolyData (ASCII): one line cell per element, clip frame in mm (z = 0).
std::string stage_vtp(const ClipModel& m, const ClipSnapshot* s, const std::string& title) {
  const ClipGeometry& g = m.geometry();
  const int N = g.elements(), P = g.nodes();
  VtkPiece piece;
  piece.field_data.push_back({"t_days", "Float64", 1, {s ? s->t_days : 0.0}});
  piece.field_data.push_back({"load_carried", "Int32", 1, {s && s->load_carried ? 1.0 : 0.0}});
  VtkArray displacement{"displacement_mm", "Float64", 3, {}};
  for (int n = 0; n < P; ++n) {
    const Eigen::Vector2d p = s ? Eigen::Vector2d(s->q.segment<2>(2 * n)) : g.nodes_mm[n];
    piece.points.emplace_back(p.x(), p.y(), 0.0);
    const Eigen::Vector2d u = p - g.nodes_mm[n];
    displacement.values.insert(displacement.values.end(), {u.x(), u.y(), 0.0});
  }
  piece.point_data.push_back(std::move(displacement));
  auto cell_array = [&](const char* type, const char* name, auto value) {
    VtkArray a{name, type, 1, {}};
    for (int e = 0; e < N; ++e) a.values.push_back(value(e));
    piece.cell_data.push_back(std::move(a));
  };
  cell_array("Float64", "d", [&](int e) { return s ? s->d[e] : 0.0; });
  cell_array("Float64", "remaining", [&](int e) { return s ? 1.0 - s->d[e] : 1.0; });
  cell_array("Float64", "E_star", [&](int e) { return s ? s->energies.density[e] : 0.0; });
  cell_array("Float64", "E_star_mJ", [&](int e) { return s ? s->energies.e_star_mJ[e] : 0.0; });
  cell_array("Int32", "fractured", [&](int e) { return s && s->fractured[e] ? 1.0 : 0.0; });
  cell_array("Int32", "region", [&](int e) { return double(static_cast<int>(g.region[e])); });
  cell_array("Int32", "element_id", [&](int e) { return double(e); });
  for (int e = 0; e < N; ++e) piece.add_cell(std::array<int, 2>{e, e + 1});
  return vtk_polydata_xml(piece, VtkPolyCells::lines, title);
}

/// The clip's centroid curve in a state as plot lines: one series per run of intact elements
/// (broken elements leave gaps), the first named, the rest unlisted.
void add_clip_series(std::vector<PlotSeries>& out, const ClipModel& m, const ClipSnapshot* s, const std::string& name,
                     Rgb colour, bool dashed) {
  const ClipGeometry& g = m.geometry();
  auto node = [&](int n) { return s ? Eigen::Vector2d(s->q.segment<2>(2 * n)) : g.nodes_mm[n]; };
  PlotSeries cur;
  bool named = false;
  auto flush = [&] {
    if (cur.x.size() >= 2) {
      cur.name = name;
      cur.colour = colour;
      cur.dashed = dashed;
      cur.in_legend = !named;
      named = true;
      out.push_back(cur);
    }
    cur = PlotSeries{};
  };
  for (int e = 0; e < g.elements(); ++e) {
    if (s && s->fractured[e]) {
      flush();
      continue;
    }
    if (cur.x.empty()) cur.x.push_back(node(e).x()), cur.y.push_back(node(e).y());
    cur.x.push_back(node(e + 1).x());
    cur.y.push_back(node(e + 1).y());
  }
  flush();
}

/// The pictures of a simulation: each stage as in thesis Fig. 6.8 (original shape green, the
/// previous stage red, the current one blue; broken elements left out), the initial strain-energy
/// map along the clip (Fig. 6.3) and the mass-remaining curve (Fig. 6.7).
std::vector<Plot> degradation_plots(const ClipModel& m, const DegradationResult& r, double load_n, double tau_d) {
  const Rgb green{0.15, 0.6, 0.2}, red{0.85, 0.15, 0.1}, blue{0.1, 0.3, 0.85};
  // Plain "tau_D": the snapshot font has no Greek letters.
  const std::string note = "load " + num(load_n) + " N, tau_D " + num(tau_d) + " " + kTauUnitName +
                           "; clip frame (x across the wound, y out of the tissue)";
  std::vector<Plot> plots;
  const ClipSnapshot* previous = &r.initial;
  for (std::size_t k = 0; k < r.stages.size(); ++k) {
    const ClipSnapshot& cur = r.stages[k];
    Plot p;
    char stem[64];
    std::snprintf(stem, sizeof stem, "degradation_stage_%zu", k + 1);
    p.name = stem;
    p.title = "Clip degradation, stage " + std::to_string(k + 1) + ": day " + num(cur.t_days) + " (" +
              num(cur.t_days / 7.0) + " weeks)";
    p.note = note;
    p.x_label = "x (mm)";
    p.y_label = "y (mm)";
    add_clip_series(p.series, m, nullptr, "original shape", green, true);
    add_clip_series(p.series, m, previous, "previous stage (day " + num(previous->t_days) + ")", red, false);
    add_clip_series(p.series, m, &cur, "this stage", blue, false);
    plots.push_back(std::move(p));
    previous = &cur;
  }
  {
    const ClipGeometry& g = m.geometry();
    Plot p;
    p.name = "degradation_energy";
    p.title = "Strain energy along the deployed clip (t = 0)";
    p.note = note;
    p.x_label = "arc length from the left leg tip (mm)";
    p.y_label = std::string("E* (") + kEnergyDensityUnitName + ")";
    p.log_y = true;
    PlotSeries e;
    e.name = "E* per element";
    e.colour = red;
    double arc = 0;
    for (int i = 0; i < g.elements(); ++i) {
      const double len = (g.nodes_mm[i + 1] - g.nodes_mm[i]).norm();
      e.x.push_back(arc + 0.5 * len);
      e.y.push_back(std::max(r.initial.energies.density[i], 1e-6));
      arc += len;
    }
    p.series.push_back(std::move(e));
    plots.push_back(std::move(p));
  }
  {
    Plot p;
    p.name = "degradation_mass";
    p.title = "Mass remaining";
    p.note = note;
    p.x_label = "time (days)";
    p.y_label = "mass remaining (fraction)";
    PlotSeries mass;
    mass.name = "model";
    mass.colour = blue;
    for (const auto& s : r.steps) mass.x.push_back(s.t_days), mass.y.push_back(s.mass_fraction);
    p.series.push_back(std::move(mass));
    plots.push_back(std::move(p));
  }
  return plots;
}

/// Renders `plots` into dir/snapshots/plot_<name>.png. Without any display (no X server and no
/// Xvfb) the pictures are skipped with a warning: the numbers are the result.
void write_plot_pngs(const std::vector<Plot>& plots, const fs::path& dir) {
  SnapshotScene scene;
  scene.case_name = "degradation";
  scene.plots = plots;
  SnapshotOptions so;
  so.views = {ViewKind::plots};
  const fs::path snapshots = DegradeLayout{dir}.snapshots_dir();
  fs::create_directories(snapshots);
  NullProgress quiet;
  try {
    render_snapshots(scene, so, snapshots, quiet);
  } catch (const DisplayError& e) {
    fs::remove_all(snapshots);
    spdlog::warn("pictures skipped: {}", e.what());
  }
}

ClipPreset load_preset(const DegradeFlags& f) {
  return f.clip.empty() ? builtin_clip_preset() : read_clip_preset(f.clip);
}

nlohmann::json clip_json(const ClipModel& m) {
  const ClipPreset& p = m.preset();
  return {{"name", p.name},
          {"source", p.source},
          {"preset", p.file.string()},
          {"elements", m.geometry().elements()},
          {"length_mm", m.geometry().total_length_mm()},
          {"thickness_mm", p.thickness_mm},
          {"width_mm", p.width_mm},
          {"youngs_modulus_MPa", p.youngs_modulus_MPa},
          {"poisson_ratio", p.poisson_ratio},
          {"yield_strength_MPa", {p.yield_min_MPa, p.yield_max_MPa}},
          {"crown_radius_mm", p.crown_radius_mm},
          {"leg_length_mm", p.leg_length_mm},
          {"crown_height_mm", p.crown_height_mm},
          {"tissue_material", p.tissue_material},
          {"baseline_rate_per_day", p.baseline_rate_per_day},
          {"fracture_threshold", p.fracture_threshold},
          {"regions", {"crown", "left_leg", "left_contact", "right_leg", "right_contact"}}};
}

int run_print_clip() {
  std::cout << builtin_clip_preset_text();
  return 0;
}

int run_simulate(const DegradeFlags& f) {
  if (!(f.tau_d > 0)) throw UsageError("--tau-d must be positive (got " + num(f.tau_d) + ")",
                                       "τ_D is in week·(kJ/m³)^½; Table 6.1 gives 241.41 and 245.31");
  if (!(f.load_n >= 0)) throw UsageError("--load-n must be ≥ 0 N (got " + num(f.load_n) + ")");
  if (!(f.weeks > 0) || f.weeks > 520) throw UsageError("--weeks must lie in (0, 520] (got " + num(f.weeks) + ")");
  if (!(f.dt_days > 0) || f.dt_days > 7) throw UsageError("--dt-days must lie in (0, 7] (got " + num(f.dt_days) + ")");
  if (7.0 * f.weeks / f.dt_days > kMaxSteps)
    throw UsageError("--weeks " + num(f.weeks) + " at --dt-days " + num(f.dt_days) + " is more than " +
                         num(kMaxSteps) + " time steps",
                     "use a larger --dt-days (0.25 is the default)");
  OutputDir dir(f.out, OutputDirOptions{.inputs = {f.clip}, .command = "degrade"});
  const ClipModel model(load_preset(f), f.elements);
  DegradationOptions o;
  o.tau_d = f.tau_d;
  o.load_N = f.load_n;
  o.end_days = 7.0 * f.weeks;
  o.dt_days = f.dt_days;
  std::vector<double> stages;
  for (double s : o.stage_days)
    if (s <= o.end_days + 1e-9) stages.push_back(s);
  o.stage_days = stages;
  TerminalProgress progress;
  const DegradationResult r = simulate_degradation(model, o, &progress);
  progress.finish();
  const ClipGeometry& g = model.geometry();
  const ClipPreset& p = model.preset();

  nlohmann::json j;
  j["tool_version"] = tool_version();
  j["clip"] = clip_json(model);
  j["load_n"] = f.load_n;
  j["tau_d"] = f.tau_d;
  j["tau_d_unit"] = kTauUnitName;
  j["energy_unit"] = kEnergyDensityUnitName;
  j["weeks"] = f.weeks;
  j["dt_days"] = f.dt_days;
  j["frame"] = "clip frame, mm: x across the wound (incision at x = 0), y out of the tissue (surface y = 0), z = 0";
  nlohmann::json dep = nlohmann::json::array();
  for (const auto& rec : r.deployment_steps)
    dep.push_back({{"iterations", rec.iterations}, {"converged", rec.converged},
                   {"final_residual_N", rec.final_residual_N}, {"non_pd_shifts", rec.non_pd_shifts},
                   {"energy_mJ", rec.energy_mJ}});
  j["deployment"] = {{"load_steps", dep},
                     {"max_displacement_mm", r.max_displacement_mm},
                     {"max_bending_stress_MPa", r.max_bending_stress_MPa},
                     {"exceeds_yield", r.max_bending_stress_MPa > p.yield_min_MPa},
                     {"potential_mJ", r.initial.energies.total_potential_mJ}};
  // Where the initial energy peaks, per region (Fig. 6.3).
  nlohmann::json peaks = nlohmann::json::object();
  for (int reg = 0; reg < 5; ++reg) {
    int best = -1;
    for (int e = 0; e < g.elements(); ++e)
      if (static_cast<int>(g.region[e]) == reg && (best < 0 || r.initial.energies.density[e] > r.initial.energies.density[best]))
        best = e;
    if (best >= 0) {
      const Eigen::Vector2d c = (g.nodes_mm[best] + g.nodes_mm[best + 1]) / 2;
      peaks[region_name(static_cast<ClipRegion>(reg))] = {
          {"element", best}, {"E_star", r.initial.energies.density[best]}, {"x_mm", c.x()}, {"y_mm", c.y()}};
    }
  }
  j["initial_energy_peaks"] = peaks;
  nlohmann::json st = nlohmann::json::array();
  st.push_back({{"file", DegradeLayout::stage_name(0, 0.0)}, {"t_days", 0.0}, {"weeks", 0.0}, {"previous", nullptr}});
  for (std::size_t k = 0; k < r.stages.size(); ++k) {
    st.push_back({{"file", DegradeLayout::stage_name(k + 1, r.stages[k].t_days / 7.0)}, {"t_days", r.stages[k].t_days}, {"weeks", r.stages[k].t_days / 7.0},
                  {"previous", st.back()["file"]}});
  }
  j["original"] = DegradeLayout::original_name;
  j["stages"] = st;
  const double mass0_mg = p.density_g_per_cm3 * p.area_mm2() * g.total_length_mm();
  j["initial_mass_mg"] = mass0_mg;
  j["final_mass_fraction"] = r.steps.back().mass_fraction;
  j["load_released_day"] = r.load_released_day < 0 ? nlohmann::json(nullptr) : nlohmann::json(r.load_released_day);
  nlohmann::json frac = nlohmann::json::array();
  for (int e = 0; e < g.elements(); ++e)
    if (r.fracture_day[e] >= 0)
      frac.push_back({{"element", e}, {"region", region_name(g.region[e])}, {"t_days", r.fracture_day[e]}});
  j["fractures"] = frac;
  j["total_iterations"] = r.total_iterations;
  j["all_converged"] = r.all_converged;

  std::ostringstream csv;
  csv << "t_days,mass_fraction,mass_mg,fractured_elements,load_carried,stored_energy_mJ,potential_mJ,iterations,residual_N\n";
  for (const auto& s : r.steps)
    csv << num(s.t_days) << ',' << num(s.mass_fraction) << ',' << num(s.mass_fraction * mass0_mg) << ',' << s.fractured
        << ',' << (s.load_carried ? 1 : 0) << ',' << num(s.stored_mJ) << ',' << num(s.potential_mJ) << ','
        << s.iterations << ',' << num(s.residual_N) << '\n';

  const fs::path out = dir.path();
  dir.commit("degrade", [&](const fs::path& dir) {
    const DegradeLayout staged{dir};
    write_file_atomic(staged.original(), stage_vtp(model, nullptr, "original (stress-free) shape"));
    write_file_atomic(staged.stage(0, 0.0), stage_vtp(model, &r.initial, "deployed, t = 0"));
    for (std::size_t k = 0; k < r.stages.size(); ++k)
      write_file_atomic(dir / st[k + 1]["file"].get<std::string>(),
                 stage_vtp(model, &r.stages[k], "t = " + num(r.stages[k].t_days) + " days"));
    write_file_atomic(staged.mass(), csv.str());
    if (f.snapshots) write_plot_pngs(degradation_plots(model, r, f.load_n, f.tau_d), dir);
    write_file_atomic(staged.summary(), j.dump(2) + "\n");
  });
  std::cout << "clip " << p.name << " (" << g.elements() << " elements) under " << num(f.load_n) << " N, τ_D "
            << num(f.tau_d) << " " << kTauUnitName << "\n"
            << "  deployment: max displacement " << show(r.max_displacement_mm) << " mm, max bending stress "
            << show(r.max_bending_stress_MPa) << " MPa (yield " << num(p.yield_min_MPa) << "–" << num(p.yield_max_MPa)
            << " MPa; the model is elastic)\n"
            << "  mass remaining after " << num(f.weeks) << " weeks: " << show(100 * r.steps.back().mass_fraction) << " %\n";
  if (r.load_released_day >= 0)
    std::cout << "  the clip stopped holding the wound on day " << show(r.load_released_day) << " (a leg broke)\n";
  if (!r.all_converged) std::cout << "  warning: some minimisations did not reach the force tolerance (see mass.csv residual_N)\n";
  std::cout << "wrote " << out.string() << "\n";
  return 0;
}

int run_fit(const DegradeFlags& f) {
  if (!(f.load_n >= 0)) throw UsageError("--load-n must be ≥ 0 N (got " + num(f.load_n) + ")");
  if (!(f.dt_days > 0) || f.dt_days > 7) throw UsageError("--dt-days must lie in (0, 7] (got " + num(f.dt_days) + ")");
  OutputDir out_dir(f.out, OutputDirOptions{.inputs = {f.fit, f.clip}, .command = "degrade"});
  const MassSeries data = read_mass_csv(f.fit, f.max_increase);
  if (data.t_days.size() > 100000)
    throw CalibrationDataError("the mass series has " + std::to_string(data.t_days.size()) + " rows", f.fit,
                               "give at most 100 000 (weighings are days apart; resample a logger's series)");
  if (data.t_days.back() / f.dt_days > kMaxSteps)
    throw CalibrationDataError("the mass series reaches day " + num(data.t_days.back()) + ": more than " +
                                   num(kMaxSteps) + " time steps of " + num(f.dt_days) + " days",
                               f.fit, "check the time column (days), or use a larger --dt-days");
  const ClipModel model(load_preset(f), f.elements);
  DegradationOptions o;
  o.load_N = f.load_n;
  o.dt_days = f.dt_days;
  TerminalProgress progress;
  const TauFit fit = fit_tau_d(model, o, data, {}, &progress);
  progress.finish();
  DegradationOptions best = o;
  best.tau_d = fit.tau_d;
  best.keep_stages = false;
  best.end_days = std::ceil(data.t_days.back() / o.dt_days - 1e-9) * o.dt_days;
  const DegradationResult curve = simulate_degradation(model, best, nullptr);

  nlohmann::json j;
  j["tool_version"] = tool_version();
  j["data"] = fs::absolute(f.fit).string();
  j["points"] = data.t_days.size();
  j["clip"] = clip_json(model);
  j["load_n"] = f.load_n;
  j["tau_d"] = fit.tau_d;
  j["tau_d_unit"] = kTauUnitName;
  j["r2"] = fit.r2;
  j["rmse"] = fit.rmse;
  j["sse"] = fit.sse;
  j["evaluations"] = fit.evaluations;
  j["at_search_bound"] = fit.at_bound;
  j["dt_days"] = f.dt_days;
  std::ostringstream csv, curve_csv;
  csv << "t_days,mass_fraction,model_mass_fraction,residual\n";
  for (std::size_t i = 0; i < data.t_days.size(); ++i)
    csv << num(data.t_days[i]) << ',' << num(data.mass_fraction[i]) << ',' << num(fit.predicted[i]) << ','
        << num(fit.predicted[i] - data.mass_fraction[i]) << '\n';
  curve_csv << "t_days,mass_fraction\n";
  for (const auto& s : curve.steps) curve_csv << num(s.t_days) << ',' << num(s.mass_fraction) << '\n';
  const fs::path out = out_dir.path();
  out_dir.commit("degrade-fit", [&](const fs::path& dir) {
    const DegradeLayout staged{dir};
    write_file_atomic(staged.fit_json(), j.dump(2) + "\n");
    write_file_atomic(staged.fit_csv(), csv.str());
    write_file_atomic(staged.model_mass(), curve_csv.str());
    if (f.snapshots) {
      Plot p;
      p.name = "degradation_fit";
      p.title = "Mass remaining: measured and fitted (tau_D " + num(fit.tau_d) + ")";
      p.note = fs::path(f.fit).filename().string() + ", load " + num(f.load_n) + " N; R² " + num(fit.r2) + ", RMSE " +
               num(fit.rmse);
      p.x_label = "time (days)";
      p.y_label = "mass remaining (fraction)";
      PlotSeries measured;
      measured.name = "measured";
      measured.points = true;
      measured.colour = {0.1, 0.1, 0.1};
      measured.x = data.t_days;
      measured.y = data.mass_fraction;
      PlotSeries model_line;
      model_line.name = "model";
      model_line.colour = {0.85, 0.15, 0.1};
      for (const auto& s : curve.steps) model_line.x.push_back(s.t_days), model_line.y.push_back(s.mass_fraction);
      p.series = {measured, model_line};
      write_plot_pngs({p}, dir);
    }
  });
  std::cout << "τ_D = " << show(fit.tau_d) << " " << kTauUnitName << " from " << data.t_days.size() << " points: R² "
            << show(fit.r2) << ", RMSE " << show(fit.rmse) << (fit.at_bound ? " (at the search bound)" : "") << "\n"
            << "wrote " << out.string() << "\n";
  return 0;
}

}  // namespace

std::vector<Command> degradation_commands(CLI::App& app) {
  auto f = std::make_shared<DegradeFlags>();
  auto* cmd = app.add_subcommand(
      "degrade",
      "Strain-energy-driven degradation of the magnesium micro-clip (thesis ch. 6). Deploys the clip\n"
      "(data/clips.toml or --clip) on a wound under --load-n, integrates ḋ = (1 − d)(k0 + √E*/τ_D) with the\n"
      "energy re-minimised every step, and writes DIR/original.vtp, DIR/stage_*.vtp (t = 0 and 0.5 … 2.5\n"
      "weeks; cell data d and E* per element), DIR/mass.csv and DIR/summary.json.\n"
      "With --fit MASS.csv (columns t_days, mass_fraction) calibrates τ_D instead: DIR/fit.json, fit.csv,\n"
      "model_mass.csv.");
  cmd->add_option("--out", f->out, "output directory: new, empty, or one organsmith wrote before (other files are never touched; required unless --print-clip)");
  cmd->add_option("--clip", f->clip, "clip preset TOML (default: the embedded data/clips.toml; see --print-clip)");
  cmd->add_option("--load-n", f->load_n, "wound tension held by the clip, N (default 5: the thesis' loaded group)");
  cmd->add_option("--tau-d", f->tau_d, "τ_D of 6.16 in week·(kJ/m³)^½ (default 241.41, Table 6.1 group 1)");
  cmd->add_option("--weeks", f->weeks, "simulated time in weeks (default 4)");
  cmd->add_option("--dt-days", f->dt_days, "time step in days (default 0.1)");
  cmd->add_option("--elements", f->elements, "beam elements (default: the preset's)")->check(CLI::Range(8, 100000));
  cmd->add_option("--fit", f->fit, "calibrate τ_D to this mass-remaining CSV instead of simulating");
  cmd->add_option("--max-increase", f->max_increase,
                  "--fit: largest rise of mass_fraction over an earlier row accepted as weighing noise (default 0.05)")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_flag("!--no-snapshots", f->snapshots,
                "do not render DIR/snapshots/*.png (stages as in thesis Fig. 6.8, energy map, mass curve)");
  cmd->add_flag("--print-clip", f->print_clip, "print the embedded clip preset (a starting point for --clip) and exit");
  return {{cmd, [f] {
             if (f->print_clip) return run_print_clip();
             if (f->out.empty()) throw UsageError("degrade needs --out DIR", "see `organsmith degrade --help`");
             return f->fit.empty() ? run_simulate(*f) : run_fit(*f);
           }}};
}

}  // namespace organsmith
