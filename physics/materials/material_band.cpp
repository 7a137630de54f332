// Material bands (see material_band.h for the method and why).

#include "physics/materials/material_band.h"

#include "core/errors.h"
#include "core/format.h"
#include "physics/materials/uncertainty.h"

#include <cmath>

namespace organsmith::physics {

std::string band_member_name(double level) {
  const long pct = std::lround(level * 100);
  return std::string("p") + (pct < 10 ? "0" : "") + std::to_string(pct);
}

MaterialBand material_band(const RegionLaw& law, const MaterialBandOptions& o) {
  if (law.sd.empty())
    throw InputError(ExitCode::calibration_data,
                     "material '" + law.id + "' carries no parameter spread, so it has no material band", {},
                     "use a preset with standard deviations (e.g. fung-wall/table-5.1.1/mean) or a `calibrate` result "
                     "(its standard errors)");
  const std::vector<LawCurve> curves = law_curves(law, o.fit.samples);
  const auto model = make_model(law.material.model, law.options);
  const std::vector<double> mean = parameter_values(*model, law.material.parameters);
  const std::vector<double> sd = parameter_values(*model, law.sd);

  // Every sampled point of the paths the law is evaluated on (the direction mean is formed per draw).
  std::vector<LoadPoint> points;
  std::vector<std::size_t> first;  // column of each curve's first point; npos for the direction mean
  for (const auto& c : curves) {
    first.push_back(c.direction_mean ? std::size_t(-1) : points.size());
    if (c.direction_mean) continue;
    for (double l : c.stretch) points.push_back({l, c.equibiaxial ? l : 1.0, c.load});
  }
  MonteCarloOptions mo;
  mo.samples = o.draws;
  mo.seed = o.seed;
  const MonteCarloResult mc = monte_carlo(*model, points, mean, sd, mo);

  // Columns per curve (draws × stretches), keeping only draws that are a tissue in tension on
  // every path: positive, increasing stress.
  const Eigen::Index n_draws = mc.stress_Pa.rows();
  std::vector<bool> valid(std::size_t(n_draws), true);
  auto column = [&](std::size_t curve, std::size_t i, Eigen::Index s) {
    const LawCurve& c = curves[curve];
    if (!c.direction_mean) return mc.stress_Pa(s, Eigen::Index(first[curve] + i));
    double sum = 0;
    int n = 0;
    for (std::size_t k = 0; k < curves.size(); ++k)
      if (!curves[k].direction_mean && !curves[k].equibiaxial) sum += mc.stress_Pa(s, Eigen::Index(first[k] + i)), ++n;
    return sum / n;
  };
  for (Eigen::Index s = 0; s < n_draws; ++s)
    for (std::size_t k = 0; k < curves.size() && valid[std::size_t(s)]; ++k)
      for (std::size_t i = 0; i < curves[k].stretch.size(); ++i) {
        const double T = column(k, i, s);
        if (!(T > 0) || (i > 0 && !(T > column(k, i - 1, s)))) {
          valid[std::size_t(s)] = false;
          break;
        }
      }
  MaterialBand band;
  band.spread_kind = law.sd_kind;
  band.draws = o.draws;
  band.rejected_draws = o.draws - int(n_draws);
  for (bool v : valid) band.rejected_draws += v ? 0 : 1;
  const int kept = o.draws - band.rejected_draws;
  if (kept < o.draws / 2)
    throw InputError(ExitCode::calibration_data,
                     "material '" + law.id + "': only " + std::to_string(kept) + " of " + std::to_string(o.draws) +
                         " draws over its spread give a stress that is positive and rising",
                     {}, "the spread is too wide for a material band; check the standard deviations");

  for (double level : o.levels) {
    std::vector<LawCurve> pc = curves;
    for (std::size_t k = 0; k < pc.size(); ++k)
      for (std::size_t i = 0; i < pc[k].stretch.size(); ++i) {
        MonteCarloResult one;
        one.stress_Pa.resize(kept, 1);
        Eigen::Index row = 0;
        for (Eigen::Index s = 0; s < n_draws; ++s)
          if (valid[std::size_t(s)]) one.stress_Pa(row++, 0) = column(k, i, s);
        const double lv[1] = {level};
        pc[k].nominal_stress_Pa[i] = stress_quantiles(one, 0, lv)[0];
      }
    MaterialBandMember m;
    m.name = band_member_name(level);
    m.level = level;
    RegionLaw named = law;
    named.id = law.id + " " + m.name + " (" + std::to_string(kept) + " draws over its " + law.sd_kind + ")";
    m.fit = fit_solver_curves(named, std::move(pc), o.fit);
    m.fit.material.law_id = law.id;
    band.members.push_back(std::move(m));
  }
  return band;
}

}  // namespace organsmith::physics
