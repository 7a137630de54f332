// The interactive preview window.

#include "viewer/preview.h"

#include "viewer/detail/vtk_scene.h"

#include <Eigen/Geometry>
#include <spdlog/spdlog.h>
#include <vtkCallbackCommand.h>
#include <vtkCamera.h>
#include <vtkCommand.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkObjectFactory.h>
#include <vtkProp3D.h>
#include <vtkProperty.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkTextProperty.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <thread>

namespace organsmith {

using namespace viewer_detail;

std::string haptic_mode_name(HapticMode mode) {
  switch (mode) {
    case HapticMode::guidance_only: return "guidance only";
    case HapticMode::mixed: return "mixed";
    case HapticMode::reaction_only: return "reaction only";
  }
  return "?";
}

namespace {

using Clock = std::chrono::steady_clock;

/// The device side of the preview. Until the haptics stage lands this is a passive device: the
/// loop runs at the device rate, takes the mouse target as the tool position and computes no
/// force. Its measured rate is what the corner shows.
class PassiveDevice {
 public:
  explicit PassiveDevice(double rate_hz) : period_(std::chrono::duration<double>(1.0 / std::max(1.0, rate_hz))) {}
  ~PassiveDevice() { stop(); }

  void start(const Eigen::Vector3d& p) {
    target_ = position_ = p;
    running_ = true;
    thread_ = std::thread([this] { loop(); });
  }
  void stop() {
    running_ = false;
    if (thread_.joinable()) thread_.join();
  }
  void set_target(const Eigen::Vector3d& p) {
    std::lock_guard lock(mutex_);
    target_ = p;
  }
  Eigen::Vector3d target() const {
    std::lock_guard lock(mutex_);
    return target_;
  }
  Eigen::Vector3d position() const {
    std::lock_guard lock(mutex_);
    return position_;
  }
  double rate_hz() const { return rate_hz_.load(); }

 private:
  void loop() {
    auto next = Clock::now();
    auto window_start = next;
    long ticks = 0;
    while (running_) {
      {
        std::lock_guard lock(mutex_);
        position_ = target_;  // passive: no dynamics, no force
      }
      ++ticks;
      const auto now = Clock::now();
      const double elapsed = std::chrono::duration<double>(now - window_start).count();
      if (elapsed >= 0.5) {
        rate_hz_ = double(ticks) / elapsed;
        ticks = 0;
        window_start = now;
      }
      next += std::chrono::duration_cast<Clock::duration>(period_);
      if (next < now) next = now;  // fell behind: do not try to catch up in a burst
      std::this_thread::sleep_until(next);
    }
  }

  std::chrono::duration<double> period_;
  mutable std::mutex mutex_;
  Eigen::Vector3d target_ = Eigen::Vector3d::Zero(), position_ = Eigen::Vector3d::Zero();
  std::atomic<bool> running_{false};
  std::atomic<double> rate_hz_{0.0};
  std::thread thread_;
};

struct PreviewState {
  PreviewOptions options;
  PassiveDevice* device = nullptr;
  vtkRenderer* renderer = nullptr;
  vtkTextActor* mode_label = nullptr;
  vtkTextActor* corner = nullptr;
  std::vector<vtkProp3D*> tool;
  HapticMode mode = HapticMode::mixed;
  double scene_size_mm = 100.0;
  Clock::time_point started = Clock::now();
  Clock::time_point fps_window = Clock::now();
  int frames = 0;
  double fps = 0.0;

  Clock::duration frame_period{};
  Clock::time_point next_frame = Clock::now();
  long total_frames = 0;
  double render_ms_sum = 0;  ///< time spent in Render(), for the mean frame cost
  double fps_min = 1e9;

  /// " (render: mean N fps, slowest half-second N fps; device loop N Hz)".
  std::string stats() const {
    const double t = std::chrono::duration<double>(Clock::now() - started).count();
    char b[160];
    std::snprintf(b, sizeof b,
                  " (render: mean %.1f fps, slowest half-second %.1f fps, mean frame %.1f ms; device loop %.0f Hz)",
                  t > 0 ? total_frames / t : 0.0, fps_min < 1e9 ? fps_min : 0.0,
                  total_frames > 0 ? render_ms_sum / total_frames : 0.0, device->rate_hz());
    return b;
  }

  void emit(const std::string& e) const {
    if (options.on_event) options.on_event(e);
  }

