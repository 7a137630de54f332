#include "physics/haptics/haptic_loop.h"

#include "core/csv.h"
#include "core/errors.h"
#include "core/file_io.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <string>

#if defined(__linux__)
#include <pthread.h>
#include <sched.h>
#include <sys/prctl.h>
#endif

namespace organsmith::physics {

namespace fs = std::filesystem;

// ---- modes ---------------------------------------------------------------------------------------

ForceWeights weights(ForceMode mode) noexcept {
  switch (mode) {
    case ForceMode::guidance: return {1.0, 0.0};
    case ForceMode::mixed: return {0.5, 0.5};
    case ForceMode::reaction: return {0.0, 1.0};
  }
  return {0.0, 0.0};
}

std::string_view mode_name(ForceMode mode) noexcept {
  switch (mode) {
    case ForceMode::guidance: return "guidance";
    case ForceMode::mixed: return "mixed";
    case ForceMode::reaction: return "reaction";
  }
  return "?";
}

ForceMode parse_force_mode(std::string_view name) {
  for (ForceMode m : {ForceMode::guidance, ForceMode::mixed, ForceMode::reaction})
    if (mode_name(m) == name) return m;
  throw UsageError("unknown force mode '" + std::string(name) + "'", "modes: guidance, mixed, reaction");
}

Eigen::Vector3d clamp_force(const Eigen::Vector3d& F, double limit) noexcept {
  if (!F.allFinite() || !(limit > 0.0)) return Eigen::Vector3d::Zero();
  const double m = F.norm();
  if (m > limit) return F * (limit / m);
  return F;
}

Eigen::Vector3d mix_forces(const Eigen::Vector3d& G, const Eigen::Vector3d& R, ForceMode mode, double limit) noexcept {
  const ForceWeights w = weights(mode);
  // A term with zero weight never contributes, even when it is not finite.
  Eigen::Vector3d F = Eigen::Vector3d::Zero();
  if (w.guidance != 0.0) F += w.guidance * G;
  if (w.reaction != 0.0) F += w.reaction * R;
  return clamp_force(F, limit);
}

// ---- scripted device -----------------------------------------------------------------------------

ScriptedDevice::ScriptedDevice(std::vector<double> t, std::vector<Eigen::Vector3d> p, const fs::path& source)
    : t_(std::move(t)), p_(std::move(p)) {
  auto bad = [&](const std::string& what) {
    return InputError(ExitCode::unsupported_input, what, source,
                      "a trajectory is CSV t_s,x,y,z (seconds, LPS mm) with strictly increasing time");
  };
  if (t_.size() != p_.size()) throw bad("times and positions differ in number");
  if (t_.size() < 2) throw bad("the trajectory has " + std::to_string(t_.size()) + " sample(s); at least 2 are needed");
  for (std::size_t i = 0; i < t_.size(); ++i) {
    if (!std::isfinite(t_[i]) || !p_[i].allFinite()) throw bad("sample " + std::to_string(i) + " is not finite");
    if (i > 0 && !(t_[i] > t_[i - 1]))
      throw bad("time does not increase at sample " + std::to_string(i) + " (" + std::to_string(t_[i - 1]) + " s, then " +
                std::to_string(t_[i]) + " s)");
  }
  // The replay keeps a record per 1 kHz tick: an hour is 3.6 million of them (~100 MB).
  if (duration_s() > kMaxTrajectorySpanS)
    throw bad("the trajectory spans " + std::to_string(duration_s()) + " s, more than the limit of " +
              std::to_string(int(kMaxTrajectorySpanS)) + " s (one hour)");
}

ScriptedDevice ScriptedDevice::read_csv(const fs::path& path) {
  const std::string hint = "a trajectory is CSV with header t_s,x,y,z (seconds, LPS mm), time strictly increasing";
  const std::string text = read_input_file(path, "the trajectory file", ExitCode::unsupported_input, hint);
  auto bad = [&](int line, const std::string& what) {
    return InputError(ExitCode::unsupported_input, "line " + std::to_string(line) + ": " + what, path, hint);
  };
  std::vector<CsvRow> rows;
  try {
    rows = parse_csv_rows(text, path, ExitCode::unsupported_input);
  } catch (const Error& e) {
    throw InputError(e.code(), e.message(), path, hint);
  }
  if (rows.empty()) throw InputError(ExitCode::unsupported_input, "the trajectory file is empty", path, hint);
  lowercase_fields(rows.front());
  const std::vector<std::string>& header = rows.front().fields;
  std::array<int, 4> col{-1, -1, -1, -1};
  for (std::size_t c = 0; c < header.size(); ++c) {
    const std::string& n = header[c];
    if (n == "t_s" || n == "t" || n == "time_s") col[0] = int(c);
    for (int a = 0; a < 3; ++a) {
      const std::string base(1, "xyz"[a]);
      if (n == base || n == base + "_mm" || n == base + "_lps_mm") col[std::size_t(a + 1)] = int(c);
    }
  }
  if (*std::min_element(col.begin(), col.end()) < 0) throw bad(rows.front().line, "the header must name t_s, x, y and z");
  std::vector<double> t;
  std::vector<Eigen::Vector3d> p;
  for (std::size_t r = 1; r < rows.size(); ++r) {
    const int lineno = rows[r].line;
    const std::vector<std::string>& f = rows[r].fields;
    if (f.size() != header.size())
      throw bad(lineno, std::to_string(f.size()) + " fields where the header has " + std::to_string(header.size()));
    double v[4];
    for (int k = 0; k < 4; ++k) {
      const std::string& s = f[std::size_t(col[std::size_t(k)])];
      const std::optional<double> parsed = csv_number(s);
      if (!parsed || !std::isfinite(*parsed))
        throw bad(lineno, "'" + s + "' is not a finite number (column " + std::string(k == 0 ? "t_s" : std::string(1, "xyz"[k - 1])) + ")");
      v[k] = *parsed;
    }
    if (!t.empty() && !(v[0] > t.back()))
      throw bad(lineno, "time " + f[std::size_t(col[0])] + " s does not increase (previous " + std::to_string(t.back()) + " s)");
    t.push_back(v[0]);
    p.emplace_back(v[1], v[2], v[3]);
  }
  if (t.size() < 2)
    throw InputError(ExitCode::unsupported_input, "the trajectory has fewer than 2 samples", path,
                     "a trajectory is CSV with header t_s,x,y,z (seconds, LPS mm)");
  return ScriptedDevice(std::move(t), std::move(p), path);
}

Eigen::Vector3d ScriptedDevice::position_lps_mm(double t) noexcept {
  if (!(t > t_.front())) return p_.front();
  if (t >= t_.back()) return p_.back();
  if (cursor_ + 1 >= t_.size() || t < t_[cursor_]) cursor_ = 0;
  while (cursor_ + 2 < t_.size() && t >= t_[cursor_ + 1]) ++cursor_;
  const double f = (t - t_[cursor_]) / (t_[cursor_ + 1] - t_[cursor_]);
  return p_[cursor_] + f * (p_[cursor_ + 1] - p_[cursor_]);
}

// ---- loop ----------------------------------------------------------------------------------------

void validate(const LoopOptions& o) {
  validate(o.guidance);
  auto positive = [](double v) { return v > 0.0 && std::isfinite(v); };
  if (!positive(o.rate_Hz) || o.rate_Hz > 100000) throw UsageError("the loop rate must be in (0, 100000] Hz");
  if (!positive(o.force_limit_N)) throw UsageError("the force limit must be positive (N)");
  if (!(o.hand_stiffness_N_per_mm >= 0) || !std::isfinite(o.hand_stiffness_N_per_mm))
    throw UsageError("the hand stiffness must be non-negative (N/mm)");
  if (!(o.step_mm_per_N >= 0) || !std::isfinite(o.step_mm_per_N)) throw UsageError("the descent step α must be non-negative (mm/N)");
  if (!positive(o.max_step_mm)) throw UsageError("the largest tool step must be positive (mm)");
  if (o.timing_capacity < 1) throw UsageError("the timing capacity must be at least 1 tick");
  if (!(o.spin_us >= 0) || o.spin_us * 1e-6 * o.rate_Hz > 0.5)
    throw UsageError("the spin before each tick must be non-negative and at most half a period (µs)");
}

HapticLoop::HapticLoop(HapticDevice& device, const PathIndex* path, const ContactModel* contact, const LoopOptions& options)
    : device_(device), path_(path), contact_(contact), options_(options), mode_(int(options.mode)) {
  validate(options_);
  compute_us_.assign(options_.timing_capacity, 0.f);
  jitter_us_.assign(options_.timing_capacity, 0.f);
  trace_.resize(options_.trace_capacity);
}

HapticLoop::~HapticLoop() { stop(); }

HapticState HapticLoop::tick(double t_s) noexcept {
  const ForceMode mode = this->mode();
  const ForceWeights w = weights(mode);
  HapticState s;
  s.tick = tick_count_++;
  s.time_s = t_s;
  s.mode = int(mode);
  Eigen::Vector3d p = device_.position_lps_mm(t_s);
  if (!p.allFinite()) {
    faults_.fetch_add(1, std::memory_order_relaxed);
    p = have_tool_ ? tool_ : Eigen::Vector3d::Zero();
  }
  const bool simulated = !device_.renders_force();
  if (!have_tool_ || !simulated) tool_ = p, have_tool_ = true;
  const Eigen::Vector3d q = tool_;
  Eigen::Vector3d G = Eigen::Vector3d::Zero(), R = Eigen::Vector3d::Zero();
  if (path_) {
    const GuidanceSample g = guidance_force(*path_, q, options_.guidance);
    G = g.force_N;
    s.has_path = true;
    s.distance_mm = g.goal.distance_mm;
    s.band = g.band;
    s.goal_lps_mm = to_vec3(g.goal.point_lps_mm);
  }
  if (contact_) {
    const ContactSample c = contact_->evaluate(q);
    R = c.force_N;
    s.contact = c.contact;
    s.contact_surface = c.surface;
    s.penetration_mm = c.penetration_mm;
    s.contact_point_lps_mm = to_vec3(c.point_lps_mm);
    s.contact_normal = to_vec3(c.normal);
  }
  if (source_) {
    const Eigen::Vector3d Rs = source_->reaction_N(q);
    if (Rs.squaredNorm() > 0) {
      R += Rs;
      if (!s.contact) s.contact_surface = -1, s.contact_normal = to_vec3(Rs.normalized());
      s.contact = true;
    }
  }
  const Eigen::Vector3d raw = w.guidance * G + w.reaction * R;
  if (!raw.allFinite()) faults_.fetch_add(1, std::memory_order_relaxed);
  const Eigen::Vector3d F = mix_forces(G, R, mode, options_.force_limit_N);
  device_.command_force(F);
  if (simulated) {
    // Gradient descent (5.2.6–5.2.8) on w1 U + ½ k |q − p|² + the reaction's work: the displayed
    // tool moves by α times the net force on it, limited per tick.
    Eigen::Vector3d step = options_.step_mm_per_N * (F + options_.hand_stiffness_N_per_mm * (p - q));
    const double len = step.norm();
    if (!std::isfinite(len)) step.setZero();
    else if (len > options_.max_step_mm) step *= options_.max_step_mm / len;
    tool_ = q + step;
  }
  s.device_lps_mm = to_vec3(p);
  s.tool_lps_mm = to_vec3(q);
  s.force_N = to_vec3(F);
  s.guidance_N = to_vec3(G.allFinite() ? G : Eigen::Vector3d::Zero());
  s.reaction_N = to_vec3(R.allFinite() ? R : Eigen::Vector3d::Zero());
  s.measured_rate_Hz = rate_Hz_.load(std::memory_order_relaxed);
  const std::size_t ti = trace_size_.load(std::memory_order_relaxed);
  if (ti < trace_.size()) {
    TraceSample& t = trace_[ti];
    t.t_s = t_s;
    t.device_lps_mm = s.device_lps_mm;
    t.tool_lps_mm = s.tool_lps_mm;
    t.force_N = s.force_N;
    t.distance_mm = s.distance_mm;
    t.guidance_N = G.allFinite() ? G.norm() : 0.0;
    t.reaction_N = R.allFinite() ? R.norm() : 0.0;
    t.band = s.band;
    t.contact = s.contact;
    trace_size_.store(ti + 1, std::memory_order_release);
  }
  state_.write(s);
  return s;
}

void HapticLoop::start() {
  if (running()) throw UsageError("the haptic loop is already running");
  if (thread_.joinable()) thread_.join();
  stop_requested_.store(false);
  ticks_.store(0);
  overruns_.store(0);
  faults_.store(0);
  elapsed_s_.store(0.0);
  rate_Hz_.store(0.0);
  trace_size_.store(0);
  tick_count_ = 0;
  have_tool_ = false;
  running_.store(true, std::memory_order_release);
  thread_ = std::thread([this] { run(); });
}

void HapticLoop::stop() {
  stop_requested_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
  running_.store(false, std::memory_order_release);
}

bool HapticLoop::wait(double timeout_s) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (running() && std::chrono::steady_clock::now() < until) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  if (!running() && thread_.joinable()) thread_.join();
  return !running();
}

