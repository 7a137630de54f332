// The organsmith command line.

#include "core/errors.h"
#include "pipeline/output/tool_info.h"
#include "core/format.h"
#include "pipeline/case/case_file.h"
#include "pipeline/cli/commands.h"
#include "pipeline/io/ingest.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/phantom/phantom.h"
#include "pipeline/phantom/phantom_files.h"
#include "pipeline/run/runner.h"
#include "pipeline/run/terminal_progress.h"

#include <cmath>
#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>

using namespace organsmith;
namespace fs = std::filesystem;

namespace {

std::string vec(const Eigen::Vector3d& v, int digits = 2) {
  return "(" + format_fixed(v.x(), digits) + ", " + format_fixed(v.y(), digits) + ", " + format_fixed(v.z(), digits) + ")";
}

/// Three-letter code of the patient directions the i, j, k axes point to (e.g. "LPS").
std::string orientation_code(const Eigen::Matrix3d& d) {
  std::string code;
  for (int c = 0; c < 3; ++c) {
    int axis = 0;
    d.col(c).cwiseAbs().maxCoeff(&axis);
    const bool pos = d(axis, c) > 0;
    code += pos ? "LPS"[axis] : "RAI"[axis];
  }
  return code;
}

struct IngestFlags {
  std::string series;
  bool allow_modality = false;
  std::int64_t max_memory_mb = 0;

