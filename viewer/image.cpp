// PNG files through VTK's PNG reader and writer.

#include "viewer/image.h"

#include "core/errors.h"

#include <vtkImageData.h>
#include <vtkPNGReader.h>
#include <vtkPNGWriter.h>
#include <vtkSmartPointer.h>
#include <vtkUnsignedCharArray.h>
#include <vtkPointData.h>

#include <system_error>

namespace organsmith {

void write_png(const RgbImage& image, const std::filesystem::path& path) {
  auto data = vtkSmartPointer<vtkImageData>::New();
  data->SetDimensions(image.width_px, image.height_px, 1);
  data->AllocateScalars(VTK_UNSIGNED_CHAR, 3);
  auto* dst = static_cast<unsigned char*>(data->GetScalarPointer());
  const std::size_t row = std::size_t(image.width_px) * 3;
  for (int y = 0; y < image.height_px; ++y)  // VTK images start at the bottom row
    std::copy(image.rgb.begin() + std::size_t(image.height_px - 1 - y) * row,
              image.rgb.begin() + std::size_t(image.height_px - y) * row, dst + std::size_t(y) * row);
  auto writer = vtkSmartPointer<vtkPNGWriter>::New();
  writer->SetInputData(data);
  writer->SetFileName(path.string().c_str());
  writer->Write();
  std::error_code ec;
  if (writer->GetErrorCode() != 0 || !std::filesystem::exists(path, ec))
    throw OutputError("cannot write the PNG", path, "check that the directory exists and has free space");
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
