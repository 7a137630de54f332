#include "core/process.h"

#include "core/errors.h"
#include "core/file_io.h"

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <fcntl.h>
#include <sstream>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace fs = std::filesystem;

namespace organsmith {

fs::path find_on_path(const std::string& name) {
  if (name.empty()) return {};
  if (name.find('/') != std::string::npos) return access(name.c_str(), X_OK) == 0 ? fs::path(name) : fs::path();
  const char* path = std::getenv("PATH");
  std::stringstream ss(path ? path : "/usr/bin:/bin");
  std::string dir;
  while (std::getline(ss, dir, ':'))
    if (!dir.empty() && access((fs::path(dir) / name).c_str(), X_OK) == 0) return fs::path(dir) / name;
  return {};
}

fs::path self_executable() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : p;
}

namespace {

int decode(int status) {
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return -1;
}

}  // namespace

ChildProcess::ChildProcess(const ChildSpec& spec) : group_(spec.own_process_group) {
  // Everything the child needs is prepared before fork (only async-signal-safe calls after it).
  std::vector<std::string> argv_text;
  argv_text.push_back(spec.exe.string());
  for (const auto& a : spec.args) argv_text.push_back(a);
  std::vector<char*> argv;
  for (auto& a : argv_text) argv.push_back(a.data());
  argv.push_back(nullptr);
  const std::string log = spec.log.string(), cwd = spec.cwd.string(), exe = spec.exe.string();

  pid_ = fork();
  if (pid_ < 0) throw Error(ExitCode::internal, "cannot start a process (fork failed)", spec.exe);
  if (pid_ == 0) {
    if (group_) setpgid(0, 0);
    if (!cwd.empty() && chdir(cwd.c_str()) != 0) _exit(127);
    if (!log.empty()) {
      const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      if (fd < 0) _exit(127);
      dup2(fd, 1);
      dup2(fd, 2);
      close(fd);
    }
    for (const auto& [k, v] : spec.env) setenv(k.c_str(), v.c_str(), 1);
    // The parent's SIGINT/SIGTERM handlers do not survive exec; restore defaults explicitly.
    ::signal(SIGINT, SIG_DFL);
    ::signal(SIGTERM, SIG_DFL);
    execv(exe.c_str(), argv.data());
    _exit(127);
  }
  if (group_) setpgid(pid_, pid_);  // also from the parent, so signal() never races the child's setpgid
}

ChildProcess::~ChildProcess() {
  if (pid_ > 0 && !exit_) {
    signal(SIGKILL);
    wait();
  }
}

std::optional<int> ChildProcess::poll() {
  if (exit_ || pid_ <= 0) return exit_;
  int status = 0;
  const pid_t w = waitpid(pid_, &status, WNOHANG);
  if (w == pid_) exit_ = decode(status), signal_ = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  return exit_;
}

int ChildProcess::wait() {
  if (exit_) return *exit_;
  int status = 0;
  while (waitpid(pid_, &status, 0) < 0)
    if (errno != EINTR) return -1;
  exit_ = decode(status);
  signal_ = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  return *exit_;
}

void ChildProcess::signal(int sig) {
  if (exit_ || pid_ <= 0) return;
  if (group_) ::kill(-pid_, sig);
  else ::kill(pid_, sig);
}

CommandResult run_command(const fs::path& exe, const std::vector<std::string>& args, double timeout_s,
                          const std::vector<std::pair<std::string, std::string>>& env) {
  char name[] = "/tmp/organsmith-cmd-XXXXXX";
  const int fd = mkstemp(name);
  if (fd < 0) throw Error(ExitCode::internal, "cannot create a temporary file for a command's output", "/tmp");
  close(fd);
  CommandResult r;
  {
    ChildSpec spec;
    spec.exe = exe;
    spec.args = args;
    spec.log = name;
    spec.env = env;
    ChildProcess child(spec);
    const auto t0 = std::chrono::steady_clock::now();
    for (;;) {
      if (auto code = child.poll()) {
        r.exit_code = *code;
        break;
      }
      if (timeout_s > 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) {
        child.signal(SIGKILL);
        child.wait();
        r.exit_code = -1;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  r.output = read_file(name).value_or("");
  fs::remove(name);
  return r;
}

}  // namespace organsmith
