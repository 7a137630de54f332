// Over 400 lines: the mouse device, the deformed surface (dented, or the organ's FE model), the
// state shared by the 1 kHz loop and the render timer, and the interactor style are parts of one
// window that VTK callbacks reach through one state.
// The interactive preview window: the mouse is a haptic device for the 1 kHz loop; the window
// draws what the loop publishes.

#include "viewer/preview.h"

#include "viewer/detail/vtk_scene.h"

#include <Eigen/Geometry>
#include <spdlog/spdlog.h>
#include <vtkArrowSource.h>
#include <vtkCallbackCommand.h>
#include <vtkCamera.h>
#include <vtkCommand.h>
#include <vtkFloatArray.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkLineSource.h>
#include <vtkMatrix4x4.h>
#include <vtkObjectFactory.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyDataMapper.h>
#include <vtkProp3D.h>
#include <vtkProperty.h>
#include <vtkProperty2D.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkSphereSource.h>
#include <vtkTextProperty.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <cstdio>
#include <map>
#include <memory>

namespace organsmith {

using namespace viewer_detail;
using physics::ForceMode;

std::string preview_mode_label(ForceMode mode) {
  switch (mode) {
    case ForceMode::guidance: return "guidance only";
    case ForceMode::mixed: return "mixed";
    case ForceMode::reaction: return "reaction only";
  }
  return "?";
}

namespace {

using Clock = std::chrono::steady_clock;

/// The mouse as a haptic device: the window's thread stores the pointer's position in the scene
/// (a single writer), the loop thread reads it lock-free at 1 kHz. A mouse pushes nothing back,
/// so the loop moves the displayed tool by the force instead (renders_force() is false).
/// With a recorded hand path (`script`) the path moves the hand instead and the mouse only turns
/// the view: the loop thread is then the single writer.
class MouseDevice final : public physics::HapticDevice {
 public:
  MouseDevice(const Eigen::Vector3d& start, physics::ScriptedDevice* script)
      : target_(physics::to_vec3(script ? script->position_lps_mm(0.0) : start)), script_(script) {}
  Eigen::Vector3d position_lps_mm(double t_s) noexcept override {
    if (!script_) return physics::to_eigen(target_.read());
    const Eigen::Vector3d p = script_->position_lps_mm(t_s);
    target_.write(physics::to_vec3(p));
    return p;
  }
  /// Window thread only; ignored while a recorded path moves the hand.
  void set(const Eigen::Vector3d& p) noexcept {
    if (!script_) target_.write(physics::to_vec3(p));
  }
  Eigen::Vector3d get() const noexcept { return physics::to_eigen(target_.read()); }

 private:
  SeqLock<physics::Vec3> target_;
  physics::ScriptedDevice* script_ = nullptr;
};

/// A drawn organ surface that the tool dents: the deformer's vertices go into the VTK points,
/// and the normals around the moved vertices are recomputed so that the dent is shaded.
struct DeformedSurface {
  int contact_index = -1;  ///< surface index in the ContactModel
  physics::SurfaceDeformer deformer;
  Ptr<vtkPolyData> polydata;
  std::vector<std::int32_t> tri_start, tri_ids;  ///< vertex → incident triangles (CSR)
  std::vector<std::int32_t> last_moved;
  std::vector<char> affected;
  bool dented = false;

  DeformedSurface(int index, const SurfaceMesh& mesh, double radius_mm, Ptr<vtkPolyData> pd)
      : contact_index(index), deformer(mesh, radius_mm), polydata(std::move(pd)) {
    const std::size_t nv = mesh.vertices_lps_mm.size();
    tri_start.assign(nv + 1, 0);
    for (const auto& t : mesh.triangles)
      for (int c = 0; c < 3; ++c) ++tri_start[std::size_t(t[c]) + 1];
    for (std::size_t i = 0; i < nv; ++i) tri_start[i + 1] += tri_start[i];
    tri_ids.resize(tri_start.back());
    std::vector<std::int32_t> fill(tri_start.begin(), tri_start.end() - 1);
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
      for (int c = 0; c < 3; ++c) tri_ids[fill[mesh.triangles[t][c]]++] = std::int32_t(t);
    affected.assign(nv, 0);
  }

