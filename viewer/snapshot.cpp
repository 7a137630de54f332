// Over 400 lines: every kind of snapshot view (3D organs, overview, slices, tet cuts, plots, a
// solver's deformed organ) and the one renderer they share.
// Off-screen snapshot views.

#include "viewer/snapshot.h"

#include "core/format.h"
#include "viewer/detail/slice.h"
#include "viewer/detail/vtk_scene.h"

#include <vtkAxis.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkChartLegend.h>
#include <vtkChartXY.h>
#include <vtkContextActor.h>
#include <vtkContextScene.h>
#include <vtkDataSetMapper.h>
#include <vtkDoubleArray.h>
#include <vtkImageActor.h>
#include <vtkImageData.h>
#include <vtkImageMapper3D.h>
#include <vtkLookupTable.h>
#include <vtkPen.h>
#include <vtkPlot.h>
#include <vtkPlotPoints.h>
#include <vtkPoints.h>
#include <vtkPointData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkProperty2D.h>
#include <vtkRendererCollection.h>
#include <vtkScalarBarActor.h>
#include <vtkStringArray.h>
#include <vtkTable.h>
#include <vtkTextProperty.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>

namespace organsmith {

using namespace viewer_detail;

namespace {

const Rgb kDarkText{0.08, 0.09, 0.12};
const Rgb kGreyText{0.30, 0.32, 0.36};
const Rgb kLightText{0.95, 0.95, 0.95};
const Rgb kContourYellow{1.0, 0.88, 0.1};

std::string capitalised(std::string s) {
  if (!s.empty()) s[0] = char(std::toupper(static_cast<unsigned char>(s[0])));
  return s;
}

/// The organ colour scaled to full brightness: outlines stay visible over a dark CT.
Rgb bright(const Rgb& c) {
  const double m = std::max({c.r, c.g, c.b, 1e-6});
  return {c.r / m, c.g / m, c.b / m};
}

bool wants(const SnapshotOptions& o, ViewKind k) { return std::find(o.views.begin(), o.views.end(), k) != o.views.end(); }

/// Organs with at least one non-context surface, in the order they first appear.
std::vector<std::string> surface_organs(const SnapshotScene& scene) {
  std::vector<std::string> out;
  for (const auto& s : scene.surfaces)
    if (!s.context && std::find(out.begin(), out.end(), s.organ) == out.end()) out.push_back(s.organ);
  return out;
}

constexpr SliceAxis kAxes[] = {SliceAxis::axial, SliceAxis::coronal, SliceAxis::sagittal};

struct Layout {
  int w, h, band;  ///< window size and the height of the title band (px)
};

Layout layout_of(const SnapshotOptions& o) {
  return {o.width_px, o.height_px, std::max(48, int(std::lround(o.height_px * 0.105)))};
}

/// The title band across the top: a title and one line of detail.
Ptr<vtkRenderer> title_band(const Layout& L, const std::string& title, const std::string& detail, const Rgb& bg,
                            const Rgb& fg, const Rgb& fg2) {
  auto r = Ptr<vtkRenderer>::New();
  r->SetViewport(0, 1.0 - double(L.band) / L.h, 1, 1);
  r->SetBackground(bg.r, bg.g, bg.b);
  r->InteractiveOff();
  const int big = std::max(12, int(L.band * 0.36)), small = std::max(10, int(L.band * 0.22));
  r->AddViewProp(text(title, big, fg, 0.015 * L.w, L.band * 0.93, 0, 2, true));
  r->AddViewProp(text(detail, small, fg2, 0.015 * L.w, L.band * 0.10, 0, 0));
  return r;
}

Ptr<vtkRenderer> main_area(const Layout& L, double x0, double x1, bool dark) {
  auto r = Ptr<vtkRenderer>::New();
  r->SetViewport(x0, 0, x1, 1.0 - double(L.band) / L.h);
  if (dark) {
    r->SetBackground(0, 0, 0);
  } else {
    r->GradientBackgroundOn();
    r->SetBackground(0.80, 0.82, 0.86);   // bottom
    r->SetBackground2(0.98, 0.98, 0.99);  // top
  }
  r->SetUseDepthPeeling(1);
  r->SetMaximumNumberOfPeels(6);
  r->SetOcclusionRatio(0.0);
  return r;
}

/// Coloured swatches with names, top right of a renderer (viewport pixels).
void add_legend(vtkRenderer* r, const std::vector<std::pair<std::string, Rgb>>& entries, int vw, int vh,
                const Rgb& text_colour) {
  const int font = std::max(11, vh / 42);
  const double line = font * 1.5, sw = font * 0.9;
  double y = vh - 0.03 * vh - font;
  // Right-aligned block: the longest name (≈ 0.55 em per character) ends at the margin.
  std::size_t longest = 0;
  for (const auto& e : entries) longest = std::max(longest, e.first.size());
  const double x = std::max(0.02 * vw, vw - 0.015 * vw - sw * 1.6 - 0.55 * font * double(longest));
  if (!entries.empty()) {  // a pale backdrop keeps the names readable over surfaces and paths
    const double x0 = x - 0.4 * font, x1 = vw - 0.005 * vw, y1 = y + sw + 0.4 * font,
                 y0 = y - line * double(entries.size() - 1) - 0.4 * font;
    r->AddViewProp(rect_2d(x0, y0, x1, y1, Rgb{1, 1, 1}, 0.8));
  }
  for (const auto& [name, colour] : entries) {
    r->AddViewProp(rect_2d(x, y, x + sw, y + sw, colour));
    r->AddViewProp(text(name, font, text_colour, x + sw * 1.6, y + sw * 0.5, 0, 1));
    y -= line;
  }
}

double mm_per_px(vtkRenderer* r, int viewport_h_px) {
  return 2.0 * r->GetActiveCamera()->GetParallelScale() / viewport_h_px;
}

/// Line segments along the pixel edges between `organ` and everything else: the exact voxel
/// outline, crisp at any zoom. Points are in the slice's (s, t) plane coordinates at height z.
Ptr<vtkPolyData> label_outline(const SliceSample& s, std::uint8_t organ, double z) {
  auto pts = Ptr<vtkPoints>::New();
  auto lines = Ptr<vtkCellArray>::New();
  auto in = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < s.width && y < s.height && s.labels[std::size_t(y) * s.width + x] == organ;
  };
  const double h = s.pixel_mm;
  auto seg = [&](double xa, double ya, double xb, double yb) {
    const vtkIdType a = pts->InsertNextPoint(s.s0 + xa * h, s.t0 + ya * h, z);
    const vtkIdType b = pts->InsertNextPoint(s.s0 + xb * h, s.t0 + yb * h, z);
    const vtkIdType ids[2] = {a, b};
    lines->InsertNextCell(2, ids);
  };
  if (!s.labels.empty())
    for (int y = -1; y < s.height; ++y)
      for (int x = -1; x < s.width; ++x) {
        const bool c = in(x, y);
        if (c != in(x + 1, y)) seg(x + 0.5, y - 0.5, x + 0.5, y + 0.5);
        if (c != in(x, y + 1)) seg(x - 0.5, y + 0.5, x + 0.5, y + 0.5);
      }
  auto pd = Ptr<vtkPolyData>::New();
  pd->SetPoints(pts);
  pd->SetLines(lines);
  return pd;
}

Ptr<vtkActor> line_actor(vtkPolyData* pd, const Rgb& c, double width) {
  auto m = Ptr<vtkPolyDataMapper>::New();
  m->SetInputData(pd);
  m->ScalarVisibilityOff();
  auto a = Ptr<vtkActor>::New();
  a->SetMapper(m);
  a->GetProperty()->SetColor(c.r, c.g, c.b);
  a->GetProperty()->SetLineWidth(float(width));
  a->GetProperty()->LightingOff();
  return a;
}

/// "0.01", "0.1", "1", "10", "100", "1 k", "10 k", "100 k", "1 M", … for 10^e.
std::string decade_label(int e) {
  static const char* suffix[] = {"", " k", " M", " G", " T"};
  if (e < 0) {
    std::string s = "0.";
    for (int i = 1; i < -e; ++i) s += '0';
    return s + "1";
  }
  const int group = std::min(e / 3, 4);
  std::string s = "1";
  for (int i = 0; i < e - 3 * group; ++i) s += '0';
  return s + suffix[group];
}

/// Decade ticks (1, 10, 100, …) on an axis whose data are log10 of the values.
void decade_ticks(vtkAxis* axis, const Plot& p, bool x_axis) {
  double lo = 1e300, hi = -1e300;
  for (const auto& sr : p.series)
    for (const double v : x_axis ? sr.x : sr.y)
      if (v > 0) lo = std::min(lo, std::log10(v)), hi = std::max(hi, std::log10(v));
  if (!(hi >= lo)) return;
  const int e0 = int(std::floor(lo)), e1 = int(std::ceil(hi));
  auto pos = Ptr<vtkDoubleArray>::New();
  auto labels = Ptr<vtkStringArray>::New();
  for (int e = e0; e <= e1; ++e) {
    pos->InsertNextValue(e);
    labels->InsertNextValue(decade_label(e));
  }
  axis->SetCustomTickPositions(pos, labels);
  axis->SetBehavior(vtkAxis::FIXED);
  axis->SetRange(e0, e1);
}

}  // namespace

