#pragma once
// Test data for the viewer, made from the phantom's ground truth: a small phantom written once
// per machine (cached in the temp dir), label-map surfaces, a voxel-built tetrahedral mesh, a
// centreline path, a tool with a force and two plots.

#include "viewer/image.h"
#include "viewer/scene.h"

#include <filesystem>
#include <memory>

namespace organsmith::testing {

/// A small phantom (128² in-plane) written by the CLI: <dir>/dicom, ground_truth.nii.gz, seeds.json.
std::filesystem::path small_phantom_dir();

/// The scene of every view, owning the CT and labels it points to.
struct TestScene {
  Volume ct;
  LabelMap labels;
  SnapshotScene scene;
};
std::unique_ptr<TestScene> make_test_scene();

/// Six-tet (Kuhn) subdivision of each voxel carrying `label`, sampled every `step` voxels.
TetMesh voxel_tets(const LabelMap& labels, std::uint8_t label, int step);

/// The display colour the organ registry gives `organ` (data/organs.toml).
Rgb organ_colour(const std::string& organ);

/// Pixel statistics.
double grey_variance(const RgbImage& img);
/// Number of pixels within `tol` (per channel, 0–255) of `c`.
std::size_t count_colour(const RgbImage& img, const Rgb& c, int tol);
/// Number of pixels whose hue is close to `c`'s (same dominant channel order, saturated).
std::size_t count_hue(const RgbImage& img, const Rgb& c);

}  // namespace organsmith::testing
