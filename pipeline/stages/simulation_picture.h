#pragma once
// The picture of a solver's answer: the organ deformed under its load case, coloured by von
// Mises stress, over its undeformed outline (simulation/<organ>.png, written by the simulate stage).

#include "pipeline/stages/simulate.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace organsmith {

/// Draws `sim` (a converged run, displacements and stresses at the nodes) into `png`, width ×
/// height pixels, off-screen. Throws DisplayError when nothing can render.
void draw_simulation(const Simulation& sim, const std::filesystem::path& png, int width_px = 1024, int height_px = 768);

/// A finite-element state drawn the same way: the boundary of the tetrahedra (corner faces of one
/// element only; 4- or 10-node, C3D10 order) at rest and moved by `u_mm` (3 per node), coloured by
/// `element_values` averaged onto the nodes (titled `value_title`), with `detail` under the title.
void draw_deformed_tets(const std::string& organ, const std::vector<Eigen::Vector3d>& nodes_lps_mm,
                        const std::vector<std::array<std::int32_t, 10>>& elements, const std::vector<double>& u_mm,
                        const std::vector<double>& element_values, const std::string& value_title, const std::string& detail,
                        const std::filesystem::path& png, int width_px = 1024, int height_px = 768);

/// The indentation's force against depth (an indentation run), with a reference curve
/// ([depth mm, force N], e.g. the thesis' organ law over the probe's area) when not empty.
void draw_indentation_plot(const Simulation& sim, const std::vector<std::array<double, 2>>& reference,
                           const std::string& reference_name, const std::filesystem::path& png, int width_px = 1024,
                           int height_px = 768);

}  // namespace organsmith