ViewKind parse_view_kind(const std::string& name) {
  if (name == "organs") return ViewKind::organ_3d;
  if (name == "overview") return ViewKind::overview_3d;
  if (name == "slices") return ViewKind::slices;
  if (name == "tets") return ViewKind::tets;
  if (name == "plots") return ViewKind::plots;
  throw UsageError("unknown view '" + name + "'", "use organs, overview, slices, tets or plots");
}

std::vector<std::string> snapshot_view_names(const SnapshotScene& scene, const SnapshotOptions& o) {
  std::vector<std::string> names;
  if (wants(o, ViewKind::organ_3d))
    for (const auto& organ : surface_organs(scene)) names.push_back("3d_" + organ);
  if (wants(o, ViewKind::overview_3d) && (!scene.surfaces.empty() || !scene.paths.empty()))
    names.push_back("3d_overview");
  if (wants(o, ViewKind::slices) && scene.ct)
    for (const auto& organ : scene.organs) {
      Eigen::Vector3d c;
      if (!scene.labels || !label_centroid(*scene.labels, organ.label, c)) continue;
      for (const auto a : kAxes) names.push_back("slice_" + organ.name + "_" + slice_axis_name(a));
    }
  if (wants(o, ViewKind::tets))
    for (const auto& t : scene.tet_meshes)
      if (!t.mesh.tets.empty()) names.push_back("tets_" + t.organ);
  if (wants(o, ViewKind::plots))
    for (const auto& p : scene.plots) names.push_back("plot_" + p.name);
  return names;
}

