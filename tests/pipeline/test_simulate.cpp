// Over 400 lines: each test runs CalculiX on one organ and case and checks its answer against a
// closed-form estimate; the estimates (thin-walled shell, ring section, flat punch) and the shared
// case runner belong beside the tests that use them.
// The organs' load cases run unedited in CalculiX through `organsmith run` ([stages.simulate]) and
// `organsmith simulate`: converged, the fixed set's reaction balances the load (the probe's force,
// or the pressure integrated over the deformed loaded faces), and the answer lies within an order of
// magnitude of a closed-form estimate from the exported material: the gallbladder's indentation on
// the phantom, its pressure case and the trachea on real scans. Pressures are chosen inside the thesis law's
// calibrated range (see README "Simulation"): at the physiological defaults (1.5 and 2 kPa) the
// thesis' gallbladder wall law is driven far past it. Needs calculix-ccx; skipped without it.

#include "meshing/export.h"
#include "physics/materials/solver_fit.h"
#include "pipeline/io/image_io.h"
#include "pipeline/stages/simulate.h"
#include "viewer/image.h"

#include "tests/support/test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

namespace fs = std::filesystem;
using namespace organsmith;
using organsmith::testing::quoted;
using organsmith::testing::read_json;
using organsmith::testing::run_cli;

