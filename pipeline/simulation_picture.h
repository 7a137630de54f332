#pragma once
// The picture of a solver's answer: the organ deformed under its load case, coloured by von
// Mises stress, over its undeformed outline (simulation/<organ>.png, written by the simulate stage).

#include "pipeline/simulate.h"

#include <filesystem>

namespace organsmith {

/// Draws `sim` (a converged run, displacements and stresses at the nodes) into `png`, width ×
/// height pixels, off-screen. Throws DisplayError when nothing can render.
void draw_simulation(const Simulation& sim, const std::filesystem::path& png, int width_px = 1024, int height_px = 768);

/// The indentation's force against depth (an indentation run), with a reference curve
/// ([depth mm, force N], e.g. the thesis' organ law over the probe's area) when not empty.
void draw_indentation_plot(const Simulation& sim, const std::vector<std::array<double, 2>>& reference,
                           const std::string& reference_name, const std::filesystem::path& png, int width_px = 1024,
                           int height_px = 768);

}  // namespace organsmith
