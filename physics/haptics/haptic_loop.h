#pragma once
// The 1 kHz force loop (thesis §5.1.6: force to the device at 1000 Hz; §5.2.1: F = w1 G + w2 R
// in three modes). A dedicated thread wakes on a steady-clock schedule, reads the device, computes
// guidance and reaction forces, mixes, clamps and sends them, and publishes its state to other
// threads (the display) without locks. Nothing is allocated and no lock is taken inside the loop.
//
// For the interactive preview (viewer): implement HapticDevice for the mouse (its position read
// from an atomic/SeqLock the UI thread writes), construct a HapticLoop with the path and contact
// model, start() it, read state() each frame (tool, force, contact for SurfaceDeformer), switch
// modes with set_mode() from the key handler, stop() on close.
//
// Units: LPS mm, N, s.

#include "physics/haptics/contact.h"
#include "physics/haptics/guidance.h"
#include "core/seqlock.h"

#include <Eigen/Core>

#include <array>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string_view>
#include <thread>
#include <type_traits>
#include <vector>

namespace organsmith::physics {

// ---- modes and mixing ----------------------------------------------------------------------------

/// The three force-integration modes of thesis §5.2.1.
enum class ForceMode : int {
  guidance = 0,  ///< w1 = 1, w2 = 0: guidance only
  mixed = 1,     ///< w1 = w2 = 0.5
  reaction = 2,  ///< w1 = 0, w2 = 1: reaction only (no guidance)
};

struct ForceWeights {
  double guidance = 0.0, reaction = 0.0;  ///< w1, w2 (sum 1, eq. 5.2.2)
};

ForceWeights weights(ForceMode mode) noexcept;
/// "guidance", "mixed", "reaction".
std::string_view mode_name(ForceMode mode) noexcept;
/// Parses a mode name; throws UsageError listing the names.
ForceMode parse_force_mode(std::string_view name);

/// F with its magnitude limited to limit_N (direction kept); a non-finite F gives zero.
Eigen::Vector3d clamp_force(const Eigen::Vector3d& F_N, double limit_N) noexcept;
/// F = w1 G + w2 R (eq. 5.2.1), clamped.
Eigen::Vector3d mix_forces(const Eigen::Vector3d& G_N, const Eigen::Vector3d& R_N, ForceMode mode,
                           double limit_N) noexcept;

// ---- lock-free hand-over -------------------------------------------------------------------------

// SeqLock (core/seqlock.h) hands states between threads without locks.
using Vec3 = std::array<double, 3>;
inline Vec3 to_vec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
inline Eigen::Vector3d to_eigen(const Vec3& v) { return {v[0], v[1], v[2]}; }

// ---- devices -------------------------------------------------------------------------------------

/// A haptic device, as the loop sees it. Called from the loop thread only, at the loop rate:
/// implementations must not block, allocate or lock (read an atomic or a SeqLock written by
/// whatever thread owns the real input).
class HapticDevice {
 public:
  virtual ~HapticDevice() = default;
  /// Tool tip position at loop time t_s (seconds since start()), LPS mm.
  virtual Eigen::Vector3d position_lps_mm(double t_s) noexcept = 0;
  /// The force to render, N (already mixed and clamped). Devices without actuators ignore it.
  virtual void command_force(const Eigen::Vector3d& /*force_N*/) noexcept {}
  /// True for devices that push the user's hand (a real haptic device): the tool is then where
  /// the device is. False (default) for position-only inputs (scripted, mouse): the loop then
  /// moves the displayed tool by the force it would have rendered (the gradient-descent pull).
  virtual bool renders_force() const noexcept { return false; }
  /// True when a scripted input has ended (the loop then stops by itself).
  virtual bool finished(double /*t_s*/) const noexcept { return false; }
};

/// Replays a recorded trajectory (t_s, x, y, z in LPS mm), linearly interpolated, holding the
/// last point after the end. Used by tests, benchmarks, `organsmith haptics` and movies.
/// The longest trajectory a ScriptedDevice replays, seconds (its trace holds a record per tick).
inline constexpr double kMaxTrajectorySpanS = 3600.0;

class ScriptedDevice final : public HapticDevice {
 public:
  /// Throws InputError (exit code 18) naming `source` when there are fewer than 2 samples, a
  /// value is not finite, time does not strictly increase, or it spans more than
  /// kMaxTrajectorySpanS.
  ScriptedDevice(std::vector<double> t_s, std::vector<Eigen::Vector3d> points_lps_mm,
                 const std::filesystem::path& source = {});
  /// Reads CSV with a header naming t_s, x, y, z (x_mm … also accepted). Throws InputError with
  /// file and line (exit code 3 when missing, 18 when malformed).
  static ScriptedDevice read_csv(const std::filesystem::path& path);

