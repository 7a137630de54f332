#pragma once
// What the viewer draws, in core types only (LPS millimetres throughout). A scene is filled by
// the caller from whatever the pipeline has produced so far; every part is optional.

#include "core/geometry.h"
#include "core/volume.h"

#include <Eigen/Core>

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// A colour with components in [0, 1].
struct Rgb {
  double r = 1.0, g = 1.0, b = 1.0;
};

/// One triangle surface to draw.
struct SceneSurface {
  std::string name;   ///< e.g. "gallbladder", "gallbladder_wall_inner", "trachea_wall"
  std::string organ;  ///< the organ it belongs to (views are made per organ)
  SurfaceMesh mesh;
  Rgb colour;                             ///< used for triangles without a region colour
  double opacity = 1.0;                   ///< 1 = opaque; walls are drawn translucent (≈ 0.35)
  std::map<std::int32_t, Rgb> region_colours;  ///< per mesh.region_ids value; empty = `colour`
  bool context = false;  ///< surrounding anatomy (liver, lungs): drawn faint, only in overviews
  /// Where it came from, shown in the title, e.g. "mesh stage" or "label-map isosurface".
  std::string source;
};

/// One tetrahedral mesh to draw as a cut view coloured by element quality.
struct SceneTetMesh {
  std::string organ;
  TetMesh mesh;
};

/// A guidance path or centreline, drawn as a tube.
struct ScenePath {
  Polyline line;
  Rgb colour{1.0, 0.85, 0.1};
  double radius_mm = 0.8;
};

/// The tool proxy and the force it feels.
struct SceneTool {
  Eigen::Vector3d tip_lps_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis_lps = Eigen::Vector3d(0, -1, 0);  ///< unit vector from tip towards the handle
  std::optional<Eigen::Vector3d> force_N;                 ///< drawn as an arrow from the tip when given
};

/// A solver's answer on an organ (the simulate stage): its boundary surface undeformed and
/// deformed (the same triangles), with a value per vertex of the deformed one. Drawn as the view
/// "simulation_<organ>": the deformed surface coloured by the value over the undeformed one,
/// translucent.
struct SceneDeformation {
  std::string organ;
  SurfaceMesh undeformed, deformed;
  std::vector<double> values;    ///< per vertex of `deformed`
  std::string value_title;       ///< colour bar title, e.g. "von Mises, Pa"
  std::string detail;            ///< line under the title: load, largest displacement, …
};

/// One series of an XY plot.
struct PlotSeries {
  std::string name;
  std::vector<double> x, y;  ///< same length
  bool points = false;       ///< true: markers only (measurements); false: a line (fits, CDFs)
  Rgb colour{0.1, 0.3, 0.8};
  bool dashed = false;       ///< lines only: dashed (bands, secondary curves)
  bool in_legend = true;     ///< false: not listed (the second line of a band)
  int marker = 0;            ///< points only: 0 circle, 1 square, 2 diamond, 3 cross, 4 plus
};

/// An XY chart (calibration fits, Monte Carlo CDFs). Axis labels carry units.
struct Plot {
  std::string name;  ///< file stem: the PNG is plot_<name>.png
  std::string title;
  std::string x_label, y_label;
  std::vector<PlotSeries> series;
  std::string note;  ///< one line under the title: where the data come from
  bool log_x = false;  ///< logarithmic x axis (positive values only; decade ticks)
  bool log_y = false;  ///< logarithmic y axis (positive values only; decade ticks)
};

/// An organ to slice through: name and the label value that marks it in `labels`.
struct SceneOrgan {
  std::string name;
  std::uint8_t label = 0;
  Rgb colour{0.6, 0.6, 0.62};  ///< its display colour (the organ registry's)
};

/// Everything a set of snapshots is made from. The volume and label map are borrowed: they
/// must outlive the calls that use the scene (they are large; the scene never copies them).
struct SnapshotScene {
  std::string case_name;                 ///< shown in titles, e.g. "phantom"
  const Volume* ct = nullptr;            ///< CT in HU, for slice views
  const LabelMap* labels = nullptr;      ///< segmentation on the CT's grid
  std::string labels_source;             ///< e.g. "segmentation" or "phantom ground truth"
  std::vector<SceneOrgan> organs;        ///< organs to slice through (and to make 3D views of)
  std::vector<ContourStack> contours;    ///< segmentation contours, drawn on axial slices
  std::vector<SceneSurface> surfaces;
  std::vector<SceneTetMesh> tet_meshes;
  std::vector<ScenePath> paths;
  std::optional<SceneTool> tool;
  std::vector<Plot> plots;
  std::vector<SceneDeformation> deformations;
};

}  // namespace organsmith
