// Over 400 lines: the segmentation sweep and the mesh sweep of the same variants share the scan
// loaders, the variant list and the ingest reordering in this file's anonymous namespace.
// Robustness sweep of the segmentation: each shared real case and the phantom, changed the ways
// unseen scans differ (slice thickness 0.7–5 mm, a field of view cutting the organ, RAS and
// sagittal storage, a 10° oblique grid, +20 HU noise, the seed moved 5 mm along each axis or
// placed in the neck or the fundus), scored against the equally changed reference.
// Targets: gallbladder Dice ≥ 0.95 × the unchanged scan's, trachea ≥ 0.97. The table in
// segmentation/README.md is this test's output. Variants still short of the target are listed
// in kShortOfTarget with what they reach.

#include "tests/support/test_support.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/ingest.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/case/stage_options.h"
#include "pipeline/phantom/phantom.h"
#include "scan_variants.h"
#include "meshing/mesh.h"
#include "physics/haptics/contact.h"
#include "physics/haptics/paths.h"
#include "segmentation/segment.h"

#include <gtest/gtest.h>

#include <cctype>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <cstdio>
#include <algorithm>
#include <functional>
#include <sstream>

using namespace organsmith;
using namespace organsmith::testing;
namespace fs = std::filesystem;

namespace {

/// What ingest hands the stages: the volume reordered to axial slices.
Scan as_ingested(const Scan& s) {
  const auto order = axial_axis_order(s.ct.grid);
  if (order == std::array<int, 3>{0, 1, 2}) return s;
  return {permute_axes(s.ct, order), permute_axes(s.ref, order), s.seed_lps_mm};
}

struct Variant {
  std::string name;
  std::function<Scan(const Scan&)> make;
};

std::vector<Variant> scan_variants(bool thin_slices) {
  std::vector<Variant> v;
  for (double t : {0.7, 1.0, 2.0, 3.0, 5.0}) {
    if (!thin_slices && t < 1.5) continue;
    char name[32];
    std::snprintf(name, sizeof name, "%.1f mm slices", t);
    v.push_back({name, [t](const Scan& s) { return resample_slices(s, t); }});
  }
  v.push_back({"cut at high-k edge", [](const Scan& s) { return crop_through_organ(s, 0.6, true); }});
  v.push_back({"cut at low-k edge", [](const Scan& s) { return crop_through_organ(s, 0.4, false); }});
  v.push_back({"stored RAS", stored_ras});
  v.push_back({"stored sagittal", stored_sagittal});
  v.push_back({"oblique 10 deg", [](const Scan& s) { return tilted(s, 10.0); }});
  v.push_back({"noise 20 HU", [](const Scan& s) { return with_noise(s, 20.0, 11); }});
  return v;
}

struct Row {
  std::string variant;
  double dice = 0, volume_error = 0, seconds = 0;
  double rule_dice = -1;  ///< airway: the reference's rule (−500 HU) on the variant's CT, against the reference
  std::string error;
};

Row segment_and_score(const std::string& name, const Scan& raw, const std::string& organ, bool seeded) {
  const Scan s = as_ingested(raw);
  Row row;
  row.variant = name;
  NullProgress np;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    OrganRequest req{organ, {}, {}};
    if (seeded) req.seed_lps_mm = s.seed_lps_mm;
    const SegmentationResult r = segment_organs(s.ct, {req}, sweep_segment_options(), np);
    row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const Score sc = score_against(s.ref, r.labels, r.organs[0].label);
    // To look at a variant: ORGANSMITH_SWEEP_DUMP=DIR keeps its CT, reference, segmentation and seed.
    if (const char* dump = std::getenv("ORGANSMITH_SWEEP_DUMP")) {
      std::string dir = organ + "_" + name;
      for (char& c : dir)
        c = c == '+' ? 'p' : c == '-' ? 'm' : std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
      const fs::path d = fs::path(dump) / dir;
      fs::create_directories(d);
      write_volume_file(s.ct, d / "ct.nii.gz");
      write_label_map(s.ref, d / "ref.nii.gz");
      write_label_map(r.labels, d / "seg.nii.gz");
      if (seeded)
        std::ofstream(d / "seed.txt") << s.seed_lps_mm.x() << ',' << s.seed_lps_mm.y() << ',' << s.seed_lps_mm.z() << '\n';
    }
    row.dice = sc.dice;
    row.volume_error = sc.volume_error;
    if (organ == "trachea") row.rule_dice = score_against(s.ref, air_under_reference(s, -500.0f), 1).dice;
  } catch (const std::exception& e) {
    row.error = e.what();
  }
  char rule[32] = "";
  if (row.rule_dice >= 0) std::snprintf(rule, sizeof rule, " %.3f |", row.rule_dice);
  std::printf("| %-12s | %-26s | %.3f | %+6.1f %% | %5.2f s |%s%s\n", organ.c_str(), name.c_str(), row.dice,
              100 * row.volume_error, row.seconds, rule, row.error.empty() ? "" : (" " + row.error).c_str());
  std::fflush(stdout);
  return row;
}

