// `organsmith pull --pacs URL --study UID --cache DIR`: a CT study from a PACS into a private
// cache (pacs/pacs.h), ready as the input of `organsmith run`.

#include "pacs/pacs.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/cli/commands.h"
#include "pipeline/run/terminal_progress.h"

#include "core/errors.h"
#include "core/format.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>

namespace organsmith {
namespace fs = std::filesystem;

namespace {

struct PullArgs {
  std::string pacs, study, series, cache, calling_aet = "ORGANSMITH", ca_file;
  double timeout_s = 60;
  int retries = 3;
  int move_port = 0;
  bool purge = false, json = false;
};

/// The cache holds patient data: never inside (or as) an organsmith output directory.
void check_cache_location(const fs::path& cache) {
  for (fs::path p = fs::absolute(cache).lexically_normal(); !p.empty(); p = p.parent_path()) {
    if (fs::exists(OutputLayout{p}.manifest()))
      throw OutputError("the PACS cache would lie inside an organsmith output directory (" + p.string() + ")", cache,
                        "keep the cache apart from outputs: it holds patient data, outputs must not");
    if (p == p.parent_path()) break;
  }
}

int cmd_pull(const PullArgs& a) {
  const fs::path cache = fs::absolute(a.cache);
  if (a.purge) {
    const bool removed = purge_study(cache, a.study);
    std::cout << (removed ? "removed study " : "no study ") << uid_key(a.study) << (removed ? " from " : " in ")
              << cache.string() << "\n";
    return 0;
  }
  if (a.pacs.empty()) throw UsageError("--pacs URL is required to pull", "e.g. --pacs http://pacs:8042/dicom-web");
  check_cache_location(cache);
  PacsEndpoint pacs = parse_pacs_url(a.pacs, a.calling_aet);
  pacs.ca_file = a.ca_file;
  pacs.timeout_s = a.timeout_s;
  pacs.retries = a.retries;
  pacs.move_port = a.move_port;
  if (a.move_port > 0 && pacs.kind != PacsEndpoint::Kind::dimse)
    throw UsageError("--move-port is for DIMSE (dicom://AET@host:port)", "DICOMweb retrieves by WADO-RS");
  PullOptions o;
  o.study_uid = a.study;
  o.series_uid = a.series;
  o.cache_dir = cache;
  TerminalProgress progress(spdlog::get_level() >= spdlog::level::warn);
  const PullResult r = pull_study(pacs, o, progress);
  progress.finish();
  const double mb = double(r.bytes_fetched) / 1e6;
  if (a.json) {
    std::cout << nlohmann::json{{"study_key", uid_key(a.study)},
                                {"study_dir", r.study_dir.string()},
                                {"series", r.series},
                                {"instances", r.instances},
                                {"fetched", r.fetched},
                                {"reused", r.reused},
                                {"bytes_fetched", r.bytes_fetched},
                                {"seconds", r.seconds}}
                     .dump(2)
              << "\n";
  } else {
    std::cout << "pulled study " << uid_key(a.study) << ": " << r.instances << " instances in " << r.series
              << " CT series (" << r.fetched << " fetched, " << r.reused << " already cached), " << format_g(mb, 3)
              << " MB in " << format_g(r.seconds, 3) << " s"
              << (r.seconds > 0 && mb > 0 ? " (" + format_g(mb / r.seconds, 3) + " MB/s)" : std::string()) << "\n  "
              << r.study_dir.string() << "\n";
  }
  return 0;
}

}  // namespace

std::vector<Command> pacs_commands(CLI::App& app) {
  auto a = std::make_shared<PullArgs>();
  auto* cmd = app.add_subcommand(
      "pull",
      "Pull a CT study from a PACS into a local cache: by DICOMweb (QIDO-RS, WADO-RS; --pacs\n"
      "http(s)://host:port/dicom-web, basic auth from ORGANSMITH_PACS_USER/ORGANSMITH_PACS_PASSWORD\n"
      "or ~/.netrc) or by DIMSE (C-FIND, then C-GET, or C-MOVE with --move-port; --pacs\n"
      "dicom://AET@host:port). Instances already in\n"
      "the cache and intact are not fetched again; a pull cut off half-way resumes. The cache holds\n"
      "patient data (folders 0700, files 0600, named by hashes): keep it private, outside any output\n"
      "directory. The study's folder is an input for `organsmith run`. Exit 90: PACS unreachable;\n"
      "91: refused (credentials, AE titles); 92: study or series not found; 93: no CT series; 94:\n"
      "transfer cut off. See README.md, 'PACS'.");
  cmd->add_option("--pacs", a->pacs, "http(s)://host:port/dicom-web or dicom://AET@host:port");
  cmd->add_option("--study", a->study, "StudyInstanceUID")->required();
  cmd->add_option("--series", a->series, "SeriesInstanceUID (default: every CT series of the study)");
  cmd->add_option("--cache", a->cache, "the cache folder (created 0700)")->required();
  cmd->add_option("--calling-aet", a->calling_aet, "DIMSE: our AE title (default ORGANSMITH)");
  cmd->add_option("--move-port", a->move_port,
                  "DIMSE: retrieve by C-MOVE to our own C-STORE SCP on this port instead of C-GET (the PACS must "
                  "know our AE title at this host and port)")
      ->check(CLI::Range(1, 65535));
  cmd->add_option("--ca-file", a->ca_file, "HTTPS: CA bundle that signs the PACS' certificate");
  cmd->add_option("--timeout-s", a->timeout_s, "seconds before a silent PACS counts as gone (default 60)")
      ->check(CLI::Range(1.0, 3600.0));
  cmd->add_option("--retries", a->retries, "retries of a failed request, with back-off (default 3)")->check(CLI::Range(0, 20));
  cmd->add_flag("--purge", a->purge, "remove the study from the cache instead of pulling it");
  cmd->add_flag("--json", a->json, "print the result as JSON");
  return {{cmd, [a] { return cmd_pull(*a); }}};
}

}  // namespace organsmith
