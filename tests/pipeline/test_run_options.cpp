// Case-file stage options take effect in `organsmith run`, and a changed option reruns exactly
// the stages it affects and those after them.

#include "core/errors.h"
#include "core/sha256.h"
#include "pipeline/io/image_io.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <map>
#include <set>

using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;
using organsmith::testing::file_digests;
using organsmith::testing::has_staging_leftover;
using organsmith::testing::quoted;
using organsmith::testing::read_json;
namespace fs = std::filesystem;

namespace {



/// stage name → status of the manifest's stage records.
std::map<std::string, std::string> statuses(const fs::path& out) {
  std::map<std::string, std::string> s;
  const nlohmann::json manifest = read_json(out / "manifest.json");  // the loop must not outlive it
  for (const auto& st : manifest["stages"]) s[st["name"]] = st["status"];
  return s;
}

const char* kSmallCase = R"([case]
name = "options"
input = "phantom"
[phantom]
size = 256
slice_mm = 2.5
[[organ]]
name = "gallbladder"
[[organ]]
name = "trachea"
)";

}  // namespace

TEST(RunOptions, StageOptionsTakeEffectAndAChangeRerunsOnlyWhatFollowsIt) {
  ScratchDir tmp("run-options");
  const fs::path out = tmp / "out";
  auto write_case = [&](const std::string& stages) { std::ofstream(tmp / "case.toml") << kSmallCase << stages; };
  const std::string mesh_options =
      "[stages.mesh]\nedge_mm = 3.0\nwall_mm = { gallbladder = 3.0 }\nformats = [\"stl\", \"vtu\", \"inp\"]\n";
  write_case(mesh_options);
  std::string log;
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) + " --until guide", &log), 0) << log;

  // edge_mm = 3: every surface's mean edge within 3 mm ± 25 % — or within 25 % of the finer edge
  // of the remedy meshing kept for an organ whose first mesh missed a gate (its warnings say so).
  for (const char* organ : {"gallbladder", "trachea"}) {
    const auto qj = read_json(out / "meshes" / organ / "quality.json");
    ASSERT_FALSE(qj["surfaces"].empty()) << organ;
    double edge = 3.0;
    for (const auto& w : qj["warnings"]) {
      const std::string t = w.get<std::string>();
      const auto kept = t.find("kept the remedy"), at = t.find("edge ", t.find("kept the remedy") + 1);
      if (kept != std::string::npos && at != std::string::npos) edge = std::stod(t.substr(at + 5));
    }
    for (const auto& [name, s] : qj["surfaces"].items()) {
      const double mean = s["edge_length_mm"]["mean"].get<double>();
      EXPECT_NEAR(mean, edge, 0.25 * edge) << organ << " " << name;
    }
  }
  // formats: only the three asked for.
  std::set<std::string> extensions;
  for (const auto& e : fs::recursive_directory_iterator(out / "meshes"))
    if (e.is_regular_file() && e.path().filename() != "quality.json") extensions.insert(e.path().extension().string());
  EXPECT_EQ(extensions, (std::set<std::string>{".stl", ".vtu", ".inp"}));
  // wall_mm.gallbladder = 3: the wall's inner surface lies 3 mm inside the outer one (compared
  // with the 2 mm default below).
  auto inner_volume = [&] {
    const auto qj = read_json(out / "meshes" / "gallbladder" / "quality.json");
    return qj["surfaces"]["gallbladder_wall_inner"]["volume_mm3"].get<double>();
  };
  const double inner_3mm = inner_volume();
  EXPECT_EQ(read_json(out / "paths" / "trachea_incision.json")["properties"]["last_ring"], 6);  // 3 + 4 − 1

  // A guide option changes only the guide stage (and the snapshot after it, not run here).
  write_case(mesh_options + "[stages.guide]\nring_count = 3\n");
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) + " --until guide", &log), 0) << log;
  auto st = statuses(out);
  for (const char* s : {"phantom", "ingest", "segment", "mesh", "attach"}) EXPECT_EQ(st[s], "skipped (unchanged)") << s;
  EXPECT_EQ(st["guide"], "ran");
  EXPECT_EQ(read_json(out / "paths" / "trachea_incision.json")["properties"]["last_ring"], 5);  // 3 + 3 − 1
  // A mesh option reruns mesh and guide (which reads the meshes), not what comes before.
  write_case("[stages.mesh]\nedge_mm = 3.0\nformats = [\"stl\", \"vtu\", \"inp\"]\n[stages.guide]\nring_count = 3\n");
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) + " --until guide", &log), 0) << log;
  st = statuses(out);
  for (const char* s : {"phantom", "ingest", "segment", "attach"}) EXPECT_EQ(st[s], "skipped (unchanged)") << s;
  EXPECT_EQ(st["mesh"], "ran");
  EXPECT_EQ(st["guide"], "ran");
  // One more millimetre of wall over the organ's ≈ 2000 mm² surface: ≈ 1500–2500 mm³ less inside.
  const double inner_2mm = inner_volume();
  EXPECT_GT(inner_2mm - inner_3mm, 1000.0) << inner_2mm << " vs " << inner_3mm;

  // A misspelt key stops the run before anything is written, naming file, line, key and the fix.
  write_case(mesh_options + "bogus_key = 7\n");
  EXPECT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(tmp / "other"), &log), 20) << log;
  EXPECT_NE(log.find("bogus_key"), std::string::npos) << log;
  EXPECT_NE(log.find("line 15"), std::string::npos) << log;
  EXPECT_NE(log.find("case.toml"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(tmp / "other"));
}

