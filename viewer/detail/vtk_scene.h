#pragma once
// Private to the viewer: core types → VTK objects, and the pieces every view shares (titles,
// scale bars, parallel cameras fitted to bounds). VTK appears here and in the viewer's .cpp
// files only.

#include "viewer/image.h"
#include "viewer/scene.h"

#include <vtkActor.h>
#include <vtkActor2D.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkProp.h>
#include <vtkRenderWindow.h>
#include <vtkRenderer.h>
#include <vtkSmartPointer.h>
#include <vtkTextActor.h>
#include <vtkTransform.h>
#include <vtkUnstructuredGrid.h>

#include <array>
#include <string>
#include <vector>

namespace organsmith::viewer_detail {

template <typename T>
using Ptr = vtkSmartPointer<T>;

/// A render window on the session's X display: fixed size, no multisampling.
Ptr<vtkRenderWindow> make_window(void* x_display, int width_px, int height_px, bool offscreen);

/// Triangles with area-weighted vertex normals, and per-triangle RGB when `region_colours` is
/// non-empty (a "colours" cell array).
Ptr<vtkPolyData> to_polydata(const SurfaceMesh& mesh, const std::map<std::int32_t, Rgb>& region_colours = {},
                             bool normals = true);
Ptr<vtkPolyData> to_polydata(const Polyline& line);
/// Tets with a "quality" cell array (3 r_in / R_circ, 1 = regular).
Ptr<vtkUnstructuredGrid> to_grid(const TetMesh& mesh, const std::vector<std::int32_t>& keep);

/// The surface's actor (region colours, opacity, back faces culled); `polydata`, when given,
/// receives the data drawn (the preview moves its points).
Ptr<vtkActor> surface_actor(const SceneSurface& s, Ptr<vtkPolyData>* polydata = nullptr);
/// The same with the data already converted (to_polydata of s.mesh and s.region_colours).
Ptr<vtkActor> surface_actor(const SceneSurface& s, vtkPolyData* polydata);
Ptr<vtkActor> path_actor(const ScenePath& p);
/// Transform that maps +x of a VTK source to `dir`, scaled by `length` (and by `width` across),
/// placed at `origin`.
Ptr<vtkTransform> along(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double length, double width);
/// Tip sphere and shaft (length_mm), coloured `colour`; arrow for the force when given.
std::vector<Ptr<vtkProp>> tool_props(const SceneTool& tool, double length_mm, const Rgb& colour);

/// 3 r_in / R_circ of a tetrahedron (1 for the regular one, → 0 when degenerate).
double tet_radius_ratio(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                        const Eigen::Vector3d& d);

/// Axis-aligned bounds (xmin, xmax, ymin, ymax, zmin, zmax) of the visible props; false when empty.
bool visible_bounds(vtkRenderer* r, std::array<double, 6>& b);

/// Parallel camera looking along `view_dir` (from the camera towards the data) with `up`,
/// fitting `bounds` into the renderer's viewport with `margin` (fraction) around it.
void fit_parallel_camera(vtkRenderer* r, const std::array<double, 6>& bounds, const Eigen::Vector3d& view_dir,
                         const Eigen::Vector3d& up, double aspect, double margin = 0.08);

/// A view direction from the patient's front turned `azimuth_deg` towards the patient's left and
/// `elevation_deg` towards the head.
Eigen::Vector3d anterior_view(double azimuth_deg, double elevation_deg);

/// Text in viewport pixels; `font_px` is the font size; justification 0 left, 1 centre, 2 right;
/// vertical 0 bottom, 1 centre, 2 top.
Ptr<vtkTextActor> text(const std::string& s, int font_px, const Rgb& colour, double x_px, double y_px,
                       int justify = 0, int vjustify = 0, bool bold = false);

/// A filled rectangle in viewport pixels (legend swatches and backdrops).
Ptr<vtkActor2D> rect_2d(double x0_px, double y0_px, double x1_px, double y1_px, const Rgb& colour,
                        double opacity = 1.0);

/// The scale-bar shape through four points in viewport pixels: the bar 0–1 and end ticks 0–2,
/// 1–3, three pixels wide. Moving the points moves the bar (the preview does so every frame).
Ptr<vtkActor2D> scale_bar_actor(vtkPoints* points, const Rgb& colour);

/// A scale bar at the viewport's lower left: a round length (1, 2, 5 × 10ⁿ mm) about a fifth
/// of the viewport's width, with end ticks and "<n> mm".
void add_scale_bar(vtkRenderer* r, double mm_per_px, int viewport_w_px, int viewport_h_px, const Rgb& colour);

/// Writes the front of `window` into an RgbImage (top row first).
RgbImage grab(vtkRenderWindow* window);

}  // namespace organsmith::viewer_detail