/// Variants short of the target, with the figure reached. The sweep holds them at that
/// figure, less 0.01, so that they cannot get worse unseen, and prints them as short. Every other
/// variant must meet the target. The trachea's resampled variants are interpolated from 8 mm
/// slices, where the reference (labels box-averaged, ≥ ½) and the interpolated CT disagree: the
/// reference's own rule (air below −500 HU, Dice 1.000 on the scan's own slices) reaches only
/// 0.94–0.96 on them, so they are also held within kRuleMargin of that figure (README).
struct Short {
  std::string case_name, organ, variant;
  double reached;
};
const std::vector<Short> kShortOfTarget = {
    {"chest-dicom-8mm", "trachea", "0.7 mm slices", 0.937},
    {"chest-dicom-8mm", "trachea", "1.0 mm slices", 0.935},
    {"chest-dicom-8mm", "trachea", "2.0 mm slices", 0.939},
    {"chest-dicom-8mm", "trachea", "3.0 mm slices", 0.940},
    {"chest-dicom-8mm", "trachea", "5.0 mm slices", 0.955},
};
constexpr double kRuleMargin = 0.015;

void sweep(const std::string& case_name, const Scan& base, const std::string& organ, bool seeded, bool thin_slices,
           double absolute_floor) {
  std::printf("%s, %s:\n", case_name.c_str(), organ.c_str());
  const Row b = segment_and_score("unchanged", base, organ, seeded);
  ASSERT_TRUE(b.error.empty()) << b.error;
  const double floor = absolute_floor > 0 ? absolute_floor : 0.95 * b.dice;
  std::vector<Row> rows;
  for (const Variant& v : scan_variants(thin_slices)) rows.push_back(segment_and_score(v.name, v.make(base), organ, seeded));
  if (seeded) {
    const char* axis = "LPS";
    for (int a = 0; a < 3; ++a)
      for (double d : {-5.0, 5.0}) {
        Scan s = base;
        s.seed_lps_mm[a] += d;
        char name[48];
        std::snprintf(name, sizeof name, "seed %+.0f mm %c", d, axis[a]);
        rows.push_back(segment_and_score(name, s, organ, true));
      }
    for (int end : {-1, 1}) {
      Scan s = base;
      s.seed_lps_mm = seed_near_end(base, end, 4.0);
      rows.push_back(segment_and_score(end < 0 ? "seed at one end (neck/fundus)" : "seed at other end", s, organ, true));
    }
  }
  int short_count = 0;
  for (const Row& r : rows) {
    const auto known = std::find_if(kShortOfTarget.begin(), kShortOfTarget.end(), [&](const Short& k) {
      return k.case_name == case_name && k.organ == organ && k.variant == r.variant;
    });
    if (known != kShortOfTarget.end()) {
      ++short_count;
      std::printf("short of target (%.3f): %s, %s at %.3f\n", floor, case_name.c_str(), r.variant.c_str(), r.dice);
      EXPECT_GE(r.dice, known->reached - 0.01) << case_name << ", " << r.variant << " got worse";
      if (r.rule_dice >= 0)
        EXPECT_GE(r.dice, r.rule_dice - kRuleMargin) << case_name << ", " << r.variant << ": the reference's rule reaches "
                                                     << r.rule_dice;
      continue;
    }
    EXPECT_TRUE(r.error.empty()) << case_name << ", " << r.variant << ": " << r.error;
    EXPECT_GE(r.dice, floor) << case_name << ", " << r.variant << " (unchanged " << b.dice << ")";
  }
  std::printf("%s, %s: %zu variants, %d short of the target %.3f\n", case_name.c_str(), organ.c_str(), rows.size(),
              short_count, floor);
}

Scan phantom_scan(std::uint8_t label, const std::string& seed_organ) {
  static const Phantom ph = [] {
    NullProgress np;
    PhantomOptions po;
    po.size_vox = 256;  // 1.56 mm pixels, 2.5 mm slices
    return synthesize_phantom(po, np);
  }();
  Scan s;
  s.ct = ph.ct;
  s.ref.grid = ph.truth.grid;
  s.ref.labels.resize(ph.truth.labels.size());
  for (std::size_t i = 0; i < s.ref.labels.size(); ++i) s.ref.labels[i] = ph.truth.labels[i] == label ? 1 : 0;
  s.seed_lps_mm = ph.seeds_lps_mm.count(seed_organ) ? ph.seeds_lps_mm.at(seed_organ) : Eigen::Vector3d::Zero();
  return s;
}

Scan real_scan(const std::string& ct, const std::string& ref) {
  NullProgress np;
  Scan s;
  s.ct = ingest(real_data_dir() / ct, IngestOptions{}, np).volume;
  const LabelMap r = read_label_map(real_data_dir() / ref);
  // The reference may store the same grid in another axis order than the series as read: look
  // each CT voxel up in it by position.
  s.ref.grid = s.ct.grid;
  s.ref.labels.assign(s.ct.hu.size(), 0);
  const auto& n = s.ct.grid.size_vox;
  for (std::int64_t k = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i) {
        const Eigen::Vector3d t =
            r.grid.lps_mm_to_index(s.ct.grid.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k))));
        const std::int64_t ri = std::llround(t.x()), rj = std::llround(t.y()), rk = std::llround(t.z());
        EXPECT_LT((t - Eigen::Vector3d(double(ri), double(rj), double(rk))).norm(), 0.05) << ref << ": grids differ";
        if (r.grid.contains(ri, rj, rk) && r.at(ri, rj, rk)) s.ref.labels[std::size_t(s.ct.grid.offset(i, j, k))] = 1;
      }
  return s;
}

}  // namespace

TEST(SegmentSweep, RealGallbladder) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  Scan s = real_scan("abdomen-ct-3mm/ct.nii.gz", "abdomen-ct-3mm/gallbladder-reference.nii.gz");
  s.seed_lps_mm = seed_at_centre(s.ref);
  sweep("abdomen-ct-3mm", s, "gallbladder", true, true, 0);
}

