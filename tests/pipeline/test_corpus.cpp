// The corpus suite (reliability): a seeded generator (corpus_gen*.cpp) makes hundreds of
// malformed or hostile inputs — DICOM series, NIfTI/NRRD/MetaImage files, label maps, case files,
// CSVs, output-path traps — and each goes through the command that takes it, as a user would run
// it. Every run must end within its time limit with an exit code from README's table that is not
// 1 (internal error), its failure message must name the file, nothing it was given or that a user
// owns may change, no staging folder may stay behind, and a failed command leaves no output
// but what a manifest lists with matching hashes. Cases built to be invalid must fail. Each kind
// prints its tally (the figures reported for the issue).

#include "corpus_gen.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>
#include <map>
#include <regex>
#include <set>

using namespace organsmith::testing;
namespace fs = std::filesystem;

namespace {

/// The exit codes of README's table.
std::set<int> documented_codes() {
  std::ifstream in(fs::path(ORGANSMITH_SOURCE_DIR) / "README.md");
  std::set<int> codes;
  const std::regex row(R"(^\| (\d+) \| )");
  std::smatch m;
  for (std::string line; std::getline(in, line);)
    if (std::regex_search(line, m, row)) codes.insert(std::stoi(m[1]));
  return codes;
}

/// Digest of a file or of every file under a folder (a missing path digests as empty).
std::map<std::string, std::string> digest(const fs::path& p) {
  if (p.empty() || !fs::exists(p)) return {};
  if (fs::is_directory(p)) return file_digests(p);
  return {{p.filename().string(), file_digests(p.parent_path())[p.filename().string()]}};
}

/// A failed command's output folder: absent, empty, or only files a manifest lists with their hashes.
bool output_whole(const fs::path& out, std::string* why) {
  if (out.empty() || !fs::exists(out) || count_files(out) == 0) return true;
  const fs::path manifest = out / "manifest.json";
  if (!fs::exists(manifest)) return *why = "files but no manifest in " + out.string(), false;
  std::set<std::string> listed{"manifest.json"};
  const nlohmann::json m = read_json(manifest);
  const auto digests = file_digests(out);
  for (const auto& s : m.value("stages", nlohmann::json::array()))
    for (const auto& o : s.value("outputs", nlohmann::json::array())) {
      const std::string path = o.value("path", "");
      listed.insert(path);
      const auto it = digests.find(path);
      if (it == digests.end() || it->second != o.value("sha256", ""))
        return *why = "manifest entry " + path + " missing or changed", false;
    }
  for (const auto& [path, sha] : digests)
    if (!listed.count(path)) return *why = "unlisted file " + path, false;
  return true;
}

struct Tally {
  int cases = 0, crashes = 0, hangs = 0, exit1 = 0, undocumented = 0, unnamed = 0, garbage = 0, touched = 0,
      staging = 0, partial = 0;
  std::map<int, int> by_code;
};

void run_corpus(const std::string& kind, const std::vector<CorpusCase>& cases, const fs::path& root) {
  static const std::set<int> codes = documented_codes();
  ASSERT_GT(codes.size(), 20u) << "README's exit-code table was not found";
  ASSERT_GT(cases.size(), 10u);
  Tally t;
  for (const auto& c : cases) {
    const auto before = digest(c.guarded);
    // timeout(1): 124 when the limit passed, 128 + n when organsmith died of signal n.
    const CliResult r = run_cli_bounded(c.args, 90, root);
    const std::string what = c.kind + " / " + c.name + " (exit " + std::to_string(r.exit_code) + "):\n" +
                             r.output.substr(0, 1500);
    ++t.cases;
    ++t.by_code[r.exit_code];
    if (r.exit_code == 124 || r.exit_code == 137) ++t.hangs, ADD_FAILURE() << "hang: " << what;
    else if (r.exit_code > 124 || r.exit_code < 0) ++t.crashes, ADD_FAILURE() << "crash: " << what;
    else if (r.exit_code == 1) ++t.exit1, ADD_FAILURE() << "internal error: " << what;
    else if (!codes.count(r.exit_code)) ++t.undocumented, ADD_FAILURE() << "undocumented code: " << what;
    if (c.must_fail && r.exit_code == 0) ++t.garbage, ADD_FAILURE() << "read as valid: " << what;
    if (r.exit_code != 0 && !c.named.empty() && r.output.find(c.named.filename().string()) == std::string::npos)
      ++t.unnamed, ADD_FAILURE() << "the message does not name " << c.named.filename() << ": " << what;
    if (digest(c.guarded) != before) ++t.touched, ADD_FAILURE() << "changed " << c.guarded << ": " << what;
    if (has_staging_leftover(root)) {
      ++t.staging, ADD_FAILURE() << "staging folder left: " << what;
      for (auto it = fs::recursive_directory_iterator(root); it != fs::recursive_directory_iterator(); ++it)
        if (it->path().filename().string().find(".staging-") != std::string::npos) fs::remove_all(it->path()), it.pop();
    }
    std::string why;
    if (r.exit_code != 0 && !output_whole(c.out, &why)) ++t.partial, ADD_FAILURE() << why << ": " << what;
  }
  std::string codes_seen;
  for (const auto& [code, count] : t.by_code) codes_seen += " " + std::to_string(code) + "×" + std::to_string(count);
  std::printf("corpus %-12s %3d cases: crashes %d, hangs %d, exit-1 %d, undocumented %d, unnamed %d, read as valid %d, "
              "inputs touched %d, staging left %d, partial output %d; codes%s\n",
              kind.c_str(), t.cases, t.crashes, t.hangs, t.exit1, t.undocumented, t.unnamed, t.garbage, t.touched,
              t.staging, t.partial, codes_seen.c_str());
}

/// The mutation seed (ORGANSMITH_CORPUS_SEED, default 1): CI repeats one corpus, a user can draw others.
std::mt19937 corpus_rng(unsigned salt) {
  const char* s = std::getenv("ORGANSMITH_CORPUS_SEED");
  return std::mt19937((s ? unsigned(std::stoul(s)) : 1u) * 7919u + salt);
}

}  // namespace

