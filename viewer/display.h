#pragma once
// The X display the viewer renders through. Debian's VTK 9.1 renders only through X
// (vtkXOpenGLRenderWindow on Mesa llvmpipe), so a machine without a display gets a private
// Xvfb for the lifetime of one DisplaySession. No environment variable is changed: the session
// hands its own connection to each render window.

#include "core/errors.h"

#include <memory>
#include <string>

namespace organsmith {

/// No X server could be reached and none could be started (exit code `output`: nothing could
/// be drawn). The hint names the Debian package `xvfb`.
class DisplayError : public Error {
 public:
  DisplayError(std::string message, std::string hint)
      : Error(ExitCode::output, std::move(message), {}, std::move(hint)) {}
};

struct DisplayOptions {
  /// X display to use, e.g. ":0"; empty = $DISPLAY, and when that is unset a private Xvfb.
  std::string display;
  /// Start a private Xvfb when no display is named (default true). When false and no display
  /// is named, DisplaySession throws DisplayError.
  bool allow_xvfb = true;
  /// Start a private Xvfb even when a display is named or $DISPLAY is set (tests, batch jobs
  /// that must not draw on someone's screen). Default false.
  bool private_xvfb = false;
  std::string xvfb_program = "Xvfb";  ///< looked up in PATH
  int xvfb_width_px = 1920;           ///< screen of the private Xvfb (must hold the largest window)
  int xvfb_height_px = 1200;
  double xvfb_start_timeout_s = 15.0; ///< how long to wait for Xvfb to accept connections
};

/// An open connection to an X display, started privately when needed; closes it (and stops
/// the private Xvfb) when destroyed. Logs once when it starts an Xvfb. Not copyable.
class DisplaySession {
 public:
  explicit DisplaySession(const DisplayOptions& options = {});
  ~DisplaySession();
  DisplaySession(const DisplaySession&) = delete;
  DisplaySession& operator=(const DisplaySession&) = delete;

  /// The display name, e.g. ":0" or ":37" (a private Xvfb).
  const std::string& name() const;
  /// True when this session started its own Xvfb.
  bool private_xvfb() const;
  /// The Xlib `Display*`, typeless so that X and VTK stay out of public headers.
  void* x_display() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace organsmith