namespace {

bool have_ccx() { return std::system("command -v ccx > /dev/null 2>&1") == 0; }

/// Pressure (Pa) that holds a thin-walled tube (plane strain along its axis, both ends fixed) or
/// sphere of the exported Ogden solid at hoop stretch λ: tube p = σθ t0/(r0 λ²) with
/// σθ = Σ 2μ/α (λ^α − λ^−α); sphere p = 2 t0 T_eq(λ)/(r0 λ²).
double thin_wall_pressure_Pa(const nlohmann::json& solver, double l, double t0, double r0, bool sphere) {
  double s = 0;
  for (std::size_t k = 0; k < solver["mu_Pa"].size(); ++k) {
    const double mu = solver["mu_Pa"][k], a = solver["alpha"][k];
    s += sphere ? 2 * mu / a * (std::pow(l, a - 1) - std::pow(l, -2 * a - 1)) : 2 * mu / a * (std::pow(l, a) - std::pow(l, -a));
  }
  return sphere ? 2 * t0 * s / (r0 * l * l) : s * t0 / (r0 * l * l);
}

/// The hoop stretch at which the thin-walled estimate holds pressure p (bisection).
double thin_wall_stretch(const nlohmann::json& solver, double p_Pa, double t0, double r0, bool sphere) {
  double lo = 1.0, hi = 2.0;
  for (int i = 0; i < 80; ++i) {
    const double mid = 0.5 * (lo + hi);
    (thin_wall_pressure_Pa(solver, mid, t0, r0, sphere) < p_Pa ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

/// The organ's load case in `out` converged and balances; the lumen grows by about what a
/// thin-walled estimate of the exported wall material says (within an order of magnitude): the
/// lumen as a sphere (gallbladder) or a tube of its length (trachea) of the same volume, the wall
/// thickness of the registry.
void expect_load_case_answered(const fs::path& out, const std::string& organ, double p_Pa) {
  const nlohmann::json materials = read_json(out / "materials.json");
  const nlohmann::json s = read_json(out / "simulation" / (organ + ".json"));
  EXPECT_TRUE(s["converged"].get<bool>());
  EXPECT_DOUBLE_EQ(s["load_factor"].get<double>(), 1.0);
  // Equilibrium: the reaction at the fixed set against the pressure integrated over the deformed
  // loaded faces (computed by organsmith, not read from the solver), relative to p Σ|A|.
  EXPECT_LT(s["reaction_balance_error"].get<double>(), 0.01) << s.dump(2);
  EXPECT_GT(s["lumen_volume_change_mm3"].get<double>(), 0.0);
  const bool sphere = organ == "gallbladder";
  const double V0 = s["lumen_volume_mm3"].get<double>();
  const double t0 = sphere ? 2.0 : 2.5;
  double r0 = std::cbrt(3 * V0 / (4 * M_PI));
  if (!sphere) {
    // Tube length from the mesh's extent along the cut axis (superior–inferior).
    const auto vtu = read_solver_inp(out / "meshes" / organ / (organ + ".inp"));
    double zlo = 1e300, zhi = -1e300;
    for (const auto& x : vtu.model.nodes_lps_mm) zlo = std::min(zlo, x.z()), zhi = std::max(zhi, x.z());
    r0 = std::sqrt(V0 / (M_PI * (zhi - zlo)));
  }
  const double l = thin_wall_stretch(materials["regions"][organ + "_wall"]["solver"], p_Pa, t0, r0, sphere);
  const double estimate_mm3 = V0 * (sphere ? std::pow(l, 3) - 1 : l * l - 1);
  const double ratio = s["lumen_volume_change_mm3"].get<double>() / estimate_mm3;
  std::printf("%s: %d increments, %.1f s; max displacement %.3g mm; lumen %.4g ml, change %.4g ml, thin-walled %.4g ml "
              "(hoop stretch %.3f, r0 %.2f mm): ratio %.2f; balance %.2g\n",
              organ.c_str(), s["increments"].get<int>(), s["solver_seconds"].get<double>(), s["max_displacement_mm"].get<double>(),
              V0 / 1000, s["lumen_volume_change_mm3"].get<double>() / 1000, estimate_mm3 / 1000, l, r0, ratio,
              s["reaction_balance_error"].get<double>());
  EXPECT_GT(ratio, 0.1);
  EXPECT_LT(ratio, 10.0);
  EXPECT_TRUE(fs::exists(out / "simulation" / (organ + ".vtu")));
  EXPECT_TRUE(fs::exists(out / "simulation" / (organ + "_solver") / "solver.log"));
}

/// The trachea's load case in `out` converged and balances, and its lumen widens by what a
/// thin-walled estimate of its two tissues says. Hoop stress σ = p r0 / t0; a ring section
/// stretches its cartilage arc (fraction f of the circumference, data/organs.toml) and its
/// membrane in series, Δr = r0 σ (f/Ec + (1 − f)/Em); between rings (1 − h/pitch of the length)
/// the annular ligament alone, Δr = r0 σ / Em. The lower bound holds the ligament to the rings
/// (ring sections everywhere), the upper lets it widen alone; the length-weighted mean of the two
/// is the estimate. E = 6 C10 (incompressible neo-Hookean). The mean Δr of the model is the lumen's
/// volume change over its side area, ΔV / (2π r0 L).
void expect_trachea_answered(const fs::path& out, double p_Pa) {
  const nlohmann::json materials = read_json(out / "materials.json");
  const nlohmann::json s = read_json(out / "simulation" / "trachea.json");
  EXPECT_TRUE(s["converged"].get<bool>());
  EXPECT_DOUBLE_EQ(s["load_factor"].get<double>(), 1.0);
  EXPECT_LT(s["reaction_balance_error"].get<double>(), 0.01) << s.dump(2);
  const double Ec = 6 * materials["regions"]["trachea_cartilage"]["solver"]["inp"]["C10_Pa"].get<double>();
  const double Em = 6 * materials["regions"]["trachea_membrane"]["solver"]["inp"]["C10_Pa"].get<double>();
  const auto inp = read_solver_inp(out / "meshes" / "trachea" / "trachea.inp");
  double zlo = 1e300, zhi = -1e300;
  for (const auto& x : inp.model.nodes_lps_mm) zlo = std::min(zlo, x.z()), zhi = std::max(zhi, x.z());
  const double V0 = s["lumen_volume_mm3"].get<double>(), L = zhi - zlo, r0 = std::sqrt(V0 / (M_PI * L)), t0 = 2.5;
  const double f = 270.0 / 360.0, ring_fraction = 4.0 / 6.1;  // data/organs.toml [trachea] rings
  const double sigma = p_Pa * r0 / t0;
  const double ring = r0 * sigma * (f / Ec + (1 - f) / Em), ligament = r0 * sigma / Em;
  const double estimate = ring_fraction * ring + (1 - ring_fraction) * ligament;
  const double dr = s["lumen_volume_change_mm3"].get<double>() / (2 * M_PI * r0 * L);
  std::printf("trachea: %d increments, %.1f s; lumen r0 %.2f mm over %.1f mm; mean radial expansion %.4g mm; thin-walled: "
              "ring section %.4g mm, ligament %.4g mm, length-weighted %.4g mm (ratio %.2f); balance %.2g\n",
              s["increments"].get<int>(), s["solver_seconds"].get<double>(), r0, L, dr, ring, ligament, estimate, dr / estimate,
              s["reaction_balance_error"].get<double>());
  // Between the bounds (the rings hold the ligaments back, but not completely).
  EXPECT_GT(dr, 0.5 * ring);
  EXPECT_LT(dr, ligament);
  EXPECT_TRUE(fs::exists(out / "simulation" / "trachea.vtu"));
}

/// Runs a one-organ case on a real scan (`input`, the organ from `label_map`) to the simulate
/// stage with `mesh_options` (lines of [stages.mesh]) and the simulate stage on; the output folder.
fs::path run_real_case(const fs::path& tmp, const fs::path& input, const std::string& organ, const fs::path& label_map,
                       const std::string& mesh_options) {
  const fs::path out = tmp / "out";
  std::ofstream(tmp / "case.toml") << "[case]\ninput = " << quoted(input) << "\n[[organ]]\nname = \"" << organ
                                   << "\"\nlabel_map = " << quoted(label_map) << "\n[stages.mesh]\n" << mesh_options
                                   << "[stages.simulate]\nenabled = true\n";
  const auto r = run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) + " --until simulate");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  return out;
}

/// A text file's whole content.
std::string file_text(const fs::path& p) {
  std::ifstream in(p);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace

// The thesis' indentation test (§5.1.2) on the phantom's gallbladder at the registry's defaults
// (the 5 mm probe at the centre of the free surface opposite the liver bed, depth from the
// organ's thickness): the curve rises with depth, the probe's force and the liver bed's reaction
// balance, the small-depth stiffness is that of a rigid flat punch on an incompressible solid of
// the organ's small-strain modulus (Sneddon: k = 8 μ a) within an order of magnitude, and the
// state the figures are taken at keeps every region's 99th-percentile stretch inside its
// calibrated range. Coarse (6 mm) tetrahedra keep the solver to seconds. Then `simulate` on the
// run's directory skips the unchanged stage, and one out of time stops with exit 71 and leaves
// the results as they were.
TEST(Simulate, IndentationCurveRisesBalancesAndStaysInRange) {
  if (!have_ccx()) GTEST_SKIP() << "CalculiX (ccx) not installed: apt-get install calculix-ccx (scripts/install-deps)";
  organsmith::testing::ScratchDir tmp("simulate-indent");
  const fs::path out = tmp / "out";
  {
    std::ofstream c(tmp / "case.toml");
    c << "[case]\ninput = \"phantom\"\n[phantom]\nsize = 256\n[[organ]]\nname = \"gallbladder\"\n"
         "[stages.mesh]\nedge_mm = 3.0\ntet_edge_mm = 6.0\nformats = [\"inp\"]\n[stages.simulate]\nenabled = true\n";
  }
  const auto r = run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) + " --until simulate");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json s = read_json(out / "simulation" / "gallbladder.json");
  ASSERT_TRUE(s.contains("indentation")) << s.dump(2);
  const nlohmann::json& ind = s["indentation"];
  EXPECT_TRUE(s["converged"].get<bool>()) << s.dump(2);
  EXPECT_DOUBLE_EQ(ind["probe_diameter_mm"].get<double>(), 5.0);
  const auto& curve = ind["curve"];
  ASSERT_GE(curve.size(), 10u) << ind.dump(2);
  for (std::size_t i = 1; i < curve.size(); ++i) {
    EXPECT_GT(curve[i][0].get<double>(), curve[i - 1][0].get<double>()) << "depth at point " << i;
    EXPECT_GT(curve[i][1].get<double>(), curve[i - 1][1].get<double>()) << "force at point " << i;
  }
  EXPECT_LT(ind["reaction_balance_error"].get<double>(), 0.01) << ind.dump(2);
  EXPECT_NEAR(-ind["fixed_reaction_N"].get<double>(), ind["probe_force_N"].get<double>(),
              0.01 * ind["probe_force_N"].get<double>());
  // Sneddon's flat punch on an incompressible half-space, k = 8 μ a, with the body's μ0.
  const nlohmann::json materials = read_json(out / "materials.json");
  double mu0_Pa = 0;
  for (double mu : materials["regions"]["gallbladder_body"]["solver"]["mu_Pa"]) mu0_Pa += mu;
  const double k_punch = 8 * mu0_Pa * 1e-6 * 2.5;  // N/mm
  const double k = ind["stiffness_N_per_mm_at_1mm"].get<double>();
  std::printf("indentation: %zu points to %.3g mm (%s), %.3g N; k(1 mm) %.3g N/mm, flat punch 8 mu a %.3g N/mm (ratio "
              "%.2f); %d increments, %.1f s\n",
              curve.size(), ind["depth_mm"].get<double>(), ind["limited_by"].get<std::string>().c_str(),
              curve.back()[1].get<double>(), k, k_punch, k / k_punch, s["increments"].get<int>(),
              s["solver_seconds"].get<double>());
  EXPECT_GT(k, 0.1 * k_punch);
  EXPECT_LT(k, 10 * k_punch);
  for (const auto& [region, st] : s["principal_stretch"].items()) {
    ASSERT_GT(st["calibrated_max"].get<double>(), 1.0) << region;
    EXPECT_LE(st["p99"].get<double>(), st["calibrated_max"].get<double>() + 1e-6) << region;
  }
  {  // the phantom's liver touches its gallbladder: the fixed set is where it does
    EXPECT_NE(file_text(out / "meshes" / "gallbladder" / "gallbladder.inp").find("gallbladder_liver_bed: the liver bed from the liver label"),
              std::string::npos);
  }

  // `simulate` on the run's directory: the stage is unchanged, so it is skipped (same outputs);
  // out of time it stops with exit 71 and the earlier results stay as they were.
  const auto before = organsmith::testing::file_digests(out / "simulation");  // solver_seconds included: a rerun would differ
  const auto again = run_cli("simulate " + quoted(out));
  EXPECT_EQ(again.exit_code, 0) << again.output;
  EXPECT_EQ(organsmith::testing::file_digests(out / "simulation"), before);
  const auto late = run_cli("simulate " + quoted(out) + " --organ gallbladder --timeout-s 0.5");
  EXPECT_EQ(late.exit_code, 71) << late.output;
  EXPECT_NE(late.output.find("did not finish"), std::string::npos) << late.output;
  EXPECT_EQ(organsmith::testing::file_digests(out / "simulation"), before);
  EXPECT_FALSE(organsmith::testing::has_staging_leftover(out));

  // The haptic model pressed as the solver pressed it: the same 10-node mesh and law give the
  // solver's curve (issue 38 asks for 15 %; the same discretisation should agree to round-off, so
  // 1 % catches a wrong element, law or boundary). The real-time model pressed through its threads
  // at the quasi-static default speed: the force the loop gives the tool follows the solver's
  // curve within the 15 % (what it feels between equilibria is their tangent's
  // extrapolation, so this fails where the equilibria or their response are wrong), the hold feels
  // the same grip's static answer, and the organ is back at rest a second after the tool left.
  const auto ind_run = run_cli("haptics " + quoted(out) + " --indent gallbladder --out " + quoted(tmp / "indent.json"));
  ASSERT_EQ(ind_run.exit_code, 0) << ind_run.output;
  const nlohmann::json h = read_json(tmp / "indent.json");
  ASSERT_TRUE(h.contains("solver_curve")) << h.dump(2);
  EXPECT_EQ(h["curve"].size(), curve.size() - (curve[0][0].get<double>() == 0.0 ? 1 : 0));
  EXPECT_LT(h["solver_curve"]["largest_relative_difference_past_20pct_depth"].get<double>(), 0.01) << h["solver_curve"].dump(2);
  const nlohmann::json& press = h["fe"]["press"];
  EXPECT_GT(press["peak_force_N"].get<double>(), 0.0) << h["fe"].dump(2);
  ASSERT_TRUE(press.contains("felt_curve_against_solver")) << h["fe"].dump(2);
  const nlohmann::json& felt = press["felt_curve_against_solver"];
  EXPECT_GE(felt["depth_mm_solver_N_press_N_relative_difference"].size(), curve.size() / 2) << felt.dump(2);
  EXPECT_LT(felt["largest_relative_difference_past_20pct_depth"].get<double>(), 0.15) << felt.dump(2);
  EXPECT_NEAR(press["force_at_end_of_hold_N"].get<double>(), press["static_force_same_grip_N"].get<double>(),
              0.05 * press["static_force_same_grip_N"].get<double>());
  EXPECT_LT(press["rest_fraction_of_depth"].get<double>(), 0.01) << h["fe"].dump(2);
  std::printf("haptics --indent: curve within %.2g of CalculiX past 20 %% of the depth; real-time model %d nodes, force felt at "
              "%.2g mm/s within %.2g of CalculiX, equilibria %.3g Hz (p50 %.3g ms), display update p99 %.3g ms, force loop %.0f Hz\n",
              h["solver_curve"]["largest_relative_difference_past_20pct_depth"].get<double>(), h["fe"]["nodes"].get<int>(),
              press["speed_mm_per_s"].get<double>(), felt["largest_relative_difference_past_20pct_depth"].get<double>(),
              h["fe"]["equilibrium_hz"].get<double>(), h["fe"]["equilibrium_ms_p50"].get<double>(),
              h["fe"]["update_ms_p99"].get<double>(), h["fe"]["force_rate_hz"].get<double>());
  // Its picture, and the snapshot stage's when the case asks for it (the other stages reused).
  EXPECT_TRUE(fs::exists(tmp / "indent.png"));
  std::ofstream(tmp / "case.toml", std::ios::app) << "[stages.snapshot]\nviews = [\"organs\"]\nwidth_px = 640\nheight_px = 480\n"
                                                     "indent = [\"gallbladder\"]\n";
  const auto snap = run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out));
  ASSERT_EQ(snap.exit_code, 0) << snap.output;
  const fs::path png = out / "snapshots" / "indent_gallbladder.png";
  ASSERT_TRUE(fs::exists(png)) << snap.output;
  std::ifstream pin(png, std::ios::binary);
  unsigned char header[24] = {};
  pin.read(reinterpret_cast<char*>(header), 24);
  auto be32 = [&](int at) { return (header[at] << 24) | (header[at + 1] << 16) | (header[at + 2] << 8) | header[at + 3]; };
  EXPECT_EQ(be32(16), 640);
  EXPECT_EQ(be32(20), 480);
  EXPECT_NE(snap.output.find("snapshot: indent_gallbladder.png"), std::string::npos) << snap.output;
}