struct SnapshotRenderer::Impl {
  SnapshotOptions opt;
  DisplaySession display;
  Ptr<vtkRenderWindow> window;

  explicit Impl(const SnapshotOptions& o) : opt(o), display(o.display) {
    if (o.width_px < 64 || o.height_px < 64 || o.width_px > 8192 || o.height_px > 8192)
      throw UsageError("snapshot size " + std::to_string(o.width_px) + "x" + std::to_string(o.height_px) +
                           " is out of range", "use a size between 64x64 and 8192x8192");
    window = make_window(display.x_display(), o.width_px, o.height_px, /*offscreen=*/true);
    window->SetNumberOfLayers(2);  // layer 1: guidance paths over the surfaces
  }

  /// VTK copies of the surfaces drawn so far (see SnapshotRenderer::forget_surfaces).
  struct CachedSurface {
    std::uint64_t fingerprint = 0;
    Ptr<vtkPolyData> polydata;
  };
  std::map<const SurfaceMesh*, CachedSurface> surfaces;

  static std::uint64_t fingerprint(const SceneSurface& s) {
    std::uint64_t h = 1469598103934665603ull;
    auto mix = [&h](const void* p, std::size_t n) {
      const auto* b = static_cast<const unsigned char*>(p);
      for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
    };
    const SurfaceMesh& m = s.mesh;
    const std::size_t nv = m.vertices_lps_mm.size(), nt = m.triangles.size();
    mix(&nv, sizeof nv);
    mix(&nt, sizeof nt);
    for (std::size_t k = 0; k < 64 && nv > 0; ++k) mix(m.vertices_lps_mm[k * (nv - 1) / 63].data(), 3 * sizeof(double));
    for (std::size_t k = 0; k < 64 && nt > 0; ++k) mix(m.triangles[k * (nt - 1) / 63].data(), 3 * sizeof(std::int32_t));
    for (const auto& [id, c] : s.region_colours) {
      mix(&id, sizeof id);
      mix(&c, sizeof c);
    }
    return h;
  }

  Ptr<vtkActor> cached_surface_actor(const SceneSurface& s) {
    CachedSurface& c = surfaces[&s.mesh];
    const std::uint64_t f = fingerprint(s);
    if (!c.polydata || c.fingerprint != f) {
      c.polydata = to_polydata(s.mesh, s.region_colours);
      c.fingerprint = f;
    }
    return surface_actor(s, c.polydata);
  }

  void clear() {
    vtkRendererCollection* rc = window->GetRenderers();
    while (rc->GetNumberOfItems() > 0) window->RemoveRenderer(rc->GetFirstRenderer());
  }

