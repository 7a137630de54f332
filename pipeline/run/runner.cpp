// The stage runner. Over 400 lines for a reason: it is the one place that knows every stage of a
// run, what each takes from the run's model or its files and what its fingerprint covers. The
// stages' bodies are free functions (stages/*_stage.h, review/snapshot_stage.h); what stays here
// is their order, their inputs, fingerprints and records.

#include "pipeline/run/runner.h"
#include "pipeline/output/tool_info.h"

#include "pacs/pacs.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "core/memory.h"
#include "core/sha256.h"
#include "pipeline/stages/guide_stage.h"
#include "pipeline/stages/ingest_stage.h"
#include "pipeline/stages/mesh_stage.h"
#include "pipeline/stages/simulate_stage.h"
#include "pipeline/stages/segment_stage.h"
#include "pipeline/review/snapshot_stage.h"
#include "pipeline/io/ingest.h"
#include "pipeline/phantom/phantom.h"
#include "pipeline/io/image_io.h"
#include "pipeline/phantom/phantom_files.h"
#include "meshing/export.h"
#include "meshing/mesh.h"
#include "physics/haptics/contact.h"
#include "physics/materials/presets.h"
#include "core/format.h"
#include "pipeline/stages/organ_fe.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/review/output_scene.h"
#include "pipeline/run/run_model.h"
#include "viewer/snapshot.h"
#include "segmentation/segment.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <fstream>
#include <functional>
#include <optional>
#include <random>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

/// True when every output a previous run recorded is still there, unchanged.
bool outputs_intact(const nlohmann::json& outputs, const fs::path& out_dir) {
  if (!outputs.is_array() || outputs.empty()) return false;
  for (const auto& o : outputs) {
    const fs::path p = out_dir / o.value("path", "");
    std::error_code ec;
    if (!fs::is_regular_file(p, ec) || fs::file_size(p, ec) != o.value("bytes", std::uint64_t(0))) return false;
    if (sha256_file(p) != o.value("sha256", "")) return false;
  }
  return true;
}

/// A cheap fingerprint of an input on disk: relative path, size and modification time of every
/// file (hashing the pixels would cost as much as reading them).
std::string input_stat_digest(const fs::path& input) {
  Sha256 s;
  auto add = [&](const fs::path& f, const fs::path& rel) {
    std::error_code ec;
    const auto size = fs::file_size(f, ec);
    const auto mtime = fs::last_write_time(f, ec).time_since_epoch().count();
    std::ostringstream line;
    line << rel.generic_string() << '\t' << size << '\t' << mtime << '\n';
    s.update(line.str());
  };
  if (fs::is_directory(input)) {
    std::vector<fs::path> files;
    for (const auto& e : fs::recursive_directory_iterator(input))
      if (e.is_regular_file()) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) add(f, fs::relative(f, input));
  } else {
    add(input, input.filename());
  }
  return s.hex_digest();
}


struct Stage {
  std::string name;
  std::string fingerprint;
  /// Writes the stage's files into the staging directory given.
  std::function<void(const fs::path& staging)> run;
};

class Runner {
 public:
  Runner(const CaseFile& c, const RunOptions& options, Progress& progress)
      : case_(c),
        options_(options),
        progress_(progress),
        out_dir_(c.out_dir, OutputDirOptions{.inputs = c.synthesize_phantom ? std::vector<fs::path>{}
                                                                            : std::vector<fs::path>{c.input},
                                             .command = "run"}),
        out_(out_dir_.path()),
        layout_{out_},
        previous_(out_dir_.previous_manifest()),
        materials_json_(materials_json(c)) {}

  RunSummary run() {
    try {
      run_stages();
    } catch (...) {
      std::error_code ec;
      // Everything in a directory this command created is its own.
      if (options_.all_or_nothing && !out_dir_.existed()) fs::remove_all(out_, ec);
      throw;
    }
    RunSummary summary;
    summary.out_dir = out_;
    summary.stages = records_;
    out_dir_.write_manifest(manifest_header());
    summary.manifest = out_dir_.manifest();
    return summary;
  }

 private:
  /// A PACS input: the study into its cache (only what is not there intact is fetched).
  void pull_from_pacs() {
    const PacsSource& src = *case_.pacs;
    PacsEndpoint pacs = parse_pacs_url(src.url, src.calling_aet);
    pacs.ca_file = src.ca_file;
    pacs.timeout_s = src.timeout_s;
    pacs.retries = src.retries;
    pacs.move_port = src.move_port;
    PullOptions o;
    o.study_uid = src.study_uid;
    o.series_uid = case_.ingest.series_uid;
    o.cache_dir = src.cache_dir;
    const PullResult r = pull_study(pacs, o, progress_);
    spdlog::info("pulled study {} from PACS '{}': {} instances ({} fetched, {} cached) in {:.1f} s", uid_key(src.study_uid),
                 src.name, r.instances, r.fetched, r.reused, r.seconds);
  }

