#pragma once
// The organ in the haptic loop: a TissueModel stepped in time by its own thread (backward Euler,
// 60 Hz by default) and a local model of the tool's contact handed to the 1 kHz force loop
// (the multirate scheme of the haptics literature: the FE model at the display rate, the force
// at the haptic rate from the contact's force and stiffness at the last update).
//
// Contact: the tool tip is a sphere. When it touches the deformed outer surface, the surface
// nodes within the grip radius of the touched node are held to the tool (as the simulate stage's
// bonded probe) and follow its motion from there; they let go when the tissue would pull the
// tool (the tool withdrawn). The held nodes are where the tool is, so the tool never passes
// through the surface. Where the touched nodes are all fixed (the liver bed, a cut end) the
// tissue cannot give way: the tool meets a stiff wall there instead.
//
// Tangent: each update does a fixed number of corrections with the last factorised tangent (a
// back-substitution each). A second thread keeps refactorising the tangent at the latest state on
// a twin of the model and hands it over between updates, so that the update thread assembles
// and factorises only when the contact begins or ends (its held set changes) or the corrections
// made the residual grow (counted in `refreshes`).
//
// Threads: set_tool() from the haptic loop (or a scripted device), tool_force_N() from the
// haptic loop (lock-free, no allocation), positions() from the display (a mutex, at the display
// rate). Units: LPS mm, N, s.

#include "core/seqlock.h"
#include "physics/tissue/tissue_model.h"

#include <Eigen/Core>

#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <utility>
#include <vector>

namespace organsmith::physics {

struct RealtimeOptions {
  double update_hz = 60.0;         ///< FE updates per second (the step is 1/update_hz)
  int corrections_per_update = 8;  ///< at most this many back-substitutions with the last tangent per update …
  double correction_budget_ms = 8.0;  ///< … and none started past this (half a 60 Hz frame)
  double tool_radius_mm = 2.0;     ///< the tool tip's sphere
  double grip_radius_mm = 2.5;     ///< surface nodes within this of the touched node follow the tool (5 mm probe); its ring where fewer than three
  double wall_stiffness_N_per_mm = 1.0;  ///< where the tool meets only fixed nodes: a wall this stiff
  double max_lag_mm = 0.5;         ///< … and an update whose step leaves them further behind converges fully
  double max_step_mm = 0.25;       ///< the held nodes follow the tool by at most this per update (the force loop's stiffness covers the rest)
  bool background_tangent = true;  ///< refactorise on a second thread (false: in the update, where the corrections do not halve the residual)
};

/// What the FE thread publishes after each update, for the force loop.
struct ToolContact {
  bool in_contact = false;
  std::array<double, 3> tool_mm{0, 0, 0};        ///< the tool position this update solved for
  std::array<double, 3> force_on_tool_N{0, 0, 0};
  std::array<double, 9> stiffness_N_per_mm{};    ///< d(force on tool)/d(tool position), column-major
  std::array<double, 3> normal{0, 0, 0};         ///< outward surface normal where the contact began
  std::array<double, 3> held_mm{0, 0, 0};        ///< the gripped nodes' common displacement
  std::uint64_t update = 0;
};

class RealtimeTissue {
 public:
  /// `surface_triangles`: the outer surface, three node ids per face, outward. The model's
  /// boundary is set here (fixed nodes; nothing held).
  RealtimeTissue(TissueModel& model, std::vector<std::int32_t> fixed_nodes, std::vector<std::int32_t> surface_triangles,
                 RealtimeOptions options = {});
  ~RealtimeTissue();
  RealtimeTissue(const RealtimeTissue&) = delete;
  RealtimeTissue& operator=(const RealtimeTissue&) = delete;

  void start();  ///< the update thread
  void stop();

  /// Where the tool tip is now (any one thread).
  void set_tool(const Eigen::Vector3d& tip_lps_mm) noexcept;
  /// The force on the tool at tip position x: the last update's force plus its stiffness times
  /// the tool's motion since (zero out of contact, never pulling). Lock-free.
  Eigen::Vector3d tool_force_N(const Eigen::Vector3d& tip_lps_mm) const noexcept;
  ToolContact contact() const noexcept { return contact_.read(); }

  /// One update now, on the calling thread (tests and offline replays; not while started).
  void update_once();

  /// Deformed node positions at the last update.
  void positions(std::vector<Eigen::Vector3d>& out) const;
  /// Displacement at the last update (mm, 3 per node).
  Eigen::VectorXd displacement_mm() const;

  std::vector<double> update_ms() const;  ///< every update's wall time so far
  double update_ms_percentile(double p) const;  ///< of update_ms(), p in [0, 1] (0 before any update)
  std::vector<std::int32_t> grip_nodes() const;  ///< the nodes the tool holds now (none out of contact)
  std::uint64_t updates() const { return updates_.load(); }
  double achieved_update_hz() const;
  std::uint64_t refreshes() const { return refreshes_.load(); }  ///< updates that refactorised the tangent
  std::uint64_t tangents_adopted() const { return adopted_.load(); }  ///< tangents from the second thread

 private:
  TissueModel& model_;
  RealtimeOptions o_;
  std::vector<std::int32_t> fixed_, tri_, surface_nodes_;
  SeqLock<std::array<double, 3>> tool_;
  SeqLock<ToolContact> contact_;
  mutable std::mutex display_mutex_;
  Eigen::VectorXd shown_u_;
  std::vector<std::int32_t> shown_grip_;
  std::vector<double> update_ms_;
  std::atomic<std::uint64_t> updates_{0}, refreshes_{0}, adopted_{0};
  std::atomic<bool> running_{false};
  std::thread thread_, tangent_thread_;
  // The twin the second thread factorises on; model_mutex_ guards model_ against the hand-over.
  std::unique_ptr<TissueModel> twin_;
  std::mutex model_mutex_, twin_mutex_;
  bool twin_ready_ = false;
  std::atomic<bool> release_wanted_{false};  ///< the update thread waits for the twin's released tangent  ///< twin_ holds a factor not yet offered (under twin_mutex_)
  void refresh_loop();
  double started_s_ = 0.0, stopped_s_ = 0.0;
  // Contact state (update thread only).
  bool gripping_ = false;
  Eigen::Vector3d grip_tool0_ = Eigen::Vector3d::Zero(), grip_u0_ = Eigen::Vector3d::Zero(), grip_normal_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d held_ = Eigen::Vector3d::Zero();  ///< where the held nodes were sent last update
  std::vector<char> is_fixed_;
  std::map<std::pair<std::int32_t, std::int32_t>, std::int32_t> mid_;  ///< 10-node: edge → its mid-side node
  double rigid_gap_ = 0.0;  ///< < 0: the tool is into fixed nodes by this much (this update)
  Eigen::Vector3d rigid_normal_ = Eigen::Vector3d::UnitZ();
  void run();
};

}  // namespace organsmith::physics
