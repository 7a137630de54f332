// `segment` subcommand: GVF-snake segmentation of the gallbladder (seeded) and the trachea
// (found automatically) into labels.nii.gz, contours_<organ>.json and overlay PNGs.

#include "core/errors.h"
#include "core/file_io.h"
#include "pipeline/cli/commands.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/ingest.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/run/runner.h"
#include "pipeline/run/terminal_progress.h"
#include "segmentation/presets.h"
#include "segmentation/segment.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

struct SegmentFlags {
  std::string input;
  std::string out;
  std::vector<std::string> organs;
  std::vector<std::string> seeds;      // "X,Y,Z" LPS mm
  std::vector<std::string> seeds_ijk;  // "I,J,K"
  std::string presets;                 // TOML file overriding data/organs.toml
  bool force = false;                  // redo the stages even when unchanged
  std::string name;                    // case name (titles, manifest); default: the output folder's name
  bool print_presets = false;
};

std::array<double, 3> parse_triple(const std::string& s, const char* what) {
  std::array<double, 3> v{};
  std::istringstream in(s);
  char c1 = 0, c2 = 0;
  if (!(in >> v[0] >> c1 >> v[1] >> c2 >> v[2]) || c1 != ',' || c2 != ',' || !(in >> std::ws).eof())
    throw UsageError(std::string(what) + " '" + s + "' is not three comma-separated numbers",
                     std::string("write it as ") + (std::string(what) == "--seed" ? "X,Y,Z (LPS mm), e.g. --seed=-27.3,-35.2,-347.5"
                                                                                  : "I,J,K (voxel index), e.g. --seed-ijk 120,140,33"));
  return v;
}

int run_segment(const SegmentFlags& f) {
  if (f.print_presets) {
    std::fwrite(default_organ_presets_toml().data(), 1, default_organ_presets_toml().size(), stdout);
    return 0;
  }
  // Required unless --print-presets (checked here: CLI11 has no conditional `required`).
  if (f.input.empty()) throw UsageError("INPUT is required", "give a DICOM directory or file, or a NIfTI/NRRD/MHA volume");
  if (f.out.empty()) throw UsageError("--out is required", "give the output directory, e.g. --out seg");
  if (f.organs.empty()) throw UsageError("--organ is required", "--organ gallbladder --seed X,Y,Z and/or --organ trachea");
  const auto t0 = std::chrono::steady_clock::now();
  SegmentOptions options;
  if (!f.presets.empty()) {
    auto text = read_file(f.presets);
    if (!text) throw InputError(ExitCode::input_not_found, "cannot read the organ presets file", f.presets);
    options.preset_overrides_toml = std::move(*text);
  }
  const auto presets = options.preset_overrides_toml.empty()
                           ? default_organ_presets()
                           : parse_organ_presets(options.preset_overrides_toml, default_organ_presets());
  // Seeds go, in order, to the organs that need one (--seed and --seed-ijk are not mixed, so
  // the pairing is unambiguous).
  if (!f.seeds.empty() && !f.seeds_ijk.empty())
    throw UsageError("give the seeds either all as --seed (LPS mm) or all as --seed-ijk (voxel index)");
  std::vector<OrganRequest> requests;
  std::size_t next_seed = 0;
  const std::size_t n_seeds = f.seeds.size() + f.seeds_ijk.size();
  for (const auto& name : f.organs) {
    auto it = presets.find(name);
    if (it == presets.end()) {
      std::string known;
      for (const auto& [organ, _] : presets) known += (known.empty() ? "" : ", ") + organ;
      throw UsageError("unknown organ '" + name + "'", "organs with a segmentation preset: " + known);
    }
    OrganRequest r;
    r.organ = name;
    if (it->second.needs_seed) {
      if (next_seed >= n_seeds)
        throw UsageError("--organ " + name + " needs a seed", "add --seed X,Y,Z (LPS mm) or --seed-ijk I,J,K after it");
      if (!f.seeds.empty()) {
        const auto v = parse_triple(f.seeds[next_seed], "--seed");
        r.seed_lps_mm = Eigen::Vector3d(v[0], v[1], v[2]);
      } else {
        const auto v = parse_triple(f.seeds_ijk[next_seed], "--seed-ijk");
        r.seed_ijk = std::array<std::int64_t, 3>{std::int64_t(std::llround(v[0])), std::int64_t(std::llround(v[1])),
                                                 std::int64_t(std::llround(v[2]))};
      }
      ++next_seed;
    }
    requests.push_back(std::move(r));
  }
  if (next_seed != n_seeds)
    throw UsageError(std::to_string(n_seeds) + " seeds given for " + std::to_string(next_seed) + " seeded organs",
                     "give one --seed per --organ gallbladder; the trachea needs none");

  // The segment command is the run of a case made from its flags, up to the segment stage: the
  // same writers, the same files (ingest.json, labels.nii.gz, contours_<organ>.json, overlays/,
  // manifest.json), and `mesh DIR`, `guide DIR`, `snapshot DIR` continue it.
  CaseFile c;
  c.name = f.name.empty() ? fs::absolute(f.out).lexically_normal().filename().string() : f.name;
  if (c.name.empty()) c.name = "case";
  c.input = fs::weakly_canonical(fs::absolute(f.input));
  c.out_dir = f.out;
  for (const auto& r : requests) {
    OrganSpec o;
    o.name = r.organ;
    o.seed_lps_mm = r.seed_lps_mm;
    if (r.seed_ijk) o.seed_ijk = Eigen::Vector3d(double((*r.seed_ijk)[0]), double((*r.seed_ijk)[1]), double((*r.seed_ijk)[2]));
    c.organs.push_back(std::move(o));
  }
  if (!options.preset_overrides_toml.empty()) set_segment_presets(c, options.preset_overrides_toml, f.presets);
  RunOptions ro;
  ro.until = "segment";
  ro.force = f.force;
  ro.all_or_nothing = true;
  TerminalProgress progress;
  const RunSummary summary = run_case(c, ro, progress);
  progress.finish();
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  spdlog::info("segmentation written to {} in {:.2f} s: labels.nii.gz, contours_<organ>.json, overlays/, ingest.json",
               summary.out_dir.string(), s);
  return 0;
}

}  // namespace

