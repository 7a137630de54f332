// The simulate stage (stages/simulate_stage.h): every organ's exported load case in CalculiX.

#include "pipeline/stages/simulate_stage.h"

#include "core/errors.h"
#include "core/format.h"
#include "physics/materials/models.h"
#include "physics/materials/presets.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/stages/simulate.h"
#include "pipeline/stages/simulation_picture.h"
#include "viewer/snapshot.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

/// The thesis' own reading of the indentation test (§5.1.5, Figure 5.1.6): the organ's law
/// (its body region's, thesis Table 5.1.2) as a uniaxial nominal stress at strain depth /
/// organ thickness, the mean of its two directions, times the probe's area.
void thesis_indentation_curve(const OrganInfo& info, IndentationResult& ind) {
  const auto it = info.materials.find(info.name + "_body");
  if (it == info.materials.end() || !(ind.probe.thickness_mm > 0)) return;
  const physics::RegionLaw law = region_law(it->second);
  const auto model = physics::make_model(law.material.model, law.options);
  const std::vector<double> p = physics::parameter_values(*model, law.material.parameters);
  const double area_m2 = M_PI * 0.25 * ind.probe.diameter_mm * ind.probe.diameter_mm * 1e-6;
  for (const auto& [depth, force] : ind.curve) {
    const double l = 1.0 + depth / ind.probe.thickness_mm;
    const double T = 0.5 * (model->respond_one({l, 1.0, physics::LoadCase::uniaxial_circumferential}, p) +
                            model->respond_one({l, 1.0, physics::LoadCase::uniaxial_longitudinal}, p));
    ind.thesis_curve.push_back({depth, std::isfinite(T) ? T * area_m2 : 0.0});
  }
  ind.thesis_source = law.id + " at strain depth / " + format_g(ind.probe.thickness_mm, 3) + " mm, times the probe's area";
}

/// The material band's variants of one organ (meshes/<organ>/band/), each run like the organ's
/// own INP in `work`/band_<variant>/. A variant that does not converge is recorded with the
/// solver's words and a warning; it does not fail the stage (the organ's own result stands).
nlohmann::json simulate_band(const OutputLayout& layout, const std::string& organ, const fs::path& work,
                             const SimulateOptions& so, Progress& progress) {
  std::map<std::string, SimulationResult> variants;
  for (const char* v : {"p05", "p50", "p95"}) {
    const fs::path inp = layout.band_input(organ, v);
    if (!fs::exists(inp))
      throw InputError(ExitCode::input_not_found, organ + ": no material band to simulate", inp,
                       "write one with [stages.mesh] material_band = true (or `organsmith mesh DIR --material-band`)");
    const fs::path dir = work / (std::string("band_") + v);
    try {
      Simulation sim = simulate_inp(inp, dir, so, progress);
      variants[v] = sim.result;
      spdlog::info("simulate: {} band {}: largest displacement {:.3g} mm, lumen change {:.4g} ml", organ, v,
                   sim.result.max_displacement_mm, sim.result.lumen_volume_change_mm3 / 1000);
    } catch (const SimulationError& e) {
      if (e.code() != ExitCode::solver_failed) throw;
      SimulationResult failed;
      failed.organ = organ;
      failed.solver_message = e.message();
      variants[v] = failed;
      spdlog::warn("simulate: {} band {}: {}", organ, v, e.message());
    }
    for (const char* f : {"job.frd", "job.cvg", "job.12d", "spooles.out"}) fs::remove(dir / f);
  }
  return band_summary(variants);
}

}  // namespace