  void add_to(CLI::App* app) {
    app->add_option("--series", series, "DICOM SeriesInstanceUID to read (default: the CT series with the most slices)");
    app->add_flag("--allow-modality", allow_modality, "read a non-CT series (values are then not HU)");
    app->add_option("--max-memory-mb", max_memory_mb, "memory budget for the decoded volume in MiB (default: 60 % of RAM)")
        ->check(CLI::NonNegativeNumber);
  }
  void apply(IngestOptions& o) const {
    if (!series.empty()) o.series_uid = series;
    if (allow_modality) o.allow_modality = true;
    if (max_memory_mb > 0) o.max_memory_bytes = max_memory_mb << 20;
  }
};

int cmd_info(const fs::path& input, const IngestFlags& flags, bool as_json) {
  IngestOptions options;
  flags.apply(options);
  TerminalProgress progress(spdlog::get_level() >= spdlog::level::warn);
  const IngestResult r = ingest(input, options, progress);
  progress.finish();
  const ImageGrid& g = r.volume.grid;
  if (as_json) {
    nlohmann::json j = {{"format", r.report.format},
                        {"size_vox", g.size_vox},
                        {"spacing_mm", {g.spacing_mm.x(), g.spacing_mm.y(), g.spacing_mm.z()}},
                        {"origin_lps_mm", {g.origin_lps_mm.x(), g.origin_lps_mm.y(), g.origin_lps_mm.z()}},
                        {"orientation", orientation_code(g.direction_lps)},
                        {"hu_range", {r.report.hu_min, r.report.hu_max}},
                        {"warnings", r.report.warnings}};
    if (r.report.format.rfind("DICOM", 0) == 0)
      j["series"] = {{"series_uid", r.report.series.series_uid}, {"modality", r.report.series.modality},
                     {"description", r.report.series.description}, {"slices", r.report.series.files},
                     {"transfer_syntax", r.report.series.transfer_syntax}};
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  const auto [lo, hi] = g.bounds_lps_mm();
  std::cout << "format       " << r.report.format << "\n";
  if (r.report.format.rfind("DICOM", 0) == 0) {
    const auto& s = r.report.series;
    std::cout << "series       " << (s.series_uid.empty() ? "(no SeriesInstanceUID)" : s.series_uid) << "\n"
              << "             " << s.modality << ", " << s.files << " slices"
              << (s.description.empty() ? "" : ", \"" + s.description + "\"") << ", " << s.transfer_syntax << "\n";
  }
  std::cout << "size         " << g.size_vox[0] << " × " << g.size_vox[1] << " × " << g.size_vox[2] << " voxels\n"
            << "spacing      " << format_fixed(g.spacing_mm.x(), 3) << " × " << format_fixed(g.spacing_mm.y(), 3) << " × "
            << format_fixed(g.spacing_mm.z(), 3) << " mm\n"
            << "orientation  " << orientation_code(g.direction_lps) << " (axes i, j, k point to these patient directions)\n"
            << "origin       " << vec(g.origin_lps_mm) << " mm LPS (centre of voxel 0,0,0)\n"
            << "extent       " << vec(lo) << " to " << vec(hi) << " mm LPS\n"
            << "HU range     " << format_fixed(r.report.hu_min, 0) << " to " << format_fixed(r.report.hu_max, 0) << "\n";
  for (const auto& o : r.report.other_series)
    std::cout << "also seen    " << o.series_uid << " (" << o.modality << ", " << o.files << " files"
              << (o.description.empty() ? "" : ", \"" + o.description + "\"") << ") — read it with --series\n";
  for (const auto& w : r.report.warnings) std::cout << "warning      " << w << "\n";
  return 0;
}

int cmd_phantom(const fs::path& out, const PhantomOptions& options) {
  TerminalProgress progress(spdlog::get_level() >= spdlog::level::warn);
  const auto t0 = std::chrono::steady_clock::now();
  OutputDir dir(out, OutputDirOptions{.command = "phantom"});
  const fs::path final_dir = dir.path();
  dir.commit("phantom", [&](const fs::path& staging) {
    const Phantom ph = synthesize_phantom(options, progress);
    write_phantom_files(ph, options, staging, progress);
  });
  progress.finish();
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  spdlog::info("phantom written to {} in {:.2f} s: dicom/ (CT series), ground_truth.nii.gz, seeds.json",
               final_dir.string(), s);
  return 0;
}

void list_written(const RunSummary& summary) {
  std::cout << "organsmith wrote into " << summary.out_dir.string() << ":\n";
  for (const auto& st : summary.stages) {
    std::map<std::string, int> per_dir;
    std::cout << "  stage " << st.name << (st.skipped ? " (unchanged, reused)" : "") << ", "
              << format_fixed(st.seconds) << " s:\n";
    for (const auto& o : st.outputs) {
      const fs::path p = o["path"].get<std::string>();
      if (p.parent_path().filename() == "dicom") {
        ++per_dir[p.parent_path().generic_string()];
        continue;
      }
      std::cout << "    " << p.generic_string() << "\n";
    }
    for (const auto& [dir, n] : per_dir) std::cout << "    " << dir << "/ (" << n << " DICOM slices)\n";
  }
  std::cout << "  manifest.json\n";
  // The solver runs on request (a minute or so per organ): say how, where a mesh stage ran or was
  // reused and simulate was not part of this run.
  const auto ran = [&](const char* name) {
    return std::any_of(summary.stages.begin(), summary.stages.end(), [&](const auto& st) { return st.name == name; });
  };
  if (ran("mesh") && !ran("simulate"))
    std::cout << "the organs' load cases in CalculiX (about a minute per organ): organsmith simulate "
              << summary.out_dir.string() << "\n";
}

int cmd_run(const std::string& case_path, const std::string& out, bool force, const std::string& until,
            bool allow_quality_failures, const IngestFlags& flags) {
  CaseFile c = case_path.empty() ? default_case() : load_case_file(case_path);
  if (!out.empty()) c.out_dir = out;
  if (allow_quality_failures) c.stages.mesh.quality_gate = "report";
  flags.apply(c.ingest);
  spdlog::info("case '{}': {} → {}", c.name, c.synthesize_phantom ? std::string("synthetic phantom") : c.input.string(),
               fs::absolute(c.out_dir).string());
  TerminalProgress progress(spdlog::get_level() >= spdlog::level::warn);
  RunOptions options;
  options.force = force;
  options.until = until;
  const RunSummary summary = run_case(c, options, progress);
  progress.finish();
  list_written(summary);
  return 0;
}

/// The first option value that reads as a number but not a finite one ("nan", "inf", "1e999"),
/// or empty. CLI11's range checks compare, and every comparison with NaN is false, so such a
/// value would pass them and reach a stage; no option of organsmith takes one.
std::string non_finite_option_value(int argc, char** argv) {
  for (int a = 1; a < argc; ++a) {
    std::string arg = argv[a];
    std::string value;
    if (const auto eq = arg.find('='); arg.rfind("--", 0) == 0 && eq != std::string::npos) value = arg.substr(eq + 1);
    else if (a > 1 && std::string(argv[a - 1]).rfind("-", 0) == 0) value = arg;  // also "-inf"
    if (value.empty()) continue;
    char* end = nullptr;
    const double v = std::strtod(value.c_str(), &end);
    if (end && *end == '\0' && end != value.c_str() && !std::isfinite(v))
      return (a > 1 && arg == value ? std::string(argv[a - 1]) + " " : std::string()) + arg;
  }
  return {};
}

}  // namespace

int main(int argc, char** argv) {
  install_interrupt_handler();  // first: a Ctrl-C at any moment cancels cleanly (exit 40)
  auto logger = spdlog::stderr_color_mt("organsmith");
  spdlog::set_default_logger(logger);
  spdlog::set_pattern("%^[%l]%$ %v");

  CLI::App app{
      "organsmith — patient-specific organ models from CT.\n"
      "Reads a DICOM series (or NIfTI/NRRD/MHA), segments the gallbladder and the trachea,\n"
      "and writes simulation-ready meshes, materials and guidance paths with a manifest.\n"
      "Coordinates are DICOM patient coordinates (LPS) in millimetres throughout."};
  app.require_subcommand(1);
  app.set_version_flag("--version", tool_version() + " (" + tool_git_commit() + ")");
  int verbosity = 0;
  bool quiet = false;
  int threads = 0;
  app.add_flag("-v,--verbose", verbosity, "more log output (repeat for debug)");
  app.add_flag("-q,--quiet", quiet, "only warnings and errors");
  app.add_option("--threads", threads, "worker threads (default: all cores)")->check(CLI::NonNegativeNumber);

  // info
  std::string info_input;
  bool info_json = false;
  IngestFlags info_flags;
  auto* info = app.add_subcommand("info", "Describe a CT input: series, size, spacing, orientation, HU range.\n"
                                          "Never prints patient identifiers.");
  info->add_option("INPUT", info_input, "DICOM directory or file, or .nii/.nii.gz/.nrrd/.nhdr/.mha/.mhd")->required();
  info->add_flag("--json", info_json, "print JSON instead of text");
  info_flags.add_to(info);

  // phantom
  std::string phantom_out;
  PhantomOptions phantom_options;
  auto* phantom = app.add_subcommand("phantom", "Write the synthetic torso phantom: a CT series (DIR/dicom/),\n"
                                                "its ground truth (DIR/ground_truth.nii.gz) and seeds (DIR/seeds.json).");
  phantom->add_option("--out", phantom_out,
                      "output directory: new, empty, or one organsmith wrote before (its earlier outputs are "
                      "replaced; other files are never touched)")->required();
  phantom->add_option("--seed", phantom_options.seed, "random seed (default 1)");
  phantom->add_option("--size", phantom_options.size_vox, "in-plane matrix in voxels (default 512)")->check(CLI::Range(32, 2048));
  phantom->add_option("--slice-mm", phantom_options.slice_mm, "slice spacing in mm (default 2.5)")->check(CLI::Range(0.1, 20.0));
  phantom->add_option("--extent-mm", phantom_options.extent_mm, "cranio-caudal extent in mm (default 400)")->check(CLI::Range(100.0, 2000.0));

  // run
  std::string case_path, run_out, until;
  bool force = false, print_default = false, allow_quality_failures = false;
  IngestFlags run_flags;
  auto* run = app.add_subcommand("run", "Run every stage of a case (TOML). Without a case file, runs the embedded\n"
                                        "default: the phantom, written to out/phantom/, then each stage into out/.\n"
                                        "Stages whose inputs and options are unchanged are reused.");
  run->add_option("CASE", case_path, "case file (see README.md, 'Case file')");
  run->add_option("--out", run_out, "output directory (overrides the case's [output] dir)");
  run->add_flag("--force", force, "redo every stage even when unchanged");
  run->add_flag("--allow-quality-failures", allow_quality_failures,
                "write meshes that still fail a quality gate after meshing's remedies, with warnings "
                "(default: stop with exit 61 naming organ, surface and figure; the case's [stages.mesh] "
                "quality_gate = \"report\" does the same)");
  run->add_option("--until", until, "stop after this stage (phantom, ingest, segment, …)");
  run->add_flag("--print-default-case", print_default,
                "print the embedded default case with every stage option, its default and unit, and exit");
  run_flags.add_to(run);

  std::vector<Command> commands;
  for (auto* add : {&segmentation_commands, &meshing_commands, &physics_commands, &degradation_commands,
                     &haptics_commands, &viewer_commands, &simulate_commands,
                     &cohort_commands, &pacs_commands})
    for (auto& c : (*add)(app)) commands.push_back(std::move(c));

  try {
    if (const std::string bad = non_finite_option_value(argc, argv); !bad.empty()) {
      spdlog::error("'{}': an option value must be a finite number — see --help for its range", bad);
      return int(ExitCode::usage);
    }
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : int(ExitCode::usage);
  }
  if (quiet) spdlog::set_level(spdlog::level::warn);
  else if (verbosity >= 2) spdlog::set_level(spdlog::level::debug);
  std::unique_ptr<tbb::global_control> thread_limit;
  if (threads > 0)
    thread_limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, threads);

  try {
    if (*info) return cmd_info(info_input, info_flags, info_json);
    if (*phantom) return cmd_phantom(phantom_out, phantom_options);
    if (*run) {
      if (print_default) {
        std::cout << default_case_with_options_text();
        return 0;
      }
      return cmd_run(case_path, run_out, force, until, allow_quality_failures, run_flags);
    }
    for (const auto& c : commands)
      if (c.sub->parsed()) return c.run();
  } catch (const Error& e) {
    spdlog::error("{}", e.what());
    return int(e.code());
  } catch (const std::exception& e) {
    spdlog::error("internal error: {} — please report it with the command line you used", e.what());
    return int(ExitCode::internal);
  }
  return 0;
}
