// pull_study(): which series and instances a study has, what the cache already holds intact,
// fetching the rest with retries and back-off, and the cache's files (0700 folders, 0600 files).
#include "pacs/client.h"
#include "pacs/pacs.h"

#include "core/file_io.h"
#include "core/sha256.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <sys/stat.h>

#include <chrono>
#include <cstdlib>
#include <fcntl.h>
#include <map>
#include <regex>
#include <set>
#include <thread>
#include <unistd.h>

namespace fs = std::filesystem;

namespace organsmith {

using pacs_detail::Client;

namespace {

/// Creates `dir` and its missing parents below the cache root with mode 0700.
void make_private_dir(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw OutputError("cannot create the PACS cache folder: " + ec.message(), dir, "give --cache a folder you can write");
  fs::permissions(dir, fs::perms::owner_all, fs::perm_options::replace, ec);
}

/// Writes `bytes` to `path` with mode 0600, atomically (temporary file, then rename).
void write_private_file(const fs::path& path, const std::string& bytes) {
  const fs::path tmp = path.string() + ".part";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  if (fd < 0) throw OutputError("cannot write to the PACS cache", tmp, "check the free space and the folder's rights");
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n <= 0) {
      ::close(fd);
      ::unlink(tmp.c_str());
      throw OutputError("cannot write to the PACS cache (disk full?)", tmp, "free some space and pull again");
    }
    done += std::size_t(n);
  }
  ::fchmod(fd, 0600);
  ::close(fd);
  fs::rename(tmp, path);
}

class Index {
 public:
  explicit Index(fs::path file) : file_(std::move(file)) {
    if (auto text = read_file(file_)) try {
        j_ = nlohmann::json::parse(*text);
      } catch (const nlohmann::json::exception&) {
        j_ = nlohmann::json::object();  // an unreadable index: every instance is checked again
      }
    if (!j_.is_object()) j_ = nlohmann::json::object();
  }
  /// True when the instance's file is there with the size and digest recorded when it came.
  bool intact(const std::string& key, const fs::path& file) const {
    if (!j_.contains(key)) return false;
    std::error_code ec;
    const auto size = fs::file_size(file, ec);
    if (ec || size != j_[key].value("bytes", std::uintmax_t(0))) return false;
    return sha256_file(file) == j_[key].value("sha256", "");
  }
  void record(const std::string& key, const std::string& bytes) {
    j_[key] = {{"bytes", bytes.size()}, {"sha256", sha256_hex(bytes)}};
  }
  void save() const { write_private_file(file_, j_.dump(1) + "\n"); }

 private:
  fs::path file_;
  nlohmann::json j_ = nlohmann::json::object();
};

/// Runs `f`, again after 0.5, 1, 2 … s when it fails in a way a retry may mend.
template <typename F>
auto with_retries(const PacsEndpoint& pacs, Progress& progress, F&& f) {
  for (int attempt = 0;; ++attempt) {
    try {
      return f();
    } catch (const PacsError& e) {
      const bool transient = e.code() == ExitCode::pacs_unreachable || e.code() == ExitCode::pacs_transfer;
      if (!transient || attempt >= pacs.retries) throw;
      const double wait_s = 0.5 * double(1 << attempt);
      spdlog::warn("PACS: {} — retrying in {} s ({} of {})", e.message(), wait_s, attempt + 1, pacs.retries);
      const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(wait_s);
      while (std::chrono::steady_clock::now() < until) {
        progress.check_cancelled();
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
    }
  }
}

}  // namespace

