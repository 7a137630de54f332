// Off-screen snapshots: every view exists, has the requested size, is not blank, shows the
// organ's colour, and is byte-identical across two runs.

#include "core/progress.h"
#include "tests/support/test_support.h"
#include "viewer/display.h"
#include "viewer/label_surface.h"
#include "viewer/snapshot.h"
#include "viewer_fixture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>

using namespace organsmith;
using namespace organsmith::testing;
namespace fs = std::filesystem;

namespace {

std::string file_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace

TEST(LabelSurface, ClosedOutwardAndNearTheVoxelVolume) {
  auto t = make_test_scene();
  const SurfaceMesh m = label_surface(t->labels, 1);
  ASSERT_GT(m.triangles.size(), 100u);
  const double voxel_mm3 = t->labels.volume_ml(1) * 1000.0;
  // Outward (positive) and within 15 % of the voxel volume: smoothing barely shrinks it.
  EXPECT_GT(m.signed_volume_mm3(), 0.85 * voxel_mm3);
  EXPECT_LT(m.signed_volume_mm3(), 1.15 * voxel_mm3);
  EXPECT_TRUE(label_surface(t->labels, 77).triangles.empty());
}

TEST(Snapshot, EveryViewExistsHasTheSizeIsNotBlankAndIsReproducible) {
  auto t = make_test_scene();
  ScratchDir a("viewer-a"), b("viewer-b");
  SnapshotOptions o;
  o.width_px = 800;
  o.height_px = 600;
  NullProgress progress;
  const auto first = render_snapshots(t->scene, o, a.path(), progress);
  const auto second = render_snapshots(t->scene, o, b.path(), progress);
  const auto names = snapshot_view_names(t->scene, o);
  ASSERT_EQ(first.size(), names.size());
  // 2 organ views, the overview, 3 slices × 2 organs, one tet cut, two plots.
  EXPECT_EQ(names.size(), 2u + 1u + 6u + 1u + 2u);
  const char* keep = std::getenv("ORGANSMITH_KEEP_SNAPSHOTS");  // to look at them
  for (std::size_t i = 0; i < first.size(); ++i) {
    SCOPED_TRACE(names[i]);
    if (keep) fs::copy_file(first[i], fs::path(keep) / first[i].filename(), fs::copy_options::overwrite_existing);
    ASSERT_TRUE(fs::exists(first[i]));
    const RgbImage img = read_png(first[i]);
    EXPECT_EQ(img.width_px, 800);
    EXPECT_EQ(img.height_px, 600);
    EXPECT_GT(grey_variance(img), 100.0) << "looks blank";
    EXPECT_EQ(file_bytes(first[i]), file_bytes(second[i])) << "differs between two runs";
  }
}

TEST(Snapshot, OrganViewsShowTheOrganColour) {
  auto t = make_test_scene();
  SnapshotOptions o;
  o.views = {ViewKind::organ_3d, ViewKind::slices};
  SnapshotRenderer r(o);
  for (const std::string organ : {"gallbladder", "trachea"}) {
    SCOPED_TRACE(organ);
    const RgbImage model = r.render(t->scene, "3d_" + organ);
    EXPECT_EQ(model.width_px, 1024);
    EXPECT_EQ(model.height_px, 768);
    EXPECT_GT(count_hue(model, organ_colour(organ)), 2000u);
    // The slice outline is drawn in the organ's colour at full brightness, unlit.
    const Rgb c = organ_colour(organ);
    const double m = std::max({c.r, c.g, c.b});
    const RgbImage slice = r.render(t->scene, "slice_" + organ + "_axial");
    EXPECT_GT(count_colour(slice, Rgb{c.r / m, c.g / m, c.b / m}, 12), 50u);
  }
  // The other organ's colour is absent from an organ's own view.
  const RgbImage gb = r.render(t->scene, "3d_gallbladder");
  EXPECT_LT(count_hue(gb, organ_colour("trachea")), 50u);
}

TEST(Snapshot, TetCutShowsQualityColoursAndPlotsDrawTheirSeries) {
  auto t = make_test_scene();
  SnapshotOptions o;
  SnapshotRenderer r(o);
  const RgbImage tets = r.render(t->scene, "tets_gallbladder");
  EXPECT_GT(grey_variance(tets), 100.0);
  // Kuhn tets have radius ratio ≈ 0.72: yellow-green, not the grey of the background.
  std::size_t coloured = 0;
  for (std::size_t i = 0; i + 2 < tets.rgb.size(); i += 3)
    coloured += (std::abs(tets.rgb[i] - tets.rgb[i + 2]) > 80) ? 1 : 0;
  EXPECT_GT(coloured, 5000u);
  const RgbImage fit = r.render(t->scene, "plot_fit");
  EXPECT_GT(count_hue(fit, Rgb{0.85, 0.2, 0.1}), 200u) << "the fitted curve is missing";
  EXPECT_THROW(r.render(t->scene, "no_such_view"), UsageError);
}

TEST(Snapshot, SizeOptionIsHonouredAndBadSizesAreRefused) {
  auto t = make_test_scene();
  SnapshotOptions o;
  o.width_px = 640;
  o.height_px = 480;
  SnapshotRenderer r(o);
  const RgbImage img = r.render(t->scene, "3d_overview");
  EXPECT_EQ(img.width_px, 640);
  EXPECT_EQ(img.height_px, 480);
  SnapshotOptions bad;
  bad.width_px = 10;
  EXPECT_THROW(SnapshotRenderer{bad}, UsageError);
}

TEST(Display, NoXServerAndNoXvfbNamesTheDebianPackage) {
  DisplayOptions o;
  o.display = "";
  o.xvfb_program = "organsmith-no-such-xvfb";
  // Only meaningful without a display: with DISPLAY set the session would use it.
  if (std::getenv("DISPLAY")) GTEST_SKIP() << "DISPLAY is set";
  try {
    DisplaySession s(o);
    FAIL() << "expected DisplayError";
  } catch (const DisplayError& e) {
    EXPECT_NE(std::string(e.what()).find("xvfb"), std::string::npos) << e.what();
    EXPECT_EQ(e.code(), ExitCode::output);
  }
}

TEST(Display, PrivateXvfbIsStartedAndStopped) {
  if (std::getenv("DISPLAY")) GTEST_SKIP() << "DISPLAY is set";
  std::string name;
  {
    DisplaySession s;
    EXPECT_TRUE(s.private_xvfb());
    name = s.name();
    ASSERT_FALSE(name.empty());
    EXPECT_TRUE(fs::exists("/tmp/.X11-unix/X" + name.substr(1)));
  }
  EXPECT_FALSE(fs::exists("/tmp/.X11-unix/X" + name.substr(1))) << "Xvfb " << name << " still running";
}

TEST(SnapshotCli, WritesWhatExistsAndSaysWhatIsMissing) {
  ScratchDir out("viewer-cli");
  fs::copy(small_phantom_dir(), out / "phantom", fs::copy_options::recursive);
  const CliResult r = run_cli("snapshot '" + out.path().string() + "' --size 640x480 --views organs,slices");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("not found"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("mesh"), std::string::npos) << r.output;
  const fs::path snaps = out / "snapshots";
  for (const std::string name : {"3d_gallbladder", "3d_trachea", "slice_gallbladder_axial", "slice_trachea_sagittal"}) {
    SCOPED_TRACE(name);
    ASSERT_TRUE(fs::exists(snaps / (name + ".png")));
    const RgbImage img = read_png(snaps / (name + ".png"));
    EXPECT_EQ(img.width_px, 640);
    EXPECT_EQ(img.height_px, 480);
  }
  EXPECT_FALSE(fs::exists(snaps / "3d_overview.png")) << "--views organs,slices excludes the overview";
  // Nothing staged is left behind.
  for (const auto& e : fs::directory_iterator(out.path()))
    EXPECT_EQ(e.path().filename().string().find("snapshots.staging"), std::string::npos) << e.path();

  EXPECT_EQ(run_cli("snapshot '" + out.path().string() + "' --size 12by7").exit_code, 2);
  EXPECT_EQ(run_cli("snapshot '" + (out / "absent").string() + "'").exit_code, 3);
}

namespace {

void write_text(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

}  // namespace

TEST(SnapshotCli, PlotsTheMaterialsCalibrationFitsAndMonteCarloResults) {
  ScratchDir out("viewer-plots");
  // The attach stage's materials.json (one region), a `calibrate` result and an `uncertainty
  // --method mc` result in subdirectories.
  write_text(out / "materials.json", R"({"regions": {"gallbladder_wall": {"preset": "fung-wall/table-5.1.1/mean",
    "model": "fung-wall", "constants": {}, "source": "test",
    "parameters": [{"name": "c", "value": 19.11, "unit": "Pa"}, {"name": "a1", "value": 17.06, "unit": "1"},
                   {"name": "a2", "value": 18.25, "unit": "1"}, {"name": "a4", "value": 6.59, "unit": "1"}]}}})");
  std::string fit = "specimen,load,stretch,lateral_stretch,stress_pa,model_stress_pa,residual_pa\n";
  for (int i = 1; i <= 20; ++i)
    for (const char* load : {"uniaxial-circumferential", "uniaxial-longitudinal"}) {
      const double l = 1 + 0.015 * i, k = load[9] == 'c' ? 6.0 : 9.0, m = 20.0 * (std::exp(k * (l - 1)) - 1);
      fit += std::string("s1,") + load + "," + std::to_string(l) + ",1," + std::to_string(m * 1.03) + "," +
             std::to_string(m) + "," + std::to_string(0.03 * m) + "\n";
    }
  write_text(out / "calibration" / "fit_a" / "fit.csv", fit);
  write_text(out / "calibration" / "fit_a" / "params.json",
             R"({"model": "fung-wall", "points": 40, "r2": 0.99, "rmse": 3.2, "data": "/somewhere/wall.csv"})");
  std::string cdf = "stretch,probability,stress_pa\n";
  for (const double s : {1.2, 1.4})
    for (int i = 0; i <= 100; ++i)
      cdf += std::to_string(s) + "," + std::to_string(i / 100.0) + "," + std::to_string((s - 1) * 1e4 * (0.5 + i / 100.0)) + "\n";
  write_text(out / "calibration" / "mc_b" / "cdf.csv", cdf);
  write_text(out / "calibration" / "mc_b" / "summary.json",
             R"({"method": "monte-carlo", "preset": "p", "samples": 100, "spread": "sd"})");

  const CliResult r = run_cli("snapshot '" + out.path().string() + "' --views plots --size 640x480");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const fs::path snaps = out / "snapshots";
  for (const std::string name : {"plot_materials", "plot_mc_gallbladder_wall", "plot_fit_fit_a", "plot_cdf_mc_b"}) {
    SCOPED_TRACE(name);
    ASSERT_TRUE(fs::exists(snaps / (name + ".png"))) << r.output;
    const RgbImage img = read_png(snaps / (name + ".png"));
    EXPECT_EQ(img.width_px, 640);
    EXPECT_GT(grey_variance(img), 100.0);
  }
  // The fit: measured and fitted series of both load cases, in the first two series colours
  // (blue, orange); nothing else is drawn in orange.
  const RgbImage fit_png = read_png(snaps / "plot_fit_fit_a.png");
  EXPECT_GT(count_hue(fit_png, Rgb{0.0, 0.45, 0.70}), 300u) << "circumferential series missing";
  EXPECT_GT(count_hue(fit_png, Rgb{0.84, 0.37, 0.0}), 300u) << "longitudinal series missing";
  // The materials plot: the law and its band (one region: one colour).
  const RgbImage laws = read_png(snaps / "plot_materials.png");
  EXPECT_GT(count_hue(laws, Rgb{0.0, 0.45, 0.70}), 300u);
  EXPECT_LT(count_hue(laws, Rgb{0.84, 0.37, 0.0}), 50u);

  // A named calibration directory that does not exist is an input error.
  EXPECT_EQ(run_cli("snapshot '" + out.path().string() + "' --views plots --calibration '" +
                    (out / "nope").string() + "'").exit_code,
            2);  // CLI11 rejects a missing directory as a usage error
}
