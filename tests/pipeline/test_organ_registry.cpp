// The organ registry (data/organs.toml): every stage reads its organs from it, a case adds one
// with its own registry file, and mistakes in a registry are errors naming the organ and key.

#include "core/errors.h"
#include "pipeline/case/case_file.h"
#include "pipeline/case/organ_registry.h"
#include "segmentation/presets.h"
#include "tests/support/test_support.h"
#include "viewer/image.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <set>

using namespace organsmith;
using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;
using organsmith::testing::file_digests;
using organsmith::testing::has_staging_leftover;
using organsmith::testing::quoted;
using organsmith::testing::read_json;
namespace fs = std::filesystem;

namespace {



std::string registry_error(const std::string& text) {
  try {
    parse_organ_registry(text, "/cases/organs.toml", builtin_organ_registry());
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::case_file) << e.what();
    EXPECT_EQ(e.path(), fs::path("/cases/organs.toml"));
    return e.what();
  }
  return {};
}

bool has(const std::string& s, const std::string& needle) { return s.find(needle) != std::string::npos; }

}  // namespace

TEST(OrganRegistry, EmbeddedRegistryHoldsTheModelledAndContextOrgans) {
  const OrganRegistry& r = builtin_organ_registry();
  EXPECT_EQ(r.modelled(), (std::vector<std::string>{"gallbladder", "trachea"}));
  const OrganInfo& gb = r.at("gallbladder");
  EXPECT_EQ(gb.label, 1);
  EXPECT_TRUE(gb.segmented && gb.needs_seed);
  EXPECT_EQ(gb.regions(), (std::vector<std::string>{"gallbladder_wall", "gallbladder_body"}));
  EXPECT_EQ(gb.materials.size(), 2u);
  const OrganInfo& tr = r.at("trachea");
  EXPECT_TRUE(tr.segmented && !tr.needs_seed);
  EXPECT_EQ(tr.haptic_surface, "trachea_wall");
  EXPECT_EQ(tr.wall_surface(), "trachea_wall");
  // Context organs carry the phantom's labels and a colour; they are never meshed.
  ASSERT_NE(r.find("liver"), nullptr);
  EXPECT_EQ(r.at("liver").label, 3);
  EXPECT_EQ(r.at("liver").mesh, OrganMeshModel::none);
  EXPECT_FALSE(r.at("liver").segmented);
  EXPECT_EQ(r.find_label(4)->name, "lungs");
}

