#include "pipeline/io/itk_image_io.h"

#include "core/errors.h"

#include <itkImage.h>
#include <itkImageFileReader.h>
#include <itkImageFileWriter.h>
#include <itkMetaImageIOFactory.h>
#include <itkNiftiImageIOFactory.h>
#include <itkNrrdImageIOFactory.h>

#include <algorithm>
#include <filesystem>
#include <mutex>

namespace organsmith::itk_io {

namespace {

/// ITK's IO factories are registered once per process; the CMake "UseITK" auto-registration is
/// not used so that every target links only the readers it needs.
void register_factories() {
  static std::once_flag once;
  std::call_once(once, [] {
    itk::NiftiImageIOFactory::RegisterOneFactory();
    itk::NrrdImageIOFactory::RegisterOneFactory();
    itk::MetaImageIOFactory::RegisterOneFactory();
  });
}

template <typename Pixel>
void write_itk(const std::string& path, const PlainGrid& g, const Pixel* data) {
  register_factories();
  using ImageT = itk::Image<Pixel, 3>;
  auto image = ImageT::New();
  typename ImageT::RegionType region;
  typename ImageT::SpacingType spacing;
  typename ImageT::PointType origin;
  typename ImageT::DirectionType direction;
  std::size_t n = 1;
  for (int a = 0; a < 3; ++a) {
    region.SetSize(a, itk::SizeValueType(g.size[a]));
    region.SetIndex(a, 0);
    spacing[a] = g.spacing[a];
    origin[a] = g.origin[a];
    for (int b = 0; b < 3; ++b) direction(a, b) = g.direction[3 * a + b];
    n *= std::size_t(g.size[a]);
  }
  image->SetRegions(region);
  image->SetSpacing(spacing);
  image->SetOrigin(origin);
  image->SetDirection(direction);
  // Import without copying: ITK only reads the buffer while writing.
  image->GetPixelContainer()->SetImportPointer(const_cast<Pixel*>(data), n, false);
  auto writer = itk::ImageFileWriter<ImageT>::New();
  writer->SetFileName(path);
  writer->SetInput(image);
  writer->SetUseCompression(true);
  try {
    writer->Update();
  } catch (const itk::ExceptionObject& e) {
    throw OutputError(std::string("cannot write the image: ") + e.GetDescription(), path,
                      "check that the directory is writable and the disk not full");
  }
}

/// `image`'s size, spacing, origin and direction into `g`; returns its voxel count.
template <typename ImageT>
std::size_t grid_of(const ImageT* image, PlainGrid& g) {
  const auto size = image->GetLargestPossibleRegion().GetSize();
  std::size_t n = 1;
  for (int a = 0; a < 3; ++a) {
    g.size[a] = std::int64_t(size[a]);
    g.spacing[a] = image->GetSpacing()[a];
    g.origin[a] = image->GetOrigin()[a];
    for (int b = 0; b < 3; ++b) g.direction[3 * a + b] = image->GetDirection()(a, b);
    n *= size[a];
  }
  return n;
}

}  // namespace

void read_float(const std::string& path, PlainGrid& g, const std::function<float*(std::size_t)>& allocate) {
  register_factories();
  if (!std::filesystem::exists(path))
    throw InputError(ExitCode::input_not_found, "file does not exist", path, "check the path");
  using ImageT = itk::Image<float, 3>;
  auto reader = itk::ImageFileReader<ImageT>::New();
  reader->SetFileName(path);
  try {
    reader->Update();
  } catch (const itk::ExceptionObject& e) {
    throw InputError(ExitCode::unsupported_input,
                     std::string("cannot read the image: ") + e.GetDescription(), path,
                     "give a readable NIfTI, NRRD or MetaImage file, or a DICOM directory");
  }
  const ImageT* image = reader->GetOutput();
  const std::size_t n = grid_of(image, g);
  std::copy(image->GetBufferPointer(), image->GetBufferPointer() + n, allocate(n));
}

void read_grid(const std::string& path, PlainGrid& g) {
  register_factories();
  using ImageT = itk::Image<float, 3>;
  auto reader = itk::ImageFileReader<ImageT>::New();
  reader->SetFileName(path);
  try {
    reader->UpdateOutputInformation();
  } catch (const itk::ExceptionObject& e) {
    throw InputError(ExitCode::unsupported_input, std::string("cannot read the image's header: ") + e.GetDescription(),
                     path, "give a readable NIfTI, NRRD or MetaImage file");
  }
  grid_of(reader->GetOutput(), g);
}

void write_float(const std::string& path, const PlainGrid& grid, const float* values) {
  write_itk<float>(path, grid, values);
}

void write_uint8(const std::string& path, const PlainGrid& grid, const std::uint8_t* values) {
  write_itk<std::uint8_t>(path, grid, values);
}

}  // namespace organsmith::itk_io
