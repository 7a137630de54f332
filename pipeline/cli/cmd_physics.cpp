// Over 400 lines: three commands (materials, calibrate, uncertainty) that share their model and
// fit flags.
// Physics subcommands: `calibrate` (GA + Levenberg–Marquardt fit of a constitutive model to a CSV
// of measurements), `uncertainty` (DC / IMVFOSM / Monte Carlo, thesis §4.1) and `materials` (the
// thesis parameter sets embedded from data/materials.toml).

#include "core/csv.h"
#include "core/file_io.h"
#include "pipeline/output/tool_info.h"
#include "core/errors.h"
#include "core/format.h"
#include "physics/materials/calibration.h"
#include "physics/materials/presets.h"
#include "physics/materials/uncertainty.h"
#include "pipeline/cli/commands.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/run/terminal_progress.h"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;
using namespace organsmith::physics;

namespace {

std::string num(double v) { return format_g(v, 10); }

std::string load_name(LoadCase l) {
  switch (l) {
    case LoadCase::uniaxial_circumferential: return "uniaxial-circumferential";
    case LoadCase::uniaxial_longitudinal: return "uniaxial-longitudinal";
    case LoadCase::biaxial_circumferential: return "biaxial-circumferential";
    case LoadCase::biaxial_longitudinal: return "biaxial-longitudinal";
    case LoadCase::displacement: return "cutting";
  }
  return "?";
}

/// Writes `files` (name, text) as one stage of the command's output directory: all or none.
void commit_files(OutputDir& dir, const std::string& stage,
                  const std::vector<std::pair<std::string, std::string>>& files) {
  dir.commit(stage, [&](const fs::path& staging) {
    for (const auto& [name, text] : files) write_file_atomic(staging / name, text);
  });
}

/// Options shared by the commands that build a model.
struct ModelFlags {
  std::string model;
  ModelOptions options;
  void add_to(CLI::App* app, bool required) {
    auto* o = app->add_option("--model", model,
                              "constitutive model: fung-wall, fung-organ, artery-logpoly, mooney-rivlin, ogden, "
                              "kelvin-cutting");
    if (required) o->required();
    app->add_option("--ogden-terms", options.ogden_terms, "number of Ogden terms N (default 2)")->check(CLI::Range(1, 6));
    app->add_option("--bulk-modulus-pa", options.bulk_modulus_Pa,
                    "fung-organ bulk modulus K in Pa (default 39000, thesis §5.1.5)")
        ->check(CLI::PositiveNumber);
    app->add_option("--blade-speed-m-per-s", options.blade_speed_m_per_s,
                    "kelvin-cutting blade speed v in m/s (default 0.000193, thesis §4.2.5)")
        ->check(CLI::PositiveNumber);
  }
};

/// GA / fit options shared by calibrate and uncertainty --method dc.
struct FitFlags {
  FitOptions fit;
  std::vector<double> lower, upper;
  std::string residuals = "absolute";
  bool no_polish = false;
  void add_to(CLI::App* app) {
    app->add_option("--seed", fit.ga.seed, "random seed of the genetic algorithm (default 1)");
    app->add_option("--population", fit.ga.population, "GA population size (default 200)")->check(CLI::Range(4, 100000));
    app->add_option("--generations", fit.ga.generations, "GA generations (default 200)")->check(CLI::Range(1, 100000));
    app->add_option("--selection", fit.ga.selection_fraction,
                    "fraction of each generation kept unchanged (default 0.1)")->check(CLI::Range(0.0, 0.99));
    app->add_option("--crossover", fit.ga.crossover_fraction,
                    "fraction of new individuals made by crossover, the rest by mutation (default 0.7)")
        ->check(CLI::Range(0.0, 1.0));
    app->add_option("--lower", lower, "lower bounds, one per parameter in the model's order, comma-separated "
                                      "(default: the model's search box; see `organsmith materials`)")
        ->delimiter(',');
    app->add_option("--upper", upper, "upper bounds, as --lower")->delimiter(',');
    app->add_option("--residuals", residuals,
                    "absolute: minimise Σ(model − measured)² as the thesis (default); relative: minimise "
                    "squared relative residuals (better when the error is proportional to the stress)")
        ->check(CLI::IsMember({"absolute", "relative"}));
    app->add_flag("--no-polish", no_polish, "skip the Levenberg–Marquardt polish after the GA");
  }
  FitOptions options() const {
    FitOptions o = fit;
    o.lower = lower;
    o.upper = upper;
    o.polish = !no_polish;
    return o;
  }
};

nlohmann::json fit_json(const Model& m, const FitResult& r) {
  nlohmann::json params = nlohmann::json::array();
  for (std::size_t j = 0; j < m.parameter_count(); ++j) {
    const auto& info = m.parameters()[j];
    const double se = r.standard_errors.empty() ? 0.0 : r.standard_errors[j];
    params.push_back({{"name", info.name},
                      {"value", r.parameters[j]},
                      {"unit", info.unit},
                      {"lower", r.lower[j]},
                      {"upper", r.upper[j]},
                      // null when the data cannot determine the parameter (singular Jacobian)
                      {"standard_error", std::isfinite(se) ? nlohmann::json(se) : nlohmann::json(nullptr)}});
  }
  return {{"parameters", params},
          {"sse", r.stats.sse},
          {"r2", r.stats.r2},
          {"rmse", r.stats.rmse},
          // the GA's best objective before the polish, in the fit's residual weighting
          {"ga_best_objective", r.ga_sse},
          {"lm_iterations", r.lm_iterations},
          {"seconds", r.seconds},
          {"seed", r.seed}};
}

std::string fit_csv(const CalibrationData& d, const FitResult& r, bool cutting) {
  std::ostringstream s;
  s << (cutting ? "specimen,load,displacement_m,force_n,model_force_n,residual_n\n"
                : "specimen,load,stretch,lateral_stretch,stress_pa,model_stress_pa,residual_pa\n");
  for (std::size_t i = 0; i < d.points.size(); ++i) {
    const auto& p = d.points[i];
    s << csv_field(d.specimen[i]) << ',' << load_name(p.load) << ',' << num(p.x) << ',';
    if (!cutting) s << num(p.lateral_stretch) << ',';
    s << num(d.measured[i]) << ',' << num(r.predicted[i]) << ',' << num(r.predicted[i] - d.measured[i]) << '\n';
  }
  return s.str();
}

// ---- materials ---------------------------------------------------------------------------------

/// `materials --curve REF`: the law as [[stretch, Pa], …] over its calibrated range and its solver fit.
int run_material_curve(const std::string& ref) {
  const std::string r = is_calibration_ref(ref) ? fs::absolute(ref).string() : ref;
  const physics::RegionLaw law = region_law(r);
  nlohmann::json j = {{is_calibration_ref(r) ? "calibration" : "preset", r},
                      {"model", law.material.model},
                      {"stretch_range", {1.0, law.stretch_max}},
                      {"range_source", law.range_source},
                      {"uniaxial_curve_pa", uniaxial_curve_json(r)},
                      {"solver", solver_material_json(r)}};
  std::cout << j.dump(2) << "\n";
  return 0;
}

int run_materials(bool as_json, const std::string& model_filter) {
  const MaterialLibrary lib = builtin_material_library();
  if (as_json) {
    nlohmann::json regions = nlohmann::json::object();
    for (const auto& o : builtin_organ_registry().organs)
      for (const auto& [region, id] : o.materials) regions[region] = id;
    nlohmann::json j = {{"materials", nlohmann::json::array()}, {"regions", regions}};
    for (const auto& p : lib.materials) {
      if (!model_filter.empty() && p.material.model != model_filter) continue;
      nlohmann::json params = nlohmann::json::array();
      for (const auto& q : p.material.parameters) params.push_back({{"name", q.name}, {"value", q.value}, {"unit", q.unit}});
      nlohmann::json e = {{"id", p.id}, {"model", p.material.model}, {"source", p.material.source}, {"parameters", params}};
      for (const auto& [kind, s] : p.spreads) {
        nlohmann::json sj = nlohmann::json::object();
        for (const auto& q : s) sj[q.name] = q.value;
        e[kind] = sj;
      }
      if (!p.constants.empty()) e["constants"] = p.constants;
      j["materials"].push_back(e);
    }
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  for (const auto& p : lib.materials) {
    if (!model_filter.empty() && p.material.model != model_filter) continue;
    std::cout << p.id << "  [" << p.material.model << "]\n    ";
    for (const auto& q : p.material.parameters) std::cout << q.name << " = " << num(q.value) << " " << q.unit << "   ";
    std::cout << "\n";
    for (const auto& [kind, s] : p.spreads) {
      std::cout << "    " << kind << ": ";
      for (const auto& q : s) std::cout << q.name << " " << num(q.value) << "  ";
      std::cout << "\n";
    }
    for (const auto& [k, v] : p.constants) std::cout << "    " << k << " = " << num(v) << "\n";
    std::cout << "    source: " << p.material.source << "\n";
  }
  std::cout << "\nRegions (organ registry, data/organs.toml):\n";
  for (const auto& o : builtin_organ_registry().organs)
    for (const auto& [region, id] : o.materials) std::cout << "  " << region << " -> " << id << "\n";
  std::cout << "\nDefault search boxes (calibrate --lower/--upper override):\n";
  for (const auto& name : model_names()) {
    const auto m = make_model(name);
    std::cout << "  " << name << ":";
    for (const auto& info : m->parameters())
      std::cout << " " << info.name << " [" << num(info.lower) << ", " << num(info.upper) << "] " << info.unit << ";";
    std::cout << "\n";
  }
  return 0;
}

// ---- calibrate ---------------------------------------------------------------------------------

int run_calibrate(const ModelFlags& mf, const FitFlags& ff, const fs::path& data_path, const fs::path& out_arg) {
  OutputDir dir(out_arg, OutputDirOptions{.inputs = {data_path}, .command = "calibrate"});
  const fs::path out = dir.path();
  const auto model = make_model(mf.model, mf.options);
  const bool cutting = mf.model == "kelvin-cutting";
  FitOptions o = ff.options();
  resolve_bounds(*model, o.lower, o.upper);  // reject bad bounds before reading anything
  CalibrationData data = read_calibration_csv(data_path, cutting, model->parameter_count() + 1);
  if (ff.residuals == "relative") use_relative_residuals(data);
  TerminalProgress progress;
  const FitResult r = calibrate(*model, data, o, &progress);
  progress.finish();
  nlohmann::json j = fit_json(*model, r);
  j["model"] = model->name();
  j["data"] = fs::absolute(data_path).string();
  j["points"] = data.points.size();
  j["residuals"] = ff.residuals;
  j["ga"] = {{"population", o.ga.population},
             {"generations", o.ga.generations},
             {"selection_fraction", o.ga.selection_fraction},
             {"crossover_fraction", o.ga.crossover_fraction},
             {"mutation_scale", o.ga.mutation_scale},
             {"polish", o.polish}};
  if (mf.model == "fung-organ") j["bulk_modulus_Pa"] = mf.options.bulk_modulus_Pa;
  if (!cutting) {
    // The calibrated range: a solver form of this law is fitted over it (physics/materials/solver_fit.h).
    double lo = 1e300, hi = -1e300;
    for (const auto& p : data.points) lo = std::min(lo, p.x), hi = std::max(hi, p.x);
    j["stretch_range"] = {lo, hi};
  }
  if (cutting) j["blade_speed_m_per_s"] = mf.options.blade_speed_m_per_s;
  if (mf.model == "ogden") j["ogden_terms"] = mf.options.ogden_terms;
  j["tool_version"] = tool_version();
  commit_files(dir, "calibrate", {{CalibrateLayout::fit_name, fit_csv(data, r, cutting)}, {CalibrateLayout::params_name, j.dump(2) + "\n"}});
  std::cout << model->name() << " fitted to " << data.points.size() << " points in " << num(r.seconds) << " s\n";
  for (std::size_t k = 0; k < model->parameter_count(); ++k)
    std::cout << "  " << model->parameters()[k].name << " = " << num(r.parameters[k]) << " "
              << model->parameters()[k].unit << "\n";
  std::cout << "  SSE " << num(r.stats.sse) << ", R² " << num(r.stats.r2) << ", RMSE " << num(r.stats.rmse) << "\n"
            << "wrote " << CalibrateLayout{out}.params().string() << " and " << CalibrateLayout{out}.fit().string() << "\n";
  return 0;
}

// ---- uncertainty -------------------------------------------------------------------------------

struct UncertaintyFlags {
  std::string method = "mc";
  std::string preset = "artery-logpoly/table-4.1.4/circumferential";
  std::string spread = "imvfosm_sd";
  std::string table = "table-4.1.2";
  std::string derivatives = "model";
  std::string direction = "circumferential";
  std::vector<double> stretches;
  int samples = 10000;
  std::uint64_t seed = 1;
  std::string data;
  std::string out;
};

LoadCase direction_load(const std::string& d) {
  return d == "longitudinal" ? LoadCase::uniaxial_longitudinal : LoadCase::uniaxial_circumferential;
}

int run_uncertainty(const UncertaintyFlags& u, const ModelFlags& mf, const FitFlags& ff) {
  OutputDir dir(u.out, OutputDirOptions{.inputs = {u.data}, .command = "uncertainty"});
  const fs::path out = dir.path();
  const std::string stage = "uncertainty-" + u.method;  // the methods' outputs live side by side
  const MaterialLibrary lib = builtin_material_library();
  if (u.method == "dc") {
    if (mf.model.empty() || u.data.empty())
      throw UsageError("--method dc needs --model and --data (a CSV with a 'specimen' column)");
    const auto model = make_model(mf.model, mf.options);
    const bool cutting = mf.model == "kelvin-cutting";
    FitOptions o = ff.options();
    resolve_bounds(*model, o.lower, o.upper);
    CalibrationData data = read_calibration_csv(u.data, cutting, model->parameter_count() + 1);
    if (ff.residuals == "relative") use_relative_residuals(data);
    const DirectCalculation dc = direct_calculation(*model, data, o);
    nlohmann::json j = {{"method", "dc"}, {"model", model->name()}, {"data", fs::absolute(u.data).string()}};
    std::ostringstream csv;
    csv << "specimen";
    for (const auto& info : model->parameters()) csv << ',' << info.name;
    csv << ",sse,r2,rmse\n";
    for (std::size_t s = 0; s < dc.fits.size(); ++s) {
      nlohmann::json f = fit_json(*model, dc.fits[s]);
      f["specimen"] = dc.specimens[s];
      j["specimens"].push_back(f);
      csv << dc.specimens[s];
      for (double v : dc.fits[s].parameters) csv << ',' << num(v);
      csv << ',' << num(dc.fits[s].stats.sse) << ',' << num(dc.fits[s].stats.r2) << ',' << num(dc.fits[s].stats.rmse) << '\n';
    }
    for (std::size_t k = 0; k < model->parameter_count(); ++k)
      j["summary"].push_back({{"name", model->parameters()[k].name}, {"unit", model->parameters()[k].unit},
                              {"mean", dc.mean[k]}, {"sd", dc.sd[k]}});
    commit_files(dir, stage, {{UncertaintyLayout::csv_name("dc"), csv.str()}, {UncertaintyLayout::json_name("dc"), j.dump(2) + "\n"}});
    std::cout << "DC over " << dc.fits.size() << " specimens:\n";
    for (std::size_t k = 0; k < model->parameter_count(); ++k)
      std::cout << "  " << model->parameters()[k].name << " mean " << num(dc.mean[k]) << " sd " << num(dc.sd[k]) << " "
                << model->parameters()[k].unit << "\n";
    std::cout << "wrote " << UncertaintyLayout{out}.json("dc").string() << " and " << UncertaintyLayout{out}.csv("dc").string() << "\n";
    return 0;
  }

  const MaterialPreset& preset = lib.find(u.preset);
  const auto model = make_model(preset.material.model, model_options_for(preset, mf.options));
  const auto mean = parameter_values(*model, preset.material.parameters);

  if (u.method == "imvfosm") {
    const DerivativeTable& t = lib.table(u.table);
    if (model->name() != "artery-logpoly" && u.derivatives == "printed")
      throw UsageError("--derivatives printed uses Tables 4.1.2/4.1.3, which belong to artery-logpoly");
    Eigen::MatrixXd D = t.dfdC;
    if (u.derivatives == "model") {
      std::vector<LoadPoint> pts;
      for (double s : t.stretch) pts.push_back({s, 1.0, direction_load(u.direction)});
      const std::size_t n = model->parameter_count();
      std::vector<double> f(pts.size()), jac(pts.size() * n);
      model->respond(pts, mean, f, jac);
      D.resize(static_cast<Eigen::Index>(pts.size()), static_cast<Eigen::Index>(n));
      for (std::size_t i = 0; i < pts.size(); ++i)
        for (std::size_t k = 0; k < n; ++k) D(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k)) = jac[i * n + k];
      if (!D.allFinite())
        throw CalibrationDataError("the model is undefined at the table's stretches for preset " + preset.id,
                                   {}, "use --derivatives printed, or a preset inside the model's domain");
    }
    const ImvfosmResult r = imvfosm_solve(D, t.sigma_T_Pa);
    nlohmann::json j = {{"method", "imvfosm"}, {"preset", preset.id}, {"table", t.id}, {"derivatives", u.derivatives},
                        {"rms_relative_error", r.rms_relative_error}};
    for (std::size_t k = 0; k < r.sigma.size(); ++k)
      j["sigma"].push_back({{"name", model->parameters()[k].name}, {"unit", model->parameters()[k].unit}, {"sd", r.sigma[k]}});
    std::ostringstream csv;
    csv << "stretch,sigma_T_pa,predicted_sigma_T_pa\n";
    for (std::size_t k = 0; k < t.stretch.size(); ++k)
      csv << num(t.stretch[k]) << ',' << num(t.sigma_T_Pa[k]) << ',' << num(r.predicted_sd_Pa[k]) << '\n';
    commit_files(dir, stage, {{UncertaintyLayout::csv_name("imvfosm"), csv.str()}, {UncertaintyLayout::json_name("imvfosm"), j.dump(2) + "\n"}});
    std::cout << "IMVFOSM (" << u.derivatives << " derivatives, " << t.id << "): RMS relative σ_T error "
              << num(100 * r.rms_relative_error) << " %\n";
    for (std::size_t k = 0; k < r.sigma.size(); ++k)
      std::cout << "  σ_" << model->parameters()[k].name << " = " << num(r.sigma[k]) << " " << model->parameters()[k].unit << "\n";
    std::cout << "wrote " << UncertaintyLayout{out}.json("imvfosm").string() << " and " << UncertaintyLayout{out}.csv("imvfosm").string() << "\n";
    return 0;
  }

  // Monte Carlo
  auto it = preset.spreads.find(u.spread);
  if (it == preset.spreads.end())
    throw UsageError("preset " + preset.id + " has no spread '" + u.spread + "'",
                     "see `organsmith materials` for the spreads each preset carries");
  const auto sd = parameter_values(*model, it->second);
  std::vector<double> stretches = u.stretches;
  if (stretches.empty()) stretches = lib.table("table-4.1.2").stretch;
  std::vector<LoadPoint> pts;
  for (double s : stretches) {
    if (!(s > 0)) throw UsageError("stretches must be positive");
    pts.push_back({s, 1.0, direction_load(u.direction)});
  }
  MonteCarloOptions mo;
  mo.samples = u.samples;
  mo.seed = u.seed;
  const MonteCarloResult mc = monte_carlo(*model, pts, mean, sd, mo);
  const StressMoments lin = linearised_moments(*model, pts, mean, sd);
  const StressMoments second = second_order_moments(*model, pts, mean, sd);
  std::vector<double> levels;
  for (int i = 0; i <= 100; ++i) levels.push_back(i / 100.0);
  std::ostringstream csv;
  csv << "stretch,probability,stress_pa\n";
  nlohmann::json j = {{"method", "monte-carlo"}, {"preset", preset.id}, {"spread", u.spread},
                      {"samples", u.samples}, {"seed", u.seed}, {"invalid_draws", mc.invalid_draws}};
  for (std::size_t k = 0; k < pts.size(); ++k) {
    if (mc.stress_Pa.rows() > 0) {
      const auto q = stress_quantiles(mc, static_cast<int>(k), levels);
      for (std::size_t l = 0; l < levels.size(); ++l)
        csv << num(stretches[k]) << ',' << num(levels[l]) << ',' << num(q[l]) << '\n';
    }
    j["stretches"].push_back({{"stretch", stretches[k]},
                              {"linearised_mean_pa", lin.mean_Pa[k]}, {"linearised_sd_pa", lin.sd_Pa[k]},
                              {"second_order_mean_pa", second.mean_Pa[k]}, {"second_order_sd_pa", second.sd_Pa[k]},
                              {"mc_mean_pa", mc.moments.mean_Pa[k]}, {"mc_sd_pa", mc.moments.sd_Pa[k]},
                              {"mc_median_pa", mc.median_Pa[k]}, {"mc_robust_sd_pa", mc.robust_sd_Pa[k]}});
  }
  commit_files(dir, stage, {{UncertaintyLayout::mc_cdf_name, csv.str()}, {UncertaintyLayout::mc_summary_name, j.dump(2) + "\n"}});
  std::cout << "Monte Carlo, " << u.samples << " draws of " << preset.id << " (" << u.spread << "); "
            << mc.invalid_draws << " draws outside the model's domain were left out\n"
            << "  stretch  linearised mean ± sd   MC mean ± sd   MC median ± robust sd  (Pa)\n";
  for (std::size_t k = 0; k < pts.size(); ++k)
    std::cout << "  " << num(stretches[k]) << "  " << num(lin.mean_Pa[k]) << " ± " << num(lin.sd_Pa[k]) << "   "
              << num(mc.moments.mean_Pa[k]) << " ± " << num(mc.moments.sd_Pa[k]) << "   " << num(mc.median_Pa[k])
              << " ± " << num(mc.robust_sd_Pa[k]) << "\n";
  std::cout << "wrote " << UncertaintyLayout{out}.mc_cdf().string() << " and " << UncertaintyLayout{out}.mc_summary().string() << "\n";
  return 0;
}

}  // namespace

