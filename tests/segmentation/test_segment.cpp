// Segmentation stage on the phantom and on real CT: accuracy (Dice, volume error) against the
// ground truth / references, robustness to the seed position, bad input, determinism.

#include "tests/support/test_support.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/ingest.h"
#include "pipeline/phantom/phantom.h"
#include "scan_variants.h"
#include "segmentation/segment.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <memory>

using namespace organsmith;
namespace fs = std::filesystem;

namespace {

struct Score {
  double dice = 0, volume_error = 0;  // volume error: (test − ref) / ref
};

/// Dice and volume error of `test` against `ref`. The two may store the same physical grid in
/// different axis orders (a DICOM series and a NIfTI written elsewhere): reference voxels are
/// matched to test voxels through their LPS positions.
Score score(const LabelMap& ref, std::uint8_t ref_label, const LabelMap& test, std::uint8_t test_label) {
  EXPECT_EQ(ref.grid.voxel_count(), test.grid.voxel_count());
  std::int64_t a = 0, b = 0, ab = 0;
  for (std::size_t i = 0; i < test.labels.size(); ++i) b += test.labels[i] == test_label;
  const auto& s = ref.grid.size_vox;
  for (std::int64_t k = 0; k < s[2]; ++k)
    for (std::int64_t j = 0; j < s[1]; ++j)
      for (std::int64_t i = 0; i < s[0]; ++i) {
        const std::uint8_t v = ref.at(i, j, k);
        if (!(ref_label ? v == ref_label : v != 0)) continue;
        ++a;
        const Eigen::Vector3d t =
            test.grid.lps_mm_to_index(ref.grid.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k))));
        const std::int64_t ti = std::llround(t.x()), tj = std::llround(t.y()), tk = std::llround(t.z());
        EXPECT_LT((t - Eigen::Vector3d(double(ti), double(tj), double(tk))).norm(), 0.05) << "grids differ";
        if (test.grid.contains(ti, tj, tk) && test.at(ti, tj, tk) == test_label) ++ab;
      }
  Score r;
  r.dice = a + b ? 2.0 * double(ab) / double(a + b) : 0.0;
  r.volume_error = a ? double(b - a) / double(a) : 0.0;
  return r;
}

const Phantom& phantom() {
  static const std::unique_ptr<Phantom> p = [] {
    NullProgress np;
    return std::make_unique<Phantom>(synthesize_phantom(PhantomOptions{}, np));
  }();
  return *p;
}

fs::path real(const std::string& rel) { return organsmith::testing::real_data_dir() / rel; }

Volume load(const fs::path& p) {
  NullProgress np;
  return ingest(p, IngestOptions{}, np).volume;
}

}  // namespace

TEST(SegmentPhantom, BothOrgansDiceAtLeast095) {
  const Phantom& ph = phantom();
  NullProgress np;
  const SegmentationResult r =
      segment_organs(ph.ct, {{"gallbladder", ph.seeds_lps_mm.at("gallbladder"), {}}, {"trachea", {}, {}}}, {}, np);
  const Score gb = score(ph.truth, std::uint8_t(PhantomLabel::gallbladder), r.labels, 1);
  const Score tr = score(ph.truth, std::uint8_t(PhantomLabel::trachea), r.labels, 2);
  RecordProperty("gallbladder_dice", std::to_string(gb.dice));
  RecordProperty("trachea_dice", std::to_string(tr.dice));
  std::printf("phantom: gallbladder Dice %.4f (volume %+.1f %%), trachea Dice %.4f (volume %+.1f %%)\n", gb.dice,
              100 * gb.volume_error, tr.dice, 100 * tr.volume_error);
  // Issue target: Dice ≥ 0.95 for both (reached: gallbladder 0.98, trachea 0.99).
  EXPECT_GE(gb.dice, 0.95);
  EXPECT_GE(tr.dice, 0.95);
  ASSERT_EQ(r.organs.size(), 2u);
  for (const auto& o : r.organs) {
    EXPECT_FALSE(o.contours.contours.empty());
    for (const auto& c : o.contours.contours) EXPECT_GE(c.points_lps_mm.size(), 8u);
  }
}

// The method must not depend on the 2.5 mm default slices: chest CTs come at 1–2 mm. A phantom
// with 1 mm slices and another noise/shape seed (400 slices), scored the same way. Measured:
// gallbladder 0.979, trachea 0.984 (1.25 mm: 0.971, 0.983).
TEST(SegmentPhantom, ThinSlicesAndAnotherSeedStillDiceAtLeast095) {
  PhantomOptions po;
  po.slice_mm = 1.0;
  po.seed = 7;
  NullProgress np;
  const Phantom ph = synthesize_phantom(po, np);
  const SegmentationResult r =
      segment_organs(ph.ct, {{"gallbladder", ph.seeds_lps_mm.at("gallbladder"), {}}, {"trachea", {}, {}}}, {}, np);
  const Score gb = score(ph.truth, std::uint8_t(PhantomLabel::gallbladder), r.labels, 1);
  const Score tr = score(ph.truth, std::uint8_t(PhantomLabel::trachea), r.labels, 2);
  std::printf("phantom, 1 mm slices, seed 7: gallbladder Dice %.4f (volume %+.1f %%), trachea Dice %.4f (volume %+.1f %%)\n",
              gb.dice, 100 * gb.volume_error, tr.dice, 100 * tr.volume_error);
  EXPECT_GE(gb.dice, 0.95);
  EXPECT_GE(tr.dice, 0.95);
  EXPECT_LT(std::abs(gb.volume_error), 0.15);
}