  /// Applies the contact (or releases the dent) and updates points and normals. Cost: one pass
  /// over the vertices to find the moved ones, then only their neighbourhood.
  void apply(const physics::ContactSample& c) {
    if (!c.contact && !dented) return;
    const std::vector<Eigen::Vector3d>& v = deformer.update(c);
    const SurfaceMesh& rest = deformer.rest();
    auto* pts = static_cast<float*>(polydata->GetPoints()->GetVoidPointer(0));
    std::vector<std::int32_t> moved;
    for (std::size_t i = 0; i < v.size(); ++i)
      if (v[i] != rest.vertices_lps_mm[i]) moved.push_back(std::int32_t(i));
    // Vertices whose normal changes: those of triangles around vertices moved now or before.
    std::vector<std::int32_t> touched;
    for (const auto* list : {&moved, &last_moved})
      for (const std::int32_t i : *list)
        for (std::int32_t k = tri_start[i]; k < tri_start[i + 1]; ++k)
          for (const std::int32_t j : rest.triangles[tri_ids[k]])
            if (!affected[j]) affected[j] = 1, touched.push_back(j);
    auto* normals = vtkFloatArray::SafeDownCast(polydata->GetPointData()->GetNormals());
    float* n = normals ? normals->GetPointer(0) : nullptr;
    for (const std::int32_t i : touched) {
      affected[i] = 0;
      for (int c3 = 0; c3 < 3; ++c3) pts[3 * i + c3] = float(v[i][c3]);
      if (!n) continue;
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (std::int32_t k = tri_start[i]; k < tri_start[i + 1]; ++k) {
        const auto& t = rest.triangles[tri_ids[k]];
        sum += (v[t[1]] - v[t[0]]).cross(v[t[2]] - v[t[0]]);
      }
      const double len = sum.norm();
      const Eigen::Vector3d u = len > 0 ? Eigen::Vector3d(sum / len) : Eigen::Vector3d(0, 0, 1);
      for (int c3 = 0; c3 < 3; ++c3) n[3 * i + c3] = float(u[c3]);
    }
    last_moved = std::move(moved);
    dented = c.contact;
    polydata->GetPoints()->Modified();
    if (normals) normals->Modified();
    polydata->Modified();
  }
};

/// The organ's outer surface as its real-time FE model has it: node positions copied into the
/// VTK points each frame (the model's nodes are the points; the faces are its outer triangles),
/// normals recomputed. Also what the status reports: where the surface moved most, and how far
/// the fixed set moved.
struct TissueSurface {
  const physics::RealtimeTissue* model = nullptr;
  Ptr<vtkPolyData> polydata;
  std::vector<std::array<std::int32_t, 3>> tri;
  std::vector<std::int32_t> surface_nodes, fixed;
  std::vector<Eigen::Vector3d> x, rest;
  std::vector<Eigen::Vector3d> nsum;
  double max_move_mm = 0, fixed_move_mm = 0;
  Eigen::Vector3d max_move_at = Eigen::Vector3d::Zero();

  void update() {
    model->positions(x);
    auto* pts = static_cast<float*>(polydata->GetPoints()->GetVoidPointer(0));
    for (std::size_t i = 0; i < x.size(); ++i)
      for (int c = 0; c < 3; ++c) pts[3 * i + c] = float(x[i][c]);
    if (auto* normals = vtkFloatArray::SafeDownCast(polydata->GetPointData()->GetNormals())) {
      nsum.assign(x.size(), Eigen::Vector3d::Zero());
      for (const auto& t : tri) {
        const Eigen::Vector3d n = (x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]);
        for (int c = 0; c < 3; ++c) nsum[t[c]] += n;
      }
      float* n = normals->GetPointer(0);
      for (std::int32_t i : surface_nodes) {
        const double len = nsum[i].norm();
        const Eigen::Vector3d u = len > 0 ? Eigen::Vector3d(nsum[i] / len) : Eigen::Vector3d(0, 0, 1);
        for (int c = 0; c < 3; ++c) n[3 * i + c] = float(u[c]);
      }
      normals->Modified();
    }
    max_move_mm = 0;
    for (std::int32_t i : surface_nodes)
      if (const double d = (x[i] - rest[i]).norm(); d > max_move_mm) max_move_mm = d, max_move_at = x[i];
    fixed_move_mm = 0;
    for (std::int32_t i : fixed) fixed_move_mm = std::max(fixed_move_mm, (x[i] - rest[i]).norm());
    polydata->GetPoints()->Modified();
    polydata->Modified();
  }
  /// Distance from p to the nearest fixed node at rest.
  double distance_to_fixed_mm(const Eigen::Vector3d& p) const {
    double d = 1e300;
    for (std::int32_t i : fixed) d = std::min(d, (rest[i] - p).norm());
    return fixed.empty() ? -1.0 : d;
  }
};

// Mode label colours: green, yellow, red-orange (none of them the cyan of the tool).
const Rgb kModeColours[] = {{0.45, 1.0, 0.45}, {1.0, 0.85, 0.2}, {1.0, 0.45, 0.35}};

struct PreviewState {
  PreviewOptions options;
  const PreviewHaptics* haptics = nullptr;
  const SnapshotScene* scene = nullptr;
  MouseDevice* device = nullptr;
  physics::HapticLoop* loop = nullptr;
  vtkRenderer* renderer = nullptr;
  vtkTextActor* mode_label = nullptr;
  vtkTextActor* corner = nullptr;
  std::vector<vtkProp3D*> tool;
  vtkActor* force_arrow = nullptr;
  vtkActor* hand = nullptr;          ///< where the mouse holds the tool
  vtkLineSource* spring = nullptr;   ///< hand → tool
  vtkActor* spring_actor = nullptr;
  vtkActor* goal = nullptr;          ///< nearest path point
  vtkPoints* bar_points = nullptr;   ///< scale bar (2D)
  vtkTextActor* bar_label = nullptr;
  std::vector<std::unique_ptr<DeformedSurface>> deformed;
  std::unique_ptr<TissueSurface> tissue;
  double scene_size_mm = 100.0;
  Eigen::Vector3d scene_centre = Eigen::Vector3d::Zero();
  std::array<double, 6> focus{};  ///< what the camera frames (r resets to it)
  double force_mm_per_N = 10.0;      ///< arrow length per newton
  physics::HapticState last{};

