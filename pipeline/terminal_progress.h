#pragma once
// Progress shown to a person: a redrawn bar on a terminal, plain lines otherwise (logs, CI).

#include "core/progress.h"

#include <atomic>
#include <chrono>
#include <csignal>
#include <mutex>
#include <string>

namespace organsmith {

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