std::vector<Command> physics_commands(CLI::App& app) {
  std::vector<Command> commands;

  // materials
  auto materials_json = std::make_shared<bool>(false);
  auto materials_model = std::make_shared<std::string>();
  auto* materials = app.add_subcommand("materials", "List the thesis material parameter sets (with units, spreads and\n"
                                                    "source tables), the organ-region assignment and the models' search boxes.");
  materials->add_flag("--json", *materials_json, "print JSON instead of text");
  materials->add_option("--model", *materials_model, "only presets of this model");
  auto materials_curve = std::make_shared<std::string>();
  materials->add_option("--curve", *materials_curve,
                        "print the law of this preset id (or calibrate params.json) as a uniaxial nominal-stress curve "
                        "over its calibrated range, with its solver fit, as JSON");
  commands.push_back({materials, [=] {
                        if (!materials_curve->empty()) return run_material_curve(*materials_curve);
                        return run_materials(*materials_json, *materials_model);
                      }});

  // calibrate
  auto cal_model = std::make_shared<ModelFlags>();
  auto cal_fit = std::make_shared<FitFlags>();
  auto cal_data = std::make_shared<std::string>();
  auto cal_out = std::make_shared<std::string>();
  auto* calibrate_cmd = app.add_subcommand(
      "calibrate",
      "Fit a constitutive model to measured curves with the genetic algorithm of the thesis (§4.1.2.2,\n"
      "§5.1.3) and a Levenberg–Marquardt polish. Writes DIR/params.json (values with units, bounds,\n"
      "standard errors, SSE, R², RMSE, seconds, seed) and DIR/fit.csv (measured vs model).\n"
      "CSV columns: stretch (or strain), stress_pa [, direction, specimen, lateral_stretch];\n"
      "kelvin-cutting: displacement_m, force_n [, specimen].");
  cal_model->add_to(calibrate_cmd, true);
  calibrate_cmd->add_option("--data", *cal_data, "measurements (CSV, header row; stress in Pa, displacement in m, force in N)")
      ->required();
  calibrate_cmd->add_option("--out", *cal_out, "output directory: new, empty, or one organsmith wrote before (other files are never touched)")->required();
  cal_fit->add_to(calibrate_cmd);
  commands.push_back({calibrate_cmd, [=] { return run_calibrate(*cal_model, *cal_fit, *cal_data, *cal_out); }});

  // uncertainty
  auto un = std::make_shared<UncertaintyFlags>();
  auto un_model = std::make_shared<ModelFlags>();
  auto un_fit = std::make_shared<FitFlags>();
  auto* uncertainty = app.add_subcommand(
      "uncertainty",
      "Parameter uncertainty (thesis §4.1.2.3–4.1.3):\n"
      "  --method mc       sample a preset's means and standard deviations, write stress CDFs at the given\n"
      "                    stretches (DIR/cdf.csv) and MC vs linearised moments (DIR/summary.json);\n"
      "  --method imvfosm  solve Σ(∂f/∂Ci σ_Ci)² = σ_T² for σ_C ≥ 0 at a table's strain stages;\n"
      "  --method dc       fit every specimen of --data and report the spread of the parameters.");
  uncertainty->add_option("--method", un->method, "mc (default), imvfosm or dc")->check(CLI::IsMember({"mc", "imvfosm", "dc"}));
  uncertainty->add_option("--preset", un->preset,
                          "parameter set for mc/imvfosm (default artery-logpoly/table-4.1.4/circumferential)");
  uncertainty->add_option("--spread", un->spread, "mc: which standard deviations of the preset: imvfosm_sd (default), dc_sd, sd");
  uncertainty->add_option("--table", un->table, "imvfosm: strain stages and σ_T from table-4.1.2 (default) or table-4.1.3");
  uncertainty->add_option("--derivatives", un->derivatives,
                          "imvfosm: ∂f/∂Ci from the model at the preset's means (model, default) or as printed (printed)")
      ->check(CLI::IsMember({"model", "printed"}));
  uncertainty->add_option("--direction", un->direction, "loading direction: circumferential (default) or longitudinal")
      ->check(CLI::IsMember({"circumferential", "longitudinal"}));
  uncertainty->add_option("--stretches", un->stretches, "mc: stretches (comma-separated; default 1.25,1.30,…,1.55)")->delimiter(',');
  uncertainty->add_option("--samples", un->samples, "mc: number of draws (default 10000)")->check(CLI::Range(2, 100000000));
  uncertainty->add_option("--mc-seed", un->seed, "mc: random seed (default 1)");
  uncertainty->add_option("--data", un->data, "dc: measurements with a 'specimen' column");
  uncertainty->add_option("--out", un->out, "output directory: new, empty, or one organsmith wrote before (other files are never touched)")->required();
  un_model->add_to(uncertainty, false);
  un_fit->add_to(uncertainty);
  commands.push_back({uncertainty, [=] { return run_uncertainty(*un, *un_model, *un_fit); }});
  return commands;
}

}  // namespace organsmith