// The shared real case changed the ways the unseen scans behind issue 15 differ from it, several
// at once: contrast-enhanced liver (over the liver reference, 1.5 mm rim), 5 mm slices, more
// noise, the field of view cut through the organ's cranial part; each with the
// seed at the centre and moved 5 mm cranially and caudally. The issue sets no target for these
// (its sweep is above); each variant's mean over its three seeds is held at the figure reached,
// less 0.02, so that it cannot get worse unseen. Table: segmentation/README.md.
// The shared case changed like the unseen scans of issue 15, several ways at once.
struct Unseen {
  const char* name;
  double boost_hu, slice_mm, noise_hu;
  bool cut_top;
  double reached;  // mean Dice over the three seeds
};
// On the case's own 3 mm pixels: a finer in-plane grid interpolated from them would be a
// 3 mm-resolution image on fine pixels, far blurrier than a real 0.78 mm scan.
const Unseen kUnseen[] = {
    {"liver +80 HU", 80, 3, 0, false, 0.875},
    {"liver +80 HU, +10 HU noise", 80, 3, 10, false, 0.847},
    {"liver +80 HU, 5 mm", 80, 5, 0, false, 0.830},
    {"liver +80 HU, 5 mm, +10 HU", 80, 5, 10, false, 0.844},
    {"same, cut through the top", 80, 5, 10, true, 0.878},
    {"liver +120 HU, 5 mm, +15 HU", 120, 5, 15, false, 0.837},
    {"5 mm, +10 HU", 0, 5, 10, false, 0.847},
};

Scan like_unseen(const Scan& base, const LabelMap& liver, const Unseen& u) {
  Scan s = base;
  if (u.boost_hu > 0) s = contrast_enhanced(s, liver, u.boost_hu, 1.5);
  if (u.slice_mm != s.ct.grid.spacing_mm.z()) s = resample_slices(s, u.slice_mm);
  if (u.noise_hu > 0) s = with_noise(s, u.noise_hu, 7);
  if (u.cut_top) s = crop_through_organ(s, 0.75, true);
  return s;
}

/// Segments `s` from its seed and 5 mm cranial and caudal of it; returns the three Dice.
std::vector<double> three_seeds(const Scan& s, const std::string& name) {
  std::vector<double> dice;
  for (double dz : {0.0, 5.0, -5.0}) {
    Scan v = s;
    v.seed_lps_mm.z() += dz;
    char label[128];
    std::snprintf(label, sizeof label, "%s, seed %+.0f mm S", name.c_str(), dz);
    dice.push_back(segment_and_score(label, v, "gallbladder", true).dice);
  }
  return dice;
}

/// Prints the spread of `all` and returns its mean.
double print_spread(const char* what, std::vector<double> all) {
  std::sort(all.begin(), all.end());
  double mean = 0;
  for (double d : all) mean += d / double(all.size());
  const auto below = std::count_if(all.begin(), all.end(), [](double d) { return d < 0.8; });
  std::printf("%s: %zu runs, mean Dice %.3f, lowest %.3f, median %.3f, below 0.8: %td\n", what, all.size(), mean,
              all.front(), all[all.size() / 2], below);
  return mean;
}

TEST(SegmentSweep, RealGallbladderLikeUnseenScans) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  Scan base = real_scan("abdomen-ct-3mm/ct.nii.gz", "abdomen-ct-3mm/gallbladder-reference.nii.gz");
  base.seed_lps_mm = seed_at_centre(base.ref);
  const LabelMap liver = real_scan("abdomen-ct-3mm/ct.nii.gz", "abdomen-ct-3mm/liver-reference.nii.gz").ref;
  std::vector<double> all;
  for (const Unseen& u : kUnseen) {
    const std::vector<double> d = three_seeds(like_unseen(base, liver, u), u.name);
    const double mean = (d[0] + d[1] + d[2]) / 3;
    all.insert(all.end(), d.begin(), d.end());
    std::printf("%s: mean Dice %.3f over 3 seeds\n", u.name, mean);
    EXPECT_GE(mean, u.reached - 0.02) << u.name << " got worse";
  }
  print_spread("like unseen scans", all);
}

// The same 21 runs, each on three more noise draws (+6 HU): one fixed draw per variant says
// little on scans where a few HU decide whether a short section ends the organ. Held at the mean
// reached, less 0.02.
TEST(SegmentSweep, RealGallbladderLikeUnseenScansMoreNoiseDraws) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  Scan base = real_scan("abdomen-ct-3mm/ct.nii.gz", "abdomen-ct-3mm/gallbladder-reference.nii.gz");
  base.seed_lps_mm = seed_at_centre(base.ref);
  const LabelMap liver = real_scan("abdomen-ct-3mm/ct.nii.gz", "abdomen-ct-3mm/liver-reference.nii.gz").ref;
  constexpr double kReachedMean = 0.845;
  std::vector<double> all;
  for (const Unseen& u : kUnseen) {
    const Scan s = like_unseen(base, liver, u);
    for (unsigned draw = 1; draw <= 3; ++draw) {
      const std::vector<double> d =
          three_seeds(with_noise(s, 6.0, 100 + draw), std::string(u.name) + ", draw " + std::to_string(draw));
      all.insert(all.end(), d.begin(), d.end());
    }
  }
  EXPECT_GE(print_spread("like unseen scans, three more noise draws", all), kReachedMean - 0.02);
}

