// The rules that end a seeded organ's propagation (segmentation/detail/section_rules.h), one by
// one on drawn sections: each fires on the case it names and not on a section that continues the
// organ, in the order they are tested.

#include "segmentation/detail/section_rules.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace organsmith;
using namespace organsmith::seg;

namespace {

OrganPreset preset() {
  OrganPreset p = segment_defaults();
  p.min_area_mm2 = 15;
  p.max_area_mm2 = 2600;
  p.max_area_ratio = 1.8;
  p.shift_growth_ratio = 1.25;
  p.max_shifted_fraction = 0.35;
  p.shift_tolerance_mm = 3.0;
  p.continuity_margin_mm = 2.0;
  p.min_edge_support = 0.5;
  p.max_mean_drift_hu = 25;
  return p;
}

double disc_area(double r) { return M_PI * r * r; }

struct Case {
  std::vector<Point2> previous = circle({0, 0}, 10, 64), moved, unaided, pts;
  SectionHistory h;
  Section s;
  double median = 0;
  Case() {
    moved = previous;
    h.previous = &previous;
    h.previous_area_mm2 = h.earlier_area_mm2 = disc_area(10);
    h.previous_moved = &moved;
    h.unaided = &unaided;
    h.region_area_mm2 = disc_area(10);
    h.organ_mean_hu = 10;
    h.sx = h.sy = 0.7;
    section(circle({0, 0}, 9.5, 64), disc_area(9.5));
  }
  void section(std::vector<Point2> p, double area, double edge = 1.0) {
    pts = std::move(p);
    s = {&pts, area, edge};
  }
  SectionStop judge(const OrganPreset& p = preset()) const {
    return judge_section(s, h, p, [this] { return median; });
  }
};

}  // namespace

TEST(SectionRules, ASectionThatContinuesTheOrganPasses) {
  Case c;
  EXPECT_EQ(c.judge(), SectionStop::none);
}

TEST(SectionRules, EachRuleFiresOnItsCase) {
  {
    Case c;  // smaller than the organ's smallest section
    c.section(circle({0, 0}, 2, 32), disc_area(2));
    EXPECT_EQ(c.judge(), SectionStop::collapsed);
  }
  {
    Case c;  // twice the previous area: a leak
    c.section(circle({0, 0}, 14.5, 64), disc_area(14.5));
    EXPECT_EQ(c.judge(), SectionStop::area_jumped);
  }
  {
    Case c;  // under the ratio from the last slice, but past it from the slice a span behind
    c.h.earlier_area_mm2 = disc_area(7);
    EXPECT_EQ(c.judge(), SectionStop::area_jumped);
  }
  {
    Case c;  // 1.4× the area, centred 12 mm away: most of it off the previous section
    c.section(circle({12, 0}, 11.8, 64), disc_area(11.8));
    EXPECT_EQ(c.judge(), SectionStop::grew_off_previous);
  }
  {
    Case c;  // as large as the previous, but 20 mm off where the organ's drift moves it
    c.section(circle({20, 0}, 9.5, 64), disc_area(9.5));
    EXPECT_EQ(c.judge(), SectionStop::drifted_off_previous);
    OrganPreset p = preset();
    p.continuity_margin_mm = 0;  // the rule belongs to the continuity margin
    EXPECT_EQ(c.judge(p), SectionStop::none);
  }
  {
    Case c;  // after held slices: grown off the last section found unaided, on the previous one
    c.unaided = circle({-12, 0}, 6, 64);
    c.h.unaided_area_mm2 = disc_area(6);
    EXPECT_EQ(c.judge(), SectionStop::grew_off_unaided);
    c.unaided.clear();  // no slice held just before: no such test
    EXPECT_EQ(c.judge(), SectionStop::none);
  }
  {
    Case c;  // no wall around most of it, and the 3-D region ends here
    c.section(c.pts, c.s.area_mm2, 0.3);
    c.h.region_area_mm2 = 0;
    EXPECT_EQ(c.judge(), SectionStop::edge_support_lost);
    c.h.region_area_mm2 = disc_area(10);  // the region goes on: the organ does too
    EXPECT_EQ(c.judge(), SectionStop::none);
  }
  {
    Case c;  // its tissue is 40 HU off the organ's mean
    c.median = 50;
    EXPECT_EQ(c.judge(), SectionStop::intensity_drifted);
  }
}

TEST(SectionRules, LeaksAreTheGeometricStopsAndNotesNameTheSlice) {
  EXPECT_FALSE(is_leak(SectionStop::none));
  EXPECT_FALSE(is_leak(SectionStop::collapsed));
  EXPECT_TRUE(is_leak(SectionStop::area_jumped));
  EXPECT_TRUE(is_leak(SectionStop::grew_off_previous));
  EXPECT_TRUE(is_leak(SectionStop::drifted_off_previous));
  EXPECT_TRUE(is_leak(SectionStop::grew_off_unaided));
  EXPECT_FALSE(is_leak(SectionStop::edge_support_lost));
  EXPECT_FALSE(is_leak(SectionStop::intensity_drifted));
  EXPECT_EQ(stop_note(SectionStop::area_jumped, 17), "stopped at slice 17: area jumped (leak into a neighbour)");
  EXPECT_EQ(stop_note(SectionStop::none, 3), "");
}

TEST(SectionRules, AreaOutsideMeasuresTheShareOffTheOtherSection) {
  const auto a = circle({0, 0}, 10, 64);
  EXPECT_LT(area_outside(a, a, 0.0, 0.5, 0.5), 0.02);
  // Half of a disc shifted by its diameter lies off the first; beyond 3 mm of tolerance, less.
  const auto b = circle({10, 0}, 10, 64);
  const double off = area_outside(b, a, 0.0, 0.5, 0.5);
  EXPECT_NEAR(off, 1.0 - 0.391, 0.05);  // the lens of two unit discs a radius apart: 39.1 % overlap
  EXPECT_LT(area_outside(b, a, 3.0, 0.5, 0.5), off);
}
