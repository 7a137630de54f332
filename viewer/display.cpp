// DisplaySession: an X connection, through a private Xvfb when the machine has no display.

#include "viewer/display.h"

#include <X11/Xlib.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <vector>

namespace organsmith {
namespace {

constexpr const char* kXvfbHint =
    "install the Debian package 'xvfb' (apt-get install xvfb), or run organsmith where an X "
    "display is available and DISPLAY names it";

/// Full path of `program` found in PATH, or empty.
std::string find_in_path(const std::string& program) {
  if (program.find('/') != std::string::npos) return access(program.c_str(), X_OK) == 0 ? program : std::string();
  const char* path = std::getenv("PATH");
  std::stringstream dirs(path ? path : "/usr/bin:/bin");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    if (dir.empty()) continue;
    const std::string candidate = dir + "/" + program;
    struct stat st {};
    if (stat(candidate.c_str(), &st) == 0 && S_ISREG(st.st_mode) && access(candidate.c_str(), X_OK) == 0)
      return candidate;
  }
  return {};
}

}  // namespace

struct DisplaySession::Impl {
  std::string name;
  Display* display = nullptr;
  pid_t xvfb_pid = -1;

  ~Impl() {
    if (display) XCloseDisplay(display);
    if (xvfb_pid > 0) {
      kill(xvfb_pid, SIGTERM);
      int status = 0;
      waitpid(xvfb_pid, &status, 0);
    }
  }

  void start_xvfb(const DisplayOptions& o) {
    const std::string program = find_in_path(o.xvfb_program);
    if (program.empty())
      throw DisplayError("no X display to render through: DISPLAY is unset and '" + o.xvfb_program +
                             "' (the virtual X server used for off-screen snapshots) is not installed",
                         kXvfbHint);
    int fds[2];
    if (pipe(fds) != 0) throw DisplayError("cannot start Xvfb: pipe() failed", kXvfbHint);
    fcntl(fds[0], F_SETFD, FD_CLOEXEC);
    const std::string fd_arg = std::to_string(fds[1]);
    const std::string screen = std::to_string(o.xvfb_width_px) + "x" + std::to_string(o.xvfb_height_px) + "x24";
    std::vector<std::string> args = {program, "-displayfd", fd_arg, "-screen", "0", screen, "-nolisten", "tcp",
                                     "-noreset"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const pid_t parent = getpid();
    const pid_t pid = fork();
    if (pid < 0) {
      close(fds[0]);
      close(fds[1]);
      throw DisplayError("cannot start Xvfb: fork() failed", kXvfbHint);
    }
    if (pid == 0) {
      // Child: stop with the parent even when it dies without cleaning up, keep Xvfb's chatter
      // about fonts and keymaps out of the user's terminal.
      prctl(PR_SET_PDEATHSIG, SIGTERM);
      if (getppid() != parent) _exit(127);
      const int null_fd = open("/dev/null", O_RDWR);
      if (null_fd >= 0) {
        dup2(null_fd, 0);
        dup2(null_fd, 1);
        dup2(null_fd, 2);
      }
      execv(program.c_str(), argv.data());
      _exit(127);
    }
    close(fds[1]);
    xvfb_pid = pid;

    // Xvfb writes its display number to the fd once it accepts connections.
    std::string number;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.xvfb_start_timeout_s);
    bool done = false;
    while (!done) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      pollfd p{fds[0], POLLIN, 0};
      const int r = poll(&p, 1, int(left.count()));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) break;
      char buf[32];
      const ssize_t n = read(fds[0], buf, sizeof buf);
      if (n <= 0) break;  // Xvfb closed the pipe: it exited
      for (ssize_t i = 0; i < n; ++i) {
        if (buf[i] == '\n') done = true;
        else number += buf[i];
      }
    }
    close(fds[0]);
    if (!done || number.empty())
      throw DisplayError("Xvfb (" + program + ") did not start within " + std::to_string(int(o.xvfb_start_timeout_s)) +
                             " s",
                         "check that Xvfb runs on this machine (`Xvfb :99` should stay up); the Debian package is 'xvfb'");
    name = ":" + number;
  }
};

DisplaySession::DisplaySession(const DisplayOptions& options) : impl_(std::make_unique<Impl>()) {
  std::string name = options.private_xvfb ? std::string() : options.display;
  if (name.empty() && !options.private_xvfb) {
    const char* env = std::getenv("DISPLAY");
    if (env && *env) name = env;
  }
  if (!name.empty()) {
    impl_->name = name;
    impl_->display = XOpenDisplay(name.c_str());
    if (!impl_->display)
      throw DisplayError("cannot open X display '" + name + "'",
                         "check DISPLAY, or unset it to render through a private Xvfb (Debian package 'xvfb')");
    return;
  }
  if (!options.allow_xvfb)
    throw DisplayError("no X display: DISPLAY is unset and starting a private Xvfb was not allowed",
                       "set DISPLAY, or allow the private Xvfb (Debian package 'xvfb')");
  impl_->start_xvfb(options);
  impl_->display = XOpenDisplay(impl_->name.c_str());
  if (!impl_->display)
    throw DisplayError("started Xvfb on " + impl_->name + " but cannot connect to it", kXvfbHint);
  if (options.private_xvfb)
    spdlog::info("rendering through a private Xvfb on {} (stopped when done)", impl_->name);
  else
    spdlog::info("no DISPLAY: rendering through a private Xvfb on {} (stopped when done)", impl_->name);
}

DisplaySession::~DisplaySession() = default;

const std::string& DisplaySession::name() const { return impl_->name; }
bool DisplaySession::private_xvfb() const { return impl_->xvfb_pid > 0; }
void* DisplaySession::x_display() const { return impl_->display; }

}  // namespace organsmith
