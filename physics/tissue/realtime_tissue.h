#pragma once
// The organ in the haptic loop, in two rates (the multirate scheme of the haptics literature):
//
// - Equilibrium (its own thread, as fast as it goes): the TissueModel's nonlinear quasi-static
//   equilibrium with the tool's grip where the tool is, in increments toward it, each by BFGS on
//   the last factorised tangent (TissueModel::solve_static_quasi_newton). Each converged state is published with its held-set stiffness and its response
//   (TissueModel::held_response): how every node moves, to first order, when the grip moves.
// - Update (60 Hz, its own thread): the deformation the display draws is the last equilibrium
//   plus its response to the tool's motion since (a 3-column product: microseconds).
// - Force (1 kHz, the haptic loop's thread): the last equilibrium's contact force plus its
//   held-set stiffness times the tool's motion since (lock-free, no allocation), never pulling.
//
// Between two equilibria the drawn organ and the felt force are the tangent response about the
// last one; the equilibrium closes the gap as it catches up (TISSUE.md measures it against the
// solver's curve and the rates on the 10-node gallbladder).
//
// Contact: the tool tip is a sphere. When it touches the deformed outer surface, the surface
// faces under a disc about the contact point (as the simulate stage's 5 mm probe holds its faces)
// are held to the tool and follow its motion from there; they let go when the tissue would pull
// the tool or the tool is back at the surface's rest position (then the organ is at rest: it
// carries no other load). The held nodes are where the tool is, so the tool never passes
// through the surface. Where the touched nodes are all fixed (the liver bed, a cut end) the
// tissue cannot give way: the tool meets a stiff wall there instead.
//
// Threads: set_tool() from the haptic loop (or a scripted device), tool_force_N() from the
// haptic loop, positions() from the display (a mutex, at the display rate). Units: LPS mm, N, s.

#include "core/seqlock.h"
#include "physics/tissue/tissue_model.h"

#include <Eigen/Core>

#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <mutex>
#include <thread>
#include <utility>
#include <vector>

namespace organsmith::physics {

struct RealtimeOptions {
  double update_hz = 60.0;         ///< display updates per second
  double tool_radius_mm = 2.0;     ///< the tool tip's sphere
  /// The tool holds the surface faces under a disc of this radius about the contact point (their
  /// centroids within it of the contact's axis and of its plane; all their nodes), as the simulate
  /// stage's 5 mm probe holds its faces; at least the touched node's faces.
  double grip_radius_mm = 2.5;
  double wall_stiffness_N_per_mm = 1.0;  ///< where the tool meets only fixed nodes: a wall this stiff
  /// The grip moves toward the tool by at most this per equilibrium (the response covers the rest).
  double max_increment_mm = 0.3;
  int iterations_per_equilibrium = 30;  ///< quasi-Newton iterations before the tangent is refactorised
};

/// What the equilibrium thread publishes, for the force loop.
struct ToolContact {
  bool in_contact = false;
  std::array<double, 3> tool_mm{0, 0, 0};        ///< the tool position this equilibrium is for
  std::array<double, 3> force_on_tool_N{0, 0, 0};
  std::array<double, 9> stiffness_N_per_mm{};    ///< d(force on tool)/d(tool position), column-major
  std::array<double, 3> normal{0, 0, 0};         ///< outward surface normal where the contact began
  std::array<double, 3> held_mm{0, 0, 0};        ///< the gripped nodes' common displacement
  std::uint64_t update = 0;                      ///< equilibria so far
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

  void start();  ///< the equilibrium and update threads
  void stop();

  /// The nodes the tool holds when it touches, instead of the disc under it (the simulate stage's
  /// probe nodes, for a press that is that probe). Before start(); empty: the disc.
  void hold_on_contact(std::vector<std::int32_t> nodes) { hold_on_contact_ = std::move(nodes); }

  /// Where the tool tip is now (any one thread).
  void set_tool(const Eigen::Vector3d& tip_lps_mm) noexcept;
  /// The force on the tool at tip position x: the last equilibrium's force plus its stiffness
  /// times the tool's motion since (zero out of contact, never pulling). Lock-free.
  Eigen::Vector3d tool_force_N(const Eigen::Vector3d& tip_lps_mm) const noexcept;
  ToolContact contact() const noexcept { return contact_.read(); }