TEST(OrganRegistry, MistakesNameTheOrganAndKey) {
  std::string e = registry_error("[liver]\nmesh = \"solid\"\ncolor = [1, 0, 0]\n");
  EXPECT_TRUE(has(e, "unknown key 'color'") && has(e, "did you mean 'colour'") && has(e, "line 3")) << e;
  e = registry_error("[liver]\nmesh = \"solid\"\nmaterials = { liver_wall = \"fung-wall/table-5.1.1/mean\" }\n");
  EXPECT_TRUE(has(e, "liver_wall") && has(e, "regions: liver")) << e;
  e = registry_error("[liver]\nmesh = \"solid\"\nmaterials = { liver = \"no-such/preset\" }\n");
  EXPECT_TRUE(has(e, "no-such/preset")) << e;
  e = registry_error("[spleen]\nlabel = 1\nmesh = \"solid\"\nmaterials = { spleen = \"fung-organ/table-5.1.2/mean\" }\n");
  EXPECT_TRUE(has(e, "label 1 is used by two organs")) << e;
  // A meshed region without a calibrated law would be exported with a placeholder: refused.
  e = registry_error("[spleen]\nlabel = 9\nmesh = \"solid\"\n");
  EXPECT_TRUE(has(e, "[spleen] region spleen has no material") && has(e, "organsmith materials")) << e;
  e = registry_error("[spleen]\nlabel = 9\nmesh = \"tube\"\n");
  EXPECT_TRUE(has(e, "needs wall_mm")) << e;
  e = registry_error("[spleen]\nlabel = 9\nmesh = \"cube\"\n");
  EXPECT_TRUE(has(e, "wall_body, tube, solid, none")) << e;
  e = registry_error("[liver]\ncolour = [1.5, 0, 0]\n");
  EXPECT_TRUE(has(e, "colour")) << e;
  e = registry_error("[gallbladder.segment]\nalpah = 0.5\n");
  EXPECT_TRUE(has(e, "alpah")) << e;
  // Guidance paths and beds: a path kind its mesh model cannot carry, a bed organ the registry
  // lacks, a bed on an organ without a body.
  e = registry_error("[liver]\nmesh = \"solid\"\nmaterials = { liver = \"fung-organ/table-5.1.2/mean\" }\npaths = [\"centerline\"]\n");
  EXPECT_TRUE(has(e, "[liver] paths has 'centerline', which only a tube has")) << e;
  e = registry_error("[trachea]\npaths = [\"dissection\"]\n");
  EXPECT_TRUE(has(e, "[trachea] paths has 'dissection', which only a wall_body has")) << e;
  e = registry_error("[trachea]\npaths = [\"centreline\"]\n");
  EXPECT_TRUE(has(e, "'centreline', not a path kind")) << e;
  e = registry_error("[gallbladder]\nbed_organ = \"spleen\"\n");
  EXPECT_TRUE(has(e, "bed_organ 'spleen' is no other organ of the registry") && has(e, "liver")) << e;
  e = registry_error("[trachea]\nbed_organ = \"liver\"\n");
  EXPECT_TRUE(has(e, "[trachea] has a bed_organ, which only a wall_body takes")) << e;
  EXPECT_EQ(builtin_organ_registry().path_names(),
            (std::vector<std::string>{"gallbladder_dissection", "trachea_centerline", "trachea_incision"}));
  // A case may only model organs with a mesh model, and a non-segmented one needs a label map.
  try {
    parse_case("[case]\ninput = \"scan.nii.gz\"\n[[organ]]\nname = \"lungs\"\n", "/cases/c.toml");
    ADD_FAILURE() << "a context organ was accepted as a modelled one";
  } catch (const Error& e) {
    EXPECT_TRUE(has(e.what(), "unknown organ 'lungs'") && has(e.what(), "gallbladder, trachea")) << e.what();
  }
}

// A third organ through a registry file in the case, no code change: the liver as a solid from
// the phantom's ground truth is meshed, exported with its material, and drawn in its colour.
TEST(OrganRegistry, ACaseAddsAThirdOrganThatIsMeshedExportedAndDrawn) {
  ScratchDir tmp("registry-liver");
  std::ofstream(tmp / "organs.toml") << "[liver]\nmesh = \"solid\"\n"
                                        "materials = { liver = \"fung-organ/table-5.1.2/mean\" }\n"
                                        "colour = [0.55, 0.22, 0.17]\n";
  std::ofstream(tmp / "case.toml") << "[case]\nname = \"with-liver\"\ninput = \"phantom\"\norgans = \"organs.toml\"\n"
                                      "[phantom]\nsize = 160\nslice_mm = 5.0\n"
                                      "[[organ]]\nname = \"trachea\"\n[[organ]]\nname = \"liver\"\n"
                                      "[stages.mesh]\nedge_mm = 4.0\nformats = [\"stl\", \"vtu\", \"inp\", \"feb\"]\n"
                                      // A 4 mm edge is coarse for the trachea's lumen (its volume
                                      // gate fails by 5–6 %); this test is about the third organ.
                                      "quality_gate = \"report\"\n"
                                      "[stages.snapshot]\nviews = [\"organs\"]\nwidth_px = 320\nheight_px = 240\n";
  std::string log;
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(tmp / "out"), &log), 0) << log;
  const fs::path liver = tmp / "out" / "meshes" / "liver";
  const auto quality = read_json(liver / "quality.json");
  EXPECT_EQ(quality["model"], "solid");
  EXPECT_EQ(quality["label"], 3);
  EXPECT_TRUE(quality["tetrahedra"]["passed"].get<bool>()) << quality["tetrahedra"].dump();
  // The tets fill the label's volume (the phantom's liver, ≈ 1.2 l).
  const double tet_ml = quality["tetrahedra"]["volume_mm3"].get<double>() / 1000.0;
  const double label_ml = quality["label_volume_mm3"].get<double>() / 1000.0;
  EXPECT_GT(label_ml, 500.0);
  EXPECT_NEAR(tet_ml / label_ml, 1.0, 0.03);
  // Exported with the liver's material in the solver files.
  const std::string inp = organsmith::testing::read_file(liver / "liver.inp");
  EXPECT_TRUE(has(inp, "*SOLID SECTION, ELSET=liver, MATERIAL=liver_MAT")) << inp.substr(0, 300);
  EXPECT_TRUE(fs::exists(liver / "liver.feb"));
  EXPECT_EQ(read_json(tmp / "out" / "materials.json")["regions"]["liver"]["preset"], "fung-organ/table-5.1.2/mean");
  // Drawn in the registry's colour: many pixels of its hue (red well above green and blue).
  const RgbImage img = read_png(tmp / "out" / "snapshots" / "3d_liver.png");
  std::size_t brown = 0;
  for (std::size_t p = 0; p + 2 < img.rgb.size(); p += 3) {
    const int r = img.rgb[p], g = img.rgb[p + 1], b = img.rgb[p + 2];
    brown += r > 40 && r > 1.8 * g && r > 1.8 * b;
  }
  EXPECT_GT(brown, 2000u);
  // The manifest names the registry file, so that later commands (snapshot, guide) read it too.
  EXPECT_EQ(read_json(tmp / "out" / "manifest.json")["case"]["organ_registry"], (tmp / "organs.toml").string());
}

