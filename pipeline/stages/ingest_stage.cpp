#include "pipeline/stages/ingest_stage.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "pipeline/output/output_layout.h"

#include <spdlog/spdlog.h>

#include <cmath>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

nlohmann::json grid_json(const ImageGrid& g) {
  nlohmann::json dir = nlohmann::json::array();
  for (int c = 0; c < 3; ++c) dir.push_back({g.direction_lps(0, c), g.direction_lps(1, c), g.direction_lps(2, c)});
  return {{"size_vox", g.size_vox},
          {"spacing_mm", {g.spacing_mm.x(), g.spacing_mm.y(), g.spacing_mm.z()}},
          {"origin_lps_mm", {g.origin_lps_mm.x(), g.origin_lps_mm.y(), g.origin_lps_mm.z()}},
          {"direction_lps_columns", dir}};
}

/// ingest.json's "organs": the writer of the seeds …
nlohmann::json ingest_seeds_json(const std::vector<OrganSeed>& seeds, const ImageGrid& grid) {
  nlohmann::json organs = nlohmann::json::array();
  for (const auto& s : seeds) {
    nlohmann::json oj = {{"name", s.organ}};
    if (s.lps_mm) {
      const Eigen::Vector3d ijk = grid.lps_mm_to_index(*s.lps_mm);
      oj["seed_lps_mm"] = {s.lps_mm->x(), s.lps_mm->y(), s.lps_mm->z()};
      oj["seed_ijk"] = {ijk.x(), ijk.y(), ijk.z()};
    }
    oj["seed_source"] = s.source;
    organs.push_back(oj);
  }
  return organs;
}

}  // namespace

std::vector<OrganSeed> read_ingest_seeds(const fs::path& ingest_json) {
  const std::optional<std::string> text = read_file(ingest_json);
  if (!text)
    throw InputError(ExitCode::input_not_found, "the ingest stage's record is missing", ingest_json,
                     "run the case from its start (organsmith run CASE)");
  std::vector<OrganSeed> seeds;
  try {
    const nlohmann::json j = nlohmann::json::parse(*text);
    for (const auto& o : j.at("organs")) {
      OrganSeed s{o.at("name").get<std::string>(), std::nullopt, o.value("seed_source", "")};
      if (o.contains("seed_lps_mm")) {
        const auto& p = o["seed_lps_mm"];
        s.lps_mm = Eigen::Vector3d(p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>());
      }
      seeds.push_back(std::move(s));
    }
  } catch (const nlohmann::json::exception& e) {
    throw InputError(ExitCode::unsupported_input, std::string("the ingest stage's record is malformed: ") + e.what(),
                     ingest_json, "rerun the case with --force to read the input again");
  }
  return seeds;
}

namespace {

/// Each organ's seed in LPS mm (case file, else the phantom's seeds.json) and where it came from.
std::vector<OrganSeed> resolve_seeds(const IngestStageInputs& in, const ImageGrid& grid) {
  std::vector<OrganSeed> seeds;
  for (const auto& o : in.organs) {
    OrganSeed s{o.name, std::nullopt, {}};
    const Eigen::Vector3d* ph = nullptr;
    if (in.phantom_seeds)
      if (const auto it = in.phantom_seeds->find(o.name); it != in.phantom_seeds->end()) ph = &it->second;
    if (o.seed_lps_mm) s.lps_mm = o.seed_lps_mm, s.source = "case file (LPS mm)";
    else if (o.seed_ijk) s.lps_mm = grid.index_to_lps_mm(*o.seed_ijk), s.source = "case file (voxel ijk)";
    else if (ph) s.lps_mm = *ph, s.source = "phantom seeds.json";
    else if (!o.label_map.empty()) s.source = "label map";
    else s.source = in.registry->at(o.name).needs_seed ? "none" : "automatic";
    if (s.lps_mm) {
      const Eigen::Vector3d ijk = grid.lps_mm_to_index(*s.lps_mm);
      if (!grid.contains(std::lround(ijk.x()), std::lround(ijk.y()), std::lround(ijk.z())))
        throw InputError(ExitCode::bad_seed, "the seed of organ '" + o.name + "' lies outside the image", in.case_file,
                         "check the seed: LPS mm as shown by `organsmith info`");
    }
    seeds.push_back(std::move(s));
  }
  return seeds;
}

}  // namespace

IngestStageResult ingest_stage(const IngestStageInputs& in, const IngestOptions& options, const fs::path& staging,
                               Progress& progress) {
  IngestResult r = ingest(in.input, options, progress);
  for (const auto& w : r.report.warnings) spdlog::warn("ingest: {}", w);
  const std::string digest = volume_digest(r.volume);
  nlohmann::json j;
  j["format"] = r.report.format;
  j["digest_sha256"] = digest;
  j["grid"] = grid_json(r.volume.grid);
  j["hu_range"] = {r.report.hu_min, r.report.hu_max};
  if (r.report.format.rfind("DICOM", 0) == 0) {
    j["series"] = {{"series_uid", r.report.series.series_uid},
                   {"modality", r.report.series.modality},
                   {"slices", r.report.series.files},
                   {"transfer_syntax", r.report.series.transfer_syntax}};
    j["other_series"] = nlohmann::json::array();
    for (const auto& s : r.report.other_series)
      j["other_series"].push_back({{"series_uid", s.series_uid}, {"modality", s.modality}, {"files", s.files}});
  }
  j["warnings"] = r.report.warnings;
  IngestStageResult out;
  out.seeds = resolve_seeds(in, r.volume.grid);
  j["organs"] = ingest_seeds_json(out.seeds, r.volume.grid);
  out.input = {{"format", j["format"]}, {"digest_sha256", digest}, {"grid", j["grid"]}};
  write_file_atomic(OutputLayout{staging}.ingest(), j.dump(2) + "\n");
  out.volume = std::move(r.volume);
  return out;
}

}  // namespace organsmith
