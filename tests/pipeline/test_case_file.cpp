#include "core/errors.h"
#include "pipeline/case/case_file.h"
#include "segmentation/presets.h"

#include <gtest/gtest.h>

using namespace organsmith;
namespace fs = std::filesystem;

namespace {
ExitCode parse_code(const std::string& text) {
  try {
    parse_case(text, "/cases/test.toml");
  } catch (const Error& e) {
    return e.code();
  }
  return ExitCode::ok;
}
}  // namespace

TEST(CaseFile, EmbeddedDefaultRunsThePhantomWithBothOrgans) {
  const CaseFile c = default_case();
  EXPECT_TRUE(c.synthesize_phantom);
  ASSERT_EQ(c.organs.size(), 2u);
  EXPECT_EQ(c.organs[0].name, "gallbladder");
  EXPECT_EQ(c.organs[1].name, "trachea");
  EXPECT_EQ(c.phantom.size_vox, 512);
  EXPECT_EQ(c.out_dir, fs::path("out"));
}

TEST(CaseFile, PathsAreRelativeToTheCaseFileAndSeedsParse) {
  const CaseFile c = parse_case(R"(
[case]
name = "chest"
input = "scans/chest"
[ingest]
series = "1.2.3"
max_memory_mb = 2048
[[organ]]
name = "gallbladder"
seed_lps_mm = [10.5, -20, 300]
[[organ]]
name = "trachea"
seed_ijk = [256, 240, 12]
[output]
dir = "results"
[stages.mesh]
edge_mm = 4.0
wall_mm = { gallbladder = 3 }
formats = ["stl", "inp"]
quality_gate = "enforce"
[stages.guide]
ring_count = 3
[stages.snapshot]
width_px = 640
views = ["organs"]
)",
                                "/cases/chest.toml");
  EXPECT_FALSE(c.synthesize_phantom);
  EXPECT_EQ(c.input, fs::path("/cases/scans/chest"));
  EXPECT_EQ(c.out_dir, fs::path("/cases/results"));
  EXPECT_EQ(c.ingest.series_uid, "1.2.3");
  EXPECT_EQ(c.ingest.max_memory_bytes, std::int64_t(2048) << 20);
  ASSERT_TRUE(c.organs[0].seed_lps_mm);
  EXPECT_DOUBLE_EQ(c.organs[0].seed_lps_mm->x(), 10.5);
  ASSERT_TRUE(c.organs[1].seed_ijk);
  EXPECT_DOUBLE_EQ(c.organs[1].seed_ijk->z(), 12.0);
  // Every [stages.*] key lands in its stage's typed options.
  EXPECT_DOUBLE_EQ(c.stages.mesh.edge_mm, 4.0);
  EXPECT_DOUBLE_EQ(c.stages.mesh.wall_mm.at("gallbladder"), 3.0);
  EXPECT_EQ(c.stages.mesh.formats, (std::vector<std::string>{"stl", "inp"}));
  EXPECT_EQ(c.stages.mesh.quality_gate, "enforce");
  EXPECT_EQ(c.stages.guide.incision.ring_count, 3);
  EXPECT_EQ(c.stages.snapshot.width_px, 640);
  EXPECT_EQ(c.stages.snapshot.views, (std::vector<std::string>{"organs"}));
  // Resolved options round-trip into the manifest's JSON.
  const auto j = to_json(c);
  EXPECT_EQ(j["organs"][0]["seed_lps_mm"][2], 300.0);
}