  Clock::time_point started = Clock::now();
  Clock::time_point fps_window = Clock::now();
  int frames = 0;
  double fps = 0.0;
  Clock::duration frame_period{};
  Clock::time_point next_frame = Clock::now();
  long total_frames = 0;
  double render_ms_sum = 0;  ///< time spent in Render(), for the mean frame cost
  double fps_min = 1e9;

  double cpu_started_ms = 0;
  std::string last_corner;
  Clock::time_point next_corner = Clock::now();

  static double cpu_ms() {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
  }

  /// " (render: …; haptic loop …)" for the quit event.
  std::string stats() const {
    const double t = std::chrono::duration<double>(Clock::now() - started).count();
    const double cpu = cpu_ms() - cpu_started_ms;
    const physics::LoopStats ls = loop->stats();
    char b[400];
    std::snprintf(b, sizeof b,
                  " (render: mean %.1f fps, slowest half-second %.1f fps, mean frame %.1f ms, %ld frames; "
                  "process CPU %.2f cores; haptic loop %.0f Hz, %llu ticks, %llu overruns, tick p99 %.1f us, "
                  "jitter p99 %.1f us)",
                  t > 0 ? total_frames / t : 0.0, fps_min < 1e9 ? fps_min : 0.0,
                  total_frames > 0 ? render_ms_sum / total_frames : 0.0, total_frames,
                  t > 0 ? cpu / (1e3 * t) : 0.0, ls.rate_Hz, (unsigned long long)ls.ticks,
                  (unsigned long long)ls.overruns, ls.compute_us.p99, ls.jitter_us.p99);
    return b;
  }

  void emit(const std::string& e) const {
    if (options.on_event) options.on_event(e);
  }

  void set_mode(ForceMode m) {
    loop->set_mode(m);
    const Rgb& c = kModeColours[int(m)];
    const int key = int(m) + 1;
    mode_label->SetInput(("mode " + std::to_string(key) + ": " + preview_mode_label(m)).c_str());
    mode_label->GetTextProperty()->SetColor(c.r, c.g, c.b);
    mode_changed = true;
    emit("mode " + std::to_string(key) + " " + preview_mode_label(m));
  }

  /// One line a test (or a curious user, key s) can read: where the hand and the tool are, and
  /// how far each is from the guidance path.
  std::string status() const {
    const physics::HapticState s = loop->state();
    const Eigen::Vector3d tool = physics::to_eigen(s.tool_lps_mm), hand = physics::to_eigen(s.device_lps_mm);
    double tool_path = -1, hand_path = -1;
    if (haptics->path) {
      tool_path = haptics->path->nearest(tool).distance_mm;
      hand_path = haptics->path->nearest(hand).distance_mm;
    }
    char b[400];
    std::snprintf(b, sizeof b,
                  "status mode=%s tool_path_mm=%.3f hand_path_mm=%.3f force_N=%.4f contact=%d loop_Hz=%.0f "
                  "tool_lps_mm=%.2f,%.2f,%.2f hand_lps_mm=%.2f,%.2f,%.2f fps=%.1f",
                  std::string(physics::mode_name(ForceMode(s.mode))).c_str(), tool_path, hand_path,
                  physics::to_eigen(s.force_N).norm(), s.contact ? 1 : 0, s.measured_rate_Hz, tool.x(), tool.y(),
                  tool.z(), hand.x(), hand.y(), hand.z(), fps);
    std::string line = b;
    if (tissue) {
      std::snprintf(b, sizeof b,
                    " fe_nodes=%zu fe_update_hz=%.1f fe_update_ms_p50=%.2f fe_update_ms_p99=%.2f fe_moved_mm=%.3f "
                    "fe_moved_to_tool_mm=%.2f fe_moved_to_fixed_mm=%.2f fe_fixed_moved_mm=%.4f",
                    tissue->x.size(), tissue->model->achieved_update_hz(), tissue->model->update_ms_percentile(0.5),
                    tissue->model->update_ms_percentile(0.99), tissue->max_move_mm,
                    (tissue->max_move_at - tool).norm(), tissue->distance_to_fixed_mm(tissue->max_move_at),
                    tissue->fixed_move_mm);
      line += b;
    }
    return line;
  }

