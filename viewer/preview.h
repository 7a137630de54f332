#pragma once
// The interactive preview: a VTK window with the organs, paths and a tool proxy driven by the
// mouse (screen-plane motion; wheel for depth). Keys 1/2/3 switch guidance-only, mixed and
// reaction-only modes. Until the haptics stage lands, the tool is passive: a 1 kHz device
// thread follows the mouse, and the corner says that no force is computed.

#include "viewer/display.h"
#include "viewer/scene.h"

#include <functional>
#include <string>

namespace organsmith {

/// Haptic interaction modes (thesis §5.2: guidance force, reaction force, or both).
enum class HapticMode { guidance_only = 1, mixed = 2, reaction_only = 3 };
std::string haptic_mode_name(HapticMode mode);  ///< "guidance only", "mixed", "reaction only"

struct PreviewOptions {
  int width_px = 1024;          ///< window size (default 1024 × 768)
  int height_px = 768;
  std::string title = "organsmith preview";  ///< window title (tests find the window by it)
  double device_rate_hz = 1000.0;  ///< device-thread loop rate (default 1 kHz)
  double render_rate_hz = 30.0;    ///< redraw rate of the window (default 30 Hz)
  double quit_after_s = 0.0;       ///< close by itself after this long (0 = only when the user closes it)
  DisplayOptions display;          ///< default: $DISPLAY, else a private Xvfb (nothing visible then)
  /// Called (on the window's thread) for each user action: "mode 2 mixed", "quit", …
  std::function<void(const std::string&)> on_event;
};

/// Opens the preview window on `scene` and returns when the user closes it (q, Esc, or the
/// window's close button). Throws DisplayError when no display can be had.
void run_preview(const SnapshotScene& scene, const PreviewOptions& options);

}  // namespace organsmith
