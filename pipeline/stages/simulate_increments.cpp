// A solver step increment by increment: every converged increment's displacement (.frd) and
// the printed RF totals (.dat), and from them the indentation curve and the pressure at which a
// region reaches the top of its calibrated range (see simulate.h).

#include "pipeline/stages/simulate.h"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

namespace organsmith {
namespace fs = std::filesystem;

std::vector<SolverIncrement> read_frd_increments(const fs::path& path, std::size_t node_count) {
  std::ifstream in(path);
  if (!in) throw SimulationError(ExitCode::solver_failed, "the solver wrote no result file", path);
  std::vector<SolverIncrement> out;
  std::string line;
  double block_time = 0.0;
  bool disp = false, open_block = false;  // open_block: a DISP block not yet closed by " -3"
  auto field = [&](std::size_t col) { return std::strtod(line.substr(col, 12).c_str(), nullptr); };
  while (std::getline(in, line)) {
    if (line.rfind("  100CL", 0) == 0) {
      block_time = std::strtod(line.substr(12, 12).c_str(), nullptr);
      continue;
    }
    if (line.rfind(" -4", 0) == 0) {
      disp = line.size() >= 13 && line.substr(5, 8).find("DISP") != std::string::npos;
      if (disp) out.push_back({block_time, std::vector<std::array<double, 3>>(node_count, {0, 0, 0})});
      open_block = disp;
      continue;
    }
    if (line.rfind(" -3", 0) == 0) {
      disp = open_block = false;
      continue;
    }
    if (!disp || line.rfind(" -1", 0) != 0 || line.size() < 13 + 36) continue;
    const long id = std::strtol(line.substr(3, 10).c_str(), nullptr, 10) - 1;
    if (id < 0 || std::size_t(id) >= node_count) continue;
    for (int k = 0; k < 3; ++k) out.back().displacement_mm[std::size_t(id)][k] = field(13 + 12 * std::size_t(k));
  }
  // A block the solver was still writing (read while it runs, or cut by a kill) is not a result.
  if (open_block) out.pop_back();
  return out;
}

std::vector<std::pair<double, std::array<double, 3>>> read_dat_series(const fs::path& dat, const std::string& set) {
  std::ifstream in(dat);
  std::string line;
  std::vector<std::pair<double, std::array<double, 3>>> out;
  std::string want = "for set " + set;
  for (char& c : want) c = char(std::toupper(static_cast<unsigned char>(c)));
  while (std::getline(in, line)) {
    if (line.find("total force") == std::string::npos) continue;
    std::string up = line;
    for (char& c : up) c = char(std::toupper(static_cast<unsigned char>(c)));
    // "… for set NAME and time  0.5000000E-01": the set name must end where " AND TIME" begins
    const auto at = up.find(want + " AND TIME");
    if (at == std::string::npos) continue;
    const double time = std::strtod(line.substr(at + want.size() + 9).c_str(), nullptr);
    while (std::getline(in, line)) {
      std::stringstream ss(line);
      std::array<double, 3> f{};
      if (ss >> f[0] >> f[1] >> f[2]) {
        if (in.eof()) break;  // a line the solver was still writing (no newline yet)
        out.push_back({time, f});
        break;
      }
    }
  }
  return out;
}

std::map<std::string, std::pair<double, double>> region_stretches(const SolverInput& in,
                                                                  const std::vector<std::array<double, 3>>& u) {
  const SolverModel& m = in.model;
  std::map<std::string, std::vector<double>> stretches;
  for (std::size_t e = 0; e < m.elements.size(); ++e) {
    const std::string& region = m.region_names.at(m.region_ids[e]);
    if (std::find(in.inactive_regions.begin(), in.inactive_regions.end(), region) != in.inactive_regions.end()) continue;
    const auto& el = m.elements[e];
    Eigen::Matrix3d dX, dx;
    for (int k = 0; k < 3; ++k) {
      const auto a = std::size_t(el[std::size_t(k + 1)]), b = std::size_t(el[0]);
      dX.col(k) = m.nodes_lps_mm[a] - m.nodes_lps_mm[b];
      dx.col(k) = dX.col(k) + Eigen::Vector3d(u[a][0] - u[b][0], u[a][1] - u[b][1], u[a][2] - u[b][2]);
    }
    if (std::abs(dX.determinant()) < 1e-12) continue;
    const Eigen::Matrix3d F = dx * dX.inverse();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(F.transpose() * F, Eigen::EigenvaluesOnly);
    stretches[region].push_back(std::sqrt(std::max(0.0, eig.eigenvalues()(2))));
  }
  std::map<std::string, std::pair<double, double>> out;
  for (auto& [region, v] : stretches) {
    std::sort(v.begin(), v.end());
    out[region] = {v.back(), v[std::size_t(0.99 * double(v.size() - 1))]};
  }
  return out;
}

namespace {

/// The first point along increments (time, p99 per region) where a region's p99 reaches its
/// range: the interpolated time and the region; time < 0 when none does.
std::pair<double, std::string> range_crossing(const SolverInput& in, const std::vector<SolverIncrement>& incs,
                                              const std::map<std::string, double>& range) {
  double t_prev = 0.0;
  std::map<std::string, double> prev;  // p99 at the previous increment (1 at rest)
  for (const auto& inc : incs) {
    const auto st = region_stretches(in, inc.displacement_mm);
    double best_t = -1;
    std::string best;
    for (const auto& [region, mx_p99] : st) {
      const auto r = range.find(region);
      if (r == range.end() || !(r->second > 1.0) || mx_p99.second < r->second) continue;
      const double before = prev.count(region) ? prev[region] : 1.0;
      const double f = mx_p99.second > before ? (r->second - before) / (mx_p99.second - before) : 1.0;
      const double t = t_prev + std::clamp(f, 0.0, 1.0) * (inc.time - t_prev);
      if (best_t < 0 || t < best_t) best_t = t, best = region;
    }
    if (best_t >= 0) return {best_t, best};
    for (const auto& [region, mx_p99] : st) prev[region] = mx_p99.second;
    t_prev = inc.time;
  }
  return {-1.0, {}};
}

}  // namespace

double indentation_range_time(const SolverInput& in, const fs::path& frd, const fs::path& dat,
                              const std::map<std::string, double>& range) {
  if (!in.indentation() || range.empty() || !fs::exists(frd) || !fs::exists(dat)) return -1.0;
  const auto incs = read_frd_increments(frd, in.model.nodes_lps_mm.size());
  const double t = range_crossing(in, incs, range).first;
  if (t < 0) return -1.0;
  // The curve interpolates the force between the increments around the crossing: both files
  // must hold the one after it (the .dat is written behind the .frd).
  const auto probe = read_dat_series(dat, in.probe_node_set), fixed = read_dat_series(dat, in.fixed_node_set);
  const bool printed = !probe.empty() && !fixed.empty() && probe.back().first >= t - 1e-12 && fixed.back().first >= t - 1e-12;
  return printed ? t : -1.0;
}

IndentationResult evaluate_indentation(const SolverInput& in, const std::vector<SolverIncrement>& incs,
                                       const std::vector<std::pair<double, std::array<double, 3>>>& probe_rf,
                                       const std::vector<std::pair<double, std::array<double, 3>>>& fixed_rf,
                                       const std::map<std::string, double>& range) {
  IndentationResult r;
  r.probe = in.probe;
  r.step_depth_mm = in.probe_depth_mm;
  const Eigen::Vector3d d = in.probe.direction_lps.normalized();
  const double flip = in.ras ? -1.0 : 1.0;  // RF printed in the file's frame
  auto along = [&](const std::array<double, 3>& f) { return flip * f[0] * d.x() + flip * f[1] * d.y() + f[2] * d.z(); };
  const auto [t_range, region] = range_crossing(in, incs, range);
  const double t_end = t_range >= 0 ? t_range : (probe_rf.empty() ? 0.0 : probe_rf.back().first);
  r.range_region = region;
  if (!region.empty()) r.range_stretch = range.at(region);
  r.curve.push_back({0.0, 0.0});
  double t_prev = 0.0, f_prev = 0.0;
  for (const auto& [t, f] : probe_rf) {
    const double force = along(f);
    if (t > t_end + 1e-12) {  // the range is reached inside this increment: interpolate
      if (t_end > t_prev) r.curve.push_back({t_end * in.probe_depth_mm, f_prev + (force - f_prev) * (t_end - t_prev) / (t - t_prev)});
      break;
    }
    r.curve.push_back({t * in.probe_depth_mm, force});
    t_prev = t, f_prev = force;
  }
  r.range_depth_mm = r.curve.back()[0];
  // dF/dδ at 1 mm: the slope of the segment holding it.
  r.stiffness_N_per_mm_at_1mm = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 1; i < r.curve.size(); ++i)
    if (r.curve[i - 1][0] <= 1.0 && r.curve[i][0] >= 1.0 && r.curve[i][0] > r.curve[i - 1][0]) {
      r.stiffness_N_per_mm_at_1mm = (r.curve[i][1] - r.curve[i - 1][1]) / (r.curve[i][0] - r.curve[i - 1][0]);
      break;
    }
  // Balance at the deepest increment both sets printed.
  if (!probe_rf.empty() && !fixed_rf.empty()) {
    const auto& [tp, fp] = probe_rf.back();
    for (const auto& [tf, ff] : fixed_rf)
      if (std::abs(tf - tp) < 1e-9) {
        r.probe_force_N = along(fp);
        r.fixed_reaction_N = along(ff);
        const Eigen::Vector3d a(fp[0] + ff[0], fp[1] + ff[1], fp[2] + ff[2]);
        const double mag = std::hypot(fp[0], fp[1], fp[2]);
        r.balance_error = mag > 0 ? a.norm() / mag : 0.0;
      }
  }
  return r;
}