// Contrast-enhanced liver with bowel against the organ's body: on some noise draws the unaided
// fit takes the bowel on three slices running while each held section stays on the organ's
// wall, with up to 58 % of it on the reach's limit. Of 30 draws of this variant (seed 5 mm
// caudal), three ended the organ there (Dice 0.63–0.65); three held sections in a row and up to
// 65 % on the limit with the wall seen recover one of them, this draw (0.641 before, 0.874).
TEST(SegmentSweep, RealGallbladderBowelAgainstTheBodyOnThreeSlices) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  Scan base = real_scan("abdomen-ct-3mm/ct.nii.gz", "abdomen-ct-3mm/gallbladder-reference.nii.gz");
  base.seed_lps_mm = seed_at_centre(base.ref);
  const LabelMap liver = real_scan("abdomen-ct-3mm/ct.nii.gz", "abdomen-ct-3mm/liver-reference.nii.gz").ref;
  Scan s = with_noise(like_unseen(base, liver, kUnseen[1]), 6.0, 324);
  s.seed_lps_mm.z() -= 5.0;
  const Row r = segment_and_score("liver +80 HU, +10 HU noise, +6 HU draw 324, seed -5 mm S", s, "gallbladder", true);
  EXPECT_GE(r.dice, 0.8) << r.error;
}

// A seed at either end of the organ (the neck or the fundus tip, 4 mm inside) on the real case with
// more noise (+8 HU, four draws): at the tip the seed's start can fit a bowel loop touching the
// organ there and follow it for a slice or two (the seed at the other end gave Dice 0.023 on draws
// 2 and 3 before min_extent_mm; 0.884 and 0.885 with it). Every run must find the organ (Dice >= 0.8).
TEST(SegmentSweep, RealGallbladderSeedAtAnEndOnNoisierScans) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  Scan base = real_scan("abdomen-ct-3mm/ct.nii.gz", "abdomen-ct-3mm/gallbladder-reference.nii.gz");
  std::vector<double> all;
  for (unsigned draw = 1; draw <= 4; ++draw) {
    const Scan noisy = with_noise(base, 8.0, 200 + draw);
    for (int end : {-1, 1}) {
      Scan s = noisy;
      s.seed_lps_mm = seed_near_end(base, end, 4.0);
      const std::string name = std::string(end < 0 ? "seed at one end" : "seed at other end") + ", +8 HU, draw " +
                               std::to_string(draw);
      const Row r = segment_and_score(name, s, "gallbladder", true);
      EXPECT_GE(r.dice, 0.8) << name << ": " << r.error;
      all.push_back(r.dice);
    }
  }
  print_spread("seed at an end, +8 HU", all);
}

TEST(SegmentSweep, RealTrachea) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const Scan s = real_scan("chest-dicom-8mm/dicom", "chest-dicom-8mm/trachea-reference.nii.gz");
  sweep("chest-dicom-8mm", s, "trachea", false, true, 0.97);
}

/// The reference's outline on slice k in LPS mm: centre (L, P) and its P extent.
struct RefSection {
  double l = 0, p = 0, min_p = 1e9, max_p = -1e9;
  int n = 0;
};
RefSection ref_section(const Scan& s, std::int64_t k) {
  RefSection r;
  const ImageGrid& g = s.ct.grid;
  for (std::int64_t j = 0; j < g.size_vox[1]; ++j)
    for (std::int64_t i = 0; i < g.size_vox[0]; ++i)
      if (s.ref.at(i, j, k)) {
        const Eigen::Vector3d x = g.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k)));
        r.l += x.x(), r.p += x.y(), r.min_p = std::min(r.min_p, x.y()), r.max_p = std::max(r.max_p, x.y()), ++r.n;
      }
  if (r.n) r.l /= r.n, r.p /= r.n;
  return r;
}

/// The trachea's slices of a segmentation, from the most caudal (lowest S) up.
std::vector<std::int64_t> caudal_to_cranial(const ImageGrid& g, const OrganSegmentation& o) {
  std::vector<std::int64_t> ks;
  for (std::int64_t k = o.first_slice; k <= o.last_slice; ++k) ks.push_back(k);
  const bool k_up = g.index_to_lps_mm({0, 0, 1}).z() > g.index_to_lps_mm({0, 0, 0}).z();
  if (!k_up) std::reverse(ks.begin(), ks.end());
  return ks;
}

/// Sets `hu` on slice k where `inside(L, P)` (LPS mm) holds.
template <class F>
void paint(Scan& s, std::int64_t k, float hu, F inside) {
  const ImageGrid& g = s.ct.grid;
  for (std::int64_t j = 0; j < g.size_vox[1]; ++j)
    for (std::int64_t i = 0; i < g.size_vox[0]; ++i) {
      const Eigen::Vector3d x = g.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k)));
      if (inside(x.x(), x.y())) s.ct.hu[std::size_t(g.offset(i, j, k))] = hu;
    }
}

/// The 5 mm variant of the shared chest CT and its trachea as segmented; the stage must stop
/// there by the thick-slice carina rule (two lobes joined by a neck).
std::pair<Scan, OrganSegmentation> chest_5mm() {
  Scan base = resample_slices(real_scan("chest-dicom-8mm/dicom", "chest-dicom-8mm/trachea-reference.nii.gz"), 5.0);
  NullProgress np;
  OrganSegmentation plain = segment_organs(base.ct, {OrganRequest{"trachea", {}, {}}}, {}, np).organs[0];
  EXPECT_NE(plain.notes.back().find("two lobes"), std::string::npos) << plain.notes.back();
  return {std::move(base), std::move(plain)};
}