  void run_stages() {
    fs::path input = case_.input;
    if (case_.synthesize_phantom) {
      const nlohmann::json opts = to_json(case_)["phantom"];
      execute({"phantom", fingerprint("phantom", opts.dump()), [&](const fs::path& staging) {
                 Phantom ph = synthesize_phantom(case_.phantom, progress_);
                 const OutputLayout staged{staging};
                 fs::create_directories(staged.phantom_dir());
                 write_phantom_files(ph, case_.phantom, staged.phantom_dir(), progress_);
                 // Later stages take the truth and seeds from here, as their files hold them.
                 ph.truth.grid = read_image_grid(staged.phantom_truth());
                 model_.phantom_truth = std::move(ph.truth);
                 model_.phantom_seeds = std::move(ph.seeds_lps_mm);
               }});
      input = layout_.phantom_dicom();
    }
    if (case_.pacs) pull_from_pacs();
    input_ = input;
    const nlohmann::json ingest_opts = to_json(case_)["ingest"];
    const std::string organs = to_json(case_)["organs"].dump();
    execute({"ingest", fingerprint("ingest", ingest_opts.dump() + organs + input_stat_digest(input)),
             [&](const fs::path& staging) { write_ingest(staging); }});

    // A case with no organ can only be read (--until ingest): there is nothing to segment or mesh.
    // Checked after ingest, so that a bad input is reported as what it is first.
    if (case_.organs.empty() && !done_) {
      std::string names;
      for (const auto& n : case_.registry.modelled()) names += (names.empty() ? "\"" : ", \"") + n + "\"";
      throw CaseFileError("the case names no organ to model", case_.source,
                          "add [[organ]] tables (name = one of " + names +
                              "; an organ segmented from a seed takes seed_lps_mm), or run --until ingest to only "
                              "read the input");
    }
    if (!case_.organs.empty()) {
      const nlohmann::json seg_opts = stage_json(case_, "segment");
      execute({"segment", fingerprint("segment", seg_opts.dump() + registry_digest() + outputs_digest("ingest")),
               [&](const fs::path& staging) { write_segmentation(staging); }});
      const nlohmann::json mesh_opts = stage_json(case_, "mesh");
      // The solver files carry each region's fitted material, so the materials are part of the mesh
      // stage's fingerprint.
      // The gallbladder's fixed liver bed follows the guide stage's bed options (only those) and
      // the CT.
      const auto& bed = case_.stages.guide.dissection;
      const nlohmann::json bed_opts = {{"bed_from_ct", bed.bed_from_ct}, {"bed_distance_mm", bed.bed_distance_mm}};
      // The probe's place and depth are simulate options written into the mesh stage's INP.
      const nlohmann::json probe_opts = {{"probe_lps_mm", case_.stages.simulate.probe_lps_mm},
                                         {"probe_depth_mm", case_.stages.simulate.probe_depth_mm}};
      execute({"mesh", fingerprint("mesh", mesh_opts.dump() + registry_digest() + materials_json_.dump() +
                                               bed_opts.dump() + probe_opts.dump() + outputs_digest("ingest") +
                                               outputs_digest("segment")),
               [&](const fs::path& staging) { write_meshes(staging); }});
      execute({"attach", fingerprint("attach", to_json(case_)["organs"].dump() + materials_json_.dump()),
               [&](const fs::path& staging) {
                 const std::string text = materials_json_.dump(2) + "\n";
                 write_file_atomic(OutputLayout{staging}.materials(), text);
                 model_.materials = materials_from_text(text, layout_.materials());
               }});
      // guide: guidance paths (trachea centreline and incision, gallbladder dissection) in paths/.
      // The CT (ingest) gives the gallbladder's liver bed where no liver label does.
      execute({"guide", fingerprint("guide", stage_json(case_, "guide").dump() + outputs_digest("phantom") +
                                                 outputs_digest("ingest") + outputs_digest("segment") +
                                                 outputs_digest("mesh")),
               [&](const fs::path& staging) { write_paths(staging); }});
      // simulate: the organs' load cases in CalculiX (on request: minutes per organ).
      if (case_.stages.simulate.enabled || options_.from == "simulate" || options_.until == "simulate")
        execute({"simulate", fingerprint("simulate", stage_json(case_, "simulate").dump() + outputs_digest("mesh")),
                 [&](const fs::path& staging) { write_simulations(staging); }});
    }
    const nlohmann::json snap_opts = stage_json(case_, "snapshot");
    execute({"snapshot",
             fingerprint("snapshot", snap_opts.dump() + outputs_digest("ingest") + outputs_digest("segment") +
                                         outputs_digest("mesh") + outputs_digest("attach") +
                                         outputs_digest("guide")),
             [&](const fs::path& staging) { write_snapshots(staging); }});
  }