// A label map meshing cannot use is a typed error with its documented code, never exit 1.
TEST(RunOptions, MeshingInputProblemsExitWith60AndWriteNothing) {
  ScratchDir tmp("mesh-errors");
  organsmith::LabelMap empty;
  empty.grid.size_vox = {32, 32, 8};
  empty.grid.spacing_mm = {1.0, 1.0, 2.0};
  empty.labels.assign(std::size_t(empty.grid.voxel_count()), 0);
  organsmith::write_label_map(empty, tmp / "empty.nii.gz");
  organsmith::LabelMap speck = empty;  // one voxel of the gallbladder: too small for a surface
  speck.labels[speck.grid.offset(16, 16, 4)] = 1;
  organsmith::write_label_map(speck, tmp / "speck.nii.gz");
  organsmith::LabelMap fill = empty;  // the whole image: no organ surface inside the field of view
  std::fill(fill.labels.begin(), fill.labels.end(), std::uint8_t(1));
  organsmith::write_label_map(fill, tmp / "fill.nii.gz");
  std::string log;
  for (const char* f : {"empty.nii.gz", "speck.nii.gz", "fill.nii.gz"}) {
    EXPECT_EQ(run_cli("mesh " + quoted(tmp / f) + " --out " + quoted(tmp / "out"), &log), int(organsmith::ExitCode::mesh_input))
        << f << "\n" << log;
    EXPECT_EQ(log.find("internal error"), std::string::npos) << log;
    EXPECT_FALSE(fs::exists(tmp / "out")) << f;
  }
  EXPECT_NE(log.find("touches all six faces"), std::string::npos) << log;
  // Fractional labels (a probability map) are no label map: refused as read (18), in seconds.
  organsmith::Volume prob;
  prob.grid = empty.grid;
  prob.hu.resize(std::size_t(prob.grid.voxel_count()));
  for (std::size_t i = 0; i < prob.hu.size(); ++i) prob.hu[i] = float(i % 7) * 0.25f;
  organsmith::write_volume_file(prob, tmp / "probability.nii.gz");
  EXPECT_EQ(run_cli("mesh " + quoted(tmp / "probability.nii.gz") + " --out " + quoted(tmp / "out"), &log),
            int(organsmith::ExitCode::unsupported_input))
      << log;
  EXPECT_NE(log.find("is not a whole number"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(tmp / "out"));
}

// A mesh that fails a gate after meshing's remedies stops `run` with exit 61 naming the organ
// and the figure, writes no mesh, and `--allow-quality-failures` writes it with every attempt in
// quality.json. The scan: the phantom at 160² (2.5 mm pixels and slices); the gate: a fold limit
// of 1°, which no smooth surface of a 2.5 mm edge meets. Before it, the organ as the
// segmentation once found it on this scan, on one slice only (a 2.5 mm plate of 99 voxels): one
// voxel thin, it is refused as mesh input (no smooth surface at this grid carries it), fast.
TEST(RunOptions, AMeshFailingAGateAfterItsRemediesStopsTheRunWith61) {
  ScratchDir tmp("gate-61");
  std::string log;
  std::ofstream(tmp / "scan.toml") << "[case]\nname = \"scan\"\ninput = \"phantom\"\n[phantom]\nsize = 160\n"
                                      "slice_mm = 2.5\n[[organ]]\nname = \"gallbladder\"\n";
  ASSERT_EQ(run_cli("run " + quoted(tmp / "scan.toml") + " --out " + quoted(tmp / "scan") + " --until segment", &log), 0)
      << log;
  organsmith::LabelMap one = organsmith::read_label_map(tmp / "scan" / "labels.nii.gz");
  const std::int64_t nx = one.grid.size_vox[0], ny = one.grid.size_vox[1], nz = one.grid.size_vox[2];
  std::vector<std::int64_t> ks;
  for (std::int64_t k = 0; k < nz; ++k)
    if (std::any_of(one.labels.begin() + k * nx * ny, one.labels.begin() + (k + 1) * nx * ny, [](auto v) { return v == 1; }))
      ks.push_back(k);
  ASSERT_GE(ks.size(), 3u) << "the phantom's gallbladder was not found";
  const std::int64_t mid = ks[ks.size() / 2];
  for (std::int64_t k = 0; k < nz; ++k)
    if (k != mid) std::fill(one.labels.begin() + k * nx * ny, one.labels.begin() + (k + 1) * nx * ny, std::uint8_t(0));
  organsmith::write_label_map(one, tmp / "one_slice.nii.gz");
  std::ofstream(tmp / "plate.toml") << "[case]\nname = \"plate\"\ninput = " << quoted(tmp / "scan" / "phantom" / "dicom")
                                    << "\n[[organ]]\nname = \"gallbladder\"\nlabel_map = " << quoted(tmp / "one_slice.nii.gz")
                                    << "\n";
  EXPECT_EQ(run_cli("run " + quoted(tmp / "plate.toml") + " --out " + quoted(tmp / "plate"), &log),
            int(organsmith::ExitCode::mesh_input))
      << log;
  EXPECT_NE(log.find("one voxel thin"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(tmp / "plate" / "meshes"));

  std::ofstream(tmp / "case.toml") << "[case]\nname = \"gate\"\ninput = " << quoted(tmp / "scan" / "phantom" / "dicom")
                                   << "\n[[organ]]\nname = \"gallbladder\"\nlabel_map = "
                                   << quoted(tmp / "scan" / "labels.nii.gz") << "\n[stages.mesh]\nmax_fold_deg = 1\n";
  const fs::path out = tmp / "out";
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out), &log),
            int(organsmith::ExitCode::mesh_quality))
      << log;
  EXPECT_NE(log.find("also after meshing's remedies"), std::string::npos) << log;
  EXPECT_NE(log.find("gallbladder: "), std::string::npos) << log;  // organ (surface) and figure
  EXPECT_NE(log.find("folded beyond 1°"), std::string::npos) << log;
  EXPECT_NE(log.find("--allow-quality-failures"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(out / "meshes")) << "a mesh failing its gate was written";
  EXPECT_FALSE(fs::exists(out / "snapshots"));
  EXPECT_FALSE(has_staging_leftover(out));
  EXPECT_TRUE(fs::exists(out / "labels.nii.gz"));  // the stages before it are kept for a rerun

  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) +
                        " --until mesh --allow-quality-failures",
                    &log),
            0)
      << log;
  const nlohmann::json q = read_json(out / "meshes" / "gallbladder" / "quality.json");
  EXPECT_FALSE(q["passed"].get<bool>());
  int remedies = 0;
  bool kept = false;
  for (const auto& w : q["warnings"]) {
    const std::string s = w.get<std::string>();
    remedies += s.find(": remedy ") != std::string::npos;
    kept = kept || s.find("kept the") != std::string::npos;
  }
  EXPECT_EQ(remedies, 6) << q.dump(2);  // smoother, finer, both, three other samplings
  EXPECT_TRUE(kept);
}