void HapticLoop::run() noexcept {
#if defined(__linux__)
  // The default 50 µs timer slack would show up as jitter; ask for the finest wake-ups.
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
  // A real-time priority keeps compiles and renders from delaying the tick (the thread sleeps
  // > 95 % of the time, so it cannot starve the machine). Refused without the privilege: then
  // the loop runs at normal priority and says so in its statistics.
  if (options_.realtime_priority) {
    sched_param sp{};
    sp.sched_priority = 20;
    realtime_.store(pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0);
  }
#endif
  using clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<clock::duration>(std::chrono::duration<double>(1.0 / options_.rate_Hz));
  const auto start = clock::now();
  auto next = start;
  clock::time_point first_wake{}, last_wake{};
  std::uint64_t n = 0;
  const std::size_t cap = compute_us_.size();
  const auto spin = std::chrono::duration_cast<clock::duration>(std::chrono::duration<double, std::micro>(options_.spin_us));
  while (!stop_requested_.load(std::memory_order_acquire)) {
    std::this_thread::sleep_until(next - spin);
    while (clock::now() < next) {
    }
    const auto wake = clock::now();
    const double t_s = std::chrono::duration<double>(wake - start).count();
    if (device_.finished(t_s)) break;
    tick(t_s);
    const auto done = clock::now();
    if (n == 0) first_wake = wake;
    last_wake = wake;
    compute_us_[n % cap] = float(std::chrono::duration<double, std::micro>(done - wake).count());
    jitter_us_[n % cap] = float(std::abs(std::chrono::duration<double, std::micro>(wake - next).count()));
    ++n;
    ticks_.store(n, std::memory_order_relaxed);
    const double span = std::chrono::duration<double>(last_wake - first_wake).count();
    elapsed_s_.store(std::chrono::duration<double>(done - start).count(), std::memory_order_relaxed);
    if (span > 0) rate_Hz_.store(double(n - 1) / span, std::memory_order_relaxed);
    next += period;
    if (done > next + period) {  // more than a period behind: re-base rather than burst
      overruns_.fetch_add(1, std::memory_order_relaxed);
      next = done + period;
    }
  }
  running_.store(false, std::memory_order_release);
}

