// PNG files: written with libpng directly (one cheap filter, chosen zlib level: faster than
// vtkPNGWriter's adaptive filtering), read through VTK's reader.

#include "viewer/image.h"

#include "core/errors.h"

#include <vtkImageData.h>
#include <vtkPNGReader.h>
#include <vtkSmartPointer.h>
#include <vtkUnsignedCharArray.h>
#include <vtkPointData.h>

#include <png.h>

#include <algorithm>
#include <csetjmp>
#include <cstdio>
#include <system_error>

namespace organsmith {

namespace {

/// libpng reports errors by longjmp: this function keeps no object with a destructor alive
/// across the setjmp, and returns false on failure.
bool encode_png(FILE* f, const RgbImage& image, int compression_level) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  if (!png) return false;
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    return false;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_init_io(png, f);
  png_set_IHDR(png, info, png_uint_32(image.width_px), png_uint_32(image.height_px), 8, PNG_COLOR_TYPE_RGB,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  // One cheap filter (Up: rendered views are mostly flat or vertical gradients) instead of the
  // adaptive choice among five per row, which costs more time than it saves in size here.
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_UP);
  png_set_compression_level(png, std::clamp(compression_level, 0, 9));
  png_write_info(png, info);
  const std::size_t row = std::size_t(image.width_px) * 3;
  for (int y = 0; y < image.height_px; ++y)
    png_write_row(png, const_cast<png_bytep>(image.rgb.data() + std::size_t(y) * row));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

void write_png(const RgbImage& image, const std::filesystem::path& path, int compression_level) {
  if (image.width_px <= 0 || image.height_px <= 0 ||
      image.rgb.size() != std::size_t(image.width_px) * std::size_t(image.height_px) * 3)
    throw OutputError("cannot write an empty or malformed image as a PNG", path);
  FILE* f = std::fopen(path.string().c_str(), "wb");
  if (!f) throw OutputError("cannot create the PNG", path, "check that the directory exists and is writable");
  const bool ok = encode_png(f, image, compression_level);
  const bool closed = std::fclose(f) == 0;
  if (!ok || !closed) {
    std::error_code ec;
    std::filesystem::remove(path, ec);
    throw OutputError("cannot write the PNG", path, "check that the disk has free space");
  }
}

RgbImage read_png(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw InputError(ExitCode::input_not_found, "no such PNG file", path);
  auto reader = vtkSmartPointer<vtkPNGReader>::New();
  if (!reader->CanReadFile(path.string().c_str()))
    throw InputError(ExitCode::unsupported_input, "not a PNG file", path);
  reader->SetFileName(path.string().c_str());
  reader->Update();
  vtkImageData* data = reader->GetOutput();
  int dims[3];
  data->GetDimensions(dims);
  const int nc = data->GetNumberOfScalarComponents();
  if (data->GetScalarType() != VTK_UNSIGNED_CHAR || nc < 1 || nc > 4)
    throw InputError(ExitCode::unsupported_input, "PNG is not 8-bit grey/RGB(A)", path);
  RgbImage img;
  img.width_px = dims[0];
  img.height_px = dims[1];
  img.rgb.resize(std::size_t(dims[0]) * dims[1] * 3);
  const auto* src = static_cast<const unsigned char*>(data->GetScalarPointer());
  for (int y = 0; y < dims[1]; ++y)
    for (int x = 0; x < dims[0]; ++x) {
      const unsigned char* s = src + (std::size_t(dims[1] - 1 - y) * dims[0] + x) * nc;
      unsigned char* d = img.rgb.data() + (std::size_t(y) * dims[0] + x) * 3;
      if (nc >= 3) {
        d[0] = s[0];
        d[1] = s[1];
        d[2] = s[2];
      } else {
        d[0] = d[1] = d[2] = s[0];
      }
    }
  return img;
}

}  // namespace organsmith
