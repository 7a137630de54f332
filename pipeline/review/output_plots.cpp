// Plots drawn from an output directory: the calibrated laws of the organ regions with their
// Monte Carlo band and CDFs, and the results of `organsmith calibrate` and `uncertainty`.

#include "pipeline/review/output_plots.h"

#include "core/csv.h"
#include "core/errors.h"
#include "core/file_io.h"
#include "core/format.h"
#include "physics/materials/presets.h"
#include "physics/materials/uncertainty.h"
#include "pipeline/output/json_file.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/review/output_scene.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

/// A results table another command wrote (fit.csv, cdf.csv); null when absent or malformed
/// (said in the log: a review picture is skipped, not the run).
std::optional<CsvTable> read_csv(const fs::path& p) {
  const std::optional<std::string> text = read_file(p);
  if (!text) return std::nullopt;
  try {
    return parse_csv(*text, p, ExitCode::unsupported_input);
  } catch (const Error& e) {
    spdlog::warn("{}; not drawn", e.what());
    return std::nullopt;
  }
}

/// The number in a row's column, NaN when absent or not a number.
double number(const CsvRow& row, int col) {
  if (col < 0 || std::size_t(col) >= row.fields.size()) return std::nan("");
  return csv_number(row.fields[std::size_t(col)]).value_or(std::nan(""));
}

// Series colours for several curves on one chart (colour-blind friendly order).
const Rgb kSeriesColours[] = {{0.00, 0.45, 0.70}, {0.84, 0.37, 0.00}, {0.00, 0.62, 0.45}, {0.80, 0.47, 0.65},
                              {0.34, 0.71, 0.91}, {0.90, 0.62, 0.00}, {0.35, 0.35, 0.35}};
Rgb series_colour(std::size_t i) { return kSeriesColours[i % std::size(kSeriesColours)]; }

}  // namespace

/// `organsmith calibrate` output (params.json + fit.csv): measured points against the fitted
/// model, one pair of series per specimen and load case.
std::optional<Plot> calibration_fit_plot(const fs::path& dir, const std::string& stem) {
  const nlohmann::json params = read_json_or_null(CalibrateLayout{dir}.params());
  const auto csv = read_csv(CalibrateLayout{dir}.fit());
  if (!params.is_object() || !csv) return std::nullopt;
  const bool cutting = csv->column("displacement_m") >= 0;
  const int cx = csv->column(cutting ? "displacement_m" : "stretch");
  const int cm = csv->column(cutting ? "force_n" : "stress_pa");
  const int cf = csv->column(cutting ? "model_force_n" : "model_stress_pa");
  const int cs = csv->column("specimen"), cl = csv->column("load");
  if (cx < 0 || cm < 0 || cf < 0) {
    spdlog::warn("{}: columns not as `organsmith calibrate` writes them; not drawn", CalibrateLayout{dir}.fit().string());
    return std::nullopt;
  }
  // Measured points by (load, specimen): colour by load case, marker by specimen. The fitted
  // model by load case (one model for every specimen), at the measured abscissae.
  std::vector<std::string> loads, specimens;
  std::map<std::pair<std::string, std::string>, PlotSeries> measured;
  std::map<std::string, std::map<double, std::pair<double, int>>> fitted;  // load → x → (sum, n)
  auto index_of = [](std::vector<std::string>& v, const std::string& k) {
    const auto it = std::find(v.begin(), v.end(), k);
    if (it != v.end()) return std::size_t(it - v.begin());
    v.push_back(k);
    return v.size() - 1;
  };
  for (const auto& row : csv->rows) {
    const std::string spec = cs >= 0 ? row.fields[std::size_t(cs)] : "";
    std::string load = cl >= 0 ? row.fields[std::size_t(cl)] : "";
    if (load.rfind("uniaxial-", 0) == 0) load = load.substr(9);
    const double x0 = number(row, cx), m = number(row, cm), f = number(row, cf);
    if (!std::isfinite(x0) || !std::isfinite(m) || !std::isfinite(f)) continue;
    // Cutting: displacement in mm and force in N read better; stress in kPa.
    const double x = cutting ? x0 * 1e3 : x0, scale = cutting ? 1.0 : 1e-3;
    const std::size_t li = index_of(loads, load), si = index_of(specimens, spec);
    PlotSeries& ms = measured[{load, spec}];
    if (ms.x.empty()) {
      ms.name = (load.empty() ? std::string("measured") : load) + (spec.empty() ? "" : " (" + spec + ")");
      ms.points = true;
      ms.colour = series_colour(li);
      ms.marker = int(si % 5);
    }
    ms.x.push_back(x), ms.y.push_back(m * scale);
    auto& acc = fitted[load][x];
    acc.first += f * scale, acc.second += 1;
  }
  if (measured.empty()) return std::nullopt;
  Plot p;
  p.name = "fit_" + stem;
  const std::string model = params.value("model", std::string("model"));
  p.title = "Calibration: measured vs fitted " + model;
  p.x_label = cutting ? "blade displacement (mm)" : "stretch";
  p.y_label = cutting ? "force (N)" : "nominal stress (kPa)";
  std::string note = fs::path(params.value("data", std::string("?"))).filename().string() + "  |  " +
                     std::to_string(params.value("points", 0)) + " points";
  if (params.contains("r2") && params["r2"].is_number()) note += "  |  R² " + format_fixed(params["r2"].get<double>(), 4);
  if (params.contains("rmse") && params["rmse"].is_number())
    note += ", RMSE " + format_g(params["rmse"].get<double>(), 4) + (cutting ? " N" : " Pa");
  p.note = note + "  |  " + dir.filename().string();
  std::size_t shown = 0;
  for (const auto& load : loads) {
    for (const auto& spec : specimens)
      if (auto it = measured.find({load, spec}); it != measured.end() && shown < 12) {
        p.series.push_back(std::move(it->second));
        ++shown;
      }
    PlotSeries line;
    line.name = (load.empty() ? std::string("") : load + " ") + "fitted";
    line.colour = series_colour(std::size_t(std::find(loads.begin(), loads.end(), load) - loads.begin()));
    for (const auto& [x, acc] : fitted[load]) line.x.push_back(x), line.y.push_back(acc.first / acc.second);
    p.series.push_back(std::move(line));
  }
  if (measured.size() > 12) p.note += "  |  first 12 of " + std::to_string(measured.size()) + " measured curves";
  return p;
}

