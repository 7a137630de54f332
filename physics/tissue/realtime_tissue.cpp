#include "physics/tissue/realtime_tissue.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>
#include <utility>

namespace organsmith::physics {

namespace {
double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, std::size_t(p * double(v.size())))];
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
  eq_.u = model_.displacement_mm();
  shown_u_ = eq_.u;
  increment_mm_ = o_.max_increment_mm;
  tool_.write({1e30, 1e30, 1e30});
}

RealtimeTissue::~RealtimeTissue() { stop(); }

void RealtimeTissue::start() {
  if (running_.load()) return;
  running_.store(true);
  started_s_ = now_s();
  solve_thread_ = std::thread([this] {
    while (running_.load())
      if (!solve_once()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  });
  update_thread_ = std::thread([this] {
    const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(1.0 / o_.update_hz));
    auto next = std::chrono::steady_clock::now();
    while (running_.load()) {
      update_display();
      next += period;
      const auto now = std::chrono::steady_clock::now();
      if (next < now) next = now;  // late: do not try to catch up
      std::this_thread::sleep_until(next);
    }
  });
}

void RealtimeTissue::stop() {
  if (!running_.exchange(false)) return;
  stopped_s_ = now_s();
  if (solve_thread_.joinable()) solve_thread_.join();
  if (update_thread_.joinable()) update_thread_.join();
}

RealtimeTissue::Touch RealtimeTissue::touch(const Eigen::Vector3d& tool) const {
  const auto& X = model_.mesh().nodes_mm;
  const Eigen::VectorXd& u = model_.displacement_mm();
  auto at = [&](std::int32_t i) { return Eigen::Vector3d(X[i] + u.segment<3>(3 * i)); };
  Touch t;
  // Nearest surface corner and its outward normal on the deformed surface.
  double dmin = 1e300;
  for (std::int32_t i : tri_)
    if (const double d = (at(i) - tool).squaredNorm(); d < dmin) dmin = d, t.node = i;
  if (t.node < 0) return t;
  for (std::size_t f = 0; f + 2 < tri_.size(); f += 3)
    if (tri_[f] == t.node || tri_[f + 1] == t.node || tri_[f + 2] == t.node)
      t.normal += (at(tri_[f + 1]) - at(tri_[f])).cross(at(tri_[f + 2]) - at(tri_[f]));
  if (!(t.normal.norm() > 0)) return Touch{};
  t.normal.normalize();
  const Eigen::Vector3d p = at(t.node);
  t.gap_mm = (tool - p).dot(t.normal) - o_.tool_radius_mm;
  // Too far sideways for the sphere to reach this surface: no touch.
  if (std::sqrt(dmin) >= o_.tool_radius_mm + o_.grip_radius_mm + std::max(0.0, t.gap_mm)) t.gap_mm = 1e300;
  // The disc under the tool: faces whose centroid is within the grip radius of the axis through
  // the tool along the normal and of the tangent plane at the touched node (the simulate stage's
  // probe faces), with every node of those faces; at least the touched node's faces.
  const Eigen::Vector3d c = tool - (tool - p).dot(t.normal) * t.normal;
  const double R = o_.grip_radius_mm;
  std::set<std::int32_t> g;
  auto add_face = [&](std::size_t f) {
    for (int k = 0; k < 3; ++k) {
      g.insert(tri_[f + k]);
      if (const auto it = mid_.find(std::minmax(tri_[f + k], tri_[f + (k + 1) % 3])); it != mid_.end()) g.insert(it->second);
    }
  };
  bool any = false;
  for (std::size_t f = 0; f + 2 < tri_.size(); f += 3) {
    const Eigen::Vector3d r = (at(tri_[f]) + at(tri_[f + 1]) + at(tri_[f + 2])) / 3.0 - c;
    const double axial = r.dot(t.normal);
    if ((r - axial * t.normal).norm() <= R && std::abs(axial) <= R) add_face(f), any = true;
  }
  if (!any)
    for (std::size_t f = 0; f + 2 < tri_.size(); f += 3)
      if (tri_[f] == t.node || tri_[f + 1] == t.node || tri_[f + 2] == t.node) add_face(f);
  if (!hold_on_contact_.empty()) g = std::set<std::int32_t>(hold_on_contact_.begin(), hold_on_contact_.end());
  for (std::int32_t i : g)
    if (!is_fixed_[std::size_t(i)]) t.grip.push_back(i);
  return t;
}

namespace {

/// The tool is gone, or back at or outside the surface's rest position along the grip's normal:
/// without its load the organ's equilibrium is the rest state.
bool withdrawn_to_rest(const Eigen::Vector3d& tool, const Eigen::Vector3d& grip_offset, const Eigen::Vector3d& normal) {
  return !(tool.allFinite() && tool.norm() < 1e20) || (tool + grip_offset).dot(normal) >= 0.0;
}

}  // namespace

