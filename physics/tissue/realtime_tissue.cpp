#include "physics/tissue/realtime_tissue.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <utility>

namespace organsmith::physics {

namespace {
double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

RealtimeTissue::RealtimeTissue(TissueModel& model, std::vector<std::int32_t> fixed, std::vector<std::int32_t> tri,
                               RealtimeOptions o)
    : model_(model), o_(o), fixed_(std::move(fixed)), tri_(std::move(tri)) {
  std::set<std::int32_t> s(tri_.begin(), tri_.end());
  if (model_.mesh().nodes_per_element == 10) {
    // The surface's mid-side nodes join the corners: a patch held by its corners only would
    // leave the quadratic edges between them free to fold.
    static constexpr int edge[6][3] = {{0, 1, 4}, {1, 2, 5}, {2, 0, 6}, {0, 3, 7}, {1, 3, 8}, {2, 3, 9}};
    for (const auto& el : model_.mesh().elements)
      for (const auto& e : edge) mid_[std::minmax(el[e[0]], el[e[1]])] = el[e[2]];
    for (std::size_t t = 0; t + 2 < tri_.size(); t += 3)
      for (int k = 0; k < 3; ++k)
        if (const auto it = mid_.find(std::minmax(tri_[t + k], tri_[t + (k + 1) % 3])); it != mid_.end()) s.insert(it->second);
  }
  surface_nodes_.assign(s.begin(), s.end());
  is_fixed_.assign(model_.node_count(), 0);
  for (std::int32_t i : fixed_) is_fixed_[std::size_t(i)] = 1;
  model_.set_boundary(fixed_, {});
  shown_u_ = model_.displacement_mm();
  tool_.write({1e30, 1e30, 1e30});
}

RealtimeTissue::~RealtimeTissue() { stop(); }

void RealtimeTissue::start() {
  if (running_.load()) return;
  // The first tangent before the clock starts: the first update then corrects with it.
  model_.refresh_tangent(1.0 / o_.update_hz);
  running_.store(true);
  started_s_ = now_s();
  if (o_.background_tangent) {
    if (!twin_) twin_ = std::make_unique<TissueModel>(model_.mesh(), model_.options());
    tangent_thread_ = std::thread([this] { refresh_loop(); });
  }
  thread_ = std::thread([this] { run(); });
}

void RealtimeTissue::stop() {
  if (!running_.exchange(false)) return;
  if (thread_.joinable()) thread_.join();
  if (tangent_thread_.joinable()) tangent_thread_.join();
  stopped_s_ = now_s();
}

void RealtimeTissue::refresh_loop() {
  // Normal priority: the force loop takes real-time priority where it can (HapticLoop), and a
  // tangent starved of the CPU (SCHED_IDLE was tried) makes the updates refactorise themselves.
  const double dt = 1.0 / o_.update_hz;
  while (running_.load()) {
    {
      std::lock_guard<std::mutex> lock(twin_mutex_);
      if (!twin_ready_) {
        {
          std::lock_guard<std::mutex> m(model_mutex_);
          twin_->copy_state_from(model_);
          // A release asked for: the tangent of the tissue let go, for the update to take with it.
          if (release_wanted_.load()) twin_->set_boundary(fixed_, {});
        }
        twin_->refresh_tangent(dt);
        twin_ready_ = true;
      }
    }
    // Offered to the update thread; wait for it to be taken (or the boundary to move on).
    for (int i = 0; i < 200 && running_.load(); ++i) {
      {
        std::lock_guard<std::mutex> lock(twin_mutex_);
        if (!twin_ready_) break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    std::lock_guard<std::mutex> lock(twin_mutex_);
    twin_ready_ = false;
  }
}

void RealtimeTissue::set_tool(const Eigen::Vector3d& p) noexcept { tool_.write({p.x(), p.y(), p.z()}); }

Eigen::Vector3d RealtimeTissue::tool_force_N(const Eigen::Vector3d& x) const noexcept {
  const ToolContact c = contact_.read();
  if (!c.in_contact) return Eigen::Vector3d::Zero();
  const Eigen::Map<const Eigen::Matrix3d> K(c.stiffness_N_per_mm.data());
  const Eigen::Vector3d F = Eigen::Vector3d(c.force_on_tool_N.data()) + K * (x - Eigen::Vector3d(c.tool_mm.data()));
  const Eigen::Vector3d n(c.normal.data());
  return F.dot(n) > 0 ? F : Eigen::Vector3d::Zero();  // tissue pushes, never pulls
}

void RealtimeTissue::run() {
  const double period = 1.0 / o_.update_hz;
  auto next = std::chrono::steady_clock::now();
  while (running_.load()) {
    update_once();
    next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(period));
    const auto now = std::chrono::steady_clock::now();
    if (next < now) next = now;  // late: do not try to catch up
    std::this_thread::sleep_until(next);
  }
}

void RealtimeTissue::update_once() {
  const auto t0 = std::chrono::steady_clock::now();
  const auto tp = tool_.read();
  const Eigen::Vector3d tool(tp[0], tp[1], tp[2]);
  const double dt = 1.0 / o_.update_hz;
  std::unique_lock<std::mutex> model_lock(model_mutex_);  // against the twin's copy of the state
  const auto& X = model_.mesh().nodes_mm;
  const Eigen::VectorXd& u = model_.displacement_mm();
  auto at = [&](std::int32_t i) { return Eigen::Vector3d(X[i] + u.segment<3>(3 * i)); };

  if (!gripping_ && tool.allFinite() && tool.norm() < 1e20) {
    // Nearest surface node and its outward normal on the deformed surface.
    std::int32_t best = -1;
    double dmin = 1e300;
    for (std::int32_t i : tri_)  // the corners: the faces' normals are theirs
      if (const double d = (at(i) - tool).squaredNorm(); d < dmin) dmin = d, best = i;
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (std::size_t t = 0; t + 2 < tri_.size(); t += 3)
      if (tri_[t] == best || tri_[t + 1] == best || tri_[t + 2] == best)
        n += (at(tri_[t + 1]) - at(tri_[t])).cross(at(tri_[t + 2]) - at(tri_[t]));
    if (best >= 0 && n.norm() > 0) {
      n.normalize();
      const double gap = (tool - at(best)).dot(n) - o_.tool_radius_mm;
      if (gap < 0 && std::sqrt(dmin) < o_.tool_radius_mm + o_.grip_radius_mm) {
        // The nodes within the grip radius, and at least the touched node's ring (its faces'
        // nodes): on a mesh coarser than the tool a single held node would be a point load.
        std::set<std::int32_t> g;
        for (std::int32_t i : surface_nodes_)
          if ((at(i) - at(best)).norm() <= o_.grip_radius_mm) g.insert(i);
        for (std::size_t t = 0; t + 2 < tri_.size() && g.size() < 3; t += 3)
          if (tri_[t] == best || tri_[t + 1] == best || tri_[t + 2] == best)
            for (int k = 0; k < 3; ++k) {
              g.insert(tri_[t + k]);
              if (const auto it = mid_.find(std::minmax(tri_[t + k], tri_[t + (k + 1) % 3])); it != mid_.end()) g.insert(it->second);
            }
        std::vector<std::int32_t> grip;
        for (std::int32_t i : g)
          if (!is_fixed_[i]) grip.push_back(i);
        if (grip.empty()) {
          // Only fixed nodes under the tool (the liver bed, a cut end): a rigid wall there.
          rigid_gap_ = gap;
          rigid_normal_ = n;
        } else {
        gripping_ = true;
        grip_normal_ = n;
        // The held nodes start where the sphere's surface is along the normal: a tool already
        // in by `gap` pushes them in by as much.
        grip_u0_ = u.segment<3>(3 * best) + gap * n;
        grip_tool0_ = tool;
        held_ = grip_u0_;
        model_.set_boundary(fixed_, grip);
        }
      }
    }
  }
  Eigen::Vector3d held = Eigen::Vector3d::Zero();
  double lag = 0.0;  // how far the held nodes are behind the tool after this update's step
  if (gripping_) {
    // Toward the tool by at most max_step_mm: a late update does not take a jump its tangent
    // cannot follow; the force loop extrapolates the force over what is left.
    const Eigen::Vector3d want = grip_u0_ + (tool - grip_tool0_) - held_;
    held = held_ + (want.norm() > o_.max_step_mm ? want * (o_.max_step_mm / want.norm()) : want);
    lag = (want - (held - held_)).norm();
    if (release_wanted_.load()) held = held_, lag = 0.0;  // letting go: the held nodes stand still
  }
  NewtonOptions no;
  no.max_iterations = o_.corrections_per_update;
  no.time_budget_ms = o_.correction_budget_ms;
  no.force_tolerance_N = 1e-9;  // the organ at rest: soft walls (μ ≈ 100 Pa) move 0.05 mm under 10⁻⁷ N
  if (twin_) {
    std::unique_lock<std::mutex> lock(twin_mutex_, std::try_to_lock);
    if (lock.owns_lock() && twin_ready_) {
      if (release_wanted_.load() && twin_->held_nodes().empty()) {  // let go, with the tangent for it
        model_.set_boundary(fixed_, {});
        gripping_ = false;
        release_wanted_.store(false);
        held = Eigen::Vector3d::Zero();
      }
      if (model_.adopt_tangent(*twin_)) ++adopted_;
      twin_ready_ = false;
    }
  }
  // Without the second thread (not started, or switched off) this update refactorises where its
  // corrections do not halve the residual.
  // Against the clock (the second thread running) unless the tissue has fallen behind the tool
  // by more than max_lag_mm: then this update converges whatever it costs.
  const bool catch_up = lag > o_.max_lag_mm;
  const NewtonReport rep = model_.step_dynamic_reusing_tangent(held, dt, no, !(twin_ && running_.load()) || catch_up);
  if (rep.stayed) held = held_;  // not taken: the held nodes are where they were
  held_ = held;
  if (rep.refreshed) ++refreshes_;
  ToolContact c;
  if (!gripping_ && rigid_gap_ < 0) {  // the wall: k·depth along the normal, stiffness k n nᵀ
    const Eigen::Vector3d F = o_.wall_stiffness_N_per_mm * -rigid_gap_ * rigid_normal_;
    const Eigen::Matrix3d K = -o_.wall_stiffness_N_per_mm * rigid_normal_ * rigid_normal_.transpose();
    c.in_contact = true;
    c.force_on_tool_N = {F.x(), F.y(), F.z()};
    std::copy(K.data(), K.data() + 9, c.stiffness_N_per_mm.begin());
    c.normal = {rigid_normal_.x(), rigid_normal_.y(), rigid_normal_.z()};
  }
  rigid_gap_ = 0.0;
  c.update = updates_.load() + 1;
  const Eigen::Vector3d solved_for = gripping_ ? Eigen::Vector3d(grip_tool0_ + held - grip_u0_) : tool;
  c.tool_mm = {solved_for.x(), solved_for.y(), solved_for.z()};
  if (gripping_) {
    const Eigen::Vector3d F = -model_.held_force_N();
    if (!F.allFinite() || !(F.dot(grip_normal_) > 0)) {  // the tissue would pull the tool: let go
      if (twin_ && running_.load()) {
        // Once the second thread has the tangent of the tissue let go (a few updates, the held
        // nodes standing still meanwhile): no refactorisation in this thread.
        release_wanted_.store(true);
      } else {
        gripping_ = false;
        model_.set_boundary(fixed_, {});
      }
    } else {
      release_wanted_.store(false);  // pressed again before it let go
      c.in_contact = true;
      c.force_on_tool_N = {F.x(), F.y(), F.z()};
      const Eigen::Matrix3d K = -model_.held_stiffness_N_per_mm();
      std::copy(K.data(), K.data() + 9, c.stiffness_N_per_mm.begin());
      c.normal = {grip_normal_.x(), grip_normal_.y(), grip_normal_.z()};
      c.held_mm = {held.x(), held.y(), held.z()};
    }
  }
  model_lock.unlock();
  contact_.write(c);
  {
    std::lock_guard<std::mutex> lock(display_mutex_);
    shown_u_ = model_.displacement_mm();
    shown_grip_ = c.in_contact && gripping_ ? model_.held_nodes() : std::vector<std::int32_t>{};
    update_ms_.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  updates_.fetch_add(1);
}

void RealtimeTissue::positions(std::vector<Eigen::Vector3d>& out) const {
  std::lock_guard<std::mutex> lock(display_mutex_);
  const auto& X = model_.mesh().nodes_mm;
  out.resize(X.size());
  for (std::size_t i = 0; i < X.size(); ++i) out[i] = X[i] + shown_u_.segment<3>(3 * i);
}

Eigen::VectorXd RealtimeTissue::displacement_mm() const {
  std::lock_guard<std::mutex> lock(display_mutex_);
  return shown_u_;
}

std::vector<std::int32_t> RealtimeTissue::grip_nodes() const {
  std::lock_guard<std::mutex> lock(display_mutex_);
  return shown_grip_;
}

double RealtimeTissue::update_ms_percentile(double p) const {
  std::vector<double> v = update_ms();
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, std::size_t(p * double(v.size())))];
}

std::vector<double> RealtimeTissue::update_ms() const {
  std::lock_guard<std::mutex> lock(display_mutex_);
  return update_ms_;
}

double RealtimeTissue::achieved_update_hz() const {
  const double end = running_.load() ? now_s() : stopped_s_;
  return end > started_s_ ? double(updates_.load()) / (end - started_s_) : 0.0;
}

}  // namespace organsmith::physics