/// `organsmith uncertainty --method mc` output (cdf.csv + summary.json): the stress CDF at each
/// stretch.
std::optional<Plot> monte_carlo_plot(const fs::path& dir, const std::string& stem) {
  const nlohmann::json summary = read_json_or_null(UncertaintyLayout{dir}.mc_summary());
  const auto csv = read_csv(UncertaintyLayout{dir}.mc_cdf());
  if (!summary.is_object() || !csv) return std::nullopt;
  const int cs = csv->column("stretch"), cp = csv->column("probability"), cx = csv->column("stress_pa");
  if (cs < 0 || cp < 0 || cx < 0) return std::nullopt;
  std::vector<double> order;
  std::map<double, PlotSeries> by_stretch;
  for (const auto& row : csv->rows) {
    const double s = number(row, cs), p = number(row, cp), x = number(row, cx);
    if (!std::isfinite(s) || !std::isfinite(p) || !std::isfinite(x)) continue;
    if (!by_stretch.count(s)) order.push_back(s);
    by_stretch[s].x.push_back(x / 1e3);
    by_stretch[s].y.push_back(p);
  }
  if (order.empty()) return std::nullopt;
  Plot p;
  p.name = "cdf_" + stem;
  p.title = "Monte Carlo CDFs of the stress at each stretch";
  p.x_label = "nominal stress (kPa)";
  p.y_label = "probability";
  p.note = summary.value("preset", std::string("?")) + "  |  " + std::to_string(summary.value("samples", 0)) +
           " draws, spread " + summary.value("spread", std::string("?")) + "  |  " + dir.filename().string();
  // Stresses spanning more than ~1.5 decades: a logarithmic axis, else the low curves are lost.
  double lo = 1e300, hi = 0;
  for (const auto& [_, ser] : by_stretch)
    for (const double v : ser.x)
      if (v > 0) lo = std::min(lo, v), hi = std::max(hi, v);
  if (hi > 30 * lo) {
    p.log_x = true;
    p.x_label = "nominal stress (Pa, logarithmic)";
    for (auto& [_, ser] : by_stretch)
      for (double& v : ser.x) v *= 1e3;
  }
  for (std::size_t i = 0; i < order.size(); ++i) {
    PlotSeries s = std::move(by_stretch[order[i]]);
    s.name = "stretch " + format_g(order[i], 3);
    s.colour = series_colour(i);
    p.series.push_back(std::move(s));
  }
  return p;
}