  /// One equilibrium and one update now, on the calling thread (tests and offline replays; not
  /// while started).
  void update_once();

  /// Deformed node positions at the last update.
  void positions(std::vector<Eigen::Vector3d>& out) const;
  /// Displacement at the last update (mm, 3 per node).
  Eigen::VectorXd displacement_mm() const;

  std::vector<double> update_ms() const;  ///< every update's wall time so far
  double update_ms_percentile(double p) const;  ///< of update_ms(), p in [0, 1] (0 before any update)
  std::vector<double> equilibrium_ms() const;  ///< every published equilibrium's solve time
  double equilibrium_ms_percentile(double p) const;
  std::vector<std::int32_t> grip_nodes() const;  ///< the nodes the tool holds now (none out of contact)
  std::uint64_t updates() const { return updates_.load(); }
  std::uint64_t equilibria() const { return equilibria_.load(); }
  double achieved_update_hz() const;
  double achieved_equilibrium_hz() const;
  /// The tool's travel not yet in an equilibrium at the last update (mm): what the response covers.
  double last_gap_mm() const;

 private:
  TissueModel& model_;  // the equilibrium thread's (or update_once's) only
  RealtimeOptions o_;
  std::vector<std::int32_t> fixed_, tri_, surface_nodes_, hold_on_contact_;
  SeqLock<std::array<double, 3>> tool_;
  SeqLock<ToolContact> contact_;
  std::vector<char> is_fixed_;
  std::map<std::pair<std::int32_t, std::int32_t>, std::int32_t> mid_;  ///< 10-node: edge → its mid-side node
  std::atomic<bool> running_{false};
  std::thread solve_thread_, update_thread_;
  std::atomic<std::uint64_t> updates_{0}, equilibria_{0};
  double started_s_ = 0.0, stopped_s_ = 0.0;

  // The last equilibrium, for the update (under state_mutex_).
  struct Equilibrium {
    Eigen::VectorXd u;
    Eigen::MatrixXd response;  ///< empty out of contact
    Eigen::Vector3d grip_offset = Eigen::Vector3d::Zero();  ///< held displacement = tool + this, where the tissue follows
    Eigen::Vector3d held = Eigen::Vector3d::Zero();         ///< the held displacement solved for
    Eigen::Vector3d grip_normal = Eigen::Vector3d::Zero();  ///< the grip's outward normal (gripping)
    std::vector<std::int32_t> grip;
  };
  mutable std::mutex state_mutex_;
  Equilibrium eq_;
  // What the display shows (under display_mutex_).
  mutable std::mutex display_mutex_;
  Eigen::VectorXd shown_u_;
  std::vector<std::int32_t> shown_grip_;
  std::vector<double> update_ms_, equilibrium_ms_;
  double last_gap_ = 0.0;

  // Contact state (equilibrium thread only).
  bool gripping_ = false;
  Eigen::Vector3d grip_offset_ = Eigen::Vector3d::Zero(), grip_normal_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d held_ = Eigen::Vector3d::Zero();  ///< where the held nodes are
  bool settled_ = true;                              ///< no grip and at equilibrium
  double spent_ms_ = 0.0;                            ///< the next equilibrium's solve time so far
  double increment_mm_ = 0.0;                        ///< the next increment's length

  /// Where the tool would touch the deformed surface: the nearest corner node, the outward
  /// normal there, the tool sphere's gap along it, and the free nodes it would hold.
  struct Touch {
    std::int32_t node = -1;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    double gap_mm = 1e300;
    std::vector<std::int32_t> grip;  ///< sorted, no fixed node
  };
  Touch touch(const Eigen::Vector3d& tool) const;
  /// One step of the equilibrium thread: contact, one increment toward the tool, publication.
  /// False when there was nothing to do (no contact, at rest).
  bool solve_once();
  /// The tool lets go: the model carries no load but the tool's, so the equilibrium without it is
  /// the rest state, exactly (the hyperelastic energy is ≥ 0 and 0 only at a rigid motion, which
  /// the fixed sets hold at u = 0): no solve.
  void let_go();
  /// The model's state as the last equilibrium (for the update) and `c` (for the force loop).
  void publish(ToolContact c);
  void update_display();
};

}  // namespace organsmith::physics
