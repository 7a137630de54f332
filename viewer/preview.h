#pragma once
// The interactive preview: a VTK window with the organs, guidance paths and a tool proxy driven
// by the mouse through the haptics device interface (screen-plane motion; wheel for depth). The
// haptic loop (physics/haptics/haptic_loop.h) runs at its rate (1 kHz) in its own thread; the window
// draws the tool where the loop puts it, the force arrow, and the organ surface deformed around
// the contact. Keys 1/2/3 switch guidance-only, mixed and reaction-only forces.

#include "physics/haptics/contact.h"
#include "physics/haptics/guidance.h"
#include "physics/haptics/haptic_loop.h"
#include "physics/tissue/realtime_tissue.h"
#include "viewer/display.h"
#include "viewer/scene.h"

#include <Eigen/Core>

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// "guidance only", "mixed", "reaction only" (what the window and the events call the modes).
std::string preview_mode_label(physics::ForceMode mode);

struct PreviewOptions {
  int width_px = 1024;          ///< window size (default 1024 × 768)
  int height_px = 768;
  std::string title = "organsmith preview";  ///< window title (tests find the window by it)
  double render_rate_hz = 60.0;    ///< redraws asked for per second (default 60; llvmpipe may give fewer)
  double quit_after_s = 0.0;       ///< close by itself after this long (0 = only when the user closes it)
  DisplayOptions display;          ///< default: $DISPLAY, else a private Xvfb (nothing visible then)
  /// Where the hand (and the tool) start, LPS mm; default: just in front of the first organ.
  std::optional<Eigen::Vector3d> start_lps_mm;
  /// When set, the window is saved there as a PNG when it closes (for documentation).
  std::filesystem::path screenshot_png;
  /// Called (on the window's thread) for each user action: "ready", "mode 2 mixed",
  /// "status …" (key s), "quit …"; tests and the CLI print them.
  std::function<void(const std::string&)> on_event;
};

/// The force model the preview drives. Built by the caller (e.g. pipeline/cli/cmd_viewer.cpp from a
/// run's output directory); everything pointed to must outlive run_preview().
struct PreviewHaptics {
  const physics::PathIndex* path = nullptr;        ///< guidance path (null: no guidance force)
  std::string path_name;                           ///< shown in the corner
  const physics::ContactModel* contact = nullptr;  ///< organ surfaces and their laws (null: no reaction)
  /// For each surface of `contact` (same order), the index into SnapshotScene::surfaces of the
  /// surface drawn for it, which is deformed around the contact; -1 = not drawn.
  std::vector<int> contact_scene_surfaces;
  physics::LoopOptions loop;        ///< rate (default 1 kHz), force limit, guidance bands, start mode
  double deform_radius_mm = 8.0;    ///< falloff radius of the drawn deformation, mm (default 8)
  /// An organ drawn from its real-time finite-element model instead (its outer surface at the
  /// model's last update, each frame) and felt through `tissue_reaction` (added to the loop).
  /// The caller starts and stops the model; it must outlive run_preview().
  const physics::RealtimeTissue* tissue = nullptr;
  physics::ReactionSource* tissue_reaction = nullptr;
  std::vector<std::int32_t> tissue_triangles;  ///< its outer surface: node ids, three per face, outward
  std::vector<std::int32_t> tissue_fixed_nodes;  ///< reported in the status (their largest displacement)
  std::string tissue_organ;                      ///< the organ it is: its drawn surface is replaced
  /// A recorded hand path that moves the hand instead of the mouse (times from when the loop
  /// starts, about when the window opens; held at its end): demonstrations and benchmarks with
  /// the window drawing. The mouse still turns the view. Must outlive run_preview().
  physics::ScriptedDevice* hand_path = nullptr;
};

/// Opens the preview window on `scene`, runs the haptic loop while it is open, and returns when
/// the user closes it (q, Esc, or the window's close button). Throws DisplayError when no display
/// can be had, UsageError for bad loop options.
void run_preview(const SnapshotScene& scene, const PreviewOptions& options, const PreviewHaptics& haptics = {});

}  // namespace organsmith