  /// Scale bar at the lower left, measured at the tool's depth (the view is a perspective one).
  void update_scale_bar(const Eigen::Vector3d& at) {
    double right[3], up[3];
    vtkCamera* cam = renderer->GetActiveCamera();
    cam->GetViewUp(up);
    double dop[3];
    cam->GetDirectionOfProjection(dop);
    const Eigen::Vector3d r = Eigen::Vector3d(dop[0], dop[1], dop[2]).cross(Eigen::Vector3d(up[0], up[1], up[2])).normalized();
    right[0] = r.x(), right[1] = r.y(), right[2] = r.z();
    auto to_display = [&](const Eigen::Vector3d& p) {
      renderer->SetWorldPoint(p.x(), p.y(), p.z(), 1.0);
      renderer->WorldToDisplay();
      const double* d = renderer->GetDisplayPoint();
      return Eigen::Vector2d(d[0], d[1]);
    };
    const double px_per_mm = (to_display(at + 10.0 * r) - to_display(at)).norm() / 10.0;
    if (!(px_per_mm > 0) || !std::isfinite(px_per_mm)) return;
    const double target_mm = 0.18 * options.width_px / px_per_mm;
    double step = std::pow(10.0, std::floor(std::log10(target_mm)));
    for (const double m : {5.0, 2.0, 1.0})
      if (m * step <= target_mm) {
        step *= m;
        break;
      }
    const double len = step * px_per_mm;
    const double x0 = 0.02 * options.width_px, y0 = 0.2 * options.height_px, tick = 6;
    bar_points->SetPoint(0, x0, y0, 0);
    bar_points->SetPoint(1, x0 + len, y0, 0);
    bar_points->SetPoint(2, x0, y0 + tick, 0);
    bar_points->SetPoint(3, x0 + len, y0 + tick, 0);
    bar_points->Modified();
    char label[64];
    std::snprintf(label, sizeof label, "%g mm at the tool's depth", step);
    bar_label->SetInput(label);
    bar_label->SetPosition(x0, y0 + tick + 3);
  }

  void frame() {
    physics::HapticState s = loop->state();
    const bool ticked = s.tick > 0 || s.time_s > 0;
    if (!ticked) s.tool_lps_mm = s.device_lps_mm = physics::to_vec3(device->get());
    last = s;
    const Eigen::Vector3d tool_p = physics::to_eigen(s.tool_lps_mm), hand_p = physics::to_eigen(s.device_lps_mm);
    for (auto* t : tool) t->SetPosition(tool_p.x(), tool_p.y(), tool_p.z());
    hand->SetPosition(hand_p.x(), hand_p.y(), hand_p.z());
    spring->SetPoint1(hand_p.x(), hand_p.y(), hand_p.z());
    spring->SetPoint2(tool_p.x(), tool_p.y(), tool_p.z());
    spring_actor->SetVisibility((hand_p - tool_p).norm() > 0.5);

    const Eigen::Vector3d F = physics::to_eigen(s.force_N);
    const double fn = F.norm();
    if (fn > 1e-3) {
      const double len = std::max(fn * force_mm_per_N, 0.02 * scene_size_mm);
      auto t = along(tool_p, F, len, std::min(len, 0.15 * scene_size_mm));
      force_arrow->SetUserMatrix(t->GetMatrix());
      force_arrow->VisibilityOn();
    } else {
      force_arrow->VisibilityOff();
    }
    if (s.has_path) {
      goal->SetPosition(s.goal_lps_mm[0], s.goal_lps_mm[1], s.goal_lps_mm[2]);
      goal->VisibilityOn();
    } else {
      goal->VisibilityOff();
    }

    for (auto& d : deformed) {
      physics::ContactSample c;
      c.contact = s.contact && s.contact_surface == d->contact_index;
      c.surface = s.contact_surface;
      c.penetration_mm = s.penetration_mm;
      c.point_lps_mm = physics::to_eigen(s.contact_point_lps_mm);
      c.normal = physics::to_eigen(s.contact_normal);
      d->apply(c);
    }
    if (tissue) tissue->update();
    update_scale_bar(tool_p);
    // Depth range around the scene and the tool, whatever the camera or the wheel did.
    vtkCamera* cam = renderer->GetActiveCamera();
    const double dist = cam->GetDistance(), reach = 2.0 * scene_size_mm + (tool_p - scene_centre).norm();
    cam->SetClippingRange(std::max(dist - reach, 0.01 * dist), dist + reach);

    const physics::ForceMode mode = ForceMode(s.mode);
    const physics::ForceWeights w = physics::weights(mode);
    const Eigen::Vector3d G = physics::to_eigen(s.guidance_N), R = physics::to_eigen(s.reaction_N);
    std::string contact_line = "contact: none";
    if (s.contact) {
      char b[160];
      std::snprintf(b, sizeof b, "contact: %s, %.2f mm deep",
                    s.contact_surface >= 0 && std::size_t(s.contact_surface) < haptics->contact_scene_surfaces.size() &&
                            haptics->contact_scene_surfaces[s.contact_surface] >= 0
                        ? scene->surfaces[haptics->contact_scene_surfaces[s.contact_surface]].name.c_str()
                        : haptics->tissue ? (haptics->tissue_organ + " (finite-element model)").c_str() : "organ",
                    s.penetration_mm);
      contact_line = b;
    }
    char buf[768];
    std::snprintf(buf, sizeof buf,
                  "haptic loop: %.0f Hz (target %.0f)   render: %.0f fps\n"
                  "force sent: %.3f N%s   guidance %.3f N x %.1f, reaction %.4f N x %.1f\n"
                  "%s\n"
                  "%s",
                  s.measured_rate_Hz, haptics->loop.rate_Hz, fps, fn,
                  fn >= haptics->loop.force_limit_N * 0.999 ? " (clamped to the limit)" : "", G.norm(), w.guidance,
                  R.norm(), w.reaction,
                  haptics->path ? (haptics->path_name + ": tool " + fmt_mm(s.distance_mm) + " from it, hand " +
                                   fmt_mm(haptics->path->nearest(hand_p).distance_mm))
                                      .c_str()
                                : "no guidance path (run `organsmith guide`)",
                  haptics->contact || haptics->tissue ? contact_line.c_str() : "no contact surfaces: no reaction force");
    // The text is re-rasterised whenever it changes: four times a second is readable and cheap.
    const auto now = Clock::now();
    if (now >= next_corner || mode_changed) {
      corner->SetInput(buf);
      next_corner = now + std::chrono::milliseconds(250);
      mode_changed = false;
    }
  }
  bool mode_changed = false;

