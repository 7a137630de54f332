// The organ registry (data/organs.toml): every stage reads its organs from it, a case adds one
// with its own registry file, and mistakes in a registry are errors naming the organ and key.

#include "core/errors.h"
#include "pipeline/case/case_file.h"
#include "pipeline/case/organ_registry.h"
#include "tests/support/test_support.h"
#include "viewer/image.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>

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
