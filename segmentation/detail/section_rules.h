#pragma once
// The rules that end a seeded organ's slice-by-slice propagation (internal; not installed): a
// slice's section continues the organ unless one of them says why not. Each rule has its reason
// in the comments of section_rules.cpp, its parameters in the organ's preset (data/organs.toml,
// [<organ>.segment]) and a test (tests/segmentation/test_section_rules.cpp).

#include "segmentation/presets.h"
#include "segmentation/snake.h"

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace organsmith::seg {

/// Fraction of the area inside contour `a` that lies farther than `tol_mm` outside contour `b`
/// (both in slice mm, on pixels of sx × sy mm): how much of a new section is not a continuation
/// of the previous one.
double area_outside(const std::vector<Point2>& a, const std::vector<Point2>& b, double tol_mm, double sx, double sy);

/// The part of section `a` within `tol_mm` of section `b` (its largest piece, as a contour of
/// boundary-pixel centres in slice mm), and that part's area in mm²; empty where none.
std::pair<std::vector<Point2>, double> part_within(const std::vector<Point2>& a, const std::vector<Point2>& b, double tol_mm,
                                                   double sx, double sy);

/// Why a section does not continue the organ, in the order the rules are tested.
enum class SectionStop {
  none,                  ///< it continues the organ
  collapsed,             ///< area below min_area_mm2
  area_jumped,           ///< area past max_area_mm2, or max_area_ratio × the previous or earlier section (leak)
  grew_off_previous,     ///< grew (shift_growth_ratio) with much of it off the previous section (leak)
  drifted_off_previous,  ///< did not grow but lies mostly off the previous section moved by the drift (leak)
  grew_off_unaided,      ///< after held slices: grew off the last section found unaided (leak)
  edge_support_lost,     ///< no wall around most of it, and the 3-D region ends here too
  intensity_drifted,     ///< its median left the organ's mean by more than max_mean_drift_hu
};

/// True for the stops that are a leak into a neighbour (a held refit may continue the organ).
bool is_leak(SectionStop stop);

/// The note the organ keeps: "stopped at slice <k>: <reason>".
std::string stop_note(SectionStop stop, std::int64_t k);

/// A candidate section of slice k.
struct Section {
  const std::vector<Point2>* pts = nullptr;  ///< slice mm
  double area_mm2 = 0;
  double edge_support = 1;                   ///< fraction of the contour with a visible wall outside it
};

/// What a section is compared with: the slices behind it.
struct SectionHistory {
  const std::vector<Point2>* previous = nullptr;        ///< the previous section
  double previous_area_mm2 = 0;
  double earlier_area_mm2 = 0;                          ///< the section area_ratio_span_mm behind (thin slices)
  const std::vector<Point2>* previous_moved = nullptr;  ///< the previous section moved by the organ's drift
  /// After held slices: the last section found unaided (empty = no slice held just before).
  const std::vector<Point2>* unaided = nullptr;
  double unaided_area_mm2 = 0;
  double region_area_mm2 = 0;  ///< area of the organ's 3-D region under the previous section on this slice
  double organ_mean_hu = 0;    ///< the organ's mean (the centre of its window)
  double sx = 1, sy = 1;       ///< pixel size, mm
};

/// The first rule that ends the organ at `section`, or SectionStop::none. `median_hu` gives the
/// section's median HU (asked for only when every geometric rule passes).
SectionStop judge_section(const Section& section, const SectionHistory& history, const OrganPreset& p,
                          const std::function<double()>& median_hu);

}  // namespace organsmith::seg