  void view_3d(const SnapshotScene& scene, const std::string& organ) {
    const Layout L = layout_of(opt);
    const bool overview = organ.empty();
    auto r = main_area(L, 0, 1, false);
    std::vector<std::pair<std::string, Rgb>> legend;
    std::size_t triangles = 0;
    std::set<std::string> sources;
    for (const auto& s : scene.surfaces) {
      if (overview ? false : (s.context || s.organ != organ)) continue;
      r->AddViewProp(cached_surface_actor(s));
      triangles += s.mesh.triangles.size();
      if (!s.source.empty() && !s.context) sources.insert(s.source);
      legend.emplace_back(s.name + (s.context ? " (context)" : s.opacity < 1 ? " (translucent)" : ""), s.colour);
    }
    std::vector<const ScenePath*> paths;
    for (const auto& p : scene.paths)
      if (overview || p.line.name.find(organ) != std::string::npos) {
        paths.push_back(&p);
        legend.emplace_back((p.line.name.empty() ? std::string("path") : p.line.name) + " (guidance path)", p.colour);
      }
    std::array<double, 6> b{};
    bool any = visible_bounds(r, b);
    for (const auto* p : paths)
      for (const auto& q : p->line.points_lps_mm) {
        if (!any) b = {q.x(), q.x(), q.y(), q.y(), q.z(), q.z()}, any = true;
        b = {std::min(b[0], q.x()), std::max(b[1], q.x()), std::min(b[2], q.y()),
             std::max(b[3], q.y()), std::min(b[4], q.z()), std::max(b[5], q.z())};
      }
    if (overview && scene.tool) {
      const double len = any ? 0.12 * std::max({b[1] - b[0], b[3] - b[2], b[5] - b[4]}) : 20.0;
      for (auto& p : tool_props(*scene.tool, len, Rgb{0.2, 0.75, 0.95})) r->AddViewProp(p);
      legend.emplace_back("tool", Rgb{0.2, 0.75, 0.95});
      if (scene.tool->force_N) legend.emplace_back("force " + format_fixed(scene.tool->force_N->norm(), 2) + " N", Rgb{0.85, 0.1, 0.1});
      visible_bounds(r, b);
    }
    const int vh = L.h - L.band;
    if (any) {
      fit_parallel_camera(r, b, anterior_view(30, 20), Eigen::Vector3d(0, 0, 1), double(L.w) / vh, 0.10);
      add_scale_bar(r, mm_per_px(r, vh), L.w, vh, kDarkText);
    }
    // Paths as tubes at least ~5 px across, whatever the zoom, in a layer over the surfaces
    // (sharing their camera): a centreline runs inside an opaque lumen.
    // The legend goes in that layer too, over everything.
    auto over = Ptr<vtkRenderer>::New();
    over->SetLayer(1);
    over->SetViewport(r->GetViewport());
    over->SetActiveCamera(r->GetActiveCamera());
    over->InteractiveOff();
    const double px_mm = any ? mm_per_px(r, vh) : 0.0;
    for (const auto* p : paths) {
      ScenePath q = *p;
      q.radius_mm = std::max(q.radius_mm, 2.5 * px_mm);
      over->AddViewProp(path_actor(q));
    }
    add_legend(over, legend, L.w, vh, kDarkText);
    r->AddViewProp(text(std::string("front view turned 30 deg to the patient's left, 20 deg from above; parallel projection") +
                            (paths.empty() ? "" : "; paths drawn over the surfaces"),
                        std::max(10, vh / 52), kGreyText, L.w - 0.015 * L.w, 0.02 * vh, 2, 0));
    std::string src;
    for (const auto& s : sources) src += (src.empty() ? "" : ", ") + s;
    const std::string title =
        overview ? "All organs" + std::string(scene.paths.empty() ? "" : " with guidance paths") : capitalised(organ) + " - 3D model";
    std::string detail = (scene.case_name.empty() ? "" : "case " + scene.case_name + "  |  ") +
                         std::to_string(triangles) + " triangles";
    if (!src.empty()) detail += "  |  surfaces: " + src;
    window->AddRenderer(title_band(L, title, detail, Rgb{1, 1, 1}, kDarkText, kGreyText));
    window->AddRenderer(r);
    window->AddRenderer(over);
  }