// The trachea pressed on its anterior wall ([stages.mesh] indentation = ["trachea"]): the 5 mm
// probe on the front of the wall halfway between the cuts, pressed posteriorly, both cuts held.
// CalculiX's curve rises and balances; organsmith's quasi-static 10-node model, pressed the same
// way, gives the same curve (the same discretisation and law: 1 % catches a wrong element, law or
// boundary). Coarse tetrahedra keep the solver to seconds.
TEST(Simulate, TracheaPressedOnItsAnteriorWall) {
  if (!have_ccx()) GTEST_SKIP() << "CalculiX (ccx) not installed: apt-get install calculix-ccx (scripts/install-deps)";
  organsmith::testing::ScratchDir tmp("simulate-trachea-probe");
  const fs::path out = tmp / "out";
  {
    std::ofstream c(tmp / "case.toml");
    c << "[case]\ninput = \"phantom\"\n[phantom]\nsize = 256\n[[organ]]\nname = \"trachea\"\n"
         "[stages.mesh]\nedge_mm = 4.0\ntet_edge_mm = 6.0\nquality_gate = \"report\"\nformats = [\"inp\"]\n"
         "indentation = [\"trachea\"]\n[stages.simulate]\nenabled = true\n";
  }
  const auto r = run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) + " --until simulate");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(file_text(out / "meshes" / "trachea" / "trachea.inp").find("the front of the anterior wall halfway between the cuts"),
            std::string::npos);
  const nlohmann::json s = read_json(out / "simulation" / "trachea.json");
  ASSERT_TRUE(s.contains("indentation")) << s.dump(2);
  const nlohmann::json& ind = s["indentation"];
  EXPECT_TRUE(s["converged"].get<bool>()) << s.dump(2);
  // Posterior (+y in LPS) into the front wall.
  EXPECT_GT(ind["direction"][1].get<double>(), 0.9) << ind.dump(2);
  const auto& curve = ind["curve"];
  ASSERT_GE(curve.size(), 5u) << ind.dump(2);
  for (std::size_t i = 1; i < curve.size(); ++i)
    EXPECT_GT(curve[i][1].get<double>(), curve[i - 1][1].get<double>()) << "force at point " << i;
  EXPECT_LT(ind["reaction_balance_error"].get<double>(), 0.01) << ind.dump(2);

  const auto ind_run = run_cli("haptics " + quoted(out) + " --indent trachea --out " + quoted(tmp / "indent.json"));
  ASSERT_EQ(ind_run.exit_code, 0) << ind_run.output;
  const nlohmann::json h = read_json(tmp / "indent.json");
  ASSERT_TRUE(h.contains("solver_curve")) << h.dump(2);
  EXPECT_LT(h["solver_curve"]["largest_relative_difference_past_20pct_depth"].get<double>(), 0.01) << h["solver_curve"].dump(2);
  // The real-time press's felt curve is reported, not checked here: a tube's wall is meshed at its
  // thickness, and this 10-node model's equilibria come seldom for the quasi-static speed (10–14 %
  // against the 15 %, TISSUE.md). Withdrawn, the tool lets go and the wall is at rest.
  const nlohmann::json& press = h["fe"]["press"];
  EXPECT_LT(press["rest_fraction_of_depth"].get<double>(), 0.01) << h["fe"].dump(2);
  std::printf("trachea probe: %zu points to %.3g mm, %.3g N; haptics --indent within %.2g of CalculiX past 20 %% of the "
              "depth; real-time model %d nodes, equilibria %.3g Hz, force felt within %.3g of CalculiX, rest %.3g of the depth\n",
              curve.size(), ind["depth_mm"].get<double>(), curve.back()[1].get<double>(),
              h["solver_curve"]["largest_relative_difference_past_20pct_depth"].get<double>(), h["fe"]["nodes"].get<int>(),
              h["fe"]["equilibrium_hz"].get<double>(),
              press.contains("felt_curve_against_solver") ? press["felt_curve_against_solver"]["largest_relative_difference_past_20pct_depth"].get<double>() : -1.0,
              press["rest_fraction_of_depth"].get<double>());
}