  void set_mode(HapticMode m) {
    mode = m;
    static const Rgb colours[] = {{0.35, 0.85, 1.0}, {1.0, 0.85, 0.2}, {1.0, 0.45, 0.35}};
    const Rgb& c = colours[int(m) - 1];
    mode_label->SetInput(("mode " + std::to_string(int(m)) + ": " + haptic_mode_name(m)).c_str());
    mode_label->GetTextProperty()->SetColor(c.r, c.g, c.b);
    emit("mode " + std::to_string(int(m)) + " " + haptic_mode_name(m));
  }
};

/// Mouse: motion without a button moves the tool in the screen plane through its tip; the wheel
/// moves it in depth; left drag turns the camera, middle drag pans, right drag zooms.
/// Keys: 1/2/3 modes, r resets the camera, q or Esc quits.
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
    const Eigen::Vector3d tip = state->device->target();
    r->SetWorldPoint(tip.x(), tip.y(), tip.z(), 1.0);
    r->WorldToDisplay();
    const double depth = r->GetDisplayPoint()[2];
    r->SetDisplayPoint(p[0], p[1], depth);
    r->DisplayToWorld();
    const double* w = r->GetWorldPoint();
    if (w[3] == 0) return;
    state->device->set_target(Eigen::Vector3d(w[0] / w[3], w[1] / w[3], w[2] / w[3]));
  }
  void OnMouseWheelForward() override { push(+1); }
  void OnMouseWheelBackward() override { push(-1); }
  void OnChar() override {
    const char key = this->Interactor->GetKeyCode();
    const std::string sym = this->Interactor->GetKeySym() ? this->Interactor->GetKeySym() : "";
    if (key == '1' || key == '2' || key == '3') {
      state->set_mode(HapticMode(key - '0'));
      this->Interactor->Render();
    } else if (key == 'r' || key == 'R') {
      state->renderer->ResetCamera();
      this->Interactor->Render();
    } else if (key == 'q' || key == 'Q' || sym == "Escape") {
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
    state->device->set_target(state->device->target() + step);
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
  const Eigen::Vector3d p = s->device->position();
  for (auto* t : s->tool) t->SetPosition(p.x(), p.y(), p.z());
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
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "device loop: %.0f Hz (passive mouse device)\n"
                "force: not computed - haptic force model not connected yet\n"
                "render: %.0f fps\n"
                "tool tip (LPS mm): %.1f, %.1f, %.1f",
                s->device->rate_hz(), s->fps, p.x(), p.y(), p.z());
  s->corner->SetInput(buf);
  const auto r0 = Clock::now();
  s->renderer->GetRenderWindow()->Render();
  s->render_ms_sum += std::chrono::duration<double, std::milli>(Clock::now() - r0).count();
  if (s->options.quit_after_s > 0 &&
      std::chrono::duration<double>(now - s->started).count() >= s->options.quit_after_s) {
    s->emit("quit after " + std::to_string(int(s->options.quit_after_s)) + " s" + s->stats());
    s->renderer->GetRenderWindow()->GetInteractor()->TerminateApp();
  }
}

}  // namespace

void run_preview(const SnapshotScene& scene, const PreviewOptions& options) {
  DisplaySession display(options.display);
  if (display.private_xvfb())
    spdlog::warn("the preview window opens on a private Xvfb ({}): nobody will see it; set DISPLAY to watch it",
                 display.name());
  auto window = make_window(display.x_display(), options.width_px, options.height_px, /*offscreen=*/false);
  window->SetWindowName(options.title.c_str());

  auto r = Ptr<vtkRenderer>::New();
  r->GradientBackgroundOn();
  r->SetBackground(0.16, 0.17, 0.2);
  r->SetBackground2(0.36, 0.38, 0.44);
  // No depth peeling here: it multiplies the passes over the translucent context, and the
  // window must keep 30 fps on llvmpipe. Plain blending is good enough while moving.
  r->SetUseDepthPeeling(0);
  window->AddRenderer(r);

  for (const auto& s : scene.surfaces) r->AddViewProp(surface_actor(s));
  for (const auto& p : scene.paths) r->AddViewProp(path_actor(p));
  std::array<double, 6> b{-50, 50, -50, 50, -50, 50};
  visible_bounds(r, b);
  // Start the tool at the first organ's centre (not the context's).
  Eigen::Vector3d start((b[0] + b[1]) / 2, (b[2] + b[3]) / 2, (b[4] + b[5]) / 2);
  for (const auto& s : scene.surfaces)
    if (!s.context && !s.mesh.vertices_lps_mm.empty()) {
      Eigen::Vector3d lo = s.mesh.vertices_lps_mm[0], hi = lo;
      for (const auto& v : s.mesh.vertices_lps_mm) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
      start = (lo + hi) / 2 + Eigen::Vector3d(0, -(hi.y() - lo.y()) / 2 - 5.0, 0);  // just in front of it
      break;
    }
  if (scene.tool) start = scene.tool->tip_lps_mm;

  PreviewState state;
  state.options = options;
  state.renderer = r;
  state.scene_size_mm = std::max({b[1] - b[0], b[3] - b[2], b[5] - b[4], 10.0});
  const Eigen::Vector3d view_dir = anterior_view(20, 15);
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
    r->AddViewProp(p);
    if (auto* p3 = vtkProp3D::SafeDownCast(p)) {
      p3->SetPosition(start.x(), start.y(), start.z());
      state.tool.push_back(p3);
    }
  }


  const int font = std::max(12, options.height_px / 30);
  auto mode_label = text("", font, Rgb{1, 1, 1}, 0.02 * options.width_px, options.height_px * 0.97, 0, 2, true);
  auto corner = text("", std::max(10, options.height_px / 52), Rgb{0.92, 0.92, 0.92}, 0.02 * options.width_px,
                     0.02 * options.height_px, 0, 0);
  auto help = text("mouse: move tool | wheel: depth | left drag: turn | 1/2/3: mode | r: reset | q: quit",
                   std::max(10, options.height_px / 56), Rgb{0.75, 0.77, 0.82}, 0.98 * options.width_px,
                   0.02 * options.height_px, 2, 0);
  r->AddViewProp(mode_label);
  r->AddViewProp(corner);
  r->AddViewProp(help);
  state.mode_label = mode_label;
  state.corner = corner;

  PassiveDevice device(options.device_rate_hz);
  state.device = &device;
  state.set_mode(HapticMode::mixed);
  device.start(start);

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
  window->Render();
  state.emit("ready");
  interactor->Start();
  device.stop();
  window->Finalize();
}

}  // namespace organsmith