  void view_slice(const SnapshotScene& scene, const SceneOrgan& organ, SliceAxis axis) {
    const Layout L = layout_of(opt);
    Eigen::Vector3d centre;
    label_centroid(*scene.labels, organ.label, centre);
    const SliceSample s = sample_slice(*scene.ct, scene.labels, axis, centre);

    // CT in the HU window as grey RGB.
    auto img = Ptr<vtkImageData>::New();
    img->SetDimensions(s.width, s.height, 1);
    img->SetSpacing(s.pixel_mm, s.pixel_mm, 1);
    img->SetOrigin(s.s0, s.t0, 0);
    img->AllocateScalars(VTK_UNSIGNED_CHAR, 3);
    auto* px = static_cast<unsigned char*>(img->GetScalarPointer());
    const double lo = opt.hu_level - opt.hu_window / 2, span = std::max(1.0, opt.hu_window);
    for (std::size_t i = 0; i < s.hu.size(); ++i) {
      const float v = s.hu[i];
      unsigned char g = 0;
      if (std::isnan(v)) {
        px[3 * i] = 20, px[3 * i + 1] = 20, px[3 * i + 2] = 40;  // outside the scan: dark blue
        continue;
      }
      g = (unsigned char)std::lround(std::clamp((v - lo) / span, 0.0, 1.0) * 255.0);
      px[3 * i] = px[3 * i + 1] = px[3 * i + 2] = g;
    }

    // The close-up: the organ's outline in this plane, framed generously.
    double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
    for (int y = 0; y < s.height; ++y)
      for (int x = 0; x < s.width; ++x)
        if (!s.labels.empty() && s.labels[std::size_t(y) * s.width + x] == organ.label) {
          xmin = std::min(xmin, s.s0 + x * s.pixel_mm), xmax = std::max(xmax, s.s0 + x * s.pixel_mm);
          ymin = std::min(ymin, s.t0 + y * s.pixel_mm), ymax = std::max(ymax, s.t0 + y * s.pixel_mm);
        }
    double cx = 0, cy = 0, side = opt.closeup_min_mm;
    if (xmax >= xmin) {
      cx = (xmin + xmax) / 2, cy = (ymin + ymax) / 2;
      side = std::max(side, 1.6 * std::max(xmax - xmin, ymax - ymin));
    }

    const double split = 0.42;
    const int vh = L.h - L.band, left_w = int(std::lround(split * L.w)), right_w = L.w - left_w;
    const Rgb outline = bright(organ.colour);
    auto outline_pd = label_outline(s, organ.label, 0.5);

    // Segmentation contours of this organ on the axial slice nearest to the plane.
    Ptr<vtkPolyData> contour_pd;
    if (axis == SliceAxis::axial)
      for (const auto& stack : scene.contours) {
        if (stack.organ != organ.name || stack.contours.empty()) continue;
        const Eigen::Vector3d k_centre = scene.ct->grid.lps_mm_to_index(centre);
        const std::int64_t k = std::llround(k_centre.z());
        auto pts = Ptr<vtkPoints>::New();
        auto lines = Ptr<vtkCellArray>::New();
        for (const auto& c : stack.contours) {
          if (c.slice_k != k || c.points_lps_mm.size() < 2) continue;
          const auto n = vtkIdType(c.points_lps_mm.size());
          lines->InsertNextCell(n + (c.closed ? 1 : 0));
          const vtkIdType first = pts->GetNumberOfPoints();
          for (const auto& p : c.points_lps_mm) {
            const Eigen::Vector3d q = p - centre;
            lines->InsertCellPoint(pts->InsertNextPoint(q.dot(s.frame.right), q.dot(s.frame.up), 0.6));
          }
          if (c.closed) lines->InsertCellPoint(first);
        }
        if (lines->GetNumberOfCells() > 0) {
          contour_pd = Ptr<vtkPolyData>::New();
          contour_pd->SetPoints(pts);
          contour_pd->SetLines(lines);
        }
      }

    auto make_panel = [&](double x0, double x1, int vw, bool closeup) {
      auto r = main_area(L, x0, x1, true);
      auto actor = Ptr<vtkImageActor>::New();
      actor->GetMapper()->SetInputData(img);
      actor->InterpolateOff();
      r->AddViewProp(actor);
      r->AddViewProp(line_actor(outline_pd, outline, closeup ? 2.5 : 1.5));
      if (contour_pd) r->AddViewProp(line_actor(contour_pd, kContourYellow, closeup ? 2.0 : 1.0));
      std::array<double, 6> b{};
      if (closeup) {
        const double aspect = double(vw) / vh;
        const double hh = side / 2, hw = hh * aspect;
        b = {cx - hw, cx + hw, cy - hh, cy + hh, -1, 1};
      } else {
        b = {s.s0 - s.pixel_mm / 2, s.s0 + (s.width - 0.5) * s.pixel_mm, s.t0 - s.pixel_mm / 2,
             s.t0 + (s.height - 0.5) * s.pixel_mm, -1, 1};
        // Frame of the close-up.
        const double aspect = double(right_w) / vh, hh = side / 2, hw = hh * aspect;
        auto pts = Ptr<vtkPoints>::New();
        pts->InsertNextPoint(cx - hw, cy - hh, 0.7);
        pts->InsertNextPoint(cx + hw, cy - hh, 0.7);
        pts->InsertNextPoint(cx + hw, cy + hh, 0.7);
        pts->InsertNextPoint(cx - hw, cy + hh, 0.7);
        auto lines = Ptr<vtkCellArray>::New();
        const vtkIdType ids[5] = {0, 1, 2, 3, 0};
        lines->InsertNextCell(5, ids);
        auto pd = Ptr<vtkPolyData>::New();
        pd->SetPoints(pts);
        pd->SetLines(lines);
        r->AddViewProp(line_actor(pd, Rgb{0.3, 0.8, 1.0}, 1.5));
      }
      fit_parallel_camera(r, b, Eigen::Vector3d(0, 0, -1), Eigen::Vector3d(0, 1, 0), double(vw) / vh,
                          closeup ? 0.0 : 0.04);
      add_scale_bar(r, mm_per_px(r, vh), vw, vh, kLightText);
      const int f = std::max(11, vh / 36);
      r->AddViewProp(text(std::string(1, direction_letter(-s.frame.right)), f, kLightText, 0.02 * vw, vh / 2.0, 0, 1, true));
      r->AddViewProp(text(std::string(1, direction_letter(s.frame.right)), f, kLightText, 0.98 * vw, vh / 2.0, 2, 1, true));
      r->AddViewProp(text(std::string(1, direction_letter(s.frame.up)), f, kLightText, vw / 2.0, vh - 0.02 * vh, 1, 2, true));
      r->AddViewProp(text(std::string(1, direction_letter(-s.frame.up)), f, kLightText, vw / 2.0, 0.02 * vh, 1, 0, true));
      r->AddViewProp(text(closeup ? "close-up" : "whole slice", std::max(10, vh / 48), Rgb{0.3, 0.8, 1.0}, 0.02 * vw,
                          vh - 0.02 * vh, 0, 2));
      return r;
    };

    const int axis_index = axis == SliceAxis::axial ? 2 : axis == SliceAxis::coronal ? 1 : 0;
    const char* axis_letter = axis == SliceAxis::axial ? "S" : axis == SliceAxis::coronal ? "P" : "L";
    std::string detail = (scene.case_name.empty() ? "" : scene.case_name + "  |  ") + axis_letter + " = " +
                         format_fixed(centre[axis_index], 1) + " mm (LPS)  |  W " + format_fixed(opt.hu_window, 0) + " / L " +
                         format_fixed(opt.hu_level, 0) + " HU  |  outline: " +
                         (scene.labels_source.empty() ? std::string("label map") : scene.labels_source) + " voxels";
    if (contour_pd) detail += ", yellow: its contour";
    window->AddRenderer(title_band(L, capitalised(organ.name) + " - " + slice_axis_name(axis) + " slice through its centroid",
                                   detail, Rgb{0.06, 0.06, 0.08}, kLightText, Rgb{0.75, 0.76, 0.8}));
    window->AddRenderer(make_panel(0, split, left_w, false));
    window->AddRenderer(make_panel(split, 1, right_w, true));
  }