  Eigen::Vector3d position_lps_mm(double t_s) noexcept override;
  bool finished(double t_s) const noexcept override { return t_s > t_.back(); }
  double duration_s() const { return t_.back() - t_.front(); }
  const std::vector<double>& times_s() const { return t_; }
  const std::vector<Eigen::Vector3d>& points_lps_mm() const { return p_; }

 private:
  std::vector<double> t_;
  std::vector<Eigen::Vector3d> p_;
  std::size_t cursor_ = 0;  ///< last segment used (times are visited in order)
};

/// A reaction force computed elsewhere, e.g. an organ's real-time finite-element model
/// (physics/tissue/realtime_tissue.h): called by the loop thread at every tick with the tool tip,
/// so it must be lock-free and must not allocate.
class ReactionSource {
 public:
  virtual ~ReactionSource() = default;
  virtual Eigen::Vector3d reaction_N(const Eigen::Vector3d& tip_lps_mm) noexcept = 0;
};

// ---- the loop ------------------------------------------------------------------------------------

struct LoopOptions {
  double rate_Hz = 1000.0;          ///< tick rate (default 1000 Hz, thesis §5.1.6)
  double force_limit_N = 3.0;       ///< force clamp for device safety, N (default 3; Phantom Desktop peak ≈ 3.3 N)
  ForceMode mode = ForceMode::mixed;
  GuidanceOptions guidance;
  /// Position-only devices: the user's hand holds the tool with this stiffness; the displayed tool
  /// descends the energy w1·U + ½ k |q − p|² (+ the reaction) one gradient step per tick, N/mm.
  double hand_stiffness_N_per_mm = 0.5;
  /// α of eqs 5.2.6–5.2.8 for that descent, mm/N (default 0.5; stable while α (k + ξ) < 2).
  double step_mm_per_N = 0.5;
  /// Largest move of the displayed tool per tick, mm (default 0.5, i.e. 0.5 m/s at 1 kHz).
  double max_step_mm = 0.5;
  /// Ticks whose timing is kept for the percentiles (a ring; default 2^20 ≈ 17 min at 1 kHz).
  std::size_t timing_capacity = std::size_t(1) << 20;
  /// Per-tick samples kept for reports (preallocated; 0 = none).
  std::size_t trace_capacity = 0;
  /// Ask for SCHED_FIFO priority for the loop thread (granted only with the privilege; see
  /// LoopStats::realtime_priority). Default true.
  bool realtime_priority = true;
  /// Wake this long before each tick and spin to it, µs (default 200; 0 = sleep only). Timer
  /// wake-ups on a loaded or virtual machine come 50–300 µs late; the spin removes that from the
  /// tick's jitter at the cost of about spin_us / period of one core.
  double spin_us = 200.0;
};

/// Throws UsageError for unusable values.
void validate(const LoopOptions& options);

/// What the loop publishes every tick (trivially copyable, for SeqLock).
struct HapticState {
  std::uint64_t tick = 0;
  double time_s = 0.0;
  Vec3 device_lps_mm{}, tool_lps_mm{}, goal_lps_mm{};
  Vec3 force_N{}, guidance_N{}, reaction_N{};
  Vec3 contact_point_lps_mm{}, contact_normal{};
  double distance_mm = 0.0;        ///< tool to path
  double penetration_mm = 0.0;
  double measured_rate_Hz = 0.0;   ///< ticks per second since start
  int band = 0;                    ///< ξ band
  int mode = 1;                    ///< ForceMode as int
  int contact_surface = -1;
  bool contact = false;
  bool has_path = false;
};

struct Percentiles {
  double p50 = 0.0, p99 = 0.0, p999 = 0.0, max = 0.0;
};

struct LoopStats {
  std::uint64_t ticks = 0;
  std::uint64_t overruns = 0;      ///< ticks that woke more than one period late (schedule re-based)
  std::uint64_t faults = 0;        ///< non-finite device positions or forces replaced by zero force
  double elapsed_s = 0.0;
  double rate_Hz = 0.0;            ///< measured: (ticks − 1) / time between first and last tick
  bool realtime_priority = false;  ///< the loop thread ran with SCHED_FIFO priority
  Percentiles compute_us;          ///< time from wake-up to force sent
  Percentiles jitter_us;           ///< |actual wake-up − scheduled wake-up|
};

/// One tick as kept in the trace.
struct TraceSample {
  double t_s = 0.0;
  Vec3 device_lps_mm{}, tool_lps_mm{}, force_N{};
  double distance_mm = 0.0;
  double guidance_N = 0.0, reaction_N = 0.0;  ///< magnitudes before mixing
  int band = 0;
  bool contact = false;
};

class HapticLoop {
 public:
  /// `path` and `contact` may be null (no guidance / no reaction); both must outlive the loop,
  /// as must `device`. Throws UsageError for bad options.
  HapticLoop(HapticDevice& device, const PathIndex* path, const ContactModel* contact, const LoopOptions& options);
  ~HapticLoop();
  HapticLoop(const HapticLoop&) = delete;
  HapticLoop& operator=(const HapticLoop&) = delete;