TEST(CaseFile, MistakesAreRejectedNotDefaulted) {
  EXPECT_EQ(parse_code("[case]\ninput = \"phantom\"\n"), ExitCode::ok);
  EXPECT_EQ(parse_code("[case]\ninput = \"phantom\"\nnmae = \"x\"\n"), ExitCode::case_file);   // unknown key
  EXPECT_EQ(parse_code("[phantom]\nsize = \"big\"\n"), ExitCode::case_file);                  // wrong type
  EXPECT_EQ(parse_code("[phantom]\nsize = 4\n"), ExitCode::case_file);                        // out of range
  EXPECT_EQ(parse_code("[[organ]]\nname = \"spleen\"\n"), ExitCode::case_file);               // unknown organ
  EXPECT_EQ(parse_code("[[organ]]\nname = \"trachea\"\nseed_lps_mm = [1, 2]\n"), ExitCode::case_file);
  EXPECT_EQ(parse_code("[[organ]]\nname = \"trachea\"\nseed_lps_mm = [1,2,3]\nseed_ijk = [1,2,3]\n"),
            ExitCode::case_file);
  EXPECT_EQ(parse_code("[[organ]]\nname = \"trachea\"\n[[organ]]\nname = \"trachea\"\n"), ExitCode::case_file);
  EXPECT_EQ(parse_code("[case\n"), ExitCode::case_file);                                       // syntax
  EXPECT_EQ(parse_code("[ingest]\nmax_memory_mb = -1\n"), ExitCode::case_file);
  // Non-ASCII text is TOML only inside strings and comments. The code points toml++ 3.3 cannot
  // classify as whitespace or not (U+FCFF before a table header, U+011E after a backslash, U+FEFB
  // inside a malformed value: found by fuzz/fuzz_case_file.cpp) reach it only as private-use
  // stand-ins (core/toml_parse.h), so each of these is its syntax error.
  EXPECT_EQ(parse_code("\xef\xb3\xbf[case]\ninput = \"phantom\"\n"), ExitCode::case_file);
  EXPECT_EQ(parse_code("[case]\ninput = \"phantom\" \xc2\xa0\n"), ExitCode::case_file);
  EXPECT_EQ(parse_code("[case]\nname = 2c\"\xc6\x97\xd8\x93" "a\"\n"), ExitCode::case_file);  // not a string: a bare value
  EXPECT_EQ(parse_code("[case]\nname = \"\"\"a\\\xc4\x9e" "b\"\"\"\n"), ExitCode::case_file);  // \Ğ is no escape
  // After a line-ending backslash and the whitespace it trims, Ğ is text (valid TOML).
  const CaseFile trimmed = parse_case("[case]\ninput = \"phantom\"\nname = \"\"\"a\\\n  \xc4\x9e" "b\"\"\"\n", "/c/t.toml");
  EXPECT_EQ(trimmed.name, "a\xc4\x9e" "b");
  EXPECT_EQ(parse_code("# Gallenblase — \xcf\x83 \xe2\x89\x88 1 mm\n[case]\nname = \"P\xc3\xa4ttient \\\" \xe2\x80\x94\"\n"
                       "input = \"phantom\"  # \xc3\xbc\n"),
            ExitCode::ok);
  EXPECT_EQ(parse_code("[case]\nname = \"\"\"multi \xc3\xa4\n line\"\"\"\ninput = 'phantom'\n"), ExitCode::ok);
  EXPECT_EQ(parse_code("[catse]\n_mm = [1.0, 1a-h5Eph['\xef\xbb\xbb~~\n"), ExitCode::case_file);
  // Private-use characters, written or escaped, are refused: they stand in for the others.
  EXPECT_EQ(parse_code("[case]\nname = \"a\xee\x80\x80\"\ninput = \"phantom\"\n"), ExitCode::case_file);
  EXPECT_EQ(parse_code("[case]\nname = \"a\\uE000\"\ninput = \"phantom\"\n"), ExitCode::case_file);
  EXPECT_EQ(parse_code("[case]\nname = \"a\\U0000f8ff\"\ninput = \"phantom\"\n"), ExitCode::case_file);
}