  /// A 3-D view's framing (anterior, from the right and above; scale bar) and its colour bar for
  /// `lut` on the right.
  void frame_and_colour_bar(vtkRenderer* r, const Layout& L, vtkLookupTable* lut, const char* title,
                            const char* label_format) {
    const int vh = L.h - L.band;
    std::array<double, 6> b{};
    if (visible_bounds(r, b)) {
      fit_parallel_camera(r, b, anterior_view(25, 20), Eigen::Vector3d(0, 0, 1), double(L.w) / vh, 0.12);
      add_scale_bar(r, mm_per_px(r, vh), L.w, vh, kDarkText);
    }
    auto bar = Ptr<vtkScalarBarActor>::New();
    bar->SetLookupTable(lut);
    bar->SetTitle(title);
    bar->SetNumberOfLabels(6);
    bar->SetLabelFormat(label_format);
    bar->GetPositionCoordinate()->SetCoordinateSystemToNormalizedViewport();
    bar->GetPositionCoordinate()->SetValue(0.89, 0.12);
    bar->SetWidth(0.09);
    bar->SetHeight(0.76);
    bar->UnconstrainedFontSizeOn();
    for (vtkTextProperty* tp : {bar->GetTitleTextProperty(), bar->GetLabelTextProperty()}) {
      tp->SetColor(kDarkText.r, kDarkText.g, kDarkText.b);
      tp->ItalicOff();
      tp->ShadowOff();
    }
    bar->GetTitleTextProperty()->SetFontSize(std::max(10, vh / 45));
    bar->GetLabelTextProperty()->SetFontSize(std::max(10, vh / 50));
    r->AddViewProp(bar);
  }