PressureRange evaluate_pressure_range(const SolverInput& in, const std::vector<SolverIncrement>& incs,
                                      const std::map<std::string, double>& range) {
  PressureRange p;
  const auto [t, region] = range_crossing(in, incs, range);
  if (t >= 0) {
    p.in_range_pressure_kPa = t * in.pressure_MPa * 1e3;
    p.region = region;
  }
  return p;
}

nlohmann::json IndentationResult::to_json() const {
  nlohmann::json c = nlohmann::json::array();
  for (const auto& [depth, force] : curve) c.push_back({depth, force});
  nlohmann::json j = {{"probe_diameter_mm", probe.diameter_mm},
                      {"probe_lps_mm", {probe.point_lps_mm.x(), probe.point_lps_mm.y(), probe.point_lps_mm.z()}},
                      {"direction", {probe.direction_lps.x(), probe.direction_lps.y(), probe.direction_lps.z()}},
                      {"contact_area_mm2", probe.contact_area_mm2},
                      {"organ_thickness_mm", probe.thickness_mm},
                      {"step_depth_mm", step_depth_mm},
                      {"depth_mm", range_depth_mm},
                      {"limited_by", range_region.empty() ? "the step's depth (no region reached its calibrated range)"
                                                          : range_region + " reached its calibrated stretch " +
                                                                std::to_string(range_stretch).substr(0, 4)},
                      {"curve", c},
                      {"probe_force_N", probe_force_N},
                      {"fixed_reaction_N", fixed_reaction_N},
                      {"reaction_balance_error", balance_error}};
  j["stiffness_N_per_mm_at_1mm"] = std::isfinite(stiffness_N_per_mm_at_1mm) ? nlohmann::json(stiffness_N_per_mm_at_1mm) : nlohmann::json();
  if (probe.requested_offset_mm > 0) j["probe_offset_from_request_mm"] = probe.requested_offset_mm;
  if (!thesis_curve.empty()) {
    nlohmann::json t = nlohmann::json::array();
    for (const auto& [depth, force] : thesis_curve) t.push_back({depth, force});
    j["thesis_law_curve"] = {{"curve", t}, {"source", thesis_source}};
  }
  return j;
}

}  // namespace organsmith