TEST(CaseFile, NonAsciiTextInStringsAndMessagesComesBackAsWritten) {
  // ä (U+00E4), ⾀ (U+2F80) and ﹰ (U+FE70) are among the code points shielded from toml++.
  const std::string name = "P\xc3\xa4tient \xe2\xbe\x80 \xef\xb9\xb0 \xe2\x80\x94 \xc3\xa9";
  const CaseFile c = parse_case("[case]\nname = \"" + name + "\"\ninput = \"phantom\"\n", "/cases/u.toml");
  EXPECT_EQ(c.name, name);
  try {
    parse_case("[case]\ninput = \"phantom\"\n\"k\xc3\xa4y\" = 1\n", "/cases/u.toml");
    FAIL() << "an unknown key was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("k\xc3\xa4y"), std::string::npos) << e.what();
  }
}

TEST(CaseFile, SegmentationPresetsOverrideTheEmbeddedOnesAndMisspeltKeysAreRejected) {
  const CaseFile c = parse_case(R"(
[case]
input = "phantom"
[stages.segment.presets.gallbladder]
alpha = 0.85
seed_hu_range = [-20.0, 35.0]
)",
                                "/cases/p.toml");
  ASSERT_FALSE(c.segment_presets_toml.empty());
  const auto presets = parse_organ_presets(c.segment_presets_toml, default_organ_presets());
  EXPECT_DOUBLE_EQ(presets.at("gallbladder").alpha, 0.85);
  EXPECT_DOUBLE_EQ(presets.at("gallbladder").seed_hu_lo, -20.0);
  EXPECT_DOUBLE_EQ(presets.at("gallbladder").seed_hu_hi, 35.0);
  // Keys not given keep the embedded values; other organs are untouched.
  EXPECT_DOUBLE_EQ(presets.at("gallbladder").beta, default_organ_presets().at("gallbladder").beta);
  EXPECT_DOUBLE_EQ(presets.at("trachea").alpha, default_organ_presets().at("trachea").alpha);

  try {
    parse_case("[stages.segment.presets.trachea]\nmin_fil = 0.5\n", "/cases/typo.toml");
    ADD_FAILURE() << "a misspelt preset key was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::case_file);
    EXPECT_NE(std::string(e.what()).find("trachea.min_fil"), std::string::npos) << e.what();
    EXPECT_EQ(e.path(), fs::path("/cases/typo.toml"));
  }
  EXPECT_EQ(parse_code("[stages.segment.presets.trachea]\nalpha = \"soft\"\n"), ExitCode::case_file);
}

namespace {
/// The message of the CaseFileError `text` raises (empty when it parses).
std::string case_error(const std::string& text) {
  try {
    parse_case(text, "/cases/options.toml");
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::case_file) << e.what();
    EXPECT_EQ(e.path(), fs::path("/cases/options.toml"));
    return e.what();
  }
  return {};
}
bool has(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }
}  // namespace

// Stage options used to be recorded and then ignored; a typo ran with the defaults.
TEST(CaseFile, StageOptionTyposWrongTypesAndRangesAreErrorsWithLineKeyAndWhatIsAllowed) {
  std::string e = case_error("[case]\ninput = \"phantom\"\n[stages.mesh]\nedge_mm = 4.0\nbogus_key = 7\n");
  EXPECT_TRUE(has(e, "bogus_key") && has(e, "line 5") && has(e, "[stages.mesh]")) << e;
  e = case_error("[stages.mesh]\nedge_mn = 4.0\n");
  EXPECT_TRUE(has(e, "did you mean 'edge_mm'")) << e;
  e = case_error("[stages.segment]\niterations = 200\n");
  EXPECT_TRUE(has(e, "iterations") && has(e, "line 2")) << e;
  e = case_error("[stages.mseh]\nedge_mm = 4.0\n");
  EXPECT_TRUE(has(e, "unknown stage 'mseh'") && has(e, "did you mean 'mesh'")) << e;
  e = case_error("[stages.mesh]\nedge_mm = 1e9\n");
  EXPECT_TRUE(has(e, "out of range") && has(e, "0.3") && has(e, "10")) << e;
  e = case_error("[stages.mesh]\nedge_mm = nan\n");
  EXPECT_TRUE(has(e, "out of range")) << e;
  e = case_error("[stages.mesh]\nedge_mm = \"fine\"\n");
  EXPECT_TRUE(has(e, "must be a number")) << e;
  e = case_error("[stages.mesh]\nformats = [\"stl\", \"step\"]\n");
  EXPECT_TRUE(has(e, "'step'") && has(e, "feb")) << e;
  e = case_error("[stages.mesh]\nquality_gate = \"strict\"\n");
  EXPECT_TRUE(has(e, "report, enforce")) << e;
  // A case's guide paths are the registry's.
  e = case_error("[stages.guide]\npaths = [\"trachea_dissection\"]\n");
  EXPECT_TRUE(has(e, "'trachea_dissection', which no organ of the registry has") && has(e, "trachea_incision")) << e;
  e = case_error("[stages.guide]\nring_count = 2.5\n");
  EXPECT_TRUE(has(e, "must be an integer")) << e;
  e = case_error("[stages.snapshot]\nviews = [\"organz\"]\n");
  EXPECT_TRUE(has(e, "organz")) << e;
  e = case_error("[stages.attach]\nmaterial = 1\n");
  EXPECT_TRUE(has(e, "takes no options")) << e;
}