TEST(Corpus, DicomSeries) {
  ScratchDir s("corpus-dicom");
  auto rng = corpus_rng(1);
  run_corpus("dicom", dicom_corpus(s.path(), rng), s.path());
}

TEST(Corpus, NiftiFiles) {
  ScratchDir s("corpus-nifti");
  auto rng = corpus_rng(2);
  run_corpus("nifti", nifti_corpus(s.path(), rng), s.path());
}

TEST(Corpus, NrrdAndMetaImageFiles) {
  ScratchDir s("corpus-text");
  auto rng = corpus_rng(3);
  run_corpus("text-header", text_header_corpus(s.path(), rng), s.path());
}

TEST(Corpus, LabelMapsForMeshing) {
  ScratchDir s("corpus-labels");
  auto rng = corpus_rng(4);
  run_corpus("label-map", label_map_corpus(s.path(), rng), s.path());
}

TEST(Corpus, CaseFiles) {
  ScratchDir s("corpus-case");
  auto rng = corpus_rng(5);
  const CliResult d = run_cli_bounded("run --print-default-case", 30, s.path());
  ASSERT_EQ(d.exit_code, 0) << d.output;
  run_corpus("case-file", case_file_corpus(s.path(), rng, d.output), s.path());
}

TEST(Corpus, CsvFiles) {
  ScratchDir s("corpus-csv");
  auto rng = corpus_rng(6);
  run_corpus("csv", csv_corpus(s.path(), rng), s.path());
}

TEST(Corpus, OutputPathTraps) {
  ScratchDir s("corpus-out");
  auto rng = corpus_rng(7);
  run_corpus("output-path", output_path_corpus(s.path(), rng), s.path());
}