PullResult pull_study(const PacsEndpoint& pacs, const PullOptions& o, Progress& progress) {
  const auto t0 = std::chrono::steady_clock::now();
  if (o.cache_dir.empty()) throw UsageError("no PACS cache folder given", "give --cache DIR (it holds patient data: keep it private)");
  std::unique_ptr<Client> client = pacs.kind == PacsEndpoint::Kind::dicomweb ? pacs_detail::make_dicomweb_client(pacs)
                                                                              : pacs_detail::make_dimse_client(pacs);
  progress.report(0.0, "pull: asking the PACS");
  if (!with_retries(pacs, progress, [&] { return client->has_study(o.study_uid); }))
    throw PacsError(ExitCode::pacs_not_found, "the PACS has no study with this StudyInstanceUID (key " + uid_key(o.study_uid) + ")",
                    "check the UID (the PACS' own viewer shows it)");
  std::vector<std::string> series;
  if (!o.series_uid.empty()) {
    series.push_back(o.series_uid);
  } else {
    series = with_retries(pacs, progress, [&] { return client->ct_series(o.study_uid); });
    if (series.empty())
      throw PacsError(ExitCode::pacs_no_ct, "the study holds no CT series (key " + uid_key(o.study_uid) + ")",
                      "name a series with --series if it is a CT stored under another modality");
  }
  std::sort(series.begin(), series.end());

  PullResult result;
  result.study_dir = cached_study_dir(o.cache_dir, o.study_uid);
  make_private_dir(o.cache_dir);
  make_private_dir(result.study_dir);
  // The index lies beside the study's folder, so that the folder holds DICOM files only.
  Index index(result.study_dir.string() + ".index.json");
  // Every instance of every series first: the progress knows the total before fetching.
  std::vector<std::pair<std::string, std::vector<std::string>>> plan;
  for (const auto& s : series) {
    auto sops = with_retries(pacs, progress, [&] { return client->instances(o.study_uid, s); });
    if (sops.empty())
      throw PacsError(ExitCode::pacs_not_found, "the series (key " + uid_key(s) + ") is not in the study or has no instance",
                      "check --series, or leave it out to pull every CT series");
    std::sort(sops.begin(), sops.end());
    result.instances += int(sops.size());
    plan.emplace_back(s, std::move(sops));
  }
  result.series = int(plan.size());

  int done = 0;
  std::string what = "pull " + std::to_string(result.instances) + " instances";
  for (const auto& [s, sops] : plan) {
    const fs::path dir = result.study_dir / uid_key(s);
    make_private_dir(dir);
    std::set<std::string> missing;
    for (const auto& sop : sops) {
      const std::string key = uid_key(sop);
      if (index.intact(key, dir / (key + ".dcm"))) {
        ++result.reused;
        ++done;
      } else {
        missing.insert(sop);
      }
    }
    const std::size_t wanted = missing.size();
    auto store = [&](std::string&& bytes) {
      const std::string sop = pacs_detail::sop_uid_of(bytes);
      if (sop.empty() || !missing.count(sop)) return;  // truncated, corrupt or not asked for: fetched again below
      const std::string key = uid_key(sop);
      write_private_file(dir / (key + ".dcm"), bytes);
      index.record(key, bytes);
      index.save();
      missing.erase(sop);
      ++result.fetched;
      result.bytes_fetched += std::int64_t(bytes.size());
      ++done;
      // The bar counts instances; its label gives the bytes, renewed every tenth of the study.
      if (done % std::max(1, result.instances / 10) == 0 || done == result.instances)
        what = "pull " + std::to_string(result.instances) + " instances, " +
               std::to_string((result.bytes_fetched + 500000) / 1000000) + " MB fetched";
      progress.report(double(done) / std::max(1, result.instances), what);
    };
    for (int attempt = 0; !missing.empty(); ++attempt) {
      const bool whole_series = missing.size() == sops.size();
      const std::vector<std::string> ask = whole_series ? std::vector<std::string>{}
                                                        : std::vector<std::string>(missing.begin(), missing.end());
      try {
        client->retrieve(o.study_uid, s, ask, store, progress);
        if (!missing.empty())
          throw PacsError(ExitCode::pacs_transfer, std::to_string(missing.size()) + " of " + std::to_string(wanted) +
                                                       " instances did not arrive whole");
      } catch (const PacsError& e) {
        const bool transient = e.code() == ExitCode::pacs_unreachable || e.code() == ExitCode::pacs_transfer;
        if (!transient || attempt >= pacs.retries)
          throw PacsError(e.code(), e.message() + " (after " + std::to_string(attempt + 1) + " attempt(s); " +
                                        std::to_string(result.fetched + result.reused) + " of " +
                                        std::to_string(result.instances) + " instances are in the cache)",
                          "pull again later: what arrived is kept and not fetched again");
        spdlog::warn("PACS: {} — retrying the {} missing instance(s)", e.message(), missing.size());
        std::this_thread::sleep_for(std::chrono::milliseconds(500 << attempt));
      }
    }
  }
  progress.report(1.0, "pull");
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

bool purge_study(const fs::path& cache_dir, const std::string& study_uid) {
  const fs::path dir = cached_study_dir(cache_dir, study_uid);
  std::error_code ec;
  if (!fs::exists(dir, ec)) return false;
  fs::remove_all(dir, ec);
  if (!ec) fs::remove(dir.string() + ".index.json", ec);
  if (ec) throw OutputError("cannot remove the study from the cache: " + ec.message(), dir);
  return true;
}

}  // namespace organsmith