  /// Starts the loop thread (the timing statistics and trace start afresh).
  void start();
  /// Stops and joins the thread (idempotent).
  void stop();
  bool running() const noexcept { return running_.load(std::memory_order_acquire); }
  /// Waits until the device finishes and the loop has stopped by itself, or timeout. True if stopped.
  bool wait(double timeout_s);

  /// Adds a reaction source (summed with the contact model's force; null: none). Not while running.
  void set_reaction_source(ReactionSource* source) noexcept { source_ = source; }

  /// Thread-safe, lock-free.
  void set_mode(ForceMode mode) noexcept { mode_.store(int(mode), std::memory_order_relaxed); }
  ForceMode mode() const noexcept { return ForceMode(mode_.load(std::memory_order_relaxed)); }
  /// The latest tick's state, from any thread, lock-free.
  HapticState state() const noexcept { return state_.read(); }

  /// Timing statistics. Percentiles are computed only when the loop is stopped (zero while running);
  /// counts and rate are always current.
  LoopStats stats() const;
  /// The trace (valid when stopped).
  std::vector<TraceSample> trace() const;

  /// Computes one tick at loop time t_s on the calling thread, sends the force and publishes the
  /// state, exactly as the thread does. For tests and off-line replays; not while running.
  HapticState tick(double t_s) noexcept;

 private:
  void run() noexcept;

  HapticDevice& device_;
  const PathIndex* path_;
  const ContactModel* contact_;
  ReactionSource* source_ = nullptr;
  LoopOptions options_;
  std::atomic<int> mode_;
  std::atomic<bool> running_{false}, stop_requested_{false};
  std::thread thread_;
  SeqLock<HapticState> state_;
  // Loop-thread state.
  Eigen::Vector3d tool_ = Eigen::Vector3d::Zero();
  bool have_tool_ = false;
  std::uint64_t tick_count_ = 0;
  std::atomic<std::uint64_t> ticks_{0}, overruns_{0}, faults_{0};
  std::atomic<double> elapsed_s_{0.0}, rate_Hz_{0.0};
  std::atomic<bool> realtime_{false};
  std::vector<float> compute_us_, jitter_us_;
  std::vector<TraceSample> trace_;
  std::atomic<std::size_t> trace_size_{0};
};

}  // namespace organsmith::physics