void expect_same_extent(const Scan& changed, const OrganSegmentation& plain, const char* what, int slices) {
  NullProgress np;
  const OrganSegmentation o = segment_organs(changed.ct, {OrganRequest{"trachea", {}, {}}}, {}, np).organs[0];
  std::printf("trachea slices %lld–%lld (%s); with %s on %d slices: %lld–%lld (%s)\n",
              static_cast<long long>(plain.first_slice), static_cast<long long>(plain.last_slice),
              plain.notes.back().c_str(), what, slices, static_cast<long long>(o.first_slice),
              static_cast<long long>(o.last_slice), o.notes.back().c_str());
  EXPECT_EQ(o.first_slice, plain.first_slice) << what;
  EXPECT_EQ(o.last_slice, plain.last_slice) << what;
}

// The carina on thick slices: the sweep's 5 mm variant stops where the two bronchi, joined by a
// neck through the ridge's partial volume, come apart under an erosion. Air behind the lumen
// joined to it the same way (the oesophagus, through a thin wall), and the same air once the
// wall closes, under the contour that took it in above, are no carina: the stage must still
// follow the trachea down to the same slice.
TEST(SegmentSweep, AirJoinedBehindTheTracheaOnThickSlicesIsNotTheCarina) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  auto [s, plain] = chest_5mm();
  const std::vector<std::int64_t> ks = caudal_to_cranial(s.ct.grid, plain);
  int painted = 0;
  for (std::size_t i = 2; i < ks.size(); ++i) {
    const RefSection r = ref_section(s, ks[i]);
    if (!r.n) continue;
    // A pocket of air 8 mm across, 2 mm behind the lumen, joined to it by a 1.5 mm wide channel
    // from the lumen's centre; on the two most caudal of these slices the wall between them
    // closes: a separate pocket.
    const double p0 = r.max_p + 2.0 + 4.0;
    const bool joined = i >= 4;
    paint(s, ks[i], -950.0f, [&](double l, double p) {
      return std::hypot(l - r.l, p - p0) <= 4.0 || (joined && std::abs(l - r.l) <= 0.75 && p >= r.p && p <= p0);
    });
    ++painted;
  }
  ASSERT_GE(painted, 10);
  expect_same_extent(s, plain, "air joined behind it", painted);
}

TEST(SegmentSweep, PhantomGallbladder) {
  sweep("phantom 256x256x160", phantom_scan(std::uint8_t(PhantomLabel::gallbladder), "gallbladder"), "gallbladder", true, false, 0);
}

TEST(SegmentSweep, PhantomTrachea) {
  sweep("phantom 256x256x160", phantom_scan(std::uint8_t(PhantomLabel::trachea), "trachea"), "trachea", false, false, 0.97);
}

