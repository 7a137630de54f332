#pragma once
// 8-bit RGB images: what a snapshot looks like in memory, and PNG files.

#include <cstdint>
#include <filesystem>
#include <vector>

namespace organsmith {

/// An RGB image, rows top to bottom, 3 bytes per pixel (r, g, b).
struct RgbImage {
  int width_px = 0, height_px = 0;
  std::vector<std::uint8_t> rgb;  ///< width_px × height_px × 3

  const std::uint8_t* pixel(int x, int y) const { return rgb.data() + 3 * (std::size_t(y) * width_px + x); }
};

/// Writes `image` as a PNG (not atomic: write into a staging directory); zlib level
/// `compression_level` 0–9 (1: fastest, a few per cent larger). Throws OutputError.
void write_png(const RgbImage& image, const std::filesystem::path& path, int compression_level = 5);
/// Reads a PNG (RGB or RGBA; alpha dropped, grey expanded). Throws InputError.
RgbImage read_png(const std::filesystem::path& path);

}  // namespace organsmith