void RealtimeTissue::set_tool(const Eigen::Vector3d& p) noexcept { tool_.write({p.x(), p.y(), p.z()}); }

Eigen::Vector3d RealtimeTissue::tool_force_N(const Eigen::Vector3d& x) const noexcept {
  const ToolContact c = contact_.read();
  if (!c.in_contact) return Eigen::Vector3d::Zero();
  const Eigen::Map<const Eigen::Matrix3d> K(c.stiffness_N_per_mm.data());
  const Eigen::Vector3d F = Eigen::Vector3d(c.force_on_tool_N.data()) + K * (x - Eigen::Vector3d(c.tool_mm.data()));
  const Eigen::Vector3d n(c.normal.data());
  return F.dot(n) > 0 ? F : Eigen::Vector3d::Zero();  // tissue pushes, never pulls
}

bool RealtimeTissue::solve_once() {
  const auto t0 = std::chrono::steady_clock::now();
  const auto tp = tool_.read();
  const Eigen::Vector3d tool(tp[0], tp[1], tp[2]);
  const bool tool_here = tool.allFinite() && tool.norm() < 1e20;
  ToolContact c;
  c.update = equilibria_.load();
  if (!gripping_ && tool_here) {
    const Touch t = touch(tool);
    if (t.node >= 0 && t.gap_mm < 0) {
      if (t.grip.empty()) {
        // Only fixed nodes under the tool (the liver bed, a cut end): a wall, k·depth along the
        // normal, stiffness k n nᵀ.
        const Eigen::Vector3d F = o_.wall_stiffness_N_per_mm * -t.gap_mm * t.normal;
        const Eigen::Matrix3d K = -o_.wall_stiffness_N_per_mm * t.normal * t.normal.transpose();
        c.in_contact = true;
        c.tool_mm = {tool.x(), tool.y(), tool.z()};
        c.force_on_tool_N = {F.x(), F.y(), F.z()};
        std::copy(K.data(), K.data() + 9, c.stiffness_N_per_mm.begin());
        c.normal = {t.normal.x(), t.normal.y(), t.normal.z()};
      } else {
        gripping_ = true;
        settled_ = false;
        grip_normal_ = t.normal;
        // The held nodes start where the touched node is and go to where the sphere's surface is
        // along the normal: a tool already in by `gap` pushes them in by as much.
        held_ = model_.displacement_mm().segment<3>(3 * t.node);
        grip_offset_ = held_ + t.gap_mm * t.normal - tool;
        model_.set_boundary(fixed_, t.grip);
      }
    }
  }
  if (!gripping_ && settled_) {
    contact_.write(c);
    return false;
  }
  // Withdrawn: the tool is back at or outside the surface's rest position along the grip's normal
  // (or gone); the organ lets go (let_go: at rest). An increment in progress is abandoned as soon as
  // the tool gets there.
  auto withdrawn = [this] {
    const auto p = tool_.read();
    return withdrawn_to_rest(Eigen::Vector3d(p[0], p[1], p[2]), grip_offset_, grip_normal_);
  };
  if (gripping_ && withdrawn()) {
    let_go();
    spent_ms_ += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    publish(c);
    return true;
  }
  NewtonOptions no;
  if (gripping_) no.abandon = withdrawn;
  no.max_iterations = o_.iterations_per_equilibrium;
  no.force_tolerance_N = 1e-9;  // the organ at rest: soft walls (μ ≈ 100 Pa) move 0.05 mm under 10⁻⁷ N
  no.relative_tolerance = 1e-3;
  // Toward the tool by at most the increment. An increment that does not converge is made again
  // from the last equilibrium at half the length; one that converges in few iterations lets the
  // next grow by half (between a twentieth and all of max_increment_mm).
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  if (gripping_) {
    const Eigen::Vector3d want = tool_here ? Eigen::Vector3d(tool + grip_offset_) : held_;
    const Eigen::Vector3d step = want - held_;
    target = held_ + (step.norm() > increment_mm_ ? Eigen::Vector3d(step * (increment_mm_ / step.norm())) : step);
  }
  const Eigen::VectorXd from = model_.displacement_mm();
  const NewtonReport rep = model_.solve_static_quasi_newton(target, no);
  if (!rep.converged && gripping_ && withdrawn()) {  // abandoned: the next call lets go
    model_.set_displacement_mm(from);
    return true;
  }
  if (!rep.converged) {
    model_.set_displacement_mm(from);
    increment_mm_ = std::max(0.05 * o_.max_increment_mm, 0.5 * increment_mm_);
  } else {
    if (gripping_) held_ = target;
    if (rep.iterations <= 10) increment_mm_ = std::min(o_.max_increment_mm, 1.5 * increment_mm_);
  }
  spent_ms_ += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (!rep.converged) return true;  // the last equilibrium still shown; a shorter increment next
  if (gripping_) {
    const Eigen::Vector3d F = -model_.held_force_N();
    if (!F.allFinite() || !(F.dot(grip_normal_) > 0)) {  // the tissue would pull the tool: let go
      let_go();
      publish(c);
      return true;
    }
    c.in_contact = true;
    const Eigen::Vector3d at = held_ - grip_offset_;
    c.tool_mm = {at.x(), at.y(), at.z()};
    c.force_on_tool_N = {F.x(), F.y(), F.z()};
    const Eigen::Matrix3d K = -model_.held_stiffness_N_per_mm();
    std::copy(K.data(), K.data() + 9, c.stiffness_N_per_mm.begin());
    c.normal = {grip_normal_.x(), grip_normal_.y(), grip_normal_.z()};
    c.held_mm = {held_.x(), held_.y(), held_.z()};
  } else {
    settled_ = true;
  }
  publish(c);
  return true;
}