void simulate_stage(const SimulateStageInputs& in, const SimulateStageOptions& options, const fs::path& staging,
                    Progress& progress) {
  const OutputLayout layout{in.out_dir};
  const OutputLayout staged{staging};
  SimulateOptions so;
  so.threads = options.threads;
  so.timeout_s = options.timeout_s;
  if (const char* ccx = std::getenv("ORGANSMITH_CCX"); ccx && *ccx) so.solver = ccx;
  for (const auto& [region, law] : region_materials(*in.registry)) so.calibrated_stretch_max[region] = law.stretch_max;
  int ran = 0;
  for (const std::string& name : in.organs) {
    const OrganInfo& info = in.registry->at(name);
    if (info.mesh != OrganMeshModel::wall_body && info.mesh != OrganMeshModel::tube) continue;
    const auto& only = options.organs;
    if (!only.empty() && std::find(only.begin(), only.end(), name) == only.end()) {
      // Not asked for this time: its earlier results stay (carried into the new commit).
      for (const fs::path& f : {layout.simulation(name, "json"), layout.simulation(name, "vtu"),
                                 layout.simulation(name, "png"), layout.indentation_plot(name)})
        if (fs::exists(f)) {
          fs::create_directories(staged.simulation_dir());
          fs::copy_file(f, staged.simulation_dir() / f.filename());
        }
      if (fs::is_directory(layout.simulation_work(name)))
        fs::copy(layout.simulation_work(name), staged.simulation_work(name), fs::copy_options::recursive);
      continue;
    }
    const fs::path inp = layout.volume(name, "inp");
    if (!fs::exists(inp)) {
      spdlog::warn("simulate: {} has no solver input ({}); add \"inp\" to [stages.mesh] formats", name, inp.string());
      continue;
    }
    SolverInput input = read_solver_inp(inp);
    if (!has_load_case(input)) {
      spdlog::warn("simulate: {} has no load step in {} (its comments say why); skipped", name, inp.string());
      continue;
    }
    const fs::path work = staged.simulation_work(name);
    Simulation sim;
    try {
      sim = simulate_inp(inp, std::move(input), work, so, progress);
    } catch (const SimulationError& e) {
      // The staging folder goes with the failure: the solver's account is kept where the
      // message can point to it.
      std::error_code ec;
      const fs::path kept = layout.failed_solver_log(name);
      if (e.path().filename() != "solver.log" || !fs::exists(e.path(), ec)) throw;
      fs::create_directories(kept.parent_path(), ec);
      if (!ec) fs::copy_file(e.path(), kept, fs::copy_options::overwrite_existing, ec);
      if (ec) throw;
      throw SimulationError(e.code(), e.message(), kept, e.hint());
    }
    {
      std::error_code ec;
      fs::remove(layout.failed_solver_log(name), ec);
      fs::remove(layout.failed_solver_log(name).parent_path(), ec);  // only when empty
    }
    // Keep the solver's account (log, status, printed totals), not its bulky result file.
    for (const char* f : {"job.frd", "job.cvg", "job.12d", "spooles.out"}) fs::remove(work / f);
    {  // the answer against the range each region's law was calibrated over
      const auto materials = region_materials(*in.registry);
      for (auto& [region, st] : sim.result.principal_stretch)
        if (const auto it = materials.find(region); it != materials.end()) {
          st.calibrated_max = it->second.stretch_max;
          if (st.p99 > st.calibrated_max)
            spdlog::warn("simulate: {}: {} is stretched to {:.3g} (99th percentile of its elements; largest {:.3g}), "
                         "beyond the {:.3g} its law was calibrated to: there the answer is the fitted solid's "
                         "extrapolation; lower the pressure or give tissue data that reach that far",
                         name, region, st.p99, st.max, st.calibrated_max);
        }
    }
    if (options.band) sim.result.band = simulate_band(layout, name, work, so, progress);
    if (sim.result.indentation) thesis_indentation_curve(info, *sim.result.indentation);
    write_simulation_files(sim.input, sim.frd, sim.result, staged.simulation_dir());
    try {  // the picture is a review aid: without a display the numbers still stand
      draw_simulation(sim, staged.simulation(name, "png"), in.picture_width_px, in.picture_height_px);
      if (sim.result.indentation)
        draw_indentation_plot(sim, sim.result.indentation->thesis_curve, sim.result.indentation->thesis_source,
                              staged.indentation_plot(name), in.picture_width_px, in.picture_height_px);
    } catch (const DisplayError& e) {
      spdlog::warn("simulate: {}: no picture ({})", name, e.message());
    }
    const auto& r = sim.result;
    spdlog::info("simulate: {}: converged in {} increments, {:.1f} s; largest displacement {:.3g} mm, von Mises "
                 "{:.3g} Pa; reaction balance {:.2g} %",
                 name, r.increments, r.solver_seconds, r.max_displacement_mm, r.max_von_mises_Pa,
                 100 * r.balance_error);
    if (r.indentation) {
      const auto& ind = *r.indentation;
      spdlog::info("simulate: {}: {:.3g} mm probe pressed to {:.3g} mm ({}): {:.3g} mN; {:.3g} mN/mm at 1 mm",
                   name, ind.probe.diameter_mm, ind.range_depth_mm,
                   ind.range_region.empty() ? "the step's depth" : ind.range_region + " at the top of its range",
                   1e3 * ind.curve.back()[1], 1e3 * ind.stiffness_N_per_mm_at_1mm);
    }
    if (r.pressure_range)
      spdlog::warn("simulate: {}: the pressure of {:.3g} kPa takes {} past its calibrated range from {:.3g} kPa on; "
                   "above that the answer is the fitted solid's extrapolation",
                   name, r.pressure_kPa, r.pressure_range->region, r.pressure_range->in_range_pressure_kPa);
    ++ran;
  }
  if (ran == 0) spdlog::warn("simulate: no organ in this case has a wall and a load step in its solver file");
}

}  // namespace organsmith