  /// mesh builds surfaces, organ walls and tetrahedra from the segmentation and exports them
  /// into meshes/<organ>/ with the calibrated materials in the solver files.
  void write_meshes(const fs::path& staging) {
    const MeshStageOptions& mo = case_.stages.mesh;
    MeshStageInputs in;
    in.labels = &segmentation();
    in.labels_file = layout_.labels();
    for (const auto& o : case_.organs) {
      in.organs.push_back(mesh_spec(case_.registry.at(o.name), mo.wall_mm));
      in.band_organs.push_back(o.name);
    }
    in.registry = &case_.registry;
    in.truth = [this]() { return phantom_truth(); };
    in.ct = [this]() -> const Volume* { return &volume(); };
    in.guide = case_.stages.guide;
    in.probe_lps_mm = case_.stages.simulate.probe_lps_mm;
    in.probe_depth_mm = case_.stages.simulate.probe_depth_mm;
    model_.meshes = mesh_stage(in, mo, OutputLayout{staging}.meshes_dir(), progress_);
  }

  /// simulate: the organs' load cases in CalculiX (stages/simulate_stage.h).
  void write_simulations(const fs::path& staging) {
    SimulateStageInputs in;
    in.out_dir = out_;
    in.registry = &case_.registry;
    for (const auto& o : case_.organs) in.organs.push_back(o.name);
    in.picture_width_px = case_.stages.snapshot.width_px;
    in.picture_height_px = case_.stages.snapshot.height_px;
    simulate_stage(in, case_.stages.simulate, staging, progress_);
  }

  /// The segmentation: this run's, else read from labels.nii.gz (its reader).
  const LabelMap& segmentation() {
    if (!model_.labels) model_.labels = read_label_map(layout_.labels());
    return *model_.labels;
  }

  /// guide: the guidance paths from this run's label map and surfaces (in memory), else from the
  /// files of the stages it reuses.
  void write_paths(const fs::path& staging) {
    std::optional<GuideFiles> files;
    GuideInputs in;
    if (model_.labels && model_.meshes) {
      in.labels = &*model_.labels;
      in.surface = [this](const std::string& organ, const std::string& name) {
        for (const auto& o : model_.meshes->organs)
          if (o.spec.name == organ)
            for (const auto& s : o.surfaces)
              if (s.name == name) return s.mesh;
        throw InputError(ExitCode::input_not_found, "the mesh stage made no surface " + name, layout_.organ_dir(organ),
                         "check the mesh stage's warnings");
      };
      in.truth = phantom_truth();
    } else {
      files = read_guide_inputs(out_, case_.stages.mesh.ras);
      in = files->inputs();
    }
    in.ct = [this]() -> const Volume* { return &volume(); };
    GuidePaths made = write_guidance_paths(in, OutputLayout{staging}.paths_dir(), case_.stages.guide, case_.registry);
    for (const auto& f : made.files) spdlog::info("guide: paths/{}", f);
    model_.paths = std::move(made.paths);
  }

  /// snapshot: the review pictures from this run's model where it is in memory (review/snapshot_stage.h).
  void write_snapshots(const fs::path& staging) {
    SnapshotStageInputs in;
    in.out_dir = out_;
    in.ct_path = input_;
    in.registry = &case_.registry;
    in.case_name = case_.name;
    for (const auto& o : case_.organs) in.organs.push_back(o.name);
    if (model_.ct) in.ct = &*model_.ct;
    if (model_.labels) in.labels = &*model_.labels;
    if (model_.meshes && !case_.stages.mesh.ras) in.meshes = &*model_.meshes;  // the files are in RAS then
    if (model_.phantom_truth) in.phantom_truth = &*model_.phantom_truth;
    if (model_.contours) in.contours = &*model_.contours;
    if (model_.paths) in.paths = &*model_.paths;
    if (model_.materials) in.materials = &*model_.materials;
    snapshot_stage(in, case_.stages.snapshot, staging, progress_);
  }