  void view_tets(const SnapshotScene&, const SceneTetMesh& t) {
    const Layout L = layout_of(opt);
    const TetMesh& m = t.mesh;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const auto& v : m.vertices_lps_mm) centre += v;
    if (!m.vertices_lps_mm.empty()) centre /= double(m.vertices_lps_mm.size());
    // Keep the posterior half (tet centroid behind the coronal plane through the centre): the
    // camera in front then looks onto the cut.
    std::vector<std::int32_t> keep;
    std::vector<double> all_q;
    all_q.reserve(m.tets.size());
    for (std::size_t i = 0; i < m.tets.size(); ++i) {
      const auto& tet = m.tets[i];
      const Eigen::Vector3d c = (m.vertices_lps_mm[tet[0]] + m.vertices_lps_mm[tet[1]] + m.vertices_lps_mm[tet[2]] +
                                 m.vertices_lps_mm[tet[3]]) / 4.0;
      if (c.y() >= centre.y()) keep.push_back(std::int32_t(i));
      all_q.push_back(tet_radius_ratio(m.vertices_lps_mm[tet[0]], m.vertices_lps_mm[tet[1]], m.vertices_lps_mm[tet[2]],
                                       m.vertices_lps_mm[tet[3]]));
    }
    auto grid = to_grid(m, keep);
    auto lut = Ptr<vtkLookupTable>::New();
    lut->SetTableRange(0, 1);
    lut->SetHueRange(0.0, 0.33);  // red (poor) → green (regular)
    lut->SetSaturationRange(0.85, 0.85);
    lut->SetValueRange(0.95, 0.95);
    lut->SetNumberOfTableValues(256);
    lut->Build();
    auto mapper = Ptr<vtkDataSetMapper>::New();
    mapper->SetInputData(grid);
    mapper->SetLookupTable(lut);
    mapper->SetScalarModeToUseCellData();
    mapper->SetScalarRange(0, 1);
    mapper->ScalarVisibilityOn();
    auto actor = Ptr<vtkActor>::New();
    actor->SetMapper(mapper);
    actor->GetProperty()->EdgeVisibilityOn();
    actor->GetProperty()->SetEdgeColor(0.15, 0.15, 0.18);
    actor->GetProperty()->SetLineWidth(1.0);
    actor->GetProperty()->SetAmbient(0.3);
    auto r = main_area(L, 0, 1, false);
    r->AddViewProp(actor);
    const int vh = L.h - L.band;
    frame_and_colour_bar(r, L, lut, "3 r_in / R_circ", "%.1f");
    std::vector<double> sorted = all_q;
    std::sort(sorted.begin(), sorted.end());
    const double qmin = sorted.empty() ? 0 : sorted.front(), qmed = sorted.empty() ? 0 : sorted[sorted.size() / 2];
    r->AddViewProp(text("cut: coronal plane P = " + format_fixed(centre.y(), 1) + " mm, front half removed; whole tets shown",
                        std::max(10, vh / 52), kGreyText, L.w - 0.015 * L.w, 0.02 * vh, 2, 0));
    const std::string detail = std::to_string(m.tets.size()) + " tets (" + std::to_string(keep.size()) +
                               " shown)  |  radius ratio 3 r_in / R_circ (1 = regular): min " + format_fixed(qmin, 3) +
                               ", median " + format_fixed(qmed, 3);
    window->AddRenderer(title_band(L, capitalised(t.organ) + " - tetrahedral mesh, cut, coloured by quality", detail,
                                   Rgb{1, 1, 1}, kDarkText, kGreyText));
    window->AddRenderer(r);
  }

  void view_deformation(const SceneDeformation& d) {
    const Layout L = layout_of(opt);
    auto r = main_area(L, 0, 1, false);
    // The undeformed organ, translucent grey: the outline the deformation is read against.
    SceneSurface before;
    before.mesh = d.undeformed;
    before.colour = Rgb{0.55, 0.56, 0.6};
    before.opacity = 0.22;
    r->AddViewProp(surface_actor(before));
    // The deformed organ coloured by the value; the range ends at its 98th percentile so that a
    // few peak vertices (at the fixed set's edge) do not wash out the rest.
    auto pd = to_polydata(d.deformed);
    auto values = Ptr<vtkDoubleArray>::New();
    values->SetName("value");
    for (double v : d.values) values->InsertNextValue(v);
    pd->GetPointData()->SetScalars(values);
    std::vector<double> sorted = d.values;
    std::sort(sorted.begin(), sorted.end());
    const double top = sorted.empty() ? 1.0 : std::max(sorted[std::size_t(0.98 * double(sorted.size() - 1))], 1e-12);
    auto lut = Ptr<vtkLookupTable>::New();
    lut->SetTableRange(0, top);
    lut->SetHueRange(0.667, 0.0);  // blue (low) → red (high)
    lut->SetSaturationRange(0.85, 0.85);
    lut->SetValueRange(0.95, 0.95);
    lut->SetNumberOfTableValues(256);
    lut->Build();
    auto mapper = Ptr<vtkPolyDataMapper>::New();
    mapper->SetInputData(pd);
    mapper->SetLookupTable(lut);
    mapper->SetScalarModeToUsePointData();
    mapper->SetScalarRange(0, top);
    mapper->ScalarVisibilityOn();
    auto actor = Ptr<vtkActor>::New();
    actor->SetMapper(mapper);
    actor->GetProperty()->SetAmbient(0.25);
    r->AddViewProp(actor);
    const int vh = L.h - L.band;
    frame_and_colour_bar(r, L, lut, d.value_title.c_str(), "%.3g");
    r->AddViewProp(text("grey: undeformed; colour range ends at the 98th percentile (" + format_g(top, 3) + ")",
                        std::max(10, vh / 52), kGreyText, L.w - 0.015 * L.w, 0.02 * vh, 2, 0));
    window->AddRenderer(title_band(L, capitalised(d.organ) + " - deformed under its load case, coloured by stress", d.detail,
                                   Rgb{1, 1, 1}, kDarkText, kGreyText));
    window->AddRenderer(r);
  }

  void view_plot(const Plot& p) {
    const Layout L = layout_of(opt);
    auto r = Ptr<vtkRenderer>::New();
    r->SetViewport(0, 0, 1, 1.0 - double(L.band) / L.h);
    r->SetBackground(1, 1, 1);
    auto chart = Ptr<vtkChartXY>::New();
    const int vh = L.h - L.band;
    const int font = std::max(11, vh / 40);
    for (const auto& sr : p.series) {
      auto table = Ptr<vtkTable>::New();
      auto x = Ptr<vtkDoubleArray>::New();
      x->SetName(p.x_label.empty() ? "x" : p.x_label.c_str());
      auto y = Ptr<vtkDoubleArray>::New();
      y->SetName(sr.name.empty() ? "y" : sr.name.c_str());
      const std::size_t n = std::min(sr.x.size(), sr.y.size());
      for (std::size_t i = 0; i < n; ++i) {
        // Logarithmic axes are drawn as log10 of the data on a linear axis with decade ticks
        // (VTK 9.1's own log scale misplaces curves); non-positive values are left out there.
        if ((p.log_x && !(sr.x[i] > 0)) || (p.log_y && !(sr.y[i] > 0))) continue;
        x->InsertNextValue(p.log_x ? std::log10(sr.x[i]) : sr.x[i]);
        y->InsertNextValue(p.log_y ? std::log10(sr.y[i]) : sr.y[i]);
      }
      table->AddColumn(x);
      table->AddColumn(y);
      vtkPlot* plot = chart->AddPlot(sr.points ? vtkChart::POINTS : vtkChart::LINE);
      plot->SetInputData(table, 0, 1);
      plot->SetColor((unsigned char)std::lround(sr.colour.r * 255), (unsigned char)std::lround(sr.colour.g * 255),
                     (unsigned char)std::lround(sr.colour.b * 255), 255);
      plot->SetWidth(sr.points ? 1.0f : sr.dashed ? 1.8f : 2.5f);
      if (sr.dashed && !sr.points) plot->GetPen()->SetLineType(vtkPen::DASH_LINE);
      plot->SetLegendVisibility(sr.in_legend);
      if (auto* pp = vtkPlotPoints::SafeDownCast(plot); pp && sr.points) {
        static const int styles[] = {vtkPlotPoints::CIRCLE, vtkPlotPoints::SQUARE, vtkPlotPoints::DIAMOND,
                                     vtkPlotPoints::CROSS, vtkPlotPoints::PLUS};
        pp->SetMarkerStyle(styles[std::clamp(sr.marker, 0, 4)]);
        pp->SetMarkerSize(8);
      }
      plot->SetLabel(sr.name);
    }
    chart->GetAxis(vtkAxis::BOTTOM)->SetTitle(p.x_label);
    chart->GetAxis(vtkAxis::LEFT)->SetTitle(p.y_label);
    if (p.log_x) decade_ticks(chart->GetAxis(vtkAxis::BOTTOM), p, true);
    if (p.log_y) decade_ticks(chart->GetAxis(vtkAxis::LEFT), p, false);
    for (int a : {vtkAxis::BOTTOM, vtkAxis::LEFT}) {
      chart->GetAxis(a)->GetTitleProperties()->SetFontSize(font);
      chart->GetAxis(a)->GetLabelProperties()->SetFontSize(font - 2);
      chart->GetAxis(a)->GetTitleProperties()->BoldOff();
    }
    chart->SetShowLegend(true);
    chart->GetLegend()->SetLabelSize(font - 1);
    chart->GetLegend()->SetHorizontalAlignment(vtkChartLegend::LEFT);
    chart->GetLegend()->SetVerticalAlignment(vtkChartLegend::TOP);
    auto actor = Ptr<vtkContextActor>::New();
    actor->GetScene()->AddItem(chart);
    r->AddViewProp(actor);
    std::size_t points = 0;
    for (const auto& sr : p.series) points += std::min(sr.x.size(), sr.y.size());
    window->AddRenderer(title_band(L, p.title.empty() ? p.name : p.title,
                                   p.note.empty() ? std::to_string(p.series.size()) + " series, " +
                                                        std::to_string(points) + " points"
                                                  : p.note,
                                   Rgb{1, 1, 1}, kDarkText, kGreyText));
    window->AddRenderer(r);
  }

  SnapshotRenderer::FrameTimes times;

  RgbImage render(const SnapshotScene& scene, const std::string& name) {
    using Clock = std::chrono::steady_clock;
    const auto t0 = Clock::now();
    clear();
    bool built = false;
    if (name == "3d_overview") {
      view_3d(scene, "");
      built = true;
    } else if (name.rfind("3d_", 0) == 0) {
      view_3d(scene, name.substr(3));
      built = true;
    } else if (name.rfind("slice_", 0) == 0 && scene.ct && scene.labels) {
      for (const auto& organ : scene.organs)
        for (const auto a : kAxes)
          if (!built && name == "slice_" + organ.name + "_" + slice_axis_name(a)) {
            view_slice(scene, organ, a);
            built = true;
          }
    } else if (name.rfind("tets_", 0) == 0) {
      for (const auto& t : scene.tet_meshes)
        if (!built && name == "tets_" + t.organ) {
          view_tets(scene, t);
          built = true;
        }
    } else if (name.rfind("simulation_", 0) == 0) {
      for (const auto& d : scene.deformations)
        if (!built && name == "simulation_" + d.organ) {
          view_deformation(d);
          built = true;
        }
    } else if (name.rfind("plot_", 0) == 0) {
      for (const auto& p : scene.plots)
        if (!built && name == "plot_" + p.name) {
          view_plot(p);
          built = true;
        }
    }
    if (!built) throw UsageError("no view named '" + name + "' in this scene", "see snapshot_view_names()");
    const auto t1 = Clock::now();
    window->Render();
    const auto t2 = Clock::now();
    RgbImage img = grab(window);
    const auto t3 = Clock::now();
    clear();  // release the scene's buffers between views
    auto ms = [](auto a, auto b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
    times = {ms(t0, t1), ms(t1, t2), ms(t2, t3), 0.0};
    return img;
  }
};