TEST(SegmentSweep, IngestReordersASagittalSeriesToAxialSlices) {
  const Scan base = phantom_scan(std::uint8_t(PhantomLabel::gallbladder), "gallbladder");
  const Scan sag = stored_sagittal(base);
  ScratchDir tmp("sweep_sagittal");
  write_volume_file(sag.ct, tmp.path() / "sagittal.nii");
  NullProgress np;
  const IngestResult r = ingest(tmp.path() / "sagittal.nii", IngestOptions{}, np);
  EXPECT_EQ(axial_axis_order(r.volume.grid), (std::array<int, 3>{0, 1, 2}));
  EXPECT_GT(std::abs(r.volume.grid.direction_lps(2, 2)), 0.99);  // k along S
  ASSERT_TRUE(r.volume.grid.same_geometry(base.ct.grid, 1e-3));   // the phantom's own axial grid
  EXPECT_TRUE(std::equal(r.volume.hu.begin(), r.volume.hu.end(), base.ct.hu.begin()));
  ASSERT_FALSE(r.report.warnings.empty());
  EXPECT_NE(r.report.warnings.back().find("reordered to axial"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Meshes of the sweep's variants: what `run` meshes from each segmentation must pass every gate
// (surface guarantees, tetrahedral quality) after meshing's own remedies.

namespace {

struct MeshRow {
  std::string failures;  ///< empty = every gate passed and every path is valid
  std::string remedies;
  std::string paths;     ///< the paths' figures
  std::string gates;     ///< each gate's figure for this variant
  double volume_error_max = 0;  ///< largest |volume error| of its surfaces compared with the label
  double seconds = 0;
};

/// Each gate's worst figure over a sweep's variants (the margin each gate passes with).
struct GateExtremes {
  double angle_min_deg = 180, edge_fraction_min = 1, volume_error_max = 0, fold_max_deg = 0;
  double dihedral_min_deg = 180, radius_edge_max = 0;
  double gated_fold_max_deg = 0;  ///< largest fold where the gate applies (an uncut organ's own outer surface)
  double hd95_max_mm = 0, dice_label_min = 1, dice_reference_min = 1;  ///< the outer surface against the label and the reference
  void print(const char* sweep) const {
    std::printf("%s, outer surfaces: largest fold where gated %.1f° (60°), HD95 to the label ≤ %.2f mm, Dice of the enclosed "
                "solid ≥ %.3f against the label and ≥ %.3f against the reference\n",
                sweep, gated_fold_max_deg, hd95_max_mm, dice_label_min, dice_reference_min);
    std::printf("%s, worst over the variants (gate): smallest triangle angle %.1f° (25°), edges within ±25 %% %.1f %% "
                "(90 %%), |volume error| %.2f %% (3 %%), largest fold of a surface %.1f° (60° where asked), smallest "
                "dihedral %.2f° (10°), largest radius-edge %.3f (2)\n",
                sweep, angle_min_deg, 100 * edge_fraction_min, 100 * volume_error_max, fold_max_deg, dihedral_min_deg,
                radius_edge_max);
  }
};

/// `tet_edge_mm`: the tetrahedra's edge (`run`'s default, MeshStageOptions; 0 = the surface edge);
/// `edge_mm`: the surfaces' (run's default, 1.5).
MeshRow mesh_variant(const std::string& name, const Scan& raw, const std::string& organ, bool seeded, double tet_edge_mm,
                     GateExtremes& worst, double edge_mm = MeshStageOptions{}.edge_mm) {
  const Scan s = as_ingested(raw);
  NullProgress np;
  OrganRequest req{organ, {}, {}};
  if (seeded) req.seed_lps_mm = s.seed_lps_mm;
  const SegmentationResult seg = segment_organs(s.ct, {req}, {}, np);
  MeshOptions mo;
  mo.organs = {mesh_spec(builtin_organ_registry().at(organ))};
  mo.enforce_quality = false;
  mo.tet_edge_mm = tet_edge_mm;
  mo.edge_mm = edge_mm;
  MeshRow row;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    const OrganMeshes m = mesh_organs(seg.labels, mo, np);
    for (const auto& o : m.organs) {
      for (const auto& surf : o.surfaces)
        for (const auto& f : surf.quality.failures) row.failures += surf.name + ": " + f + "; ";
      // The outer surface against the label it was made from and the scan's reference.
      const SurfaceMesh& outer = o.surfaces.front().mesh;
      const double dl = enclosed_dice(outer, seg.labels, o.spec.label), dr = enclosed_dice(outer, s.ref, 0);
      const double hd = o.surfaces.front().quality.hd95_mm;
      char d[160];
      std::snprintf(d, sizeof d, "enclosed Dice %.3f to the label, %.3f to the reference (label %.3f); ", dl, dr,
                    score_against(s.ref, seg.labels, o.spec.label).dice);
      row.gates += d;
      worst.dice_label_min = std::min(worst.dice_label_min, dl);
      worst.dice_reference_min = std::min(worst.dice_reference_min, dr);
      worst.hd95_max_mm = std::max(worst.hd95_max_mm, hd);
      const bool cut = std::any_of(o.warnings.begin(), o.warnings.end(),
                                   [](const std::string& w) { return w.find("capped flat") != std::string::npos; });
      if (!cut && o.spec.model != OrganModel::tube)
        worst.gated_fold_max_deg = std::max(worst.gated_fold_max_deg, o.surfaces.front().quality.fold_max_deg);
      for (const auto& f : o.volume_quality.failures) row.failures += o.spec.name + " tetrahedra: " + f + "; ";
      for (const auto& w : o.warnings)
        if (w.find("remed") != std::string::npos || w.find("gates failed") != std::string::npos) row.remedies += w + "; ";
      char g[200];
      for (const auto& surf : o.surfaces) {
        const SurfaceQuality& q = surf.quality;
        std::snprintf(g, sizeof g, "%s %.1f° %.1f%% fold %.0f° vol %+.1f%% HD95 %.2f mm; ", surf.name.c_str(), q.angle_min_deg,
                      100 * q.edge_within_tolerance, q.fold_max_deg, 100 * q.volume_error, q.hd95_mm);
        row.gates += g;
        worst.angle_min_deg = std::min(worst.angle_min_deg, q.angle_min_deg);
        worst.edge_fraction_min = std::min(worst.edge_fraction_min, q.edge_within_tolerance);
        if (q.reference_volume_mm3 > 0) {
          worst.volume_error_max = std::max(worst.volume_error_max, std::abs(q.volume_error));
          row.volume_error_max = std::max(row.volume_error_max, std::abs(q.volume_error));
        }
        worst.fold_max_deg = std::max(worst.fold_max_deg, q.fold_max_deg);
      }
      if (o.volume_quality.tets > 0) {
        std::snprintf(g, sizeof g, "tets %.2f° %.3f", o.volume_quality.dihedral_min_deg, o.volume_quality.radius_edge_max);
        row.gates += g;
        worst.dihedral_min_deg = std::min(worst.dihedral_min_deg, o.volume_quality.dihedral_min_deg);
        worst.radius_edge_max = std::max(worst.radius_edge_max, o.volume_quality.radius_edge_max);
      }
    }
    // The organ's guidance paths, as the guide stage makes them (no liver label: the bed from the CT).
    for (const auto& o : m.organs) {
      char buf[256];
      if (o.spec.name == "gallbladder") {
        const physics::DissectionPath d = physics::gallbladder_dissection_path(o.surfaces.at(0).mesh, nullptr, {}, &s.ct);
        std::snprintf(buf, sizeof buf,
                      "dissection %s %.0f mm, covers %.2f, off-surface %.2f mm, self %.1f mm, turning %.0f° (≤ %.1f°/mm, %zu passes)",
                      d.bed_source.substr(0, 12).c_str(), d.length_mm, d.covered_fraction, d.max_surface_distance_mm,
                      d.min_self_distance_mm, d.total_turning_deg, d.max_turn_deg_per_mm, d.smoothing_passes);
        row.paths += buf;
        if (d.bed_source != "CT intensity") row.failures += "dissection bed not found in the CT: " + d.bed_source + "; ";
        if (d.max_surface_distance_mm > 1.0) row.failures += "dissection path off the surface; ";
        if (!(d.min_self_distance_mm > 0.0)) row.failures += "dissection path crosses itself; ";
        // Once around the bed, smoothly (a convex plane loop turns 360°).
        if (d.total_turning_deg > 720.0) row.failures += "dissection path turns more than 720°; ";
        // Where the field of view cuts the organ, the surface ends in a flat cap whose edge is a
        // right angle of the image, not of the organ: a rim crossing it turns there (43.8°/mm on
        // the low-k cut). Reported in the row, not enforced for the cut variants.
        if (d.max_turn_deg_per_mm > 30.0 && name.rfind("cut at", 0) != 0)
          row.failures += "dissection path turns more than 30°/mm; ";
      } else if (o.spec.name == "trachea") {
        const physics::Centerline cl = physics::trachea_centerline(seg.labels, {.label = o.spec.label, .organ = o.spec.name});
        const physics::SurfaceIndex wall({o.surfaces.at(0).mesh});
        const physics::IncisionPath inc = physics::trachea_incision_path(cl, wall);
        std::snprintf(buf, sizeof buf, "centreline %.0f mm, incision %.0f mm, off-wall %.2f mm", cl.line.length_mm(),
                      inc.length_mm, inc.max_wall_distance_mm);
        row.paths += buf;
        if (inc.max_wall_distance_mm > 1.0) row.failures += "incision path off the wall; ";
      }
    }
  } catch (const std::exception& e) {
    row.failures = std::string("error: ") + e.what();
  }
  row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("| %-12s | %-22s | edge %.1f, tets %.1f mm | %s | %5.1f s | %s | %s | %s\n", organ.c_str(), name.c_str(), edge_mm, tet_edge_mm,
              row.failures.empty() ? "all gates pass, paths valid" : row.failures.c_str(), row.seconds,
              row.gates.c_str(), row.paths.c_str(), row.remedies.empty() ? "first mesh" : row.remedies.c_str());
  std::fflush(stdout);
  return row;
}

/// The sub-voxel and calibration variants every organ's sweep adds (issue 39): the origin moved by
/// a hundredth of a millimetre and by half a millimetre, the spacing ±0.5 %.
void add_grid_variants(std::vector<std::pair<std::string, Scan>>& v, const Scan& base) {
  v.push_back({"origin +0.01 mm", shifted_origin(base, Eigen::Vector3d::Constant(0.01))});
  v.push_back({"origin +0.5/0.37/0.23 mm", shifted_origin(base, Eigen::Vector3d(0.5, 0.37, 0.23))});
  v.push_back({"spacing +0.5 %", scaled_spacing(base, 1.005)});
  v.push_back({"spacing -0.5 %", scaled_spacing(base, 0.995)});
}

/// Surface edges where a mesh stays short of a gate after the remedies, with the figure reached:
/// held there (it cannot get worse unseen) and printed as short; every other edge must pass.
/// The airway at coarse edges loses volume to its chords: a remeshed surface keeps its vertices
/// on the level set, so each flat triangle cuts inside the tube by a²/(8R) on average (edge a,
/// radius R) and the tube loses a²/(4R²) of its volume: 5.5 % at a = 3 mm for this chest's
/// R ≈ 6.4 mm, the smoothing's and the support sampling's loss on top. Its reference label meshed
/// at 1.5, 2, 2.5 and 3 mm: −2.1, −3.2, −3.7, −6.1 % (meshing/README.md "Sweep"). At 2.5 mm the
/// figure went from 3.71 to 4.22 % when σ went from 0.6 voxel (capped 1.5 mm) to 0.8 voxel
/// (capped 3 mm) for the fold gate (issue 39): the tube is smoothed more along its 8 mm slices,
/// and the 2.5 mm polygon's chords cut the rounder lumen more (3 mm: 6.35 → 6.36 %).
struct ShortGate {
  std::string organ;
  double edge_mm;
  double volume_error_reached;  ///< |volume error| reached: the only gate short
};
const std::vector<ShortGate> kShortOfGate = {{"trachea", 2.5, 0.0422}, {"trachea", 3.0, 0.0636}};

/// The unchanged scan meshed with surface edges from 1.2 to 3 mm at run's tetrahedra.
void mesh_edge_variants(const Scan& base, const std::string& organ, bool seeded, GateExtremes& worst, bool first_mesh) {
  for (const double edge_mm : {1.2, 2.0, 2.5, 3.0}) {
    const MeshRow r = mesh_variant("unchanged", base, organ, seeded, MeshStageOptions{}.tet_edge_mm, worst, edge_mm);
    const auto held = std::find_if(kShortOfGate.begin(), kShortOfGate.end(),
                                   [&](const ShortGate& s) { return s.organ == organ && s.edge_mm == edge_mm; });
    if (held != kShortOfGate.end()) {
      std::printf("  short of the volume gate (held): %s at a %.1f mm edge, |volume error| %.2f %% (reached %.2f %%)\n",
                  organ.c_str(), edge_mm, 100 * r.volume_error_max, 100 * held->volume_error_reached);
      EXPECT_LE(r.volume_error_max, held->volume_error_reached + 0.002) << "surface edge " << edge_mm << " mm";
      // Only the volume gate is short: every failure ("…; " each) is a volume one.
      std::istringstream failures(r.failures);
      for (std::string f; std::getline(failures, f, ';');)
        if (f.find_first_not_of(' ') != std::string::npos)
          EXPECT_NE(f.find("volume"), std::string::npos) << "surface edge " << edge_mm << " mm: " << f;
      continue;
    }
    EXPECT_TRUE(r.failures.empty()) << "surface edge " << edge_mm << " mm: " << r.failures;
    // From 2 mm on, the airway's chord loss alone (2.4 % at 2 mm) leaves no margin in the 3 % gate:
    // its first mesh fails there and the remedies' finer edge (1.6 mm) passes.
    if (first_mesh && edge_mm < 2.0) EXPECT_TRUE(r.remedies.empty()) << "surface edge " << edge_mm << " mm: " << r.remedies;
  }
}

}  // namespace

TEST(MeshSweep, RealTracheaVariantsPassEveryGate) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  GateExtremes worst;
  const Scan base = real_scan("chest-dicom-8mm/dicom", "chest-dicom-8mm/trachea-reference.nii.gz");
  std::vector<std::pair<std::string, Scan>> v{{"unchanged", base},
                                              {"1.0 mm slices", resample_slices(base, 1.0)},
                                              {"2.0 mm slices", resample_slices(base, 2.0)},
                                              {"5.0 mm slices", resample_slices(base, 5.0)},
                                              {"cut at high-k edge", crop_through_organ(base, 0.6, true)},
                                              {"oblique 10 deg", tilted(base, 10.0)}};
  add_grid_variants(v, base);
  // At `run`'s tetrahedral edge and at the surface's (finer tetrahedra, harder to keep in the gate).
  for (const double tet_edge_mm : {MeshStageOptions{}.tet_edge_mm, 0.0})
    for (const auto& [name, s] : v) {
      const MeshRow r = mesh_variant(name, s, "trachea", false, tet_edge_mm, worst);
      EXPECT_TRUE(r.failures.empty()) << name << ", tetrahedra " << tet_edge_mm << " mm: " << r.failures;
      // The tube's first mesh passes: quality of the method, not of the remedies' search.
      EXPECT_TRUE(r.remedies.empty()) << name << ", tetrahedra " << tet_edge_mm << " mm: " << r.remedies;
    }
  mesh_edge_variants(base, "trachea", false, worst, true);
  worst.print("real trachea mesh sweep");
}

TEST(MeshSweep, RealGallbladderVariantsPassEveryGate) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  Scan base = real_scan("abdomen-ct-3mm/ct.nii.gz", "abdomen-ct-3mm/gallbladder-reference.nii.gz");
  GateExtremes worst;
  base.seed_lps_mm = seed_at_centre(base.ref);
  std::vector<std::pair<std::string, Scan>> v{{"unchanged", base},
                                              {"1.0 mm slices", resample_slices(base, 1.0)},
                                              {"5.0 mm slices", resample_slices(base, 5.0)},
                                              {"cut at high-k edge", crop_through_organ(base, 0.6, true)},
                                              {"cut at low-k edge", crop_through_organ(base, 0.4, false)},
                                              {"oblique 10 deg", tilted(base, 10.0)}};
  add_grid_variants(v, base);
  // The seed 2 mm off the reference's centre along each axis, both ways (where a user clicks).
  for (int a = 0; a < 3; ++a)
    for (const double d : {-2.0, 2.0}) {
      Scan s = base;
      s.seed_lps_mm[a] += d;
      v.push_back({std::string("seed ") + (d > 0 ? "+" : "-") + "2 mm " + "LPS"[a], s});
    }
  // At `run`'s tetrahedral edge and at the surface's (finer tetrahedra, harder to keep in the gate).
  for (const double tet_edge_mm : {MeshStageOptions{}.tet_edge_mm, 0.0})
    for (const auto& [name, s] : v) {
      const MeshRow r = mesh_variant(name, s, "gallbladder", true, tet_edge_mm, worst);
      EXPECT_TRUE(r.failures.empty()) << name << ", tetrahedra " << tet_edge_mm << " mm: " << r.failures;
    }
  mesh_edge_variants(base, "gallbladder", true, worst, false);
  worst.print("real gallbladder mesh sweep");
}