// A scan the phantom is not: the gallbladder of a 3 mm abdominal CT (the reference mask, meshed at
// a 3 mm edge), its liver bed found in the CT itself (no liver label), run unedited. Fixed on the
// flat cranial lid the liver's usual direction picks, it did not converge; fixed where the CT says
// the liver holds it, it does (and the fold gate, asked for here, smooths the staircase: half the
// solver's time).
TEST(Simulate, RealGallbladderOnAThreeMillimetreScanConverges) {
  if (!have_ccx()) GTEST_SKIP() << "CalculiX (ccx) not installed: apt-get install calculix-ccx (scripts/install-deps)";
  ORGANSMITH_REQUIRE_REAL_DATA();
  const fs::path data = organsmith::testing::real_data_dir() / "abdomen-ct-3mm";
  organsmith::testing::ScratchDir tmp("simulate-real-gb");
  const fs::path out = run_real_case(tmp.path(), data / "ct.nii.gz", "gallbladder", data / "gallbladder-reference.nii.gz",
                                     "edge_mm = 3.0\ntet_edge_mm = 0\npressure_kPa = { gallbladder = 0.1 }\nformats = [\"inp\", \"vtp\"]\n"
                                     "max_fold_deg = 60\n");
  if (::testing::Test::HasFailure()) return;
  expect_load_case_answered(out, "gallbladder", 100.0);
  EXPECT_NE(file_text(out / "meshes" / "gallbladder" / "gallbladder.inp").find("gallbladder_liver_bed: the liver bed from the CT intensity"),
            std::string::npos)
      << "the fixed set should come from the CT (the case has no liver label)";
  const nlohmann::json q = read_json(out / "meshes" / "gallbladder" / "quality.json");
  EXPECT_LE(q["surfaces"]["gallbladder"]["fold_max_deg"].get<double>(), 60.0);
}

