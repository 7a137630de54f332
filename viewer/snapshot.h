#pragma once
// Off-screen snapshots: fixed-size PNG views of a SnapshotScene with titles and a scale bar in
// mm, cameras set from the data's bounds (parallel projection, so the scale bar is exact),
// multisampling off. The same scene and options give byte-identical PNGs.
//
// Views and their file names (stems):
//   3d_<organ>                        the organ's surfaces, coloured by region, walls translucent
//   3d_overview                       every organ, context anatomy faint, paths as tubes, tool and force
//   slice_<organ>_{axial,coronal,sagittal}
//                                     CT in a HU window through the organ's centroid, the whole slice
//                                     beside a close-up, segmentation contour over it
//   tets_<organ>                      tetrahedral mesh cut through its centroid, coloured by quality
//   plot_<name>                       XY charts (calibration fits, Monte Carlo CDFs)

#include "core/progress.h"
#include "viewer/display.h"
#include "viewer/image.h"
#include "viewer/scene.h"

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace organsmith {

/// Families of views; SnapshotOptions::views selects some.
enum class ViewKind { organ_3d, overview_3d, slices, tets, plots };

/// Parses "organs", "overview", "slices", "tets", "plots" (throws UsageError otherwise).
ViewKind parse_view_kind(const std::string& name);

struct SnapshotOptions {
  int width_px = 1024;   ///< PNG width (default 1024)
  int height_px = 768;   ///< PNG height (default 768)
  std::vector<ViewKind> views = {ViewKind::organ_3d, ViewKind::overview_3d, ViewKind::slices, ViewKind::tets,
                                 ViewKind::plots};
  double hu_window = 400.0;        ///< CT display window width, HU (default 400: soft tissue)
  double hu_level = 40.0;          ///< CT display window centre, HU (default 40)
  double closeup_min_mm = 90.0;    ///< smallest side of a slice close-up, mm (default 90)
  int png_compression = 5;         ///< zlib level of the PNGs, 0–9 (default 5; 1 is faster, files ~5 % larger)
  DisplayOptions display;          ///< where to render (default: $DISPLAY, else a private Xvfb)
};

/// The names (file stems) of the views `options` asks for that `scene` has data for, in the
/// order they are rendered.
std::vector<std::string> snapshot_view_names(const SnapshotScene& scene, const SnapshotOptions& options);

/// Renders every view of snapshot_view_names() into `dir`/<name>.png and returns the paths.
/// Writes in place: the caller stages `dir` and commits it (see pipeline/run/runner.h). Opens one
/// display session for all views. Throws DisplayError when nothing can render, OutputError when
/// a PNG cannot be written, Cancelled when `progress` asks to stop.
std::vector<std::filesystem::path> render_snapshots(const SnapshotScene& scene, const SnapshotOptions& options,
                                                    const std::filesystem::path& dir, Progress& progress);

/// A fixed-size off-screen render window kept open across views (for many frames, and for
/// timing them: the first frame pays for the window, context and shader compilation).
class SnapshotRenderer {
 public:
  explicit SnapshotRenderer(const SnapshotOptions& options);
  ~SnapshotRenderer();
  SnapshotRenderer(const SnapshotRenderer&) = delete;
  SnapshotRenderer& operator=(const SnapshotRenderer&) = delete;

  /// Renders view `name` (one of snapshot_view_names()) of `scene`. Throws UsageError for an
  /// unknown name.
  RgbImage render(const SnapshotScene& scene, const std::string& name);
  /// Renders view `name` and writes it as a PNG.
  void render_to_png(const SnapshotScene& scene, const std::string& name, const std::filesystem::path& png);
  /// Where the last render() / render_to_png() spent its time, in ms: building the VTK scene from
  /// core types, drawing (upload and rasterisation), reading the pixels back, encoding the PNG.
  struct FrameTimes {
    double build_ms = 0, draw_ms = 0, readback_ms = 0, png_ms = 0;
  };
  /// Surfaces converted to VTK are kept for the next views (an organ is drawn in its own view and
  /// in the overview). A surface is recognised by its address and a fingerprint of its size and
  /// sampled vertices; forget_surfaces() drops them (e.g. after changing meshes in place).
  void forget_surfaces();
  FrameTimes last_frame_times() const;
  /// The display this renderer draws through.
  const DisplaySession& display() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace organsmith
