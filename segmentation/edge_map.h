#pragma once
// Edge maps of one CT slice for the GVF snake (Xu & Prince 1998, §III): f = |∇(G_σ * I_w)|²,
// normalised to [0, 1], where I_w is the slice clamped to the organ's HU window. Clamping first
// keeps bone and air edges from dwarfing the soft-tissue edges the snake must find.

#include "segmentation/image2d.h"

namespace organsmith::seg {

struct EdgeMapOptions {
  double window_lo_hu = -200.0;  ///< HU mapped to 0 before smoothing (default −200)
  double window_hi_hu = 200.0;   ///< HU mapped to 1 (default 200)
  double sigma_mm = 1.5;         ///< Gaussian smoothing σ, mm (default 1.5); 0 = none
};

/// Smoothed slice in HU: G_σ * I (no window). `hu` is width × height values, x fastest;
/// spacing in mm along x and y. Used for the region statistics of the snake's pressure.
Image2f smooth_slice(const float* hu, int width, int height, double spacing_x_mm, double spacing_y_mm,
                     double sigma_mm);

/// Edge map f in [0, 1] of a slice (see file comment). Gradients are taken per pixel, so the
/// GVF that follows works in pixel units.
Image2f edge_map(const float* hu, int width, int height, double spacing_x_mm, double spacing_y_mm,
                 const EdgeMapOptions& options);

}  // namespace organsmith::seg