std::vector<Command> segmentation_commands(CLI::App& app) {
  auto flags = std::make_shared<SegmentFlags>();
  auto* sub = app.add_subcommand(
      "segment",
      "Segment organs with GVF active contours, slice by slice: the gallbladder from one seed inside it,\n"
      "the trachea automatically (most cranial round midline air lumen down to the carina).\n"
      "Runs the ingest and segment stages of `organsmith run` on a case made from these flags and writes\n"
      "what they write: DIR/labels.nii.gz (the organ registry's labels: 1 gallbladder, 2 trachea; the\n"
      "input's grid), DIR/contours_<organ>.json (LPS mm), DIR/overlays/*.png for review, DIR/ingest.json\n"
      "and DIR/manifest.json. `organsmith mesh DIR`, `guide DIR` and `snapshot DIR` continue from there.");
  sub->add_option("INPUT", flags->input, "DICOM directory or file, or .nii/.nii.gz/.nrrd/.mha (required)");
  sub->add_option("--out", flags->out, "output directory: new, empty, or one organsmith wrote before (its earlier outputs are replaced; other files are never touched) (required)");
  sub->add_flag("--force", flags->force, "redo the stage even when it is unchanged since the last run");
  sub->add_option("--organ", flags->organs, "gallbladder or trachea; repeat for several organs (required)");
  sub->add_option("--seed", flags->seeds, "seed inside the organ, X,Y,Z in LPS mm; one per seeded --organ, in order")
      ->allow_extra_args(false);
  sub->add_option("--seed-ijk", flags->seeds_ijk, "seed as voxel index I,J,K instead of --seed")->allow_extra_args(false);
  sub->add_option("--presets", flags->presets,
                  "TOML file overriding organ presets: any key of --print-presets, e.g. [gallbladder] alpha = 0.8");
  sub->add_option("--name", flags->name, "case name shown in titles and the manifest (default: DIR's folder name)");
  sub->add_flag("--print-presets", flags->print_presets,
                "print the embedded organ presets (HU windows, snake parameters, size limits, with sources) and exit");
  return {Command{sub, [flags] { return run_segment(*flags); }}};
}

}  // namespace organsmith