// The trachea of an 8 mm-slice chest CT (DICOM; the reference lumen, meshed at a 3 mm edge), both
// cut ends fixed, run unedited. At this edge its 8 mm staircase costs the lumen 6 % of its volume
// (a gate reported, not enforced here: the solver's answer is what this test checks).
TEST(Simulate, RealTracheaOnAnEightMillimetreScanConverges) {
  if (!have_ccx()) GTEST_SKIP() << "CalculiX (ccx) not installed: apt-get install calculix-ccx (scripts/install-deps)";
  ORGANSMITH_REQUIRE_REAL_DATA();
  const fs::path data = organsmith::testing::real_data_dir() / "chest-dicom-8mm";
  organsmith::testing::ScratchDir tmp("simulate-real-trachea");
  // The reference stores the lumen as 1; the organ registry's trachea label is 2.
  LabelMap lumen = read_label_map(data / "trachea-reference.nii.gz");
  for (auto& v : lumen.labels) v = v == 1 ? 2 : 0;
  write_label_map(lumen, tmp / "trachea.nii.gz");
  const fs::path out = run_real_case(tmp.path(), data / "dicom", "trachea", tmp / "trachea.nii.gz",
                                     "edge_mm = 3.0\nformats = [\"inp\", \"vtp\"]\n"
                                     "quality_gate = \"report\"\n");
  if (::testing::Test::HasFailure()) return;
  expect_trachea_answered(out, 2000.0);  // the registry's airway pressure, 2 kPa
}