/// The laws of the organ regions in materials.json (the attach stage), uniaxial, with the
/// 5–95 % band of a Monte Carlo over the preset's standard deviations where the thesis gives
/// them; and the CDFs of that Monte Carlo at a few stretches.
std::vector<Plot> material_plots(const MaterialsFile& materials, const OrganRegistry& registry) {
  std::vector<Plot> plots;
  if (materials.regions.empty() && materials.malformed.empty()) return plots;
  const physics::MaterialLibrary lib = physics::builtin_material_library();
  Plot laws;
  laws.name = "materials";
  laws.title = "Calibrated tissue laws of the organ regions";
  laws.x_label = "stretch (uniaxial)";
  laws.y_label = "nominal stress (Pa, logarithmic)";
  laws.log_y = true;
  laws.note = "materials.json (attach stage); dashed: 5 % and 95 % of 2000 Monte Carlo draws over the thesis' sd";
  Plot cdf;
  constexpr double kMaxStretch = 1.6;  // the calibrated range (physics/haptics/HAPTICS.md: ε ≤ 0.6)
  std::vector<physics::LoadPoint> pts;
  // Stretch 1.01, 1.02, …, 1.60; the unloaded state (zero stress) has no place on the chart's
  // logarithmic axis.
  for (int i = 1; i <= 60; ++i)
    pts.push_back({1.0 + (kMaxStretch - 1.0) * i / 60.0, 1.0, physics::LoadCase::uniaxial_circumferential});
  auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  // Regions with identical laws share one curve.
  std::vector<std::pair<std::vector<std::string>, OutputRegionLaw>> distinct;
  for (const auto& [region, why] : materials.malformed)
    spdlog::warn("{}: region {} of materials.json is malformed: {}", materials.source.string(), region, why);
  for (const auto& [region, law] : materials.regions) {
    bool merged = false;
    for (auto& [names, l] : distinct)
      if (l.material.model == law.material.model && l.material.parameters.size() == law.material.parameters.size() &&
          std::equal(l.material.parameters.begin(), l.material.parameters.end(), law.material.parameters.begin(),
                     [](const auto& a, const auto& b) { return a.name == b.name && a.value == b.value; })) {
        names.push_back(region);
        merged = true;
      }
    if (!merged) distinct.push_back({{region}, law});
  }
  std::size_t colour = 0;
  for (const auto& [names, law] : distinct) {
    std::unique_ptr<physics::Model> model;
    std::vector<double> mean;
    try {
      model = physics::make_model(law.material.model, law.options);
      mean = physics::parameter_values(*model, law.material.parameters);
    } catch (const Error& e) {
      spdlog::warn("materials plot: {}: {}", names.front(), e.what());
      continue;
    }
    if (model->name() == "kelvin-cutting") continue;  // not a stress–stretch law
    std::vector<double> stress(pts.size());
    model->respond(pts, mean, stress);
    std::string label;
    for (const auto& n : names) label += (label.empty() ? "" : " = ") + n;
    PlotSeries line;
    line.name = label + " (" + std::string(model->name()) + ")";
    line.colour = series_colour(colour++);
    for (std::size_t i = 0; i < pts.size(); ++i)
      if (positive(stress[i])) line.x.push_back(pts[i].x), line.y.push_back(stress[i]);
    if (line.x.empty()) continue;
    laws.series.push_back(line);
    // The band, where the preset carries standard deviations.
    const physics::MaterialPreset* preset = nullptr;
    for (const auto& m : lib.materials)
      if (m.id == law.preset_id) preset = &m;
    if (!preset) continue;
    const char* spread_kind = preset->spreads.count("sd") ? "sd" : preset->spreads.count("dc_sd") ? "dc_sd" : nullptr;
    if (!spread_kind) continue;
    std::vector<double> sd;
    try {
      sd = physics::parameter_values(*model, preset->spreads.at(spread_kind));
    } catch (const Error&) {
      continue;
    }
    physics::MonteCarloOptions mo;
    mo.samples = 2000;
    mo.seed = 1;
    const physics::MonteCarloResult mc = physics::monte_carlo(*model, pts, mean, sd, mo);
    if (mc.stress_Pa.rows() < 10) continue;
    PlotSeries lo, hi;
    lo.name = label + ": 5-95 % band", hi.name = label + " 95 %";
    hi.in_legend = false;
    lo.colour = hi.colour = line.colour;
    lo.dashed = hi.dashed = true;
    const double levels[2] = {0.05, 0.95};
    for (std::size_t k = 0; k < pts.size(); ++k) {
      const auto q = physics::stress_quantiles(mc, int(k), levels);
      if (positive(q[0])) lo.x.push_back(pts[k].x), lo.y.push_back(q[0]);
      if (positive(q[1])) hi.x.push_back(pts[k].x), hi.y.push_back(q[1]);
    }
    laws.series.push_back(lo);
    laws.series.push_back(hi);
    if (cdf.series.empty()) {
      cdf.name = "mc_" + names.front();
      cdf.title = "Monte Carlo CDFs of the " + names.front() + " stress";
      cdf.x_label = "nominal stress (Pa, logarithmic)";
      cdf.y_label = "probability";
      cdf.log_x = true;
      cdf.note = law.preset_id + ", " + std::to_string(mc.stress_Pa.rows()) + " valid draws of mean ± " + spread_kind +
                 " (independent normal parameters, seed 1)";
      std::vector<double> levels_all;
      for (int i = 0; i <= 100; ++i) levels_all.push_back(i / 100.0);
      std::size_t c = 0;
      for (const double s : {1.1, 1.2, 1.3, 1.4, 1.5}) {
        const int k = int(std::lround((s - 1.0) / (kMaxStretch - 1.0) * 60.0)) - 1;
        const auto q = physics::stress_quantiles(mc, k, levels_all);
        PlotSeries ser;
        ser.name = "stretch " + format_fixed(pts[k].x, 2);
        ser.colour = series_colour(c++);
        ser.x.resize(q.size());
        std::copy(q.begin(), q.end(), ser.x.begin());
        ser.y = levels_all;
        cdf.series.push_back(std::move(ser));
      }
    }
  }
  if (!laws.series.empty()) plots.push_back(std::move(laws));
  if (!cdf.series.empty()) plots.push_back(std::move(cdf));
  return plots;
}

}  // namespace organsmith
