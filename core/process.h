#pragma once
// Child processes: the solver, the scheduler's commands, a cohort's studies. POSIX only.

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace organsmith {

/// `name` found on PATH (or `name` itself when it holds a '/' and is executable); empty if not.
std::filesystem::path find_on_path(const std::string& name);

/// This executable (/proc/self/exe).
std::filesystem::path self_executable();

struct ChildSpec {
  std::filesystem::path exe;
  std::vector<std::string> args;                            ///< without argv[0]
  std::filesystem::path log;                                ///< stdout and stderr appended here; empty = inherited
  std::filesystem::path cwd;                                ///< empty = inherited
  std::vector<std::pair<std::string, std::string>> env;     ///< set in the child, on top of ours
  bool own_process_group = false;  ///< the child leads a new group (terminate() then reaches its children too)
};

/// A started child process. Not copyable; the destructor kills and reaps a child still running.
class ChildProcess {
 public:
  /// Starts the child; throws Error(internal) when fork fails. A child that cannot exec exits 127.
  explicit ChildProcess(const ChildSpec& spec);
  ~ChildProcess();
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  int pid() const { return pid_; }
  /// The exit code once the child has ended (128 + signal number when a signal ended it), else nothing.
  std::optional<int> poll();
  /// Waits for the end and returns the exit code as poll() does.
  int wait();
  /// Sends `signal` (to the group when own_process_group) unless the child has ended.
  void signal(int signal);
  /// The signal that ended the child (0 when it exited by itself or is still running): tells a
  /// child's own exit code above 128 from a death by signal.
  int end_signal() const { return signal_; }

 private:
  int pid_ = -1;
  bool group_ = false;
  std::optional<int> exit_;
  int signal_ = 0;
};

struct CommandResult {
  int exit_code = -1;     ///< as ChildProcess::poll; -1 when the timeout ended it
  std::string output;     ///< stdout and stderr together
};

/// Runs `exe args…` to completion (killed after `timeout_s` when > 0) and returns its output.
CommandResult run_command(const std::filesystem::path& exe, const std::vector<std::string>& args,
                          double timeout_s = 0.0,
                          const std::vector<std::pair<std::string, std::string>>& env = {});

}  // namespace organsmith