TEST(Simulate, WithoutTheSolverOnPathTheErrorNamesThePackage) {
  organsmith::testing::ScratchDir tmp("simulate-nosolver");
  const fs::path out = tmp / "out";
  {
    std::ofstream c(tmp / "case.toml");
    // Coarse on purpose (a 3 s mesh stage): this test is about the missing solver.
    c << "[case]\ninput = \"phantom\"\n[phantom]\nsize = 256\n[[organ]]\nname = \"gallbladder\"\n[stages.mesh]\n"
         "edge_mm = 3.0\ntet_edge_mm = 6.0\nquality_gate = \"report\"\nformats = [\"inp\"]\n";
  }
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) + " --until attach").exit_code, 0);
  // Hide ccx: run the same executable with a PATH that holds no solver.
  const auto r = run_cli("simulate " + quoted(out) + " --solver /nonexistent/ccx");
  EXPECT_EQ(r.exit_code, 70) << r.output;
  EXPECT_NE(r.output.find("calculix-ccx"), std::string::npos) << r.output;
}

TEST(Simulate, ACaseGivesARegionItsOwnCalibration) {
  // A researcher's own curves (here: the Table 5.1.1 mean law with twice its c, to stretch 1.25),
  // calibrated with `organsmith calibrate`, put on the gallbladder wall by the case.
  organsmith::testing::ScratchDir tmp("own-material");
  const auto model = organsmith::physics::make_model("fung-wall");
  {
    std::ofstream csv(tmp / "curves.csv");
    csv << "stretch,stress_pa,direction\n";
    for (const char* dir : {"circumferential", "longitudinal"})
      for (int i = 1; i <= 10; ++i) {
        const double l = 1.0 + 0.025 * i;
        const organsmith::physics::LoadPoint pt{l, 1.0, std::string(dir) == "circumferential"
                                                            ? organsmith::physics::LoadCase::uniaxial_circumferential
                                                            : organsmith::physics::LoadCase::uniaxial_longitudinal};
        const std::vector<double> p = {2 * 19.11, 17.06, 18.25, 6.59};
        csv << l << "," << model->respond_one(pt, p) << "," << dir << "\n";
      }
  }
  const auto cal = run_cli("calibrate --model fung-wall --data " + quoted(tmp / "curves.csv") + " --out " + quoted(tmp / "cal") +
                           " --generations 40 --population 60");
  ASSERT_EQ(cal.exit_code, 0) << cal.output;
  EXPECT_DOUBLE_EQ(read_json(tmp / "cal" / "params.json")["stretch_range"][1].get<double>(), 1.25);
  {
    std::ofstream c(tmp / "case.toml");
    c << "[case]\ninput = \"phantom\"\n[phantom]\nsize = 256\n[[organ]]\nname = \"gallbladder\"\n"
         "[materials]\ngallbladder_wall = \"cal/params.json\"\n[stages.mesh]\nedge_mm = 4.0\nformats = [\"inp\"]\n";
  }
  const auto r = run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(tmp / "out") + " --until attach");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json m = read_json(tmp / "out" / "materials.json")["regions"]["gallbladder_wall"];
  EXPECT_EQ(fs::path(m["calibration"].get<std::string>()), fs::weakly_canonical(tmp / "cal" / "params.json"));
  EXPECT_DOUBLE_EQ(m["solver"]["stretch_range"][1].get<double>(), 1.25);
  EXPECT_LT(m["solver"]["max_relative_error"].get<double>(), 0.05);
  // Twice the preset's c: the fitted solid is about twice as stiff as the preset's at small strain.
  const nlohmann::json preset = read_json(tmp / "out" / "materials.json")["regions"]["gallbladder_body"];
  double mu_own = 0, mu_preset_wall = 0;
  for (double mu : m["solver"]["mu_Pa"]) mu_own += mu;
  const auto preset_fit = organsmith::physics::fit_solver_material(
      organsmith::physics::region_law_from_preset(organsmith::physics::builtin_material_library(), "fung-wall/table-5.1.1/mean"));
  for (double mu : preset_fit.material.ogden_mu_Pa) mu_preset_wall += mu;
  EXPECT_NEAR(mu_own / mu_preset_wall, 2.0, 0.3);
  const std::string inp = organsmith::testing::read_file(tmp / "out" / "meshes" / "gallbladder" / "gallbladder.inp");
  EXPECT_NE(inp.find("params.json"), std::string::npos);
  (void)preset;

  // A reference that is neither a preset nor a calibration: exit 20, naming the key.
  {
    std::ofstream c(tmp / "bad.toml");
    c << "[case]\ninput = \"phantom\"\n[[organ]]\nname = \"gallbladder\"\n[materials]\ngallbladder_wall = \"nope/params.json\"\n";
  }
  const auto bad = run_cli("run " + quoted(tmp / "bad.toml") + " --out " + quoted(tmp / "out2"));
  EXPECT_EQ(bad.exit_code, 20) << bad.output;
  EXPECT_NE(bad.output.find("gallbladder_wall"), std::string::npos) << bad.output;
}

