#pragma once
// Pulling a CT study from a PACS into a local cache: DICOMweb (QIDO-RS, WADO-RS through libcurl)
// or DIMSE (C-FIND, C-GET through DCMTK). No libcurl or DCMTK type appears in this header.
//
// The cache holds patient data: it lives where the user says (never inside an output directory),
// its folders are mode 0700 and its files 0600, and nothing in it is named by a UID: a study is
// CACHE/<study key>/ (the first 16 hex digits of SHA-256 of the StudyInstanceUID), a series a
// folder of it named the same way, an instance <key of its SOPInstanceUID>.dcm. Beside each study
// folder, <study key>.index.json records every instance's bytes and SHA-256: a re-pull fetches only
// what is missing or no longer matches (truncated, corrupt).

#include "core/errors.h"
#include "core/progress.h"

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace organsmith {

struct PacsEndpoint {
  enum class Kind { dicomweb, dimse };
  Kind kind = Kind::dicomweb;
  std::string url;                       ///< DICOMweb: the service root, e.g. http://host:8042/dicom-web
  std::string host;                      ///< DIMSE
  int port = 104;                        ///< DIMSE
  std::string called_aet;                ///< DIMSE: the PACS' AE title
  std::string calling_aet = "ORGANSMITH";///< DIMSE: ours
  /// DIMSE: 0 = retrieve by C-GET; else by C-MOVE to our own C-STORE SCP listening on this port
  /// (for a PACS without C-GET: it must know our AE title at this host and port).
  int move_port = 0;
  std::filesystem::path ca_file;         ///< HTTPS: the CA bundle that signs the server's certificate
  /// Credentials (DICOMweb basic auth): from ORGANSMITH_PACS_USER / ORGANSMITH_PACS_PASSWORD,
  /// else ~/.netrc (or $NETRC). Never printed, never written.
  std::string user, password;
  double timeout_s = 60;                 ///< per request / association step
  int retries = 3;                       ///< attempts after the first on a transient failure, with back-off
};

/// Parses `http(s)://host:port/path` (DICOMweb) or `dicom://AET@host:port` (DIMSE). UsageError on
/// anything else. Credentials are taken from the environment here.
PacsEndpoint parse_pacs_url(const std::string& url, const std::string& calling_aet = "ORGANSMITH");

/// A PACS failure; the code says which (unreachable, refused, not found, no CT, cut off).
class PacsError : public Error {
 public:
  PacsError(ExitCode code, std::string message, std::string hint = {})
      : Error(code, std::move(message), {}, std::move(hint)) {}
};

struct PullOptions {
  std::string study_uid;
  std::string series_uid;             ///< empty = every CT series of the study
  std::filesystem::path cache_dir;
};

struct PullResult {
  std::filesystem::path study_dir;    ///< CACHE/<study key>: an input for `organsmith run`
  int series = 0;
  int instances = 0;                  ///< in the study's CT series (or the series asked for)
  int fetched = 0;                    ///< of them, fetched now
  int reused = 0;                     ///< of them, already in the cache and intact
  std::int64_t bytes_fetched = 0;
  double seconds = 0.0;
};

/// Pulls the study's CT series (or the one asked for) into the cache. Throws PacsError.
PullResult pull_study(const PacsEndpoint& pacs, const PullOptions& options, Progress& progress);

/// The study's folder in the cache (whether or not it exists).
std::filesystem::path cached_study_dir(const std::filesystem::path& cache_dir, const std::string& study_uid);

/// Removes a study from the cache; returns false when it was not there.
bool purge_study(const std::filesystem::path& cache_dir, const std::string& study_uid);

/// First 16 hex digits of SHA-256 of `uid`: how the cache and the manifests name a UID.
std::string uid_key(const std::string& uid);

}  // namespace organsmith
