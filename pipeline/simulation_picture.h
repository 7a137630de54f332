#pragma once
// The picture of a solver's answer: the organ deformed under its load case, coloured by von
// Mises stress, over its undeformed outline (simulation/<organ>.png, written by the simulate stage).

#include "pipeline/simulate.h"

#include <filesystem>

namespace organsmith {

/// Draws `sim` (a converged run, displacements and stresses at the nodes) into `png`, width ×
/// height pixels, off-screen. Throws DisplayError when nothing can render.
void draw_simulation(const Simulation& sim, const std::filesystem::path& png, int width_px = 1024, int height_px = 768);

}  // namespace organsmith
