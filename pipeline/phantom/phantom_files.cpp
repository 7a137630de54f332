#include "pipeline/phantom/phantom_files.h"
#include "core/file_io.h"

#include "core/errors.h"
#include "pipeline/io/dicom.h"
#include "pipeline/io/image_io.h"

#include <nlohmann/json.hpp>

#include <fstream>

namespace organsmith {

namespace fs = std::filesystem;

void write_phantom_files(const Phantom& phantom, const PhantomOptions& options, const fs::path& dir,
                         Progress& progress) {
  DicomSeriesIds ids;
  ids.uid_seed = "organsmith-phantom/seed=" + std::to_string(options.seed) +
                 "/size=" + std::to_string(options.size_vox) + "/slice=" + std::to_string(options.slice_mm) +
                 "/fov=" + std::to_string(options.fov_mm) + "/extent=" + std::to_string(options.extent_mm);
  write_dicom_series(phantom.ct, dir / "dicom", ids, progress);
  write_label_map(phantom.truth, dir / "ground_truth.nii.gz");
  nlohmann::json seeds = nlohmann::json::object();
  for (const auto& [organ, p] : phantom.seeds_lps_mm) seeds[organ] = {p.x(), p.y(), p.z()};
  nlohmann::json j = {{"frame", "LPS"}, {"unit", "mm"}, {"seeds_lps_mm", seeds}};
  write_file_atomic(dir / "seeds.json", j.dump(2) + "\n");
}

std::map<std::string, Eigen::Vector3d> read_seeds(const fs::path& seeds_json) {
  std::ifstream in(seeds_json);
  if (!in) throw InputError(ExitCode::input_not_found, "cannot open the seeds file", seeds_json);
  std::map<std::string, Eigen::Vector3d> seeds;
  try {
    const auto j = nlohmann::json::parse(in);
    for (const auto& [organ, p] : j.at("seeds_lps_mm").items())
      seeds[organ] = Eigen::Vector3d(p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>());
  } catch (const nlohmann::json::exception& e) {
    throw InputError(ExitCode::unsupported_input, std::string("malformed seeds file: ") + e.what(), seeds_json,
                     "expected {\"seeds_lps_mm\": {\"organ\": [x, y, z], …}}");
  }
  return seeds;
}

}  // namespace organsmith
