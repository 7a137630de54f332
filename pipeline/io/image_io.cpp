#include "pipeline/io/image_io.h"

#include "core/errors.h"
#include "pipeline/io/itk_image_io.h"
#include "pipeline/io/nifti_check.h"
#include "pipeline/io/text_header_check.h"
#include "core/memory.h"

#include <algorithm>
#include <cmath>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

std::string lower_name(const fs::path& p) {
  std::string s = p.filename().string();
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

itk_io::PlainGrid plain(const ImageGrid& g) {
  itk_io::PlainGrid p;
  for (int a = 0; a < 3; ++a) {
    p.size[a] = g.size_vox[a];
    p.spacing[a] = g.spacing_mm[a];
    p.origin[a] = g.origin_lps_mm[a];
    for (int b = 0; b < 3; ++b) p.direction[3 * a + b] = g.direction_lps(a, b);
  }
  return p;
}

ImageGrid grid(const itk_io::PlainGrid& p) {
  ImageGrid g;
  for (int a = 0; a < 3; ++a) {
    g.size_vox[a] = p.size[a];
    g.spacing_mm[a] = p.spacing[a];
    g.origin_lps_mm[a] = p.origin[a];
    for (int b = 0; b < 3; ++b) g.direction_lps(a, b) = p.direction[3 * a + b];
  }
  return g;
}

}  // namespace

bool is_volume_file_name(const fs::path& path) { return !volume_file_format(path).empty(); }

std::string volume_file_format(const fs::path& path) {
  const std::string n = lower_name(path);
  if (ends_with(n, ".nii") || ends_with(n, ".nii.gz")) return "NIfTI";
  if (ends_with(n, ".nrrd") || ends_with(n, ".nhdr")) return "NRRD";
  if (ends_with(n, ".mha") || ends_with(n, ".mhd")) return "MetaImage";
  return {};
}

namespace {
/// Every format's header is checked before ITK sees the file (ITK aborts on some corrupt NIfTI
/// headers, and allocates whatever size a header announces).
void check_before_reading(const fs::path& path, std::int64_t max_memory_bytes) {
  const std::int64_t budget = max_memory_bytes > 0 ? max_memory_bytes : default_memory_budget_bytes();
  const std::string format = volume_file_format(path);
  if (format.rfind("NIfTI", 0) == 0) check_nifti_file(path, budget);
  else if (format == "NRRD") check_nrrd_file(path, budget);
  else if (format == "MetaImage") check_metaimage_file(path, budget);
}
}  // namespace

Volume read_volume_file(const fs::path& path, std::int64_t max_memory_bytes) {
  check_before_reading(path, max_memory_bytes);
  itk_io::PlainGrid p;
  Volume v;
  itk_io::read_float(path.string(), p, [&](std::size_t n) {
    v.hu.resize(n);
    return v.hu.data();
  });
  v.grid = grid(p);
  v.grid.validate();
  return v;
}

LabelMap read_label_map(const fs::path& path) {
  check_before_reading(path, 0);
  itk_io::PlainGrid p;
  std::vector<float> values;
  itk_io::read_float(path.string(), p, [&](std::size_t n) {
    values.resize(n);
    return values.data();
  });
  LabelMap m;
  m.grid = grid(p);
  m.labels.resize(values.size());
  for (std::size_t a = 0; a < values.size(); ++a) {
    const float v = std::nearbyint(values[a]);
    if (!(v >= 0.0f && v <= 255.0f))
      throw InputError(ExitCode::unsupported_input,
                       "label value " + std::to_string(values[a]) + " is outside 0–255", path,
                       "give a label map with small non-negative integer labels");
    // A label is a class, not a measurement: fractional values (a probability map, a resampled
    // label image) are refused rather than rounded into shapes nobody drew.
    if (std::abs(values[a] - v) > 1e-3f)
      throw InputError(ExitCode::unsupported_input,
                       "label value " + std::to_string(values[a]) + " at voxel " + std::to_string(a) +
                           " is not a whole number: this is not a label map",
                       path,
                       "give integer labels (a probability map must be thresholded first, and a label image "
                       "resampled with nearest-neighbour interpolation)");
    m.labels[a] = std::uint8_t(v);
  }
  return m;
}

void write_volume_file(const Volume& volume, const fs::path& path) {
  itk_io::write_float(path.string(), plain(volume.grid), volume.hu.data());
}

void write_label_map(const LabelMap& labels, const fs::path& path) {
  itk_io::write_uint8(path.string(), plain(labels.grid), labels.labels.data());
}

ImageGrid read_image_grid(const fs::path& path) {
  itk_io::PlainGrid p;
  itk_io::read_grid(path.string(), p);
  ImageGrid g = grid(p);
  g.validate();
  return g;
}

double merge_organ_from_label_map(LabelMap& labels, const LabelMap& source, std::uint8_t label) {
  const ImageGrid& g = labels.grid;
  const bool same = g.same_geometry(source.grid);
  std::int64_t added = 0;
  for (std::int64_t k = 0; k < g.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < g.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < g.size_vox[0]; ++i) {
        std::uint8_t& v = labels.labels[g.offset(i, j, k)];
        if (v != 0) continue;
        std::uint8_t s = 0;
        if (same) {
          s = source.at(i, j, k);
        } else {
          const Eigen::Vector3d ijk = source.grid.lps_mm_to_index(g.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k))));
          const std::int64_t si = std::llround(ijk.x()), sj = std::llround(ijk.y()), sk = std::llround(ijk.z());
          if (source.grid.contains(si, sj, sk)) s = source.at(si, sj, sk);
        }
        if (s == label) v = label, ++added;
      }
  return double(added) * g.spacing_mm.prod() / 1000.0;
}

}  // namespace organsmith