// Organ lists are checked against the case's registry, not a list in the code: an organ without a
// wall has no load case; a snapshot presses only an organ whose load case is the probe.
TEST(CaseFile, OrganListsNameTheRegistrysOrgansWithTheRightLoadCase) {
  std::string e = case_error("[stages.simulate]\norgans = [\"liver\"]\n");
  EXPECT_TRUE(has(e, "'liver'") && has(e, "no organ with a load case")) << e;
  e = case_error("[stages.mesh]\nindentation = [\"spleen\"]\n");
  EXPECT_TRUE(has(e, "'spleen'") && has(e, "no organ with a wall")) << e;
  e = case_error("[stages.mesh]\nindentation = [3]\n");
  EXPECT_TRUE(has(e, "organ names") && has(e, "line 2")) << e;
  e = case_error("[stages.snapshot]\nindent = [\"trachea\"]\n");
  EXPECT_TRUE(has(e, "'trachea'") && has(e, "not the probe")) << e;
  e = case_error("[stages.mesh]\npressure_kPa = { gallbladder = 1.0 }\n[stages.snapshot]\nindent = [\"gallbladder\"]\n");
  EXPECT_TRUE(has(e, "'gallbladder'") && has(e, "not the probe")) << e;
  // The trachea pressed on its anterior wall can be drawn under the probe.
  const CaseFile c = parse_case("[case]\ninput = \"phantom\"\n[stages.mesh]\nindentation = [\"trachea\"]\n[stages.snapshot]\nindent = [\"trachea\", "
                                "\"gallbladder\"]\n[stages.simulate]\norgans = [\"trachea\"]\n",
                                "/cases/test.toml");
  EXPECT_EQ(c.stages.snapshot.indent, (std::vector<std::string>{"trachea", "gallbladder"}));
}

TEST(CaseFile, PrintedDefaultCaseListsEveryOptionAndParsesBackToTheDefaults) {
  const std::string text = default_case_with_options_text();
  const CaseFile printed = parse_case(text, {});
  const CaseFile embedded = default_case();
  for (const auto& stage : configurable_stages()) {
    EXPECT_EQ(stage_json(printed, stage), stage_json(embedded, stage)) << stage;
    // Every option of the stage is listed by name.
    const nlohmann::json options = stage_json(embedded, stage);  // items() must not outlive it
    for (const auto& [key, value] : options.items())
      if (stage != "segment") EXPECT_TRUE(has(text, "\n" + key + " = ")) << stage << "." << key;
  }
  EXPECT_TRUE(has(text, "edge_mm = 1.5")) << text;
  EXPECT_TRUE(has(text, "mm")) << "units are given";
  EXPECT_DOUBLE_EQ(StageOptions{}.mesh.edge_mm, embedded.stages.mesh.edge_mm);
}
