#include "pipeline/run/terminal_progress.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace organsmith {

namespace {
volatile std::sig_atomic_t g_interrupted = 0;  // set by the SIGINT handler only
extern "C" void on_sigint(int) { g_interrupted = 1; }
}  // namespace

void install_interrupt_handler() {
  struct sigaction sa {};
  sa.sa_handler = on_sigint;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

bool interrupted() { return g_interrupted != 0; }

TerminalProgress::TerminalProgress(bool quiet) : tty_(isatty(STDERR_FILENO) != 0), quiet_(quiet) {
  install_interrupt_handler();
}

TerminalProgress::~TerminalProgress() { finish(); }

bool TerminalProgress::cancelled() const { return g_interrupted != 0; }

void TerminalProgress::report(double fraction, std::string_view what) {
  if (quiet_) return;
  std::lock_guard lock(mutex_);
  fraction = std::clamp(fraction, 0.0, 1.0);
  if (what != task_) {
    if (bar_open_) std::fputc('\n', stderr), bar_open_ = false;
    task_ = std::string(what);
    last_step_ = -1;
  }
  if (tty_) {
    const auto now = std::chrono::steady_clock::now();
    if (fraction < 1.0 && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    const int width = 30, filled = int(fraction * width + 0.5);
    std::fprintf(stderr, "\r[%.*s%.*s] %3d %% %s", filled, "##############################",
                 width - filled, "..............................", int(fraction * 100 + 0.5), task_.c_str());
    bar_open_ = true;
    if (fraction >= 1.0) std::fputc('\n', stderr), bar_open_ = false;
  } else {
    const int step = int(fraction * 4.0 + 1e-9);  // 0, 25, 50, 75, 100 %
    if (step == last_step_) return;
    last_step_ = step;
    std::fprintf(stderr, "  %s: %d %%\n", task_.c_str(), step * 25);
  }
  std::fflush(stderr);
}

void TerminalProgress::finish() {
  std::lock_guard lock(mutex_);
  if (bar_open_) std::fputc('\n', stderr), bar_open_ = false;
}

}  // namespace organsmith