  /// The calibrated material of each organ region (physics presets, thesis tables), as written
  /// to materials.json and into the solver files.
  static nlohmann::json materials_json(const CaseFile& c) {
    std::vector<std::string> organs;
    for (const auto& o : c.organs) organs.push_back(o.name);
    return materials_json_for(c.registry, organs, c.stages.mesh.material_band);
  }

  /// The phantom's ground truth: this run's, else read from its file (null when there is none).
  const LabelMap* phantom_truth() {
    if (!model_.phantom_truth && fs::exists(layout_.phantom_truth())) model_.phantom_truth = read_label_map(layout_.phantom_truth());
    return model_.phantom_truth ? &*model_.phantom_truth : nullptr;
  }

  /// The ingested volume: kept from the ingest stage, or read again when that stage was reused.
  const Volume& volume() {
    if (!model_.ct) {
      spdlog::info("reading the input again for the stages that need it");
      model_.ct = ingest(input_, case_.ingest, progress_).volume;
    }
    return *model_.ct;
  }

  /// Digest of the files a stage of this run produced (or reused): what later stages depend on.
  std::string outputs_digest(const std::string& stage) const {
    for (const auto& r : records_)
      if (r.name == stage) {
        std::string all;
        for (const auto& o : r.outputs) all += o.value("sha256", "") + "\n";
        return sha256_hex(all);
      }
    return {};
  }

  /// segment: labels.nii.gz, contours and overlays (stages/segment_stage.h), from the organs'
  /// seeds as the ingest stage resolved them.
  void write_segmentation(const fs::path& staging) {
    SegmentStageInputs in;
    in.ct = &volume();
    const std::vector<OrganSeed>& seeds = organ_seeds();
    for (const OrganSpec& spec : case_.organs) {
      SegmentStageOrgan o;
      o.name = spec.name;
      for (const OrganSeed& s : seeds)
        if (s.organ == spec.name) o.seed_lps_mm = s.lps_mm;
      o.seed_from_case = spec.seed_lps_mm.has_value() || spec.seed_ijk.has_value();
      if (!spec.label_map.empty()) o.label_map = spec.label_map == "phantom" ? layout_.phantom_truth() : fs::path(spec.label_map);
      in.organs.push_back(std::move(o));
    }
    in.registry = &case_.registry;
    in.preset_overrides_toml = case_.segment_presets_toml;
    in.registry_toml = case_.registry_toml;
    SegmentStageResult r = segment_stage(in, staging, progress_);
    model_.labels = std::move(r.labels);
    model_.contours = std::move(r.contours);
  }

  /// Ingest writes ingest.json: what was read, its geometry and digest, and the organ seeds
  /// resolved to LPS mm.
  void write_ingest(const fs::path& staging) {
    IngestStageInputs in;
    in.input = input_;
    in.organs = case_.organs;
    in.registry = &case_.registry;
    in.case_file = case_.source;
    std::optional<std::map<std::string, Eigen::Vector3d>> read;
    if (case_.synthesize_phantom)
      in.phantom_seeds = model_.phantom_seeds ? &*model_.phantom_seeds : &read.emplace(read_seeds(layout_.phantom_seeds()));
    IngestStageResult r = ingest_stage(in, case_.ingest, staging, progress_);
    input_json_ = std::move(r.input);
    model_.seeds = std::move(r.seeds);
    model_.ct = std::move(r.volume);
  }

  /// The organ seeds: this run's ingest stage's, else read back from its ingest.json.
  const std::vector<OrganSeed>& organ_seeds() {
    if (!model_.seeds) model_.seeds = read_ingest_seeds(layout_.ingest());
    return *model_.seeds;
  }

  // The organ registry and presets in force: the case's, else the embedded ones (a build with
  // other embedded presets must not reuse a segmentation made with the old ones).
  std::string registry_digest() const {
    return sha256_hex(case_.registry_toml.empty() ? std::string(builtin_registry_toml()) : case_.registry_toml);
  }

  // The build is part of every stage's inputs: an upgraded organsmith of the same version string
  // (a development build) recomputes rather than reusing what another build wrote.
  std::string fingerprint(const std::string& stage, const std::string& inputs) const {
    return sha256_hex(tool_version() + "\n" + tool_git_commit() + "\n" + stage + "\n" + inputs);
  }

  const nlohmann::json* previous_stage(const std::string& name) const {
    if (!previous_.contains("stages")) return nullptr;
    for (const auto& s : previous_["stages"])
      if (s.value("name", "") == name) return &s;
    return nullptr;
  }

