// DICOMweb through libcurl: QIDO-RS to find a study's CT series and their instances, WADO-RS to
// retrieve them (multipart/related; type="application/dicom", in the transfer syntax they are
// stored in, so that nothing is recompressed on the way).
#include "pacs/client.h"

#include <curl/curl.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <mutex>

namespace organsmith::pacs_detail {

namespace {

struct Response {
  long status = 0;
  std::string body;
  std::string content_type;
  CURLcode code = CURLE_OK;
};

std::size_t on_body(char* data, std::size_t size, std::size_t n, void* user) {
  static_cast<Response*>(user)->body.append(data, size * n);
  return size * n;
}

std::size_t on_header(char* data, std::size_t size, std::size_t n, void* user) {
  std::string line(data, size * n);
  std::string lower = line;
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (lower.rfind("content-type:", 0) == 0) {
    std::string v = line.substr(13);
    while (!v.empty() && std::isspace(static_cast<unsigned char>(v.front()))) v.erase(v.begin());
    while (!v.empty() && std::isspace(static_cast<unsigned char>(v.back()))) v.pop_back();
    static_cast<Response*>(user)->content_type = v;
  }
  return size * n;
}

struct ProgressState {
  Progress* progress = nullptr;
};

int on_progress(void* user, curl_off_t, curl_off_t now, curl_off_t, curl_off_t) {
  auto* p = static_cast<ProgressState*>(user);
  return p->progress && p->progress->cancelled() ? 1 : 0;  // nonzero aborts the transfer
}

std::string escape_uid(const std::string& uid) {
  // UIDs are digits and dots; anything else is refused here rather than sent.
  for (char c : uid)
    if (!std::isdigit(static_cast<unsigned char>(c)) && c != '.')
      throw PacsError(ExitCode::usage, "'" + uid + "' is not a DICOM UID (digits and dots)");
  return uid;
}

class DicomWebClient final : public Client {
 public:
  explicit DicomWebClient(const PacsEndpoint& p) : pacs_(p) {
    static std::once_flag once;
    std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
    base_ = p.url;
    while (!base_.empty() && base_.back() == '/') base_.pop_back();
  }

  bool has_study(const std::string& study) override {
    const auto j = qido("/studies?StudyInstanceUID=" + escape_uid(study));
    return !j.empty();
  }

  std::vector<std::string> ct_series(const std::string& study) override {
    std::vector<std::string> out;
    for (const auto& s : qido("/studies/" + escape_uid(study) + "/series?Modality=CT")) {
      const std::string uid = tag(s, "0020000E");
      if (!uid.empty()) out.push_back(uid);
    }
    return out;
  }

  std::vector<std::string> instances(const std::string& study, const std::string& series) override {
    std::vector<std::string> out;
    for (const auto& s : qido("/studies/" + escape_uid(study) + "/series/" + escape_uid(series) + "/instances")) {
      const std::string uid = tag(s, "00080018");
      if (!uid.empty()) out.push_back(uid);
    }
    return out;
  }

  void retrieve(const std::string& study, const std::string& series, const std::vector<std::string>& sops,
                const StoreFn& store, Progress& progress) override {
    const std::string series_path = "/studies/" + escape_uid(study) + "/series/" + escape_uid(series);
    if (sops.empty()) return wado(series_path, store, progress);
    for (const auto& sop : sops) wado(series_path + "/instances/" + escape_uid(sop), store, progress);
  }