  static std::string fmt_mm(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%.1f mm", v);
    return b;
  }
};

/// Mouse: motion without a button moves the hand (and the tool with it) in the screen plane
/// through the hand's depth; the wheel moves it in depth; left drag turns the camera, middle
/// drag pans, right drag zooms. Keys: 1/2/3 modes, s prints the status, r resets the camera,
/// q or Esc quits.
class PreviewStyle : public vtkInteractorStyleTrackballCamera {
 public:
  static PreviewStyle* New();
  vtkTypeMacro(PreviewStyle, vtkInteractorStyleTrackballCamera);
  PreviewState* state = nullptr;

  void OnMouseMove() override {
    if (this->State != VTKIS_NONE) {
      vtkInteractorStyleTrackballCamera::OnMouseMove();
      return;
    }
    const int* p = this->Interactor->GetEventPosition();
    vtkRenderer* r = state->renderer;
    const Eigen::Vector3d hand = state->device->get();
    r->SetWorldPoint(hand.x(), hand.y(), hand.z(), 1.0);
    r->WorldToDisplay();
    const double depth = r->GetDisplayPoint()[2];
    r->SetDisplayPoint(p[0], p[1], depth);
    r->DisplayToWorld();
    const double* w = r->GetWorldPoint();
    if (w[3] == 0) return;
    const Eigen::Vector3d q(w[0] / w[3], w[1] / w[3], w[2] / w[3]);
    if (q.allFinite()) state->device->set(q);
  }
  void OnMouseWheelForward() override { push(+1); }
  void OnMouseWheelBackward() override { push(-1); }
  void OnChar() override {
    const char key = this->Interactor->GetKeyCode();
    const std::string sym = this->Interactor->GetKeySym() ? this->Interactor->GetKeySym() : "";
    if (key == '1' || key == '2' || key == '3') {
      state->set_mode(ForceMode(key - '1'));
      this->Interactor->Render();
    } else if (key == 's' || key == 'S') {
      state->emit(state->status());
    } else if (key == 'r' || key == 'R') {
      state->renderer->ResetCamera(state->focus.data());
      state->renderer->GetActiveCamera()->Zoom(0.85);
      this->Interactor->Render();
    } else if (key == 'q' || key == 'Q' || sym == "Escape") {
      state->loop->stop();  // its tick percentiles are taken once it has stopped
      state->emit("quit" + state->stats());
      this->Interactor->TerminateApp();
    }
  }
  // The default key bindings (stereo on 3, wireframe on w, …) would fight the modes.
  void OnKeyPress() override {}

 private:
  void push(int sign) {
    double d[3];
    state->renderer->GetActiveCamera()->GetDirectionOfProjection(d);
    const Eigen::Vector3d step = Eigen::Vector3d(d[0], d[1], d[2]) * (sign * 0.02 * state->scene_size_mm);
    state->device->set(state->device->get() + step);
  }
};
vtkStandardNewMacro(PreviewStyle);

void on_timer(vtkObject*, unsigned long, void* client, void*) {
  auto* s = static_cast<PreviewState*>(client);
  // The timer ticks faster than the frame rate; frames are due on a fixed grid so that the
  // render time does not add to the period.
  const auto tick = Clock::now();
  if (tick < s->next_frame) return;
  s->next_frame += s->frame_period;
  if (s->next_frame < tick) s->next_frame = tick + s->frame_period;
  ++s->frames;
  ++s->total_frames;
  const auto now = Clock::now();
  const double dt = std::chrono::duration<double>(now - s->fps_window).count();
  if (dt >= 0.5) {
    s->fps = s->frames / dt;
    // The first second (context creation, first uploads) is not the steady rate.
    if (std::chrono::duration<double>(now - s->started).count() > 1.5) s->fps_min = std::min(s->fps_min, s->fps);
    s->frames = 0;
    s->fps_window = now;
  }
  s->frame();
  const auto r0 = Clock::now();
  s->renderer->GetRenderWindow()->Render();
  s->render_ms_sum += std::chrono::duration<double, std::milli>(Clock::now() - r0).count();
  if (s->options.quit_after_s > 0 &&
      std::chrono::duration<double>(now - s->started).count() >= s->options.quit_after_s) {
    s->emit(s->status());  // where the hand and tool ended (a recorded hand path's end, for one)
    s->loop->stop();
    s->emit("quit after " + std::to_string(int(s->options.quit_after_s)) + " s" + s->stats());
    s->renderer->GetRenderWindow()->GetInteractor()->TerminateApp();
  }
}

Ptr<vtkActor> sphere_actor(double radius, const Rgb& c, double opacity) {
  auto src = Ptr<vtkSphereSource>::New();
  src->SetRadius(radius);
  src->SetThetaResolution(20);
  src->SetPhiResolution(14);
  auto m = Ptr<vtkPolyDataMapper>::New();
  m->SetInputConnection(src->GetOutputPort());
  auto a = Ptr<vtkActor>::New();
  a->SetMapper(m);
  a->GetProperty()->SetColor(c.r, c.g, c.b);
  a->GetProperty()->SetOpacity(opacity);
  return a;
}

}  // namespace

