#pragma once
// ITK file reading and writing behind plain types. ITK bundles its own (older) Eigen, which
// cannot share a translation unit with the system Eigen that core/ uses, so the ITK side of
// image_io lives in itk_image_io.cpp and sees only these structs.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace organsmith::itk_io {

struct PlainGrid {
  std::int64_t size[3] = {0, 0, 0};
  double spacing[3] = {1, 1, 1};
  double origin[3] = {0, 0, 0};
  double direction[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< row-major; columns are axis directions
};

/// Reads any ITK-readable scalar image as float into the buffer that `allocate(voxel_count)`
/// returns. Throws InputError.
void read_float(const std::string& path, PlainGrid& grid, const std::function<float*(std::size_t)>& allocate);
/// The grid of an image file as read_float gives it (its header only: no voxel is read).
void read_grid(const std::string& path, PlainGrid& grid);
void write_float(const std::string& path, const PlainGrid& grid, const float* values);
void write_uint8(const std::string& path, const PlainGrid& grid, const std::uint8_t* values);

}  // namespace organsmith::itk_io