 private:
  Response get(const std::string& path, const std::string& accept, Progress* progress) {
    Response r;
    CURL* curl = curl_easy_init();
    if (!curl) throw PacsError(ExitCode::internal, "cannot start libcurl");
    const std::string url = base_ + path;
    curl_slist* headers = curl_slist_append(nullptr, ("Accept: " + accept).c_str());
    ProgressState ps{progress};
    curl_easy_setopt(curl, CURLOPT_URL, url.c_str());
    curl_easy_setopt(curl, CURLOPT_HTTPHEADER, headers);
    curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, on_body);
    curl_easy_setopt(curl, CURLOPT_WRITEDATA, &r);
    curl_easy_setopt(curl, CURLOPT_HEADERFUNCTION, on_header);
    curl_easy_setopt(curl, CURLOPT_HEADERDATA, &r);
    curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS, long(1000 * std::min(pacs_.timeout_s, 30.0)));
    // A stalled transfer (under 1 byte/s for the timeout) is cut off; a large series may take long.
    curl_easy_setopt(curl, CURLOPT_LOW_SPEED_LIMIT, 1L);
    curl_easy_setopt(curl, CURLOPT_LOW_SPEED_TIME, long(pacs_.timeout_s));
    curl_easy_setopt(curl, CURLOPT_XFERINFOFUNCTION, on_progress);
    curl_easy_setopt(curl, CURLOPT_XFERINFODATA, &ps);
    curl_easy_setopt(curl, CURLOPT_NOPROGRESS, 0L);
    curl_easy_setopt(curl, CURLOPT_PROTOCOLS_STR, "http,https");
    if (!pacs_.ca_file.empty()) curl_easy_setopt(curl, CURLOPT_CAINFO, pacs_.ca_file.c_str());
    if (!pacs_.user.empty()) {
      curl_easy_setopt(curl, CURLOPT_HTTPAUTH, CURLAUTH_BASIC);
      curl_easy_setopt(curl, CURLOPT_USERNAME, pacs_.user.c_str());
      curl_easy_setopt(curl, CURLOPT_PASSWORD, pacs_.password.c_str());
    } else {
      curl_easy_setopt(curl, CURLOPT_NETRC, long(CURL_NETRC_OPTIONAL));
      if (const char* netrc = std::getenv("NETRC")) curl_easy_setopt(curl, CURLOPT_NETRC_FILE, netrc);
    }
    r.code = curl_easy_perform(curl);
    curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &r.status);
    curl_slist_free_all(headers);
    curl_easy_cleanup(curl);
    if (r.code == CURLE_ABORTED_BY_CALLBACK) throw Cancelled();
    if (r.code == CURLE_COULDNT_CONNECT || r.code == CURLE_COULDNT_RESOLVE_HOST ||
        (r.code == CURLE_OPERATION_TIMEDOUT && r.status == 0))
      throw PacsError(ExitCode::pacs_unreachable, "the PACS at " + base_ + " does not answer (" + curl_easy_strerror(r.code) + ")",
                      "check the URL and that the server runs and is reachable from here");
    if (r.code == CURLE_SSL_CACERT || r.code == CURLE_PEER_FAILED_VERIFICATION || r.code == CURLE_SSL_CONNECT_ERROR)
      throw PacsError(ExitCode::pacs_refused, "TLS with the PACS failed: " + std::string(curl_easy_strerror(r.code)),
                      "give the CA file that signs the server's certificate ([pacs.<name>] ca_file or --ca-file)");
    if (r.status == 401 || r.status == 403)
      throw PacsError(ExitCode::pacs_refused,
                      "the PACS refused the credentials (HTTP " + std::to_string(r.status) + ")",
                      "set ORGANSMITH_PACS_USER and ORGANSMITH_PACS_PASSWORD (or a ~/.netrc entry for the host)");
    return r;
  }

  nlohmann::json qido(const std::string& path) {
    const Response r = get(path, "application/dicom+json", nullptr);
    if (r.code != CURLE_OK)
      throw PacsError(ExitCode::pacs_transfer, "a query to the PACS broke off: " + std::string(curl_easy_strerror(r.code)));
    if (r.status == 204 || r.status == 404 || (r.status == 200 && r.body.find_first_not_of(" \r\n\t") == std::string::npos))
      return nlohmann::json::array();
    if (r.status != 200)
      throw PacsError(r.status >= 500 ? ExitCode::pacs_transfer : ExitCode::pacs_refused,
                      "the PACS answered a query with HTTP " + std::to_string(r.status));
    try {
      const auto j = nlohmann::json::parse(r.body);
      return j.is_array() ? j : nlohmann::json::array();
    } catch (const nlohmann::json::exception&) {
      throw PacsError(ExitCode::pacs_transfer, "the PACS answered a query with something that is not DICOM JSON");
    }
  }

  static std::string tag(const nlohmann::json& item, const char* key) {
    if (!item.contains(key) || !item[key].contains("Value") || item[key]["Value"].empty()) return {};
    const auto& v = item[key]["Value"][0];
    return v.is_string() ? v.get<std::string>() : v.dump();
  }

  void wado(const std::string& path, const StoreFn& store, Progress& progress) {
    const Response r = get(path, "multipart/related; type=\"application/dicom\"; transfer-syntax=*", &progress);
    if (r.status == 404) throw PacsError(ExitCode::pacs_not_found, "the PACS has no such series or instance");
    if (r.status != 200 && r.code == CURLE_OK)
      throw PacsError(r.status >= 500 ? ExitCode::pacs_transfer : ExitCode::pacs_refused,
                      "the PACS answered a retrieval with HTTP " + std::to_string(r.status));
    // Whatever arrived whole is stored, also when the transfer broke off later.
    const auto b = r.content_type.find("boundary=");
    if (b == std::string::npos) {
      if (r.code != CURLE_OK)
        throw PacsError(ExitCode::pacs_transfer, "a retrieval broke off: " + std::string(curl_easy_strerror(r.code)));
      throw PacsError(ExitCode::pacs_transfer, "the PACS answered a retrieval without a multipart boundary");
    }
    std::string boundary = r.content_type.substr(b + 9);
    boundary = boundary.substr(0, boundary.find(';'));
    if (boundary.size() >= 2 && boundary.front() == '"') boundary = boundary.substr(1, boundary.find('"', 1) - 1);
    const std::string delim = "--" + boundary;
    std::size_t at = r.body.find(delim);
    while (at != std::string::npos) {
      at += delim.size();
      if (r.body.compare(at, 2, "--") == 0) break;  // the closing delimiter
      const std::size_t head_end = r.body.find("\r\n\r\n", at);
      if (head_end == std::string::npos) break;
      std::string head = r.body.substr(at, head_end - at);
      std::transform(head.begin(), head.end(), head.begin(), [](unsigned char c) { return char(std::tolower(c)); });
      const std::size_t body_start = head_end + 4;
      std::size_t body_end;
      if (const auto cl = head.find("content-length:"); cl != std::string::npos) {
        body_end = body_start + std::size_t(std::strtoull(head.c_str() + cl + 15, nullptr, 10));
        if (body_end > r.body.size()) break;  // cut off inside this part
      } else {
        body_end = r.body.find("\r\n" + delim, body_start);
        if (body_end == std::string::npos) break;
      }
      store(r.body.substr(body_start, body_end - body_start));
      at = r.body.find(delim, body_end);
    }
    if (r.code != CURLE_OK)
      throw PacsError(ExitCode::pacs_transfer, "a retrieval broke off: " + std::string(curl_easy_strerror(r.code)));
  }

  PacsEndpoint pacs_;
  std::string base_;
};

}  // namespace

std::unique_ptr<Client> make_dicomweb_client(const PacsEndpoint& pacs) { return std::make_unique<DicomWebClient>(pacs); }

}  // namespace organsmith::pacs_detail