TEST(SegmentPhantom, DeterministicAcrossRunsAndThreading) {
  const Phantom& ph = phantom();
  NullProgress np;
  const std::vector<OrganRequest> req{{"gallbladder", ph.seeds_lps_mm.at("gallbladder"), {}}, {"trachea", {}, {}}};
  SegmentOptions serial;
  serial.parallel = false;
  const SegmentationResult a = segment_organs(ph.ct, req, {}, np);
  const SegmentationResult b = segment_organs(ph.ct, req, serial, np);
  EXPECT_TRUE(a.labels.labels == b.labels.labels);
  for (std::size_t i = 0; i < a.organs.size(); ++i) EXPECT_EQ(contours_json(a.organs[i]), contours_json(b.organs[i]));
}

TEST(SegmentBadInput, SeedsOutsideTheImageOrInTheWrongTissueAreRefused) {
  const Phantom& ph = phantom();
  NullProgress np;
  const auto [lo, hi] = ph.ct.grid.bounds_lps_mm();
  const Eigen::Vector3d outside = hi + Eigen::Vector3d(50, 50, 50);
  const Eigen::Vector3d air = ph.ct.grid.index_to_lps_mm({3, 3, double(ph.ct.grid.size_vox[2] / 2)});
  const Eigen::Vector3d liver = ph.seeds_lps_mm.at("liver");
  for (const auto& [what, seed] : std::vector<std::pair<std::string, Eigen::Vector3d>>{
           {"outside", outside}, {"air", air}, {"liver", liver}}) {
    try {
      segment_organs(ph.ct, {{"gallbladder", seed, {}}}, {}, np);
      ADD_FAILURE() << "a seed in " << what << " was accepted";
    } catch (const SegmentationError& e) {
      EXPECT_EQ(e.code(), ExitCode::bad_seed) << what;
      EXPECT_NE(std::string(e.what()).find("gallbladder"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("mm LPS"), std::string::npos) << e.what();  // names the seed
    }
  }
  try {
    segment_organs(ph.ct, {{"spleen", {}, {}}}, {}, np);
    ADD_FAILURE() << "an organ without a preset was accepted";
  } catch (const SegmentationError& e) {
    EXPECT_EQ(e.code(), ExitCode::organ_not_found);
  }
}

TEST(SegmentBadInput, NoTracheaInAnAbdominalScanIsAnErrorNotAnEmptyLabel) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const Volume v = load(real("abdomen-ct-3mm/ct.nii.gz"));
  NullProgress np;
  try {
    segment_organs(v, {{"trachea", {}, {}}}, {}, np);
    ADD_FAILURE() << "a trachea was reported in an abdominal CT";
  } catch (const SegmentationError& e) {
    EXPECT_EQ(e.code(), ExitCode::organ_not_found);
  }
}

TEST(SegmentReal, GallbladderFromOneSeedAndFromSeedsMoved3mm) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const Volume v = load(real("abdomen-ct-3mm/ct.nii.gz"));
  const LabelMap ref = read_label_map(real("abdomen-ct-3mm/gallbladder-reference.nii.gz"));
  const Eigen::Vector3d seed = organsmith::testing::seed_at_centre(ref);
  std::vector<Eigen::Vector3d> seeds{seed};
  for (int axis = 0; axis < 3; ++axis)
    for (double d : {-3.0, 3.0}) {
      Eigen::Vector3d s = seed;
      s[axis] += d;
      seeds.push_back(s);
    }
  NullProgress np;
  for (const auto& s : seeds) {
    const SegmentationResult r = segment_organs(v, {{"gallbladder", s, {}}}, organsmith::testing::sweep_segment_options(), np);
    const Score sc = score(ref, 0, r.labels, 1);
    std::printf("real gallbladder, seed (%.1f, %.1f, %.1f): Dice %.4f, volume error %+.1f %%\n", s.x(), s.y(), s.z(),
                sc.dice, 100 * sc.volume_error);
    // Issue targets: Dice ≥ 0.86 and |volume error| ≤ 15 % for every one of the 7 seeds
    // (reached: Dice 0.879–0.888, volume −5.0 % to −2.7 %).
    EXPECT_GE(sc.dice, 0.86) << "seed " << s.transpose();
    EXPECT_LE(std::abs(sc.volume_error), 0.15) << "seed " << s.transpose();
  }
}

TEST(SegmentReal, TracheaWithoutSeedOn8mmChestCt) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const Volume v = load(real("chest-dicom-8mm/dicom"));
  const LabelMap ref = read_label_map(real("chest-dicom-8mm/trachea-reference.nii.gz"));
  NullProgress np;
  const SegmentationResult r = segment_organs(v, {{"trachea", {}, {}}}, {}, np);
  const Score sc = score(ref, 0, r.labels, 2);
  std::printf("real trachea: Dice %.4f, volume error %+.1f %%\n", sc.dice, 100 * sc.volume_error);
  // The reference now covers the two cranial slices it had missed (cervical trachea). Issue 15
  // keeps the trachea at Dice ≥ 0.97; reached 0.995.
  EXPECT_GE(sc.dice, 0.97);
}