void RealtimeTissue::let_go() {
  gripping_ = false;
  held_.setZero();
  model_.set_boundary(fixed_, {});
  model_.set_displacement_mm(Eigen::VectorXd::Zero(model_.displacement_mm().size()));
  settled_ = true;
}

void RealtimeTissue::publish(ToolContact c) {
  c.update = equilibria_.load() + 1;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    eq_.u = model_.displacement_mm();
    if (gripping_) eq_.response = model_.held_response();
    else eq_.response.resize(0, 0);
    eq_.grip_offset = grip_offset_;
    eq_.held = held_;
    eq_.grip_normal = grip_normal_;
    eq_.grip = gripping_ ? model_.held_nodes() : std::vector<std::int32_t>{};
  }
  contact_.write(c);
  {
    std::lock_guard<std::mutex> lock(display_mutex_);
    equilibrium_ms_.push_back(spent_ms_);
  }
  spent_ms_ = 0.0;
  equilibria_.fetch_add(1);
}

void RealtimeTissue::update_display() {
  const auto t0 = std::chrono::steady_clock::now();
  const auto tp = tool_.read();
  const Eigen::Vector3d tool(tp[0], tp[1], tp[2]);
  // The last equilibrium and, in contact, its response to the tool's motion since (while the
  // tissue pushes the tool; withdrawn past that, the equilibrium lets go).
  Eigen::VectorXd u;
  std::vector<std::int32_t> grip;
  double gap = 0.0;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    if (!eq_.grip.empty() && withdrawn_to_rest(tool, eq_.grip_offset, eq_.grip_normal)) {
      // The tool is back at the surface's rest position (or gone): without its load the organ's
      // equilibrium is the rest state exactly (solve_once lets go too, once an equilibrium still
      // in progress notices; on a 10-node tube that can take seconds).
      u = Eigen::VectorXd::Zero(eq_.u.size());
    } else {
      u = eq_.u;
      grip = eq_.grip;
      if (eq_.response.cols() == 3 && eq_.response.rows() == u.size() && tool.allFinite() && tool.norm() < 1e20 &&
          tool_force_N(tool).norm() > 0) {
        const Eigen::Vector3d delta = tool + eq_.grip_offset - eq_.held;
        u.noalias() += eq_.response * delta;
        gap = delta.norm();
      }
    }
  }
  std::lock_guard<std::mutex> lock(display_mutex_);
  shown_u_ = std::move(u);
  shown_grip_ = std::move(grip);
  last_gap_ = gap;
  update_ms_.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  updates_.fetch_add(1);
}

void RealtimeTissue::update_once() {
  solve_once();
  update_display();
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

double RealtimeTissue::last_gap_mm() const {
  std::lock_guard<std::mutex> lock(display_mutex_);
  return last_gap_;
}

std::vector<double> RealtimeTissue::update_ms() const {
  std::lock_guard<std::mutex> lock(display_mutex_);
  return update_ms_;
}

double RealtimeTissue::update_ms_percentile(double p) const { return percentile(update_ms(), p); }

std::vector<double> RealtimeTissue::equilibrium_ms() const {
  std::lock_guard<std::mutex> lock(display_mutex_);
  return equilibrium_ms_;
}

double RealtimeTissue::equilibrium_ms_percentile(double p) const { return percentile(equilibrium_ms(), p); }

double RealtimeTissue::achieved_update_hz() const {
  const double end = running_.load() ? now_s() : stopped_s_;
  return end > started_s_ ? double(updates_.load()) / (end - started_s_) : 0.0;
}

double RealtimeTissue::achieved_equilibrium_hz() const {
  const double end = running_.load() ? now_s() : stopped_s_;
  return end > started_s_ ? double(equilibria_.load()) / (end - started_s_) : 0.0;
}

}  // namespace organsmith::physics
