#pragma once
// A contact sheet: many snapshots tiled on one page with a caption under each, so that a reviewer
// scans a whole cohort at a glance.

#include "viewer/image.h"

#include <filesystem>
#include <string>
#include <vector>

namespace organsmith {

struct SheetTile {
  std::filesystem::path image;  ///< a PNG; missing or unreadable → a grey tile saying "no picture"
  std::string caption;          ///< one line under the tile
  bool ok = true;               ///< false: the caption is drawn red
};

struct ContactSheetOptions {
  int tile_px = 256;   ///< tiles are scaled to this width (aspect kept)
  int columns = 0;     ///< 0 = about square
};

/// The sheet of `tiles`, in order, left to right and top to bottom.
RgbImage contact_sheet(const std::vector<SheetTile>& tiles, const ContactSheetOptions& options = {});

}  // namespace organsmith