  void execute(const Stage& stage) {
    if (done_) return;
    done_ = stage.name == options_.until;
    progress_.check_cancelled();
    StageRecord rec;
    rec.name = stage.name;
    rec.fingerprint = stage.fingerprint;
    const nlohmann::json* prev = previous_stage(stage.name);
    started_ = started_ || options_.from.empty() || stage.name == options_.from;
    if (!started_) {  // before --from: what an earlier command wrote, as it is
      // A stage that never ran here is passed over; the stages from --from on say what they miss.
      if (!prev || prev->value("status", "") == "interrupted" || !prev->contains("outputs")) return;
      rec.skipped = true;
      rec.fingerprint = prev->value("fingerprint", "");
      rec.outputs = (*prev)["outputs"];
      rec.seconds = prev->value("seconds", 0.0);
      rec.peak_rss_mib = prev->value("peak_rss_mib", 0.0);
      if (stage.name == "ingest" && previous_.contains("input")) input_json_ = previous_["input"];
      out_dir_.keep(record_json(rec));
      records_.push_back(rec);
      return;
    }
    if (!options_.force && prev && prev->value("fingerprint", "") == stage.fingerprint &&
        outputs_intact(prev->value("outputs", nlohmann::json()), out_)) {
      rec.skipped = true;
      rec.outputs = (*prev)["outputs"];
      rec.seconds = prev->value("seconds", 0.0);
      rec.peak_rss_mib = prev->value("peak_rss_mib", 0.0);
      if (stage.name == "ingest" && previous_.contains("input")) input_json_ = previous_["input"];
      spdlog::info("stage {}: unchanged since the last run, skipped (--force to redo)", stage.name);
      out_dir_.keep(record_json(rec));
      records_.push_back(rec);
      return;
    }
    spdlog::info("stage {}: running", stage.name);
    const bool per_stage_peak = reset_peak_rss();
    const auto t0 = std::chrono::steady_clock::now();
    out_dir_.set_header(manifest_header());
    rec.outputs = out_dir_.commit(stage.name, stage.run, record_json(rec));
    rec.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    rec.peak_rss_mib = peak_rss_mib();
    if (!per_stage_peak) spdlog::debug("peak memory is the process peak (cannot reset VmHWM)");
    spdlog::info("stage {}: done in {:.2f} s, peak {:.0f} MiB, {} file(s)", stage.name, rec.seconds,
                 rec.peak_rss_mib, rec.outputs.size());
    out_dir_.keep(record_json(rec));
    records_.push_back(rec);
  }

  static nlohmann::json record_json(const StageRecord& r) {
    return {{"name", r.name},
            {"fingerprint", r.fingerprint},
            {"status", r.skipped ? "skipped (unchanged)" : "ran"},
            {"seconds", r.seconds},
            {"peak_rss_mib", r.peak_rss_mib},
            {"outputs", r.outputs}};
  }

  /// Everything of the manifest but the stage records (OutputDir keeps those).
  nlohmann::json manifest_header() const {
    nlohmann::json m;
    m["case"] = to_json(case_);
    m["input"] = input_json_;
    m["coordinates"] = "LPS millimetres (DICOM patient coordinates)";
    if (!case_.organs.empty()) m["materials"] = materials_json_["regions"];
    return m;
  }

  const CaseFile& case_;
  RunOptions options_;
  Progress& progress_;
  OutputDir out_dir_;
  fs::path out_;
  OutputLayout layout_;  // paths in the output directory (and, with root = staging, in a stage's staging folder)
  nlohmann::json previous_;
  nlohmann::json materials_json_;  // the regions' calibrated laws (materials.json, the mesh stage's fingerprint)
  std::vector<StageRecord> records_;
  fs::path input_;
  RunModel model_;  // what the stages of this run made, handed on in memory
  bool done_ = false;     // set once the --until stage has run
  bool started_ = false;  // set at the --from stage
  nlohmann::json input_json_ = nlohmann::json::object();
};

}  // namespace

const std::vector<std::string>& stage_names() {
  static const std::vector<std::string> names = {"phantom", "ingest", "segment", "mesh", "attach", "guide", "simulate",
                                                  "snapshot"};
  return names;
}

RunSummary run_case(const CaseFile& c, const RunOptions& options, Progress& progress) {
  const auto& names = stage_names();
  for (const std::string* s : {&options.until, &options.from})
    if (!s->empty() && std::find(names.begin(), names.end(), *s) == names.end()) {
      std::string list;
      for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
      throw UsageError("unknown stage '" + *s + "'", "stages: " + list);
    }
  return Runner(c, options, progress).run();
}

}  // namespace organsmith
