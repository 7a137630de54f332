// Over 400 lines: every conversion of core types to VTK and the actors every view shares.
// Core types → VTK, and the shared pieces of every view.

#include "viewer/detail/vtk_scene.h"

#include <Eigen/Geometry>
#include <vtkArrowSource.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkCoordinate.h>
#include <vtkCylinderSource.h>
#include <vtkDataSetMapper.h>
#include <vtkDoubleArray.h>
#include <vtkFloatArray.h>
#include <vtkIdTypeArray.h>
#include <vtkMath.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyDataMapper.h>
#include <vtkPolyDataMapper2D.h>
#include <vtkProperty.h>
#include <vtkProperty2D.h>
#include <vtkPropCollection.h>
#include <vtkRendererCollection.h>
#include <vtkSphereSource.h>
#include <vtkTextProperty.h>
#include <vtkTransform.h>
#include <vtkTransformPolyDataFilter.h>
#include <vtkTubeFilter.h>
#include <vtkUnsignedCharArray.h>
#include <vtkXOpenGLRenderWindow.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <cstdio>

namespace organsmith {

namespace viewer_detail {

Ptr<vtkRenderWindow> make_window(void* x_display, int width_px, int height_px, bool offscreen) {
  auto w = Ptr<vtkRenderWindow>::New();
  if (auto* xw = vtkXOpenGLRenderWindow::SafeDownCast(w)) xw->SetDisplayId(x_display);
  w->SetMultiSamples(0);  // MSAA triples the cost on llvmpipe
  w->SetOffScreenRendering(offscreen ? 1 : 0);
  w->SetSize(width_px, height_px);
  w->SetAlphaBitPlanes(1);  // depth peeling for translucent walls
  return w;
}

namespace {

std::array<unsigned char, 3> bytes(const Rgb& c) {
  auto b = [](double v) { return (unsigned char)std::lround(std::clamp(v, 0.0, 1.0) * 255.0); };
  return {b(c.r), b(c.g), b(c.b)};
}

}  // namespace

Ptr<vtkPolyData> to_polydata(const SurfaceMesh& mesh, const std::map<std::int32_t, Rgb>& region_colours,
                             bool normals) {
  const auto nv = vtkIdType(mesh.vertices_lps_mm.size());
  const auto nt = vtkIdType(mesh.triangles.size());
  auto pts = Ptr<vtkPoints>::New();
  pts->SetDataTypeToFloat();
  pts->SetNumberOfPoints(nv);
  auto* p = static_cast<float*>(pts->GetVoidPointer(0));
  for (vtkIdType i = 0; i < nv; ++i)
    for (int c = 0; c < 3; ++c) p[3 * i + c] = float(mesh.vertices_lps_mm[i][c]);

  // Fixed-size cells: offsets 0, 3, 6, … and the connectivity copied in one pass.
  auto offsets = Ptr<vtkIdTypeArray>::New();
  offsets->SetNumberOfValues(nt + 1);
  auto conn = Ptr<vtkIdTypeArray>::New();
  conn->SetNumberOfValues(3 * nt);
  vtkIdType* o = offsets->GetPointer(0);
  vtkIdType* cc = conn->GetPointer(0);
  for (vtkIdType t = 0; t <= nt; ++t) o[t] = 3 * t;
  for (vtkIdType t = 0; t < nt; ++t)
    for (int c = 0; c < 3; ++c) cc[3 * t + c] = mesh.triangles[t][c];
  auto cells = Ptr<vtkCellArray>::New();
  cells->SetData(offsets, conn);

  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(pts);
  pd->SetPolys(cells);

  if (normals && nv > 0) {
    // Face normals in parallel, then summed per vertex in triangle order (the same sums, in the
    // same order, on every run: the PNGs stay byte-identical).
    std::vector<Eigen::Vector3f> face(static_cast<std::size_t>(nt));
    tbb::parallel_for(tbb::blocked_range<vtkIdType>(0, nt, 16384), [&](const tbb::blocked_range<vtkIdType>& r) {
      for (vtkIdType t = r.begin(); t < r.end(); ++t) {
        const auto& tri = mesh.triangles[std::size_t(t)];
        const Eigen::Vector3f a(p + 3 * std::size_t(tri[0]));
        const Eigen::Vector3f e1 = Eigen::Vector3f(p + 3 * std::size_t(tri[1])) - a;
        const Eigen::Vector3f e2 = Eigen::Vector3f(p + 3 * std::size_t(tri[2])) - a;
        face[std::size_t(t)] = e1.cross(e2);  // length = 2 × area: area weighting for free
      }
    });
    std::vector<Eigen::Vector3f> n(nv, Eigen::Vector3f::Zero());
    for (vtkIdType t = 0; t < nt; ++t)
      for (int c = 0; c < 3; ++c) n[mesh.triangles[std::size_t(t)][c]] += face[std::size_t(t)];
    auto arr = Ptr<vtkFloatArray>::New();
    arr->SetName("normals");
    arr->SetNumberOfComponents(3);
    arr->SetNumberOfTuples(nv);
    float* q = arr->GetPointer(0);
    for (vtkIdType i = 0; i < nv; ++i) {
      const float len = n[i].norm();
      const Eigen::Vector3f u = len > 0 ? Eigen::Vector3f(n[i] / len) : Eigen::Vector3f(0, 0, 1);
      q[3 * i] = u.x();
      q[3 * i + 1] = u.y();
      q[3 * i + 2] = u.z();
    }
    pd->GetPointData()->SetNormals(arr);
  }

  if (!region_colours.empty() && mesh.region_ids.size() == mesh.triangles.size()) {
    auto col = Ptr<vtkUnsignedCharArray>::New();
    col->SetName("colours");
    col->SetNumberOfComponents(3);
    col->SetNumberOfTuples(nt);
    for (vtkIdType t = 0; t < nt; ++t) {
      const auto it = region_colours.find(mesh.region_ids[t]);
      const auto b = bytes(it == region_colours.end() ? Rgb{0.6, 0.6, 0.6} : it->second);
      col->SetTypedTuple(t, b.data());
    }
    pd->GetCellData()->SetScalars(col);
  }
  return pd;
}

Ptr<vtkPolyData> to_polydata(const Polyline& line) {
  auto pts = Ptr<vtkPoints>::New();
  for (const auto& q : line.points_lps_mm) pts->InsertNextPoint(q.x(), q.y(), q.z());
  auto cells = Ptr<vtkCellArray>::New();
  const auto n = vtkIdType(line.points_lps_mm.size());
  cells->InsertNextCell(n + (line.closed && n > 2 ? 1 : 0));
  for (vtkIdType i = 0; i < n; ++i) cells->InsertCellPoint(i);
  if (line.closed && n > 2) cells->InsertCellPoint(0);
  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(pts);
  pd->SetLines(cells);
  return pd;
}

double tet_radius_ratio(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& p2,
                        const Eigen::Vector3d& p3) {
  const Eigen::Vector3d a = p1 - p0, b = p2 - p0, c = p3 - p0;
  const double v6 = std::abs(a.dot(b.cross(c)));  // 6 × volume
  if (v6 <= 0) return 0.0;
  const double area = 0.5 * ((p1 - p0).cross(p2 - p0).norm() + (p1 - p0).cross(p3 - p0).norm() +
                             (p2 - p0).cross(p3 - p0).norm() + (p2 - p1).cross(p3 - p1).norm());
  const double r_in = (v6 / 2.0) / area;  // 3V / A
  const Eigen::Vector3d num = a.squaredNorm() * b.cross(c) + b.squaredNorm() * c.cross(a) + c.squaredNorm() * a.cross(b);
  const double r_circ = num.norm() / (2.0 * v6);
  return r_circ > 0 ? std::clamp(3.0 * r_in / r_circ, 0.0, 1.0) : 0.0;
}

Ptr<vtkUnstructuredGrid> to_grid(const TetMesh& mesh, const std::vector<std::int32_t>& keep) {
  auto pts = Ptr<vtkPoints>::New();
  pts->SetNumberOfPoints(vtkIdType(mesh.vertices_lps_mm.size()));
  for (std::size_t i = 0; i < mesh.vertices_lps_mm.size(); ++i) pts->SetPoint(vtkIdType(i), mesh.vertices_lps_mm[i].data());
  auto grid = Ptr<vtkUnstructuredGrid>::New();
  grid->SetPoints(pts);
  grid->Allocate(vtkIdType(keep.size()));
  auto quality = Ptr<vtkDoubleArray>::New();
  quality->SetName("quality");
  quality->SetNumberOfTuples(vtkIdType(keep.size()));
  vtkIdType row = 0;
  for (const std::int32_t t : keep) {
    const auto& tet = mesh.tets[t];
    const vtkIdType ids[4] = {tet[0], tet[1], tet[2], tet[3]};
    grid->InsertNextCell(VTK_TETRA, 4, ids);
    quality->SetValue(row++, tet_radius_ratio(mesh.vertices_lps_mm[tet[0]], mesh.vertices_lps_mm[tet[1]],
                                              mesh.vertices_lps_mm[tet[2]], mesh.vertices_lps_mm[tet[3]]));
  }
  grid->GetCellData()->SetScalars(quality);
  return grid;
}

Ptr<vtkActor> surface_actor(const SceneSurface& s, Ptr<vtkPolyData>* polydata) {
  auto pd = to_polydata(s.mesh, s.region_colours);
  if (polydata) *polydata = pd;
  return surface_actor(s, pd.Get());
}

Ptr<vtkActor> surface_actor(const SceneSurface& s, vtkPolyData* pd) {
  auto mapper = Ptr<vtkPolyDataMapper>::New();
  mapper->SetInputData(pd);
  if (pd->GetCellData()->GetScalars()) {
    mapper->SetScalarModeToUseCellData();
    mapper->SetColorModeToDirectScalars();
    mapper->ScalarVisibilityOn();
  } else {
    mapper->ScalarVisibilityOff();
  }
  auto actor = Ptr<vtkActor>::New();
  actor->SetMapper(mapper);
  auto* prop = actor->GetProperty();
  prop->SetColor(s.colour.r, s.colour.g, s.colour.b);
  prop->SetOpacity(s.opacity);
  prop->SetInterpolationToGouraud();
  prop->SetSpecular(0.25);
  prop->SetSpecularPower(20);
  prop->SetDiffuse(0.8);
  prop->SetAmbient(0.15);
  // Surfaces are closed and outward: back faces are never seen, and culling them before
  // triangle setup halves llvmpipe's main cost on million-triangle meshes. (A translucent wall
  // then shows its front only, which is what a reviewer expects.)
  prop->BackfaceCullingOn();
  return actor;
}

Ptr<vtkActor> path_actor(const ScenePath& p) {
  auto tube = Ptr<vtkTubeFilter>::New();
  tube->SetInputData(to_polydata(p.line));
  tube->SetRadius(p.radius_mm);
  tube->SetNumberOfSides(16);
  tube->CappingOn();
  auto mapper = Ptr<vtkPolyDataMapper>::New();
  mapper->SetInputConnection(tube->GetOutputPort());
  mapper->ScalarVisibilityOff();
  auto actor = Ptr<vtkActor>::New();
  actor->SetMapper(mapper);
  actor->GetProperty()->SetColor(p.colour.r, p.colour.g, p.colour.b);
  actor->GetProperty()->SetSpecular(0.3);
  return actor;
}

Ptr<vtkTransform> along(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double length, double width) {
  const Eigen::Vector3d x = dir.normalized();
  Eigen::Vector3d helper = std::abs(x.z()) < 0.9 ? Eigen::Vector3d(0, 0, 1) : Eigen::Vector3d(1, 0, 0);
  const Eigen::Vector3d y = helper.cross(x).normalized();
  const Eigen::Vector3d z = x.cross(y);
  double m[16] = {x.x() * length, y.x() * width, z.x() * width, origin.x(),
                  x.y() * length, y.y() * width, z.y() * width, origin.y(),
                  x.z() * length, y.z() * width, z.z() * width, origin.z(),
                  0,              0,             0,             1};
  auto t = Ptr<vtkTransform>::New();
  t->SetMatrix(m);
  return t;
}

namespace {

Ptr<vtkActor> transformed(vtkAlgorithm* source, vtkTransform* t, const Rgb& colour) {
  auto f = Ptr<vtkTransformPolyDataFilter>::New();
  f->SetInputConnection(source->GetOutputPort());
  f->SetTransform(t);
  auto mapper = Ptr<vtkPolyDataMapper>::New();
  mapper->SetInputConnection(f->GetOutputPort());
  auto actor = Ptr<vtkActor>::New();
  actor->SetMapper(mapper);
  actor->GetProperty()->SetColor(colour.r, colour.g, colour.b);
  actor->GetProperty()->SetSpecular(0.4);
  return actor;
}

}  // namespace

std::vector<Ptr<vtkProp>> tool_props(const SceneTool& tool, double length_mm, const Rgb& colour) {
  std::vector<Ptr<vtkProp>> props;
  auto sphere = Ptr<vtkSphereSource>::New();
  sphere->SetRadius(1.0);
  sphere->SetThetaResolution(24);
  sphere->SetPhiResolution(16);
  const double tip_r = std::max(0.6, length_mm * 0.06);
  props.push_back(transformed(sphere, along(tool.tip_lps_mm, Eigen::Vector3d(1, 0, 0), tip_r, tip_r), colour));
  // vtkCylinderSource is along +y, centred: rotate it onto +x first by building it there.
  auto shaft = Ptr<vtkCylinderSource>::New();
  shaft->SetResolution(20);
  shaft->SetRadius(0.5);
  shaft->SetHeight(1.0);
  shaft->SetCenter(0, 0, 0);
  auto to_x = Ptr<vtkTransform>::New();
  const Eigen::Vector3d axis = tool.axis_lps.norm() > 0 ? tool.axis_lps.normalized() : Eigen::Vector3d(0, -1, 0);
  to_x->DeepCopy(along(tool.tip_lps_mm + axis * (length_mm / 2), axis, length_mm, tip_r * 0.8));
  to_x->RotateZ(-90);  // source +y → transform's +x
  props.push_back(transformed(shaft, to_x, colour));
  if (tool.force_N && tool.force_N->norm() > 0) {
    auto arrow = Ptr<vtkArrowSource>::New();
    arrow->SetShaftResolution(16);
    arrow->SetTipResolution(24);
    const double len = length_mm * 0.8;
    props.push_back(transformed(arrow, along(tool.tip_lps_mm, *tool.force_N, len, len), Rgb{0.85, 0.1, 0.1}));
  }
  return props;
}

bool visible_bounds(vtkRenderer* r, std::array<double, 6>& b) {
  double bb[6];
  r->ComputeVisiblePropBounds(bb);
  if (!vtkMath::AreBoundsInitialized(bb)) return false;
  std::copy(bb, bb + 6, b.begin());
  return true;
}

Eigen::Vector3d anterior_view(double azimuth_deg, double elevation_deg) {
  // Camera in front of the patient (−P) looking towards +P; azimuth turns it to the patient's
  // left (+L), elevation raises it towards the head (+S).
  const double az = azimuth_deg * M_PI / 180.0, el = elevation_deg * M_PI / 180.0;
  const Eigen::Vector3d camera_side(std::sin(az) * std::cos(el), -std::cos(az) * std::cos(el), std::sin(el));
  return -camera_side;
}

void fit_parallel_camera(vtkRenderer* r, const std::array<double, 6>& b, const Eigen::Vector3d& view_dir,
                         const Eigen::Vector3d& up_hint, double aspect, double margin) {
  const Eigen::Vector3d d = view_dir.normalized();
  const Eigen::Vector3d right = d.cross(up_hint).normalized();
  const Eigen::Vector3d up = right.cross(d);
  const Eigen::Vector3d centre((b[0] + b[1]) / 2, (b[2] + b[3]) / 2, (b[4] + b[5]) / 2);
  double hx = 0, hy = 0, hz = 0;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d corner(b[i & 1], b[2 + ((i >> 1) & 1)], b[4 + ((i >> 2) & 1)]);
    const Eigen::Vector3d q = corner - centre;
    hx = std::max(hx, std::abs(q.dot(right)));
    hy = std::max(hy, std::abs(q.dot(up)));
    hz = std::max(hz, std::abs(q.dot(d)));
  }
  const double half_h = std::max({hy, hx / aspect, 1.0}) * (1.0 + margin);
  auto* cam = r->GetActiveCamera();
  cam->ParallelProjectionOn();
  const double dist = 4.0 * std::max({hx, hy, hz, 10.0});
  const Eigen::Vector3d pos = centre - d * dist;
  cam->SetFocalPoint(centre.data());
  cam->SetPosition(pos.data());
  cam->SetViewUp(up.data());
  cam->SetParallelScale(half_h);
  cam->SetClippingRange(dist - hz * 1.5 - 1.0, dist + hz * 1.5 + 1.0);
}

Ptr<vtkTextActor> text(const std::string& s, int font_px, const Rgb& colour, double x_px, double y_px, int justify,
                       int vjustify, bool bold) {
  auto t = Ptr<vtkTextActor>::New();
  t->SetInput(s.c_str());
  auto* p = t->GetTextProperty();
  p->SetFontFamilyToArial();
  p->SetFontSize(font_px);
  p->SetColor(colour.r, colour.g, colour.b);
  p->SetBold(bold ? 1 : 0);
  p->SetJustification(justify);
  p->SetVerticalJustification(vjustify);
  // Viewport pixels, not window pixels: a view made of several renderers places its text in each.
  t->GetPositionCoordinate()->SetCoordinateSystemToViewport();
  t->SetPosition(std::round(x_px), std::round(y_px));
  return t;
}

namespace {

/// A 2D actor of `points` joined by `cells` (two-point lines, or polygons when `filled`).
Ptr<vtkActor2D> actor_2d(vtkPoints* points, const std::vector<std::vector<vtkIdType>>& cells, bool filled,
                         const Rgb& colour) {
  auto ca = Ptr<vtkCellArray>::New();
  for (const auto& c : cells) ca->InsertNextCell(vtkIdType(c.size()), c.data());
  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(points);
  if (filled) pd->SetPolys(ca);
  else pd->SetLines(ca);
  auto mapper = Ptr<vtkPolyDataMapper2D>::New();
  mapper->SetInputData(pd);
  auto actor = Ptr<vtkActor2D>::New();
  actor->SetMapper(mapper);
  actor->GetProperty()->SetColor(colour.r, colour.g, colour.b);
  return actor;
}

}  // namespace

Ptr<vtkActor2D> rect_2d(double x0, double y0, double x1, double y1, const Rgb& colour, double opacity) {
  auto pts = Ptr<vtkPoints>::New();
  pts->InsertNextPoint(x0, y0, 0);
  pts->InsertNextPoint(x1, y0, 0);
  pts->InsertNextPoint(x1, y1, 0);
  pts->InsertNextPoint(x0, y1, 0);
  auto a = actor_2d(pts, {{0, 1, 2, 3}}, true, colour);
  a->GetProperty()->SetOpacity(opacity);
  return a;
}

Ptr<vtkActor2D> scale_bar_actor(vtkPoints* points, const Rgb& colour) {
  auto a = actor_2d(points, {{0, 1}, {0, 2}, {1, 3}}, false, colour);
  a->GetProperty()->SetLineWidth(3);
  return a;
}

void add_scale_bar(vtkRenderer* r, double mm_per_px, int vw, int vh, const Rgb& colour) {
  if (!(mm_per_px > 0)) return;
  const double target_mm = 0.2 * vw * mm_per_px;
  double step = std::pow(10.0, std::floor(std::log10(target_mm)));
  for (const double m : {5.0, 2.0, 1.0})
    if (m * step <= target_mm) {
      step *= m;
      break;
    }
  const double len_px = step / mm_per_px;
  const double x0 = std::round(0.04 * vw), y0 = std::round(0.05 * vh), tick = std::max(4.0, 0.012 * vh);
  auto pts = Ptr<vtkPoints>::New();
  pts->InsertNextPoint(x0, y0, 0);
  pts->InsertNextPoint(x0 + len_px, y0, 0);
  pts->InsertNextPoint(x0, y0 + tick, 0);
  pts->InsertNextPoint(x0 + len_px, y0 + tick, 0);
  r->AddViewProp(scale_bar_actor(pts, colour));
  char label[32];
  std::snprintf(label, sizeof label, "%g mm", step);
  r->AddViewProp(text(label, std::max(12, vh / 40), colour, x0 + len_px / 2, y0 + tick + 4, 1, 0));
}

RgbImage grab(vtkRenderWindow* w) {
  const int* size = w->GetSize();
  RgbImage img;
  img.width_px = size[0];
  img.height_px = size[1];
  img.rgb.resize(std::size_t(size[0]) * size[1] * 3);
  unsigned char* data = w->GetPixelData(0, 0, size[0] - 1, size[1] - 1, /*front=*/0);
  // OpenGL's rows run bottom to top.
  for (int y = 0; y < size[1]; ++y)
    std::copy(data + std::size_t(size[1] - 1 - y) * size[0] * 3, data + std::size_t(size[1] - y) * size[0] * 3,
              img.rgb.begin() + std::size_t(y) * size[0] * 3);
  delete[] data;
  return img;
}

}  // namespace viewer_detail
}  // namespace organsmith
