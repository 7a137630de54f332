#include "pipeline/output/output_dir.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "core/sha256.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/output/tool_info.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <random>
#include <regex>
#include <set>
#include <sstream>

namespace organsmith {

std::filesystem::path make_staging_dir(const std::filesystem::path& final_path) {
  namespace fs = std::filesystem;
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

namespace fs = std::filesystem;

namespace {


fs::path normalised(const fs::path& p) {
  std::error_code ec;
  fs::path abs = fs::absolute(p, ec);
  if (ec) abs = p;
  fs::path canon = fs::weakly_canonical(abs, ec);
  return (ec ? abs : canon).lexically_normal();
}

/// Staging folders (".<stage>.staging-<hex>") and temporary files (".<name>.tmp<pid>") are
/// organsmith's own names; a killed run can leave them behind.
bool is_leftover(const fs::directory_entry& e) {
  static const std::regex staging(R"(^\..+\.staging-[0-9a-f]+$)");
  static const std::regex temp(R"(^\..+\.tmp[0-9]+$)");
  const std::string name = e.path().filename().string();
  std::error_code ec;
  if (e.is_directory(ec)) return std::regex_match(name, staging);
  return e.is_regular_file(ec) && std::regex_match(name, temp);
}

/// The manifest a previous run left in `dir`, else an empty object (a file that is not an
/// organsmith manifest is reported: every file of the directory is then the user's).
nlohmann::json manifest_left_in(const fs::path& dir) {
  const fs::path file = OutputLayout{dir}.manifest();
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return nlohmann::json::object();
  if (auto m = read_manifest(dir)) return std::move(*m);
  spdlog::warn("{} is not an organsmith manifest: every file in {} is treated as the user's", file.string(),
               dir.string());
  return nlohmann::json::object();
}

void remove_empty_parents(fs::path p, const fs::path& root) {
  std::error_code ec;
  for (p = p.parent_path(); p != root && path_is_within(p, root); p = p.parent_path())
    if (!fs::is_directory(p, ec) || !fs::is_empty(p, ec) || !fs::remove(p, ec)) break;
}

std::string record_name(const nlohmann::json& r) { return r.is_object() ? r.value("name", "") : ""; }

}  // namespace

bool path_is_within(const fs::path& p, const fs::path& root) {
  const fs::path a = normalised(p), b = normalised(root);
  auto ia = a.begin();
  for (auto ib = b.begin(); ib != b.end(); ++ib, ++ia) {
    if (ib->empty()) continue;  // a trailing separator
    if (ia == a.end() || *ia != *ib) return false;
  }
  return true;
}

OutputList list_outputs(const fs::path& root, const fs::path& relative_to) {
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(root))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  OutputList outs = nlohmann::json::array();
  for (const auto& f : files)
    outs.push_back({{"path", fs::relative(f, relative_to).generic_string()},
                    {"bytes", fs::file_size(f)},
                    {"sha256", sha256_file(f)}});
  return outs;
}

OutputDir::OutputDir(fs::path dir, OutputDirOptions options) : dir_(normalised(dir)), options_(std::move(options)) {
  const std::string& cmd = options_.command;
  std::error_code ec;
  const auto st = fs::status(dir_, ec);
  if (fs::exists(st) && !fs::is_directory(st))
    throw OutputError("the output path is a file, not a directory", dir_,
                      "give `" + cmd + "` a directory for --out (a new one is created)");
  existed_ = fs::is_directory(st);
  if (options_.in_place && !existed_)
    throw InputError(ExitCode::input_not_found, "no such output directory", dir_,
                     "give the directory that `organsmith run --out` (or segment, mesh) wrote");
  if (!existed_) {  // fail now, not after minutes of work: the nearest existing folder must take files
    fs::path p = dir_.parent_path();
    while (!p.empty() && !fs::exists(fs::symlink_status(p, ec)) && p != p.parent_path()) p = p.parent_path();
    if (!fs::is_directory(p, ec))
      throw OutputError("the output path passes through a file (" + p.string() + ")", dir_,
                        "give `" + cmd + "` a directory path for --out");
    if (::access(p.c_str(), W_OK | X_OK) != 0)
      throw OutputError("cannot create the output directory: " + p.string() + " is not writable", dir_,
                        "choose --out in a folder you can write to");
  }
  if (existed_) previous_ = manifest_left_in(dir_);

  for (const auto& input : options_.inputs) {
    if (input.empty()) continue;
    const fs::path in = normalised(input);
    if (path_is_within(dir_, in))
      throw OutputError("the output directory lies inside the input " + in.string(), dir_,
                        "organsmith never writes into its own input: choose --out outside it");
    if (path_is_within(in, dir_)) {
      const std::string rel = fs::relative(in, dir_).generic_string();
      if (!fs::is_regular_file(in, ec) || !owned(rel))
        throw OutputError("the output directory holds the input " + in.string(), dir_,
                          "organsmith never writes above its own input: choose --out beside it, e.g. " +
                              (in.parent_path().parent_path() / (cmd + "-out")).string());
    }
  }
  if (!existed_) return;

  std::vector<std::string> foreign;
  for (const auto& e : fs::directory_iterator(dir_, ec)) {
    if (is_leftover(e)) {
      spdlog::info("removing {} left by an interrupted organsmith run", e.path().string());
      fs::remove_all(e.path(), ec);
      continue;
    }
    if (previous_.empty() && !options_.in_place) foreign.push_back(e.path().filename().string());
  }
  if (!foreign.empty()) {
    std::sort(foreign.begin(), foreign.end());
    std::string names;
    for (std::size_t i = 0; i < foreign.size() && i < 3; ++i) names += (i ? ", " : "") + foreign[i];
    if (foreign.size() > 3) names += ", … (" + std::to_string(foreign.size()) + " entries)";
    throw OutputError("the output directory is not empty and holds no organsmith manifest (" + names + ")", dir_,
                      "organsmith never replaces files it did not write: choose a new or empty directory for --out "
                      "(or one that organsmith wrote before, which it updates)");
  }
}

const nlohmann::json* OutputDir::stage_record(const std::string& stage) const {
  for (const auto& r : records_)
    if (record_name(r) == stage) return &r;
  if (previous_.contains("stages"))
    for (const auto& r : previous_["stages"])
      if (record_name(r) == stage) return &r;
  return nullptr;
}

bool OutputDir::owned(const std::string& rel) const {
  if (rel == OutputLayout{}.manifest().string()) return true;
  auto listed = [&](const nlohmann::json& r) {
    if (!r.is_object() || !r.contains("outputs") || !r["outputs"].is_array()) return false;
    for (const auto& o : r["outputs"])
      if (o.is_object() && o.value("path", "") == rel) return true;
    return false;
  };
  for (const auto& r : records_)
    if (listed(r)) return true;
  if (previous_.contains("stages"))
    for (const auto& r : previous_["stages"])
      if (listed(r)) return true;
  return false;
}

OutputList OutputDir::commit(const std::string& stage, const std::function<void(const fs::path&)>& write,
                             nlohmann::json record) {
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec || !fs::is_directory(dir_))
    throw OutputError("cannot create the output directory: " + (ec ? ec.message() : "not a directory"), dir_,
                      "check that the path is writable and does not pass through a file");
  const fs::path staging = make_staging_dir(dir_ / ("." + stage));
  try {
    write(staging);
    OutputList outputs = list_outputs(staging, staging);
    std::set<std::string> fresh;
    for (const auto& o : outputs) {
      const std::string rel = o["path"].get<std::string>();
      fresh.insert(rel);
      const fs::path dest = dir_ / rel;
      if (fs::exists(fs::symlink_status(dest, ec)) && !owned(rel))
        throw OutputError("an output would replace a file organsmith did not write", dest,
                          "move that file away, or choose another --out");
      for (fs::path p = fs::path(rel).parent_path(); !p.empty(); p = p.parent_path()) {
        const auto s = fs::symlink_status(dir_ / p, ec);
        if (fs::exists(s) && !fs::is_directory(s))
          throw OutputError("an output folder would replace a file organsmith did not write", dir_ / p,
                            "move that file away, or choose another --out");
      }
    }
    const nlohmann::json* prev = stage_record(stage);
    const OutputList before = prev && prev->contains("outputs") ? (*prev)["outputs"] : nlohmann::json::array();

    // While files move, the manifest lists both the old and the new ones under this stage, with
    // no fingerprint: after a kill here a rerun redoes the stage and may replace all of them.
    nlohmann::json pending = {{"name", stage}, {"status", "interrupted"}, {"fingerprint", ""}};
    pending["outputs"] = before;
    for (const auto& o : outputs) pending["outputs"].push_back(o);
    auto set_record = [&](const nlohmann::json& r) {
      for (auto& x : records_)
        if (record_name(x) == stage) return void(x = r);
      records_.push_back(r);
    };
    set_record(pending);
    write_manifest(header_);

    for (const auto& o : outputs) {
      const std::string rel = o["path"].get<std::string>();
      const fs::path dest = dir_ / rel;
      fs::create_directories(dest.parent_path(), ec);
      fs::rename(staging / rel, dest, ec);
      if (ec) throw OutputError("cannot move the output into place: " + ec.message(), dest,
                                "check the permissions of the output directory and the free space");
    }
    for (const auto& o : before) {
      const std::string rel = o.value("path", "");
      if (rel.empty() || fresh.count(rel)) continue;
      fs::remove(dir_ / rel, ec);
      remove_empty_parents(dir_ / rel, dir_);
    }
    fs::remove_all(staging, ec);
    record["name"] = stage;
    record["outputs"] = outputs;
    set_record(record);
    write_manifest(header_);
    return outputs;
  } catch (...) {
    fs::remove_all(staging, ec);
    remove_if_unused();
    throw;
  }
}

