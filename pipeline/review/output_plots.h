#pragma once
// Plots made from what a run (or `calibrate`, `uncertainty`) left in a directory, for snapshots.

#include "pipeline/case/organ_registry.h"
#include "pipeline/review/output_scene.h"
#include "viewer/scene.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// `organsmith calibrate` output in `dir` (params.json + fit.csv): measured points against the
/// fitted model, per specimen and load case. Nothing when the files are absent or not as
/// `calibrate` writes them. `stem` names the plot (plot_fit_<stem>.png).
std::optional<Plot> calibration_fit_plot(const std::filesystem::path& dir, const std::string& stem);

/// `organsmith uncertainty --method mc` output in `dir` (cdf.csv + summary.json): the stress CDF
/// at each stretch.
std::optional<Plot> monte_carlo_plot(const std::filesystem::path& dir, const std::string& stem);

/// The laws of the organ regions of materials.json (uniaxial, with the 5–95 % band of a Monte
/// Carlo over the preset's standard deviations where the thesis gives them) and the CDFs of that
/// Monte Carlo at a few stretches.
std::vector<Plot> material_plots(const MaterialsFile& materials, const OrganRegistry& registry);

}  // namespace organsmith