// The material band carried to the solver: `run` with [stages.mesh] material_band writes the
// P5/P50/P95 INPs, which differ from the organ's own only in the material block; `simulate --band`
// runs them and the organ's largest displacement falls as the material stiffens (P5 softest),
// with the law's own answer inside the band. Coarse linear tetrahedra keep it to seconds: the
// band's order, not the answer's accuracy, is what this checks (the organ cases above do that).
// The run also draws the deformed organ coloured by stress.
TEST(Simulate, MaterialBandBracketsTheOrgansAnswer) {
  if (!have_ccx()) GTEST_SKIP() << "CalculiX (ccx) not installed: apt-get install calculix-ccx (scripts/install-deps)";
  organsmith::testing::ScratchDir tmp("simulate-band");
  const fs::path out = tmp / "out";
  {
    std::ofstream c(tmp / "case.toml");
    c << "[case]\ninput = \"phantom\"\n[phantom]\nsize = 128\n[[organ]]\nname = \"trachea\"\n"
         "[stages.mesh]\nedge_mm = 8.0\nlinear_tets = true\nquality_gate = \"report\"\nformats = [\"inp\"]\n"
         "material_band = true\n";
  }
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) + " --until attach").exit_code, 0);
  const nlohmann::json band = read_json(out / "materials.json")["regions"]["trachea_membrane"]["band"];
  ASSERT_TRUE(band.is_object());
  EXPECT_EQ(band["spread"], "sd");
  double last = 0;
  for (const char* v : {"p05", "p50", "p95"}) {
    const double top = band["members"][v]["uniaxial_curve_pa"].back()[1].get<double>();
    EXPECT_GT(top, last) << v;
    last = top;
  }
  // Each variant is the organ's INP with other material constants.
  const auto lines = [](const fs::path& p) {
    std::vector<std::string> v;
    std::ifstream in(p);
    for (std::string l; std::getline(in, l);) v.push_back(l);
    return v;
  };
  const auto own = lines(out / "meshes" / "trachea" / "trachea.inp");
  for (const char* v : {"p05", "p50", "p95"}) {
    const auto var = lines(out / "meshes" / "trachea" / "band" / (std::string("trachea.") + v + ".inp"));
    ASSERT_EQ(var.size(), own.size()) << v;
    bool in_material = false;
    int differing = 0;
    for (std::size_t i = 0; i < own.size(); ++i) {
      if (own[i].rfind("*MATERIAL", 0) == 0) in_material = true;
      if (own[i].rfind("*SOLID SECTION", 0) == 0) in_material = false;
      if (var[i] != own[i]) {
        ++differing;
        EXPECT_TRUE(in_material) << v << " line " << i + 1 << ": " << var[i];
      }
    }
    EXPECT_GT(differing, 0) << v;
  }

  const auto r = run_cli("simulate " + quoted(out) + " --band");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json s = read_json(out / "simulation" / "trachea.json");
  ASSERT_TRUE(s["band"]["all_converged"].get<bool>()) << s.dump(2);
  const auto& runs = s["band"]["variants"];
  const double d05 = runs["p05"]["max_displacement_mm"], d50 = runs["p50"]["max_displacement_mm"],
               d95 = runs["p95"]["max_displacement_mm"], own_d = s["max_displacement_mm"];
  std::printf("largest displacement: P5 material %.3g mm, P50 %.3g, P95 %.3g; the law's own %.3g\n", d05, d50, d95, own_d);
  EXPECT_GT(d05, d50);
  EXPECT_GT(d50, d95);
  EXPECT_GT(own_d, d95);
  EXPECT_LT(own_d, d05);
  EXPECT_DOUBLE_EQ(s["band"]["max_displacement_mm"][0].get<double>(), d95);
  EXPECT_DOUBLE_EQ(s["band"]["max_displacement_mm"][1].get<double>(), d05);
  for (const char* v : {"p05", "p50", "p95"}) EXPECT_LT(runs[v]["reaction_balance_error"].get<double>(), 0.01) << v;
  // The membrane's stretch against its law's calibrated range (stretch 1.3, data/materials.toml).
  const auto& st = s["principal_stretch"]["trachea_membrane"];
  EXPECT_GT(st["max"].get<double>(), 1.0);
  EXPECT_GE(st["max"].get<double>(), st["p99"].get<double>());
  EXPECT_DOUBLE_EQ(st["calibrated_max"].get<double>(), 1.3);
  EXPECT_EQ(st["beyond_calibrated_range"].get<bool>(), st["p99"].get<double>() > 1.3);

  // The picture: the deformed organ in colour (the stress map) on a white ground.
  const RgbImage png = read_png(out / "simulation" / "trachea.png");
  ASSERT_GT(png.width_px, 0);
  std::size_t coloured = 0;
  for (int y = 0; y < png.height_px; ++y)
    for (int x = 0; x < png.width_px; ++x) {
      const std::uint8_t* p = png.pixel(x, y);
      const int hi = std::max({p[0], p[1], p[2]}), lo = std::min({p[0], p[1], p[2]});
      coloured += hi - lo > 80;
    }
  EXPECT_GT(coloured, std::size_t(png.width_px) * png.height_px / 100) << "the stress-coloured organ covers < 1 % of the picture";
}
