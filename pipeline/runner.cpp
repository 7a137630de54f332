#include "pipeline/runner.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "core/memory.h"
#include "core/sha256.h"
#include "organsmith_version.h"  // generated at build time: version and git commit
#include "pipeline/guide_stage.h"
#include "pipeline/ingest.h"
#include "pipeline/phantom.h"
#include "pipeline/image_io.h"
#include "pipeline/phantom_files.h"
#include "meshing/export.h"
#include "meshing/mesh.h"
#include "physics/contact.h"
#include "physics/presets.h"
#include "pipeline/output_dir.h"
#include "pipeline/output_scene.h"
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

std::string tool_version() { return ORGANSMITH_VERSION_STRING; }
std::string tool_git_commit() { return ORGANSMITH_GIT_COMMIT; }

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

nlohmann::json grid_json(const ImageGrid& g) {
  nlohmann::json dir = nlohmann::json::array();
  for (int c = 0; c < 3; ++c) dir.push_back({g.direction_lps(0, c), g.direction_lps(1, c), g.direction_lps(2, c)});
  return {{"size_vox", g.size_vox},
          {"spacing_mm", {g.spacing_mm.x(), g.spacing_mm.y(), g.spacing_mm.z()}},
          {"origin_lps_mm", {g.origin_lps_mm.x(), g.origin_lps_mm.y(), g.origin_lps_mm.z()}},
          {"direction_lps_columns", dir}};
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
        previous_(out_dir_.previous_manifest()) {}

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
  void run_stages() {
    fs::path input = case_.input;
    if (case_.synthesize_phantom) {
      const nlohmann::json opts = to_json(case_)["phantom"];
      execute({"phantom", fingerprint("phantom", opts.dump()), [&](const fs::path& staging) {
                 const Phantom ph = synthesize_phantom(case_.phantom, progress_);
                 fs::create_directories(staging / "phantom");
                 write_phantom_files(ph, case_.phantom, staging / "phantom", progress_);
               }});
      input = out_ / "phantom" / "dicom";
    }
    input_ = input;
    const nlohmann::json ingest_opts = to_json(case_)["ingest"];
    const std::string organs = to_json(case_)["organs"].dump();
    execute({"ingest", fingerprint("ingest", ingest_opts.dump() + organs + input_stat_digest(input)),
             [&](const fs::path& staging) { write_ingest(staging); }});

    if (!case_.organs.empty()) {
      const nlohmann::json seg_opts = stage_json(case_, "segment");
      execute({"segment", fingerprint("segment", seg_opts.dump() + registry_digest() + outputs_digest("ingest")),
               [&](const fs::path& staging) { write_segmentation(staging); }});
      const nlohmann::json mesh_opts = stage_json(case_, "mesh");
      execute({"mesh", fingerprint("mesh", mesh_opts.dump() + registry_digest() + outputs_digest("segment")),
               [&](const fs::path& staging) { write_meshes(staging); }});
      execute({"attach", fingerprint("attach", to_json(case_)["organs"].dump() + materials_json().dump()),
               [&](const fs::path& staging) {
                 write_text_atomic(staging / "materials.json", materials_json().dump(2) + "\n");
               }});
      // guide: guidance paths (trachea centreline and incision, gallbladder dissection) in paths/.
      execute({"guide", fingerprint("guide", stage_json(case_, "guide").dump() + outputs_digest("phantom") +
                                                 outputs_digest("segment") + outputs_digest("mesh")),
               [&](const fs::path& staging) {
                 for (const auto& f : write_guidance_paths(out_, staging / "paths", case_.stages.guide, case_.registry))
                   spdlog::info("guide: paths/{}", f);
               }});
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
    const LabelMap labels = read_label_map(out_ / "labels.nii.gz");
    const MeshStageOptions& mo = case_.stages.mesh;
    MeshOptions options;
    options.organs.clear();
    for (const auto& o : case_.organs) options.organs.push_back(mesh_spec(case_.registry.at(o.name), mo.wall_mm));
    options.edge_mm = mo.edge_mm;
    options.tetrahedra = mo.tetrahedra;
    // "report" (the default): a failing figure is a warning and quality.json records it.
    options.enforce_quality = mo.quality_gate == "enforce";
    const OrganMeshes meshes = mesh_organs(labels, options, progress_);
    for (const auto& w : meshes.warnings) spdlog::warn("mesh: {}", w);
    for (const auto& organ : meshes.organs) {
      for (const auto& w : organ.warnings) spdlog::warn("mesh: {}", w);  // each names its organ
      for (const auto& f : organ.volume_quality.failures)
        spdlog::warn("mesh: {}: tetrahedral quality gate not met: {}", organ.spec.name, f);
      for (const auto& surf : organ.surfaces)
        for (const auto& f : surf.quality.failures) spdlog::warn("mesh: {}: {}", surf.name, f);
    }
    ExportOptions ex;
    ex.formats = mo.formats;
    ex.ras = mo.ras;
    ex.materials = region_materials(case_.registry);
    std::vector<std::string> warnings;
    fs::create_directories(staging / "meshes");
    export_meshes(meshes, staging / "meshes", ex, &warnings);
    for (const auto& w : warnings) spdlog::warn("mesh: {}", w);
  }

  /// snapshot renders the review PNGs of everything the earlier stages left in the output.
  void write_snapshots(const fs::path& staging) {
    // The scene loader reads the case (organs, input) from the manifest: record the stages so
    // far first (the final manifest replaces it when the run ends).
    out_dir_.write_manifest(manifest_header());
    LoadFlags flags;
    flags.ct = input_.string();
    OutputScene os;
    load_output_scene(out_, flags, os, progress_);
    for (const auto& m : os.missing) spdlog::info("snapshot: not found: {}", m);
    fs::create_directories(staging / "snapshots");
    SnapshotOptions so;
    so.width_px = case_.stages.snapshot.width_px;
    so.height_px = case_.stages.snapshot.height_px;
    so.views.clear();
    for (const auto& v : case_.stages.snapshot.views) so.views.push_back(parse_view_kind(v));
    const auto written = render_snapshots(os.scene, so, staging / "snapshots", progress_);
    spdlog::info("snapshot: {} views", written.size());
  }

  /// The calibrated material of each organ region (physics presets, thesis tables), as written
  /// to materials.json and into the solver files.
  nlohmann::json materials_json() const {
    std::vector<std::string> organs;
    for (const auto& o : case_.organs) organs.push_back(o.name);
    return materials_json_for(case_.registry, organs);
  }

  /// The ingested volume: kept from the ingest stage, or read again when that stage was reused.
  const Volume& volume() {
    if (!volume_) {
      spdlog::info("reading the input again for the stages that need it");
      volume_ = ingest(input_, case_.ingest, progress_).volume;
    }
    return *volume_;
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

  /// segment writes labels.nii.gz (input grid), contours_<organ>.json and overlays/*.png: the
  /// organs with a segmentation preset found by the GVF snakes, the others taken from their label
  /// maps.
  void write_segmentation(const fs::path& staging) {
    std::ifstream in(out_ / "ingest.json");
    const nlohmann::json ingest_json = nlohmann::json::parse(in);
    std::vector<OrganRequest> requests;
    for (const auto& o : ingest_json.at("organs")) {
      OrganRequest r;
      r.organ = o.at("name").get<std::string>();
      const OrganSpec* spec = case_organ(r.organ);
      if (spec && !spec->label_map.empty()) continue;
      if (o.contains("seed_lps_mm"))
        r.seed_lps_mm = Eigen::Vector3d(o["seed_lps_mm"][0].get<double>(), o["seed_lps_mm"][1].get<double>(),
                                        o["seed_lps_mm"][2].get<double>());
      // An organ found automatically ignores a phantom seed (a hint for reviewers only).
      if (!case_.registry.at(r.organ).needs_seed && !case_has_seed(r.organ)) r.seed_lps_mm.reset();
      requests.push_back(std::move(r));
    }
    SegmentOptions options;
    options.preset_overrides_toml = case_.segment_presets_toml;
    options.registry_toml = case_.registry_toml;
    SegmentationResult result = segment_organs(volume(), requests, options, progress_);
    for (const auto& spec : case_.organs) {
      if (spec.label_map.empty()) continue;
      const fs::path file = spec.label_map == "phantom" ? out_ / "phantom" / "ground_truth.nii.gz" : spec.label_map;
      const OrganInfo& info = case_.registry.at(spec.name);
      const double ml = merge_organ_from_label_map(result.labels, read_label_map(file), info.label);
      if (ml <= 0)
        throw InputError(ExitCode::organ_not_found,
                         "organ " + spec.name + " (label " + std::to_string(info.label) + ") is absent from its label map",
                         file, "check the label map and the organ's label in the organ registry");
      spdlog::info("segment: {} {:.1f} ml from the label map {}", spec.name, ml, file.filename().string());
    }
    write_label_map(result.labels, staging / "labels.nii.gz");
    for (const auto& organ : result.organs) {
      write_text_atomic(staging / ("contours_" + organ.organ + ".json"), contours_json(organ));
      spdlog::info("segment: {} {:.1f} ml on slices {}–{}", organ.organ, organ.volume_ml, organ.first_slice,
                   organ.last_slice);
      for (const auto& note : organ.notes) spdlog::info("segment: {}: {}", organ.organ, note);
    }
    fs::create_directories(staging / "overlays");
    write_overlays(volume(), result, staging / "overlays");
  }

  const OrganSpec* case_organ(const std::string& name) const {
    for (const auto& o : case_.organs)
      if (o.name == name) return &o;
    return nullptr;
  }

  bool case_has_seed(const std::string& organ) const {
    for (const auto& o : case_.organs)
      if (o.name == organ) return o.seed_lps_mm.has_value() || o.seed_ijk.has_value();
    return false;
  }

  /// Ingest writes ingest.json: what was read, its geometry and digest, and the organ seeds
  /// resolved to LPS mm.
  void write_ingest(const fs::path& staging) {
    IngestResult r = ingest(input_, case_.ingest, progress_);
    for (const auto& w : r.report.warnings) spdlog::warn("ingest: {}", w);
    input_digest_ = volume_digest(r.volume);
    nlohmann::json j;
    j["format"] = r.report.format;
    j["digest_sha256"] = input_digest_;
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
    j["organs"] = resolve_seeds(r.volume.grid);
    input_json_ = {{"format", j["format"]}, {"digest_sha256", input_digest_}, {"grid", j["grid"]}};
    write_text_atomic(staging / "ingest.json", j.dump(2) + "\n");
    volume_ = std::move(r.volume);
  }

  nlohmann::json resolve_seeds(const ImageGrid& grid) {
    std::map<std::string, Eigen::Vector3d> phantom_seeds;
    if (case_.synthesize_phantom) phantom_seeds = read_seeds(out_ / "phantom" / "seeds.json");
    nlohmann::json organs = nlohmann::json::array();
    for (const auto& o : case_.organs) {
      nlohmann::json oj = {{"name", o.name}};
      std::optional<Eigen::Vector3d> p;
      std::string source;
      if (o.seed_lps_mm) p = o.seed_lps_mm, source = "case file (LPS mm)";
      else if (o.seed_ijk) p = grid.index_to_lps_mm(*o.seed_ijk), source = "case file (voxel ijk)";
      else if (phantom_seeds.count(o.name)) p = phantom_seeds[o.name], source = "phantom seeds.json";
      else if (!o.label_map.empty()) source = "label map";
      else source = case_.registry.at(o.name).needs_seed ? "none" : "automatic";
      if (p) {
        const Eigen::Vector3d ijk = grid.lps_mm_to_index(*p);
        if (!grid.contains(std::lround(ijk.x()), std::lround(ijk.y()), std::lround(ijk.z())))
          throw InputError(ExitCode::bad_seed, "the seed of organ '" + o.name + "' lies outside the image",
                           case_.source, "check the seed: LPS mm as shown by `organsmith info`");
        oj["seed_lps_mm"] = {p->x(), p->y(), p->z()};
        oj["seed_ijk"] = {ijk.x(), ijk.y(), ijk.z()};
      }
      oj["seed_source"] = source;
      organs.push_back(oj);
    }
    return organs;
  }

  /// The case's own organ registry, when it has one (empty otherwise: the embedded registry is
  /// part of the tool version).
  std::string registry_digest() const { return case_.registry_toml.empty() ? "" : sha256_hex(case_.registry_toml); }

  std::string fingerprint(const std::string& stage, const std::string& inputs) const {
    return sha256_hex(tool_version() + "\n" + stage + "\n" + inputs);
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
    if (!case_.organs.empty()) m["materials"] = materials_json()["regions"];
    return m;
  }

  const CaseFile& case_;
  RunOptions options_;
  Progress& progress_;
  OutputDir out_dir_;
  fs::path out_;
  nlohmann::json previous_;
  std::vector<StageRecord> records_;
  std::string input_digest_;
  fs::path input_;
  std::optional<Volume> volume_;
  bool done_ = false;     // set once the --until stage has run
  bool started_ = false;  // set at the --from stage
  nlohmann::json input_json_ = nlohmann::json::object();
};

}  // namespace

fs::path make_staging_dir(const fs::path& final_path) {
  std::random_device rd;
  for (int attempt = 0; attempt < 100; ++attempt) {
    std::ostringstream name;
    name << final_path.filename().string() << ".staging-" << std::hex << rd();
    const fs::path p = final_path.parent_path() / name.str();
    std::error_code ec;
    if (fs::create_directories(p, ec)) return p;
    if (ec) throw OutputError("cannot create a staging directory: " + ec.message(), p,
                              "check that the output directory is writable");
  }
  throw OutputError("cannot create a unique staging directory", final_path);
}

void write_text_atomic(const fs::path& path, const std::string& text) { write_file_atomic(path, text); }

const std::vector<std::string>& stage_names() {
  static const std::vector<std::string> names = {"phantom", "ingest", "segment", "mesh", "attach", "guide", "snapshot"};
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

// ---- guide stage (guidance paths; also `organsmith guide`) -----------------------------------------

const std::vector<std::string>& builtin_path_names() {
  static const std::vector<std::string> names = {"trachea_centerline", "trachea_incision", "gallbladder_dissection"};
  return names;
}

std::vector<std::string> write_guidance_paths(const fs::path& out_dir, const fs::path& dest_dir,
                                              const GuideStageOptions& options, const OrganRegistry& registry) {
  for (const auto& n : options.only)
    if (std::find(builtin_path_names().begin(), builtin_path_names().end(), n) == builtin_path_names().end())
      throw UsageError("unknown path '" + n + "'", "paths: trachea_centerline, trachea_incision, gallbladder_dissection");
  const fs::path truth_file = out_dir / "phantom" / "ground_truth.nii.gz";
  fs::path labels_file = out_dir / "labels.nii.gz";
  if (!fs::exists(labels_file) && fs::exists(truth_file)) labels_file = truth_file;
  if (!fs::exists(labels_file))
    throw InputError(ExitCode::input_not_found, "no label map in the output directory", out_dir / "labels.nii.gz",
                     "run `organsmith run` (or `organsmith segment`) into this directory first");
  const LabelMap labels = read_label_map(labels_file);
  auto wanted = [&](const std::string& n, std::uint8_t label) {
    if (!options.only.empty()) return std::find(options.only.begin(), options.only.end(), n) != options.only.end();
    return labels.count(label) > 0;
  };
  auto surface = [&](const std::string& organ, const std::string& name) {
    const fs::path f = out_dir / "meshes" / organ / (name + ".stl");
    if (!fs::exists(f))
      throw InputError(ExitCode::input_not_found, "missing organ surface " + name + ".stl", f,
                       "run the mesh stage (`organsmith run`, or `organsmith mesh … --out " + (out_dir / "meshes").string() +
                           "`) first");
    return read_stl(f);
  };
  fs::create_directories(dest_dir);
  std::vector<std::string> written;
  auto emit = [&](const Polyline& line, const std::vector<std::pair<std::string, double>>& props) {
    write_text_atomic(dest_dir / (line.name + ".json"), physics::path_json(line, props));
    write_text_atomic(dest_dir / (line.name + ".vtp"), physics::path_vtp(line));
    written.push_back(line.name + ".json");
    written.push_back(line.name + ".vtp");
  };
  // The paths belong to two organs of the registry; an organ a registry lacks has no paths.
  const OrganInfo* trachea = registry.find("trachea");
  const OrganInfo* gallbladder = registry.find("gallbladder");
  const OrganInfo* liver_info = registry.find("liver");
  const bool want_centerline = trachea && wanted("trachea_centerline", trachea->label);
  const bool want_incision = trachea && wanted("trachea_incision", trachea->label);
  if (want_centerline || want_incision) {
    physics::CenterlineOptions co = options.centerline;
    co.label = trachea->label;
    const physics::Centerline cl = physics::trachea_centerline(labels, co);
    if (want_centerline)
      emit(cl.line, {{"cranial_extension_mm", cl.end_extension_mm[0]},
                     {"caudal_extension_mm", cl.end_extension_mm[1]},
                     {"spacing_mm", options.centerline.spacing_mm}});
    if (want_incision) {
      const physics::SurfaceIndex wall({surface(trachea->name, trachea->wall_surface())});
      const physics::IncisionPath inc = physics::trachea_incision_path(cl, wall, options.incision);
      emit(inc.line, {{"length_mm", inc.length_mm},
                      {"first_ring", double(inc.first_ring)},
                      {"last_ring", double(inc.last_ring)},
                      {"ring_pitch_mm", options.incision.ring_pitch_mm},
                      {"start_along_centerline_mm", inc.start_arc_mm},
                      {"end_along_centerline_mm", inc.end_arc_mm},
                      {"max_wall_distance_mm", inc.max_wall_distance_mm}});
    }
  }
  if (gallbladder && wanted("gallbladder_dissection", gallbladder->label)) {
    const SurfaceMesh gb = surface(gallbladder->name, gallbladder->surfaces().front());
    physics::DissectionOptions dopt = options.dissection;
    std::optional<LabelMap> truth;
    const LabelMap* liver = nullptr;
    if (liver_info) {
      dopt.liver_label = liver_info->label;
      if (labels.count(dopt.liver_label) > 0) {
        liver = &labels;
      } else if (fs::exists(truth_file)) {
        truth = read_label_map(truth_file);
        // The phantom's ground truth is in the same patient frame (LPS mm); its grid may differ.
        if (truth->count(dopt.liver_label) > 0) liver = &*truth;
      }
    }
    const physics::DissectionPath d = physics::gallbladder_dissection_path(gb, liver, dopt);
    spdlog::info("guide: gallbladder liver bed from the {}{}", d.bed_source,
                 d.bed_source == "liver label" && liver != &labels ? " of the phantom ground truth" : "");
    emit(d.line, {{"bed_area_mm2", d.bed_area_mm2},
                  {"bed_from_liver_label", d.bed_source == "liver label" ? 1.0 : 0.0},
                  {"max_surface_distance_mm", d.max_surface_distance_mm}});
  }
  return written;
}

}  // namespace organsmith