// An organ the embedded registry does not have, with its own load case, bed and guidance path
// and no segmentation preset (so its driver is the label map), added by a registry file and run
// end to end: the phantom's gallbladder relabelled as a "cyst" lying on the liver, loaded by a
// lumen pressure instead of the probe. Its solver file fixes its liver bed (found from the liver
// label) and presses its lumen; the guide stage rims the bed with its own dissection path.
TEST(OrganRegistry, ARegistryFileAddsAnOrganWithItsOwnLoadCaseBedAndPath) {
  ScratchDir tmp("registry-cyst");
  std::ofstream(tmp / "organs.toml") << "[gallbladder]\nlabel = 9\n"
                                        "[cyst]\nlabel = 1\nmesh = \"wall_body\"\nwall_mm = 2.0\n"
                                        "materials = { cyst_wall = \"fung-wall/table-5.1.1/mean\", cyst_body = \"fung-organ/table-5.1.2/mean\" }\n"
                                        "load_case = \"pressure\"\npressure_kPa = 1.0\nbed_organ = \"liver\"\npaths = [\"dissection\"]\n"
                                        "colour = [0.2, 0.4, 0.8]\n";
  std::ofstream(tmp / "case.toml") << "[case]\nname = \"cyst\"\ninput = \"phantom\"\norgans = \"organs.toml\"\n"
                                      "[phantom]\nsize = 160\nslice_mm = 5.0\n"
                                      "[[organ]]\nname = \"cyst\"\n"
                                      "[stages.mesh]\nformats = [\"inp\", \"vtu\"]\nquality_gate = \"report\"\n"
                                      "[stages.guide]\npaths = [\"cyst_dissection\"]\n"
                                      "[stages.snapshot]\nviews = [\"organs\"]\nwidth_px = 320\nheight_px = 240\n";
  std::string log;
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(tmp / "out"), &log), 0) << log;
  const std::string inp = organsmith::testing::read_file(tmp / "out" / "meshes" / "cyst" / "cyst.inp");
  EXPECT_TRUE(has(inp, "** cyst_liver_bed: the liver bed from the liver label")) << inp.substr(0, 1200);
  EXPECT_TRUE(has(inp, "*BOUNDARY\ncyst_liver_bed_nodes, 1, 3")) << inp.substr(0, 1200);
  EXPECT_TRUE(has(inp, "cyst_lumen, P, 0.001")) << "the registry's 1 kPa on the lumen";
  EXPECT_TRUE(has(inp, "** Load case: cyst_liver_bed fixed;")) << inp.substr(inp.find("** Load case"), 300);
  EXPECT_FALSE(has(inp, "indentation test")) << "its load case is the pressure, not the probe";
  const nlohmann::json path = read_json(tmp / "out" / "paths" / "cyst_dissection.json");
  EXPECT_EQ(path["name"], "cyst_dissection");
  EXPECT_TRUE(path["closed"].get<bool>());
  EXPECT_EQ(path["properties"]["bed_from_liver_label"].get<double>(), 1.0);
  EXPECT_GT(path["point_count"].get<int>(), 20);
  EXPECT_FALSE(fs::exists(tmp / "out" / "paths" / "gallbladder_dissection.json"));
}