SnapshotRenderer::SnapshotRenderer(const SnapshotOptions& options) : impl_(std::make_unique<Impl>(options)) {}
SnapshotRenderer::~SnapshotRenderer() = default;

RgbImage SnapshotRenderer::render(const SnapshotScene& scene, const std::string& name) {
  return impl_->render(scene, name);
}

void SnapshotRenderer::render_to_png(const SnapshotScene& scene, const std::string& name,
                                     const std::filesystem::path& png) {
  const RgbImage img = render(scene, name);
  const auto t0 = std::chrono::steady_clock::now();
  write_png(img, png, impl_->opt.png_compression);
  impl_->times.png_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

void SnapshotRenderer::forget_surfaces() { impl_->surfaces.clear(); }

SnapshotRenderer::FrameTimes SnapshotRenderer::last_frame_times() const { return impl_->times; }

const DisplaySession& SnapshotRenderer::display() const { return impl_->display; }

std::vector<std::filesystem::path> render_snapshots(const SnapshotScene& scene, const SnapshotOptions& options,
                                                    const std::filesystem::path& dir, Progress& progress) {
  const auto names = snapshot_view_names(scene, options);
  std::vector<std::filesystem::path> written;
  if (names.empty()) return written;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw OutputError("cannot create the snapshot directory: " + ec.message(), dir);
  SnapshotRenderer renderer(options);
  for (std::size_t i = 0; i < names.size(); ++i) {
    progress.check_cancelled();
    progress.report(double(i) / double(names.size()), "rendering " + names[i]);
    const auto path = dir / (names[i] + ".png");
    renderer.render_to_png(scene, names[i], path);
    written.push_back(path);
  }
  progress.report(1.0, "snapshots rendered");
  return written;
}

}  // namespace organsmith