// The trachea's resampled variants are all interpolated from 8 mm slices. The reference was drawn
// as the air below −500 HU: on the scan's own slices that rule gives it back (Dice ≥ 0.99). On
// the resampled slices the same rule applied to the interpolated CT, on the reference's own
// slices, is as far as the reference and the CT agree; the sweep holds the stage within
// kRuleMargin of it, and this test checks that it is the rule and that 0.97 is past it.
TEST(SegmentSweep, TracheaReferenceRuleOnResampledSlices) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const Scan base = real_scan("chest-dicom-8mm/dicom", "chest-dicom-8mm/trachea-reference.nii.gz");
  const double own = score_against(base.ref, air_under_reference(base, -500.0f), 1).dice;
  std::printf("| trachea | own 8 mm slices | reference's rule: Dice %.3f |\n", own);
  EXPECT_GE(own, 0.99) << "the reference is not the −500 HU air of its own slices";
  double highest = 0;
  for (double t : {0.7, 1.0, 2.0, 3.0, 5.0}) {
    const Scan s = resample_slices(base, t);
    const double d = score_against(s.ref, air_under_reference(s, -500.0f), 1).dice;
    std::printf("| trachea | %.1f mm slices | reference's rule: Dice %.3f |\n", t, d);
    highest = std::max(highest, d);
  }
  std::printf("highest Dice of the reference's rule over the resampled variants: %.3f (issue's target 0.97)\n", highest);
  EXPECT_LT(highest, 0.97) << "the issue's target is reachable on these variants: take them off kShortOfTarget";
}