TEST(OrganRegistry, SegmentPresetsStartFromTheRegistrysDefaultsTable) {
  // The presets hold no numbers of their own: an organ's preset is [segment_defaults] with its
  // own segment table over it, in the embedded registry and in a case's registry file.
  const OrganPreset d = segment_defaults();
  const auto builtin = default_organ_presets();
  EXPECT_FALSE(builtin.count(std::string(kSegmentDefaultsTable))) << "the defaults table is not an organ";
  EXPECT_FALSE(builtin_organ_registry().find(std::string(kSegmentDefaultsTable)));
  const std::string cyst =
      "[cyst]\nlabel = 9\nmesh = \"none\"\nneeds_seed = true\n[cyst.segment]\nalpha = 0.9\nregion_above_hu = 12.0\n";
  auto p = parse_organ_presets(cyst, builtin, PresetText::registry).at("cyst");
  EXPECT_EQ(p.alpha, 0.9);
  EXPECT_EQ(p.region_above_hu, 12.0);
  EXPECT_EQ(p.kappa, d.kappa);  // not in its table: the defaults'
  EXPECT_EQ(p.max_held_in_a_row, d.max_held_in_a_row);
  EXPECT_EQ(p.point_spacing_mm, d.point_spacing_mm);
  // A registry file's own defaults table applies to the organs it adds, not to the built-in ones.
  const auto with_own = parse_organ_presets("[segment_defaults]\nkappa = 0.25\n" + cyst, builtin, PresetText::registry);
  EXPECT_EQ(with_own.at("cyst").kappa, 0.25);
  EXPECT_EQ(with_own.at("gallbladder").kappa, builtin.at("gallbladder").kappa);
  // The built-in organs: a key their table leaves out is the defaults' value.
  EXPECT_EQ(builtin.at("trachea").region_above_hu, d.region_above_hu);
  // Mistakes in the defaults table are named like an organ's.
  std::string e = registry_error("[segment_defaults]\nkapa = 0.2\n");
  EXPECT_TRUE(has(e, "unknown organ preset key 'segment_defaults.kapa'")) << e;
  e = registry_error("[segment_defaults]\ngvf_mu = -1.0\n");
  EXPECT_TRUE(has(e, "must be positive")) << e;
  // Which driver finds an organ is the registry's too: the trachea's airway search, seeded otherwise.
  EXPECT_EQ(builtin.at("trachea").driver, "airway");
  EXPECT_EQ(builtin.at("gallbladder").driver, d.driver);
  EXPECT_EQ(d.driver, "seeded");
  e = registry_error("[cyst]\nlabel = 9\nmesh = \"none\"\n[cyst.segment]\ndriver = \"snake\"\n");
  EXPECT_TRUE(has(e, "cyst.driver' must be one of \"seeded\", \"airway\"")) << e;
}

TEST(OrganRegistry, PreferredPathsAreIncisionsThenDissectionsThenCentrelinesOfEveryOrgan) {
  // haptics and preview follow the first of these the run made when no path is named.
  const std::string extra =
      "[duct]\nlabel = 9\nmesh = \"tube\"\nwall_mm = 1.0\nmaterials = { duct_wall = \"fung-wall/table-5.1.1/mean\" }\n"
      "paths = [\"centerline\", \"incision\"]\n";
  const OrganRegistry r = parse_organ_registry(extra, "/cases/organs.toml", builtin_organ_registry());
  const auto all = r.path_names(), preferred = r.preferred_path_names();
  EXPECT_EQ(std::set<std::string>(all.begin(), all.end()), std::set<std::string>(preferred.begin(), preferred.end()));
  EXPECT_EQ(all.size(), preferred.size());
  auto rank = [](const std::string& n) {
    return n.ends_with("_incision") ? 0 : n.ends_with("_dissection") ? 1 : n.ends_with("_centerline") ? 2 : 3;
  };
  for (std::size_t i = 1; i < preferred.size(); ++i) EXPECT_LE(rank(preferred[i - 1]), rank(preferred[i])) << preferred[i];
  EXPECT_TRUE(std::find(preferred.begin(), preferred.end(), "duct_incision") <
              std::find(preferred.begin(), preferred.end(), "duct_centerline"));
}
