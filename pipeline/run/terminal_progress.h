#pragma once
// Progress shown to a person: a redrawn bar on a terminal, plain lines otherwise (logs, CI).

#include "core/progress.h"

#include <atomic>
#include <chrono>
#include <csignal>
#include <mutex>
#include <string>

namespace organsmith {

/// Makes SIGINT and SIGTERM request cancellation (instead of killing the process): every
/// Progress::cancelled() then returns true and the running stage stops with exit 40, leaving
/// nothing half-written. Installed first thing in main, and kept for the whole process.
void install_interrupt_handler();
/// True once SIGINT or SIGTERM arrived.
bool interrupted();

/// Prints progress to stderr. On a TTY it redraws one line "[#####.....]  45 % what"; elsewhere
/// it prints a plain line each time a task passes another 25 %. Ctrl-C requests cancellation.
class TerminalProgress final : public Progress {
 public:
  /// quiet = true: report nothing (cancellation still works).
  explicit TerminalProgress(bool quiet = false);
  ~TerminalProgress() override;
  void report(double fraction, std::string_view what) override;
  bool cancelled() const override;
  /// Ends a bar line on a terminal so that log output starts on a fresh line.
  void finish();

 private:
  bool tty_;
  bool quiet_;
  std::mutex mutex_;
  std::string task_;
  int last_step_ = -1;
  std::chrono::steady_clock::time_point last_draw_{};
  bool bar_open_ = false;
};

}  // namespace organsmith