void OutputDir::keep(const nlohmann::json& record) {
  for (auto& x : records_)
    if (record_name(x) == record_name(record)) return void(x = record);
  records_.push_back(record);
}

nlohmann::json OutputDir::manifest_json(const nlohmann::json& header) const {
  nlohmann::json m = header.is_object() ? header : nlohmann::json::object();
  if (!m.contains("case") && !m.contains("command")) m["command"] = options_.command;
  m["tool"] = {{"name", "organsmith"}, {"version", tool_version()}, {"git_commit", tool_git_commit()}};
  nlohmann::json stages = nlohmann::json::array();
  std::set<std::string> seen;
  for (const auto& r : records_) {
    stages.push_back(r);
    seen.insert(record_name(r));
  }
  if (previous_.contains("stages"))
    for (auto r : previous_["stages"]) {
      if (!r.is_object() || seen.count(record_name(r))) continue;
      if (r.value("status", "") != "interrupted") r["status"] = "kept from an earlier run";
      stages.push_back(r);
    }
  m["stages"] = stages;
  return m;
}

void OutputDir::write_manifest(const nlohmann::json& header) {
  header_ = header;
  std::error_code ec;
  fs::create_directories(dir_, ec);
  write_file_atomic(OutputLayout{dir_}.manifest(), manifest_json(header).dump(2) + "\n");
}

void OutputDir::remove_if_unused() const {
  std::error_code ec;
  if (!existed_ && fs::is_directory(dir_, ec) && fs::is_empty(dir_, ec)) fs::remove(dir_, ec);
}

}  // namespace organsmith