namespace {
Percentiles percentiles(std::vector<float> v) {
  Percentiles p;
  if (v.empty()) return p;
  auto at = [&](double q) {
    const std::size_t k = std::min(v.size() - 1, std::size_t(std::ceil(q * double(v.size()))) - (q > 0 ? 1 : 0));
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
    return double(v[k]);
  };
  p.p50 = at(0.5);
  p.p99 = at(0.99);
  p.p999 = at(0.999);
  p.max = double(*std::max_element(v.begin(), v.end()));
  return p;
}
}  // namespace

LoopStats HapticLoop::stats() const {
  LoopStats s;
  s.ticks = ticks_.load();
  s.overruns = overruns_.load();
  s.faults = faults_.load();
  s.elapsed_s = elapsed_s_.load();
  s.rate_Hz = rate_Hz_.load();
  s.realtime_priority = realtime_.load();
  if (running() || s.ticks == 0) return s;
  const std::size_t n = std::min<std::size_t>(s.ticks, compute_us_.size());
  s.compute_us = percentiles(std::vector<float>(compute_us_.begin(), compute_us_.begin() + std::ptrdiff_t(n)));
  s.jitter_us = percentiles(std::vector<float>(jitter_us_.begin(), jitter_us_.begin() + std::ptrdiff_t(n)));
  return s;
}

std::vector<TraceSample> HapticLoop::trace() const {
  const std::size_t n = trace_size_.load(std::memory_order_acquire);
  return std::vector<TraceSample>(trace_.begin(), trace_.begin() + std::ptrdiff_t(n));
}

}  // namespace organsmith::physics
