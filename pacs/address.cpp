// PACS addresses and cache keys: parsing a pacs:// or dicom:// address, and the cache folder of a
// study. No network code: the case-file parser validates addresses with it.
#include "pacs/pacs.h"

#include "core/errors.h"
#include "core/sha256.h"

#include <cstdlib>
#include <regex>

namespace fs = std::filesystem;

namespace organsmith {

std::string uid_key(const std::string& uid) { return sha256_hex(uid).substr(0, 16); }

fs::path cached_study_dir(const fs::path& cache_dir, const std::string& study_uid) {
  return cache_dir / uid_key(study_uid);
}

PacsEndpoint parse_pacs_url(const std::string& url, const std::string& calling_aet) {
  PacsEndpoint p;
  p.calling_aet = calling_aet;
  static const std::regex web(R"(^(https?)://([^/:@\s]+)(:[0-9]{1,5})?(/\S*)?$)");
  static const std::regex dimse(R"(^dicom://([^@/\s]{1,16})@([^/:@\s]+):([0-9]{1,5})/?$)");
  std::smatch m;
  if (std::regex_match(url, m, web)) {
    p.kind = PacsEndpoint::Kind::dicomweb;
    p.url = url;
  } else if (std::regex_match(url, m, dimse)) {
    p.kind = PacsEndpoint::Kind::dimse;
    p.called_aet = m[1];
    p.host = m[2];
    p.port = std::atoi(m[3].str().c_str());
    if (p.port < 1 || p.port > 65535) throw UsageError("the port in '" + url + "' is out of range");
  } else {
    throw UsageError("'" + url + "' is no PACS address",
                     "give http(s)://host:port/dicom-web for DICOMweb or dicom://AET@host:port for DIMSE");
  }
  if (p.calling_aet.empty() || p.calling_aet.size() > 16)
    throw UsageError("the calling AE title '" + p.calling_aet + "' must have 1 to 16 characters");
  if (const char* u = std::getenv("ORGANSMITH_PACS_USER")) p.user = u;
  if (const char* pw = std::getenv("ORGANSMITH_PACS_PASSWORD")) p.password = pw;
  return p;
}

}  // namespace organsmith