void run_preview(const SnapshotScene& scene, const PreviewOptions& options, const PreviewHaptics& haptics) {
  physics::validate(haptics.loop);
  if (haptics.contact && haptics.contact_scene_surfaces.size() != haptics.contact->index().surface_count())
    throw UsageError("preview: contact_scene_surfaces must name one scene surface per contact surface");
  DisplaySession display(options.display);
  if (display.private_xvfb())
    spdlog::warn("the preview window opens on a private Xvfb ({}): nobody will see it; set DISPLAY to watch it",
                 display.name());
  auto window = make_window(display.x_display(), options.width_px, options.height_px, /*offscreen=*/false);
  window->SetWindowName(options.title.c_str());

  auto r = Ptr<vtkRenderer>::New();
  // A plain background: a gradient is one more full-window pass per frame, and llvmpipe's frame
  // cost is set by the pixels it touches.
  r->SetBackground(0.20, 0.21, 0.25);
  // No depth peeling here: it multiplies the passes over the translucent walls, and the window
  // must keep 30 fps on llvmpipe. Plain blending is good enough while moving.
  r->SetUseDepthPeeling(0);
  window->AddRenderer(r);
  // Paths and the tool in a layer on top, sharing the camera: the path runs inside organs drawn
  // opaque, and the tool must stay visible when it enters tissue.
  auto top = Ptr<vtkRenderer>::New();
  top->SetLayer(1);
  top->InteractiveOff();
  top->SetActiveCamera(r->GetActiveCamera());
  window->SetNumberOfLayers(2);
  window->AddRenderer(top);

  PreviewState state;
  state.options = options;
  state.haptics = &haptics;
  state.scene = &scene;
  state.renderer = r;

  // Each organ's outermost surface only, opaque: what the tool touches and dents. Inner surfaces
  // (the gallbladder's inner wall, the tracheal lumen) are hidden behind it, and a translucent
  // wall would send every frame through VTK's order-independent transparency passes, which
  // cost llvmpipe more than all the geometry.
  std::vector<Ptr<vtkPolyData>> polydata(scene.surfaces.size());
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> boxes(scene.surfaces.size());
  std::map<std::string, std::pair<double, std::size_t>> outermost;
  for (std::size_t i = 0; i < scene.surfaces.size(); ++i) {
    const SurfaceMesh& m = scene.surfaces[i].mesh;
    if (m.vertices_lps_mm.empty()) continue;
    Eigen::Vector3d lo = m.vertices_lps_mm[0], hi = lo;
    for (const auto& v : m.vertices_lps_mm) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
    boxes[i] = {lo, hi};
    const double box = (hi - lo).prod();
    auto [it, fresh] = outermost.try_emplace(scene.surfaces[i].organ, box, i);
    if (!fresh && box > it->second.first) it->second = {box, i};
  }
  for (const auto& [organ, entry] : outermost) {
    SceneSurface s = scene.surfaces[entry.second];
    s.opacity = 1.0;
    if (haptics.tissue && organ == haptics.tissue_organ) {
      // Drawn from the FE model: its nodes are the points, its outer faces the triangles.
      auto ts = std::make_unique<TissueSurface>();
      ts->model = haptics.tissue;
      ts->model->positions(ts->rest);
      s.mesh.vertices_lps_mm = ts->rest;
      s.mesh.triangles.clear();
      s.mesh.region_ids.clear();
      s.region_colours.clear();
      std::vector<char> on(ts->rest.size(), 0);
      for (std::size_t t = 0; t + 2 < haptics.tissue_triangles.size(); t += 3) {
        const std::array<std::int32_t, 3> f{haptics.tissue_triangles[t], haptics.tissue_triangles[t + 1], haptics.tissue_triangles[t + 2]};
        s.mesh.triangles.push_back(f);
        ts->tri.push_back(f);
        for (std::int32_t v : f) on[v] = 1;
      }
      for (std::size_t i = 0; i < on.size(); ++i)
        if (on[i]) ts->surface_nodes.push_back(std::int32_t(i));
      ts->fixed = haptics.tissue_fixed_nodes;
      r->AddViewProp(surface_actor(s, &ts->polydata));
      ts->x = ts->rest;
      state.tissue = std::move(ts);
      continue;
    }
    r->AddViewProp(surface_actor(s, &polydata[entry.second]));
  }
  std::array<double, 6> b{-50, 50, -50, 50, -50, 50};
  visible_bounds(r, b);
  // The view frames the guidance path and the organs it lies on (r resets to that); without a
  // path, everything.
  if (haptics.path && !haptics.path->path().points_lps_mm.empty()) {
    const auto& pts = haptics.path->path().points_lps_mm;
    Eigen::Vector3d plo = pts[0], phi = pts[0];
    for (const auto& q : pts) plo = plo.cwiseMin(q), phi = phi.cwiseMax(q);
    Eigen::Vector3d lo = plo, hi = phi;
    for (const auto& [organ, entry] : outermost) {
      const auto& [slo, shi] = boxes[entry.second];
      if ((slo.array() <= phi.array() + 5.0).all() && (shi.array() >= plo.array() - 5.0).all())
        lo = lo.cwiseMin(slo), hi = hi.cwiseMax(shi);
    }
    b = {lo.x(), hi.x(), lo.y(), hi.y(), lo.z(), hi.z()};
  }
  state.scene_size_mm = std::max({b[1] - b[0], b[3] - b[2], b[5] - b[4], 10.0});
  state.scene_centre = Eigen::Vector3d((b[0] + b[1]) / 2, (b[2] + b[3]) / 2, (b[4] + b[5]) / 2);
  state.focus = b;
  // Paths: tubes thick enough to see at this scale.
  for (const auto& p : scene.paths) {
    ScenePath q = p;
    q.radius_mm = std::max(p.radius_mm, 0.004 * state.scene_size_mm);
    top->AddViewProp(path_actor(q));
  }
  if (haptics.contact)
    for (std::size_t k = 0; k < haptics.contact_scene_surfaces.size(); ++k) {
      const int si = haptics.contact_scene_surfaces[k];
      if (si < 0 || std::size_t(si) >= scene.surfaces.size() || !polydata[si]) continue;
      state.deformed.push_back(std::make_unique<DeformedSurface>(int(k), scene.surfaces[si].mesh,
                                                                 haptics.deform_radius_mm, polydata[si]));
    }

  // Start the hand in front of the middle of the path (the view looks along view_dir), else just
  // in front of the first organ.
  const Eigen::Vector3d view_dir = anterior_view(20, 15);
  Eigen::Vector3d start = state.scene_centre;
  if (haptics.path && !haptics.path->path().points_lps_mm.empty()) {
    const auto& pts = haptics.path->path().points_lps_mm;
    // Beside the path, to the viewer's right and a little toward the viewer: the pull (and
    // its arrow) is seen from the side.
    const Eigen::Vector3d right = view_dir.cross(Eigen::Vector3d(0, 0, 1)).normalized();
    start = pts[pts.size() / 2] + right * (0.08 * state.scene_size_mm) - view_dir * (0.03 * state.scene_size_mm);
  } else {
    for (const auto& s : scene.surfaces)
      if (!s.context && !s.mesh.vertices_lps_mm.empty()) {
        Eigen::Vector3d lo = s.mesh.vertices_lps_mm[0], hi = lo;
        for (const auto& v : s.mesh.vertices_lps_mm) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
        start = (lo + hi) / 2 + Eigen::Vector3d(0, -(hi.y() - lo.y()) / 2 - 5.0, 0);
        break;
      }
  }
  if (scene.tool) start = scene.tool->tip_lps_mm;
  if (options.start_lps_mm) start = *options.start_lps_mm;

  fit_parallel_camera(r, b, view_dir, Eigen::Vector3d(0, 0, 1), double(options.width_px) / options.height_px, 0.15);
  r->GetActiveCamera()->ParallelProjectionOff();  // perspective reads depth better when moving
  r->ResetCamera(b.data());
  r->GetActiveCamera()->Zoom(0.85);  // room for the tool to leave the organs

  // The tool is built at the origin and moved by SetPosition. Its handle leans towards the
  // viewer's upper right so that it is seen side-on, never end-on.
  SceneTool tool_shape;
  tool_shape.tip_lps_mm = Eigen::Vector3d::Zero();
  {
    double up[3];
    r->GetActiveCamera()->GetViewUp(up);
    const Eigen::Vector3d u(up[0], up[1], up[2]), right = view_dir.cross(u).normalized();
    tool_shape.axis_lps = (0.8 * u + 0.45 * right - 0.35 * view_dir).normalized();
  }
  const double tool_len = std::clamp(0.15 * state.scene_size_mm, 15.0, 80.0);
  std::vector<Ptr<vtkProp>> tool_props_kept = tool_props(tool_shape, tool_len, Rgb{0.1, 0.95, 0.95});
  for (auto& p : tool_props_kept) {
    top->AddViewProp(p);
    if (auto* p3 = vtkProp3D::SafeDownCast(p)) {
      p3->SetPosition(start.x(), start.y(), start.z());
      state.tool.push_back(p3);
    }
  }
  const double tip_r = std::max(0.6, tool_len * 0.06);
  // The force arrow: a unit arrow along +x, placed by a user matrix each frame.
  auto arrow_src = Ptr<vtkArrowSource>::New();
  arrow_src->SetShaftResolution(16);
  arrow_src->SetTipResolution(24);
  arrow_src->SetTipLength(0.3);
  arrow_src->SetTipRadius(0.12);
  arrow_src->SetShaftRadius(0.045);
  auto arrow_mapper = Ptr<vtkPolyDataMapper>::New();
  arrow_mapper->SetInputConnection(arrow_src->GetOutputPort());
  auto arrow = Ptr<vtkActor>::New();
  arrow->SetMapper(arrow_mapper);
  arrow->GetProperty()->SetColor(0.95, 0.15, 0.12);
  arrow->GetProperty()->SetSpecular(0.4);
  arrow->VisibilityOff();
  top->AddViewProp(arrow);
  state.force_arrow = arrow;
  // 3 N (the default clamp) is a fifth of the scene.
  state.force_mm_per_N = 0.2 * state.scene_size_mm / std::max(haptics.loop.force_limit_N, 1e-3);
  // Opaque: a single translucent prop would send every frame through those passes again.
  auto hand = sphere_actor(tip_r * 0.6, Rgb{0.95, 0.95, 0.95}, 1.0);
  top->AddViewProp(hand);
  state.hand = hand;
  auto spring = Ptr<vtkLineSource>::New();
  auto spring_mapper = Ptr<vtkPolyDataMapper>::New();
  spring_mapper->SetInputConnection(spring->GetOutputPort());
  auto spring_actor = Ptr<vtkActor>::New();
  spring_actor->SetMapper(spring_mapper);
  spring_actor->GetProperty()->SetColor(0.95, 0.95, 0.95);
  spring_actor->GetProperty()->SetLineWidth(1.5);
  spring_actor->GetProperty()->LightingOff();
  top->AddViewProp(spring_actor);
  state.spring = spring;
  state.spring_actor = spring_actor;
  auto goal = sphere_actor(tip_r * 0.5, Rgb{1.0, 0.97, 0.6}, 1.0);
  goal->VisibilityOff();
  top->AddViewProp(goal);
  state.goal = goal;

  // Scale bar (points moved each frame) and texts.
  auto bar_pts = Ptr<vtkPoints>::New();
  bar_pts->SetNumberOfPoints(4);
  for (int i = 0; i < 4; ++i) bar_pts->SetPoint(i, 0, 0, 0);
  r->AddViewProp(scale_bar_actor(bar_pts, Rgb{0.95, 0.95, 0.95}));
  auto bar_label = text("", std::max(10, options.height_px / 50), Rgb{0.95, 0.95, 0.95}, 0, 0, 0, 0);
  r->AddViewProp(bar_label);
  state.bar_points = bar_pts;
  state.bar_label = bar_label;

  const int font = std::max(12, options.height_px / 30);
  auto mode_label = text("", font, Rgb{1, 1, 1}, 0.02 * options.width_px, options.height_px * 0.97, 0, 2, true);
  auto corner = text("", std::max(10, options.height_px / 52), Rgb{0.92, 0.92, 0.92}, 0.02 * options.width_px,
                     0.02 * options.height_px, 0, 0);
  auto help = text("mouse: move hand | wheel: depth | left drag: turn | 1/2/3: mode | s: status | r: reset | q: quit",
                   std::max(10, options.height_px / 56), Rgb{0.75, 0.77, 0.82}, 0.98 * options.width_px,
                   0.97 * options.height_px, 2, 2);
  auto legend = text("cyan: tool   white: hand (mouse)   red: force   tubes: guidance paths",
                     std::max(10, options.height_px / 56), Rgb{0.75, 0.77, 0.82}, 0.98 * options.width_px,
                     0.97 * options.height_px - 1.6 * std::max(10, options.height_px / 56), 2, 2);
  r->AddViewProp(mode_label);
  r->AddViewProp(corner);
  r->AddViewProp(help);
  r->AddViewProp(legend);
  state.mode_label = mode_label;
  state.corner = corner;

  MouseDevice device(start, haptics.hand_path);
  physics::HapticLoop loop(device, haptics.path, haptics.contact, haptics.loop);
  loop.set_reaction_source(haptics.tissue_reaction);
  state.device = &device;
  state.loop = &loop;
  state.set_mode(haptics.loop.mode);
  loop.start();
  struct StopLoop {
    physics::HapticLoop& l;
    ~StopLoop() { l.stop(); }
  } stop_loop{loop};

  auto interactor = Ptr<vtkRenderWindowInteractor>::New();
  interactor->SetRenderWindow(window);
  auto style = Ptr<PreviewStyle>::New();
  style->state = &state;
  style->SetCurrentRenderer(r);
  interactor->SetInteractorStyle(style);
  interactor->Initialize();
  auto timer_cb = Ptr<vtkCallbackCommand>::New();
  timer_cb->SetCallback(on_timer);
  timer_cb->SetClientData(&state);
  interactor->AddObserver(vtkCommand::TimerEvent, timer_cb);
  state.frame_period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / std::max(1.0, options.render_rate_hz)));
  interactor->CreateRepeatingTimer(4);
  state.frame();
  window->Render();
  state.started = state.fps_window = Clock::now();
  state.cpu_started_ms = PreviewState::cpu_ms();
  state.emit("ready");
  interactor->Start();
  loop.stop();
  if (!options.screenshot_png.empty()) {
    state.frame();
    window->Render();
    write_png(grab(window), options.screenshot_png);
    state.emit("screenshot " + options.screenshot_png.string());
  }
  window->Finalize();
}

}  // namespace organsmith
