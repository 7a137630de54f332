#pragma once
// Synthetic CT phantom of a torso from the neck to the upper abdomen, with ground-truth labels
// and one seed point per organ. It is the embedded default input of `organsmith run`.

#include "core/progress.h"
#include "core/volume.h"

#include <Eigen/Core>

#include <cstdint>
#include <map>
#include <string>

namespace organsmith {

/// Options of the phantom synthesis. Defaults give a 512×512×160 series at 0.78×0.78×2.5 mm.
struct PhantomOptions {
  std::uint64_t seed = 1;       ///< random seed for noise and small shape variations (default 1)
  int size_vox = 512;           ///< in-plane matrix, columns = rows (default 512)
  double slice_mm = 2.5;        ///< slice spacing and thickness, mm (default 2.5)
  double fov_mm = 400.0;        ///< in-plane field of view, mm (default 400 → 0.78 mm pixels)
  double extent_mm = 400.0;     ///< cranio-caudal extent, neck to upper abdomen, mm (default 400)
  double blur_mm = 1.0;         ///< Gaussian sigma of the partial-volume blur, mm (default 1.0)
  double noise_hu = 15.0;       ///< standard deviation of additive Gaussian noise, HU (default 15)
};

/// The phantom's ground-truth label values. The embedded organ registry (data/organs.toml) gives
/// its organs the same values (a test holds them equal); every stage asks the registry.
enum class PhantomLabel : std::uint8_t {
  background = 0,
  gallbladder = 1,
  trachea = 2,
  liver = 3,
  lungs = 4,
  body = 5,  ///< soft tissue and bone inside the skin that no other label claims
};

/// Lower-case name of a phantom label ("gallbladder", …; the registry's name of that organ).
std::string phantom_label_name(PhantomLabel label);

/// A synthesized case: the CT (HU), its ground truth on the same grid (PhantomLabel values) and
/// one seed per organ, LPS mm, keyed by label name.
struct Phantom {
  Volume ct;
  LabelMap truth;
  std::map<std::string, Eigen::Vector3d> seeds_lps_mm;
};

/// Synthesizes the phantom. Deterministic: the same options give bit-identical output on any
/// thread count. Grid: identity direction cosines (i increases toward the patient's left,
/// j toward posterior, k from inferior (k = 0) to superior), as a supine axial CT.
Phantom synthesize_phantom(const PhantomOptions& options, Progress& progress);

}  // namespace organsmith
