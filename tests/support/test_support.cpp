#include "tests/support/test_support.h"

#include "core/file_io.h"
#include "core/sha256.h"

#include <fstream>

#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <random>
#include <sys/mount.h>
#include <sys/wait.h>

namespace organsmith::testing {

namespace fs = std::filesystem;

fs::path real_data_dir() {
  const fs::path p = fs::path(ORGANSMITH_SHARED_DIR) / "data" / "real";
  return fs::is_directory(p) ? p : fs::path();
}

ScratchDir::ScratchDir(const std::string& tag) {
  std::random_device rd;
  path_ = fs::temp_directory_path() / ("organsmith-test-" + tag + "-" + std::to_string(rd()));
  fs::remove_all(path_);
  fs::create_directories(path_);
}

ScratchDir::~ScratchDir() {
  std::error_code ec;
  fs::remove_all(path_, ec);
}

SmallDisk::SmallDisk(const std::string& tag, int size_kib) : dir_(tag) {
  const std::string opts = "size=" + std::to_string(size_kib) + "k,mode=0755";
  if (::mount("tmpfs", dir_.path().c_str(), "tmpfs", 0, opts.c_str()) == 0)
    mounted_ = true;
  else
    why_ = std::string("cannot mount a tmpfs for the full-disk test (") + std::strerror(errno) +
           "): it needs CAP_SYS_ADMIN, as root has here and in CI";
}

SmallDisk::~SmallDisk() {
  if (mounted_) ::umount2(dir_.path().c_str(), MNT_DETACH);
}

namespace {

/// Runs a shell command line, its output collected; a death by signal n gives `signal_base` + n.
CliResult run_shell(const std::string& cmd, int signal_base) {
  CliResult r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  std::size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : (signal_base < 0 ? -1 : signal_base + WTERMSIG(status));
  return r;
}

}  // namespace

CliResult run_cli(const std::string& args) {
  return run_shell(std::string("'") + ORGANSMITH_CLI + "' " + args + " 2>&1", -1);
}

CliResult run_cli_bounded(const std::string& args, int timeout_s, const fs::path& cwd) {
  return run_shell((cwd.empty() ? std::string() : "cd " + quoted(cwd) + " && ") + "timeout -k 5 " +
                       std::to_string(timeout_s) + " '" + ORGANSMITH_CLI + "' " + args + " 2>&1",
                   128);
}

int run_cli(const std::string& args, std::string* output) {
  CliResult r = run_cli(args);
  if (output) *output = std::move(r.output);
  return r.exit_code;
}

std::size_t count_files(const fs::path& dir) {
  if (!fs::exists(dir)) return 0;
  std::size_t n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir)) n += e.is_regular_file() ? 1 : 0;
  return n;
}

std::string read_file(const fs::path& path) { return organsmith::read_file(path).value_or(std::string()); }

bool any_file_contains(const fs::path& dir, const std::string& needle) {
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file() && read_file(e.path()).find(needle) != std::string::npos) return true;
  return false;
}

std::string quoted(const fs::path& p) { return "'" + p.string() + "'"; }

nlohmann::json read_json(const fs::path& p) {
  std::ifstream in(p);
  return nlohmann::json::parse(in);
}

std::map<std::string, std::string> file_digests(const fs::path& dir, const std::string& skip) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file() && (skip.empty() || e.path().filename() != skip))
      out[fs::relative(e.path(), dir).generic_string()] = sha256_file(e.path());
  return out;
}

bool has_staging_leftover(const fs::path& dir) {
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator(); ++it)
    if (it->path().filename().string().find(".staging-") != std::string::npos) return true;
  return false;
}

}  // namespace organsmith::testing
