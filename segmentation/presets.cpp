#include "segmentation/presets.h"

#include "core/errors.h"
#include "core/toml_parse.h"
#include "organs_toml.h"

#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <set>
#include <string>

namespace organsmith {

std::string_view default_organ_presets_toml() { return kOrgansToml; }

namespace {

using Seen = std::set<std::string, std::less<>>;

void get(const toml::table& t, const std::string& organ, Seen& seen, const char* key, double& v) {
  seen.insert(key);
  const toml::node* n = t.get(key);
  if (!n) return;
  const auto d = n->value<double>();
  if (!d) throw CaseFileError("organ preset '" + organ + "." + key + "' must be a number", {});
  if (!std::isfinite(*d))  // a NaN or infinite preset would reach the snake's arithmetic
    throw CaseFileError("organ preset '" + organ + "." + key + "' must be a finite number", {});
  v = *d;
}
void get(const toml::table& t, const std::string& organ, Seen& seen, const char* key, int& v) {
  double d = v;
  get(t, organ, seen, key, d);
  v = int(d);
}
void get(const toml::table& t, const std::string& organ, Seen& seen, const char* key, bool& v) {
  seen.insert(key);
  const toml::node* n = t.get(key);
  if (!n) return;
  if (auto b = n->value<bool>()) v = *b;
  else throw CaseFileError("organ preset '" + organ + "." + key + "' must be true or false", {});
}
void get_choice(const toml::table& t, const std::string& organ, Seen& seen, const char* key, std::string& v,
                std::initializer_list<const char*> allowed) {
  seen.insert(key);
  const toml::node* n = t.get(key);
  if (!n) return;
  std::string list;
  for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string("\"") + a + "\"";
  const auto s = n->value<std::string>();
  if (!s || std::none_of(allowed.begin(), allowed.end(), [&](const char* a) { return *s == a; }))
    throw CaseFileError("organ preset '" + organ + "." + key + "' must be one of " + list, {});
  v = *s;
}
void get_range(const toml::table& t, const std::string& organ, Seen& seen, const char* key, double& lo, double& hi) {
  seen.insert(key);
  const toml::node* n = t.get(key);
  if (!n) return;
  const toml::array* a = n->as_array();
  if (!a || a->size() != 2 || !(*a)[0].value<double>() || !(*a)[1].value<double>() ||
      *(*a)[0].value<double>() > *(*a)[1].value<double>())
    throw CaseFileError("organ preset '" + organ + "." + key + "' must be [low, high]", {});
  lo = *(*a)[0].value<double>();
  hi = *(*a)[1].value<double>();
}

void read_keys(const toml::table& t, const std::string& organ, Seen& seen, OrganPreset& p) {
  get_choice(t, organ, seen, "driver", p.driver, {"seeded", "airway"});
  get_range(t, organ, seen, "seed_hu_range", p.seed_hu_lo, p.seed_hu_hi);
  get(t, organ, seen, "seed_radius_mm", p.seed_radius_mm);
  get(t, organ, seen, "region_below_hu", p.region_below_hu);
  get(t, organ, seen, "region_above_hu", p.region_above_hu);
  get(t, organ, seen, "air_hu", p.air_hu);
  get(t, organ, seen, "pressure_ramp_hu", p.pressure_ramp_hu);
  get(t, organ, seen, "region_sigma_mm", p.region_sigma_mm);
  get(t, organ, seen, "region_sigma_px", p.region_sigma_px);
  get(t, organ, seen, "region_noise_hu", p.region_noise_hu);
  get(t, organ, seen, "region_noise_max_sigma_mm", p.region_noise_max_sigma_mm);
  get(t, organ, seen, "region_open_mm", p.region_open_mm);
  get(t, organ, seen, "region_open_fraction", p.region_open_fraction);
  get_range(t, organ, seen, "edge_window_hu", p.edge_window_lo_hu, p.edge_window_hi_hu);
  get(t, organ, seen, "edge_sigma_mm", p.edge_sigma_mm);
  get(t, organ, seen, "edge_stop", p.edge_stop);
  get(t, organ, seen, "neck_ratio", p.neck_ratio);
  get(t, organ, seen, "neck_depth_mm", p.neck_depth_mm);
  get(t, organ, seen, "seat_band_mm", p.seat_band_mm);
  get(t, organ, seen, "seat_sigma_mm", p.seat_sigma_mm);
  get(t, organ, seen, "seat_outside_mm", p.seat_outside_mm);
  get(t, organ, seen, "seat_min_contrast_hu", p.seat_min_contrast_hu);
  get(t, organ, seen, "min_edge_support", p.min_edge_support);
  get(t, organ, seen, "min_area_mm2", p.min_area_mm2);
  get(t, organ, seen, "max_area_mm2", p.max_area_mm2);
  get(t, organ, seen, "max_area_ratio", p.max_area_ratio);
  get(t, organ, seen, "seed_slide_mm", p.seed_slide_mm);
  get(t, organ, seen, "min_extent_mm", p.min_extent_mm);
  get(t, organ, seen, "divide_span_mm", p.divide_span_mm);
  get(t, organ, seen, "divide_neck_slice_fraction", p.divide_neck_slice_fraction);
  get(t, organ, seen, "shift_growth_ratio", p.shift_growth_ratio);
  get(t, organ, seen, "max_shifted_fraction", p.max_shifted_fraction);
  get(t, organ, seen, "shift_tolerance_mm", p.shift_tolerance_mm);
  get(t, organ, seen, "guide_core_fraction", p.guide_core_fraction);
  get(t, organ, seen, "area_ratio_span_mm", p.area_ratio_span_mm);
  get(t, organ, seen, "max_mean_drift_hu", p.max_mean_drift_hu);
  get(t, organ, seen, "min_fill", p.min_fill);
  get(t, organ, seen, "max_aspect", p.max_aspect);
  get(t, organ, seen, "max_midline_offset_mm", p.max_midline_offset_mm);
  get(t, organ, seen, "min_length_mm", p.min_length_mm);
  get(t, organ, seen, "start_radius_mm", p.start_radius_mm);
  get(t, organ, seen, "roi_margin_mm", p.roi_margin_mm);
  get(t, organ, seen, "max_length_mm", p.max_length_mm);
  get(t, organ, seen, "region_reach_mm", p.region_reach_mm);
  get(t, organ, seen, "continuity_margin_mm", p.continuity_margin_mm);
  get(t, organ, seen, "continuity_slope", p.continuity_slope);
  get(t, organ, seen, "max_held_in_a_row", p.max_held_in_a_row);
  get(t, organ, seen, "max_pinned_fraction", p.max_pinned_fraction);
  get(t, organ, seen, "max_pinned_fraction_walled", p.max_pinned_fraction_walled);
  get(t, organ, seen, "min_walled_edge_support", p.min_walled_edge_support);
  get(t, organ, seen, "alpha", p.alpha);
  get(t, organ, seen, "beta", p.beta);
  get(t, organ, seen, "kappa", p.kappa);
  get(t, organ, seen, "balloon", p.balloon);
  get(t, organ, seen, "point_spacing_mm", p.point_spacing_mm);
  get(t, organ, seen, "gvf_mu", p.gvf_mu);
  get(t, organ, seen, "max_iterations", p.max_iterations);
  get(t, organ, seen, "surface3d", p.surface3d);
  get(t, organ, seen, "surface3d_max_grow_mm", p.surface3d_max_grow_mm);
  get(t, organ, seen, "surface3d_curvature_mm", p.surface3d_curvature_mm);
  get(t, organ, seen, "surface3d_gvf_weight", p.surface3d_gvf_weight);
  get(t, organ, seen, "surface3d_edge_stop_hu_per_mm", p.surface3d_edge_stop_hu_per_mm);
  get(t, organ, seen, "surface3d_max_steps", p.surface3d_max_steps);
  get(t, organ, seen, "surface3d_local_radius_mm", p.surface3d_local_radius_mm);
  get(t, organ, seen, "surface3d_min_contrast_hu", p.surface3d_min_contrast_hu);
  get(t, organ, seen, "surface3d_contrast_curvature_hu", p.surface3d_contrast_curvature_hu);
  get(t, organ, seen, "surface3d_open_start_mm", p.surface3d_open_start_mm);
}

void check(const OrganPreset& p, const std::string& organ) {
  if (p.point_spacing_mm <= 0 || p.gvf_mu <= 0 || p.max_iterations < 1 || p.pressure_ramp_hu <= 0)
    throw CaseFileError("organ preset '" + organ + "': point_spacing_mm, gvf_mu, pressure_ramp_hu and max_iterations must be positive", {});
  if (!(p.surface3d_max_grow_mm >= 0 && p.surface3d_max_grow_mm <= 200) || !(p.surface3d_curvature_mm >= 0 && p.surface3d_curvature_mm <= 20) ||
      !(p.surface3d_gvf_weight >= 0 && p.surface3d_gvf_weight <= 10) || p.surface3d_max_steps < 1 || p.surface3d_max_steps > 100000 ||
      !(p.surface3d_edge_stop_hu_per_mm >= 0 && p.surface3d_edge_stop_hu_per_mm <= 1000) ||
      !(p.surface3d_local_radius_mm >= 0 && p.surface3d_local_radius_mm <= 50) ||
      !(p.surface3d_min_contrast_hu > 0 && p.surface3d_min_contrast_hu <= 1000) ||
      !(p.surface3d_contrast_curvature_hu >= 0 && p.surface3d_contrast_curvature_hu <= 1000) ||
      !(p.surface3d_open_start_mm >= 0 && p.surface3d_open_start_mm <= 50))
    throw CaseFileError("organ preset '" + organ + "': surface3d_max_grow_mm must be 0–200, surface3d_curvature_mm 0–20, "
                        "surface3d_gvf_weight 0–10, surface3d_edge_stop_hu_per_mm 0–1000, surface3d_max_steps 1–100000, "
                        "surface3d_local_radius_mm and surface3d_open_start_mm 0–50, "
                        "surface3d_min_contrast_hu above 0 and surface3d_contrast_curvature_hu 0–1000 (HU)", {});
}

void refuse_unknown(const toml::table& t, const std::string& organ, const Seen& seen) {
  // A misspelt key would otherwise fall back to the default without a word.
  for (auto&& [key, value] : t)
    if (!seen.count(key.str()))
      throw CaseFileError("unknown organ preset key '" + organ + "." + std::string(key.str()) + "'", {},
                          "`organsmith segment --print-presets` lists the keys");
}

/// `t` read over `p` as `name`'s preset keys (every key known, of its type, in range).
void read_preset(const toml::table& t, const std::string& name, OrganPreset& p) {
  Seen seen;
  read_keys(t, name, seen, p);
  check(p, name);
  refuse_unknown(t, name, seen);
}

/// The [segment_defaults] table of the registry text `root` read over `base`.
OrganPreset defaults_of(const toml::table& root, OrganPreset base) {
  const toml::node* n = root.get(kSegmentDefaultsTable);
  if (!n) return base;
  const toml::table* t = n->as_table();
  if (!t) throw CaseFileError("organ preset '" + std::string(kSegmentDefaultsTable) + "' must be a table", {});
  read_preset(*t, std::string(kSegmentDefaultsTable), base);
  return base;
}

}  // namespace

OrganPreset segment_defaults() {
  const toml::table root = parse_toml(kOrgansToml, {}, "the organ registry", "");
  OrganPreset p = defaults_of(root, OrganPreset{});
  p.organ.clear();
  return p;
}

std::map<std::string, OrganPreset> parse_organ_presets(std::string_view text, std::map<std::string, OrganPreset> base,
                                                       PresetText form) {
  const toml::table root = parse_toml(text, {}, "the organ presets", "the text must be TOML like `organsmith segment --print-presets`");
  // Where an organ new to `base` starts: the registry's defaults (a registry text's own table over
  // the embedded one).
  const OrganPreset defaults = form == PresetText::registry ? defaults_of(root, segment_defaults()) : segment_defaults();
  for (auto&& [k, node] : root) {
    const std::string organ(k.str());
    if (form == PresetText::registry && organ == kSegmentDefaultsTable) continue;
    const toml::table* entry = node.as_table();
    if (!entry) throw CaseFileError("organ preset '" + organ + "' must be a table", {});
    // Registry form: label and needs_seed on the organ, the preset in its `segment` table; an
    // organ without one is not segmented (its other keys belong to the registry).
    const toml::table* t = entry;
    if (form == PresetText::registry) {
      t = (*entry)["segment"].as_table();
      if (!t) continue;
    }
    auto it = base.find(organ);
    if (it == base.end()) it = base.emplace(organ, defaults).first;
    OrganPreset& p = it->second;
    p.organ = organ;
    Seen seen, organ_seen;
    int label = p.label;
    const toml::table& facts = form == PresetText::registry ? *entry : *t;
    Seen& facts_seen = form == PresetText::registry ? organ_seen : seen;
    get(facts, organ, facts_seen, "label", label);
    if (label < 1 || label > 255) throw CaseFileError("organ preset '" + organ + ".label' must be 1–255", {});
    p.label = std::uint8_t(label);
    get(facts, organ, facts_seen, "needs_seed", p.needs_seed);
    read_keys(*t, organ, seen, p);
    check(p, organ);
    refuse_unknown(*t, organ, seen);
  }
  return base;
}

std::map<std::string, OrganPreset> default_organ_presets() {
  return parse_organ_presets(kOrgansToml, {}, PresetText::registry);
}

}  // namespace organsmith
