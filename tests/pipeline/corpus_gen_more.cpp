// The corpus generator, continued: label maps for meshing, case files, CSV files and output-path
// traps (volumes are in corpus_gen.cpp).
#include "corpus_gen.h"

#include "tests/support/test_support.h"

#include <cmath>
#include <fstream>
#include <functional>
#include <sstream>

namespace organsmith::testing {

namespace fs = std::filesystem;

namespace {

void write_text(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary) << text;
}

/// A 16³ label volume filled by `label(i, j, k)`.
std::vector<float> labels16(const std::function<float(int, int, int)>& label) {
  std::vector<float> v(16 * 16 * 16);
  for (int k = 0; k < 16; ++k)
    for (int j = 0; j < 16; ++j)
      for (int i = 0; i < 16; ++i) v[std::size_t(i + 16 * (j + 16 * k))] = label(i, j, k);
  return v;
}

}  // namespace

std::vector<CorpusCase> label_map_corpus(const fs::path& root, std::mt19937& rng) {
  std::vector<CorpusCase> cases;
  int n = 0;
  auto add = [&](const std::string& name, bool must_fail, short datatype, const std::vector<float>& v,
                 const std::string& extra = "") {
    const fs::path dir = root / ("c" + std::to_string(n++));
    const fs::path f = dir / "labels.nii";
    write_text(f, nifti_bytes(16, 16, 16, datatype, v, 1.0f));
    cases.push_back({"label-map", name, "mesh " + quoted(f) + " --out " + quoted(dir / "out") + extra,
                     extra.empty() ? f : fs::path(), dir / "out", f, must_fail});
  };
  const auto ball = [](int i, int j, int k) { return std::hypot(i - 7.5, j - 7.5, k - 7.5) < 5 ? 1.0f : 0.0f; };
  add("empty", true, 2, labels16([](int, int, int) { return 0.0f; }));
  add("the gallbladder fills the image", true, 2, labels16([](int, int, int) { return 1.0f; }));
  add("three bars touching all six faces", true, 2, labels16([](int i, int j, int k) {
        return (i > 5 && i < 10 && j > 5 && j < 10) || (j > 5 && j < 10 && k > 5 && k < 10) || (i > 5 && i < 10 && k > 5 && k < 10)
                   ? 1.0f : 0.0f;
      }));
  add("a flat slab one voxel thick", true, 2, labels16([](int, int, int k) { return k == 8 ? 1.0f : 0.0f; }));
  add("one voxel", true, 2, labels16([](int i, int j, int k) { return i == 8 && j == 8 && k == 8 ? 1.0f : 0.0f; }));
  add("only an unknown label 7", true, 2, labels16([&](int i, int j, int k) { return 7 * ball(i, j, k); }));
  add("fractional float labels", true, 16, labels16([&](int i, int j, int k) { return 0.5f * ball(i, j, k); }));
  add("negative labels", true, 4, labels16([&](int i, int j, int k) { return -ball(i, j, k); }));
  add("label 300", true, 4, labels16([&](int i, int j, int k) { return 300 * ball(i, j, k); }));
  add("noise labels", true, 2, labels16([&](int, int, int) { return float(rng() % 2); }));
  const std::vector<float> good = labels16(ball);
  for (const char* edge : {"0", "-1", "nan", "inf", "1e9", "0.001", "abc"})
    add(std::string("--edge-mm ") + edge, true, 2, good, std::string(" --edge-mm ") + edge);
  for (const char* wall : {"gallbladder=1000", "gallbladder=nan", "gallbladder=-2", "gallbladder=0", "gallbladder=2mm", "gallbladder",
                           "=2", "liver=2", "spleen=2"})
    add(std::string("--wall-mm ") + wall, true, 2, good, std::string(" --wall-mm ") + wall);
  add("--formats none", true, 2, good, " --formats nonsense");
  return cases;
}

std::vector<CorpusCase> case_file_corpus(const fs::path& root, std::mt19937& rng, const std::string& default_case) {
  // A small CT for every case: mutations that leave the case valid only ingest it.
  std::vector<float> ct(16 * 16 * 8, 40.0f);
  write_text(root / "ct.nii", nifti_bytes(16, 16, 8, 4, ct, 1.5f));
  std::string base;
  {
    std::istringstream in(default_case);
    for (std::string line; std::getline(in, line);)
      base += (line.rfind("input = ", 0) == 0 ? "input = \"ct.nii\"" : line) + "\n";
  }
  std::vector<CorpusCase> cases;
  int n = 0;
  // `named`: the file a failure must name when it is not the case file (a missing input, a registry).
  auto add = [&](const std::string& name, bool must_fail, const std::string& text, const std::string& until = "ingest",
                 const fs::path& named = {}) {
    const fs::path f = root / ("c" + std::to_string(n++) + ".toml");
    write_text(f, text);
    cases.push_back({"case-file", name, "run " + quoted(f) + " --out " + quoted(root / ("o" + std::to_string(n))) +
                                            " --until " + until,
                     named.empty() ? f : named, root / ("o" + std::to_string(n)), root / "ct.nii", must_fail});
  };
  // Every `key = value` line of the default case (tables included), given values of the wrong
  // type, not finite, or out of range; a seeded sample of them.
  std::vector<std::pair<std::size_t, std::string>> slots;  // offset of the value, key
  for (std::size_t at = 0; at < base.size();) {
    const std::size_t eol = base.find('\n', at);
    const std::string line = base.substr(at, eol - at);
    const std::size_t eq = line.find(" = ");
    if (eq != std::string::npos && line[0] != '#' && line.rfind("input", 0) != 0 && line.rfind("name", 0) != 0)
      slots.emplace_back(at + eq + 3, line.substr(0, eq));
    at = eol + 1;
  }
  const std::vector<std::string> bad = {"\"x\"", "nan", "inf", "-inf", "-1", "0", "1e308", "[]", "{}", "true",
                                        "-9223372036854775808", "[nan]", "\"\"", "1979-05-27"};
  for (int t = 0; t < 70; ++t) {
    const auto& [at, key] = slots[std::uniform_int_distribution<std::size_t>(0, slots.size() - 1)(rng)];
    const std::string& value = bad[std::uniform_int_distribution<std::size_t>(0, bad.size() - 1)(rng)];
    const std::size_t end = base.find_first_of("#\n", at);
    add(key + " = " + value, false, base.substr(0, at) + value + " " + base.substr(end));
  }
  add("empty", true, "");
  add("only a comment", true, "# nothing\n");
  add("no input", true, "[case]\nname = \"x\"\n[[organ]]\nname = \"trachea\"\n");
  add("input missing on disk", true, "[case]\ninput = \"nowhere.nii\"\n", "ingest", "nowhere.nii");
  add("input /dev/zero", true, "[case]\ninput = \"/dev/zero\"\n[[organ]]\nname = \"trachea\"\n", "ingest", "/dev/zero");
  add("invalid UTF-8 in a string", true, "[case]\nname = \"\xff\xfe\"\ninput = \"ct.nii\"\n");
  add("invalid UTF-8 in a key", true, "[case]\nn\xc3me = 1\ninput = \"ct.nii\"\n");
  add("a UTF-8 BOM", false, "\xef\xbb\xbf[case]\ninput = \"ct.nii\"\n[[organ]]\nname = \"trachea\"\n");
  add("arrays nested 5000 deep", true, "[case]\ninput = \"ct.nii\"\nx = " + std::string(5000, '[') + std::string(5000, ']') + "\n");
  add("a 2 MB line", true, "[case]\ninput = \"ct.nii\"\nname = \"" + std::string(2 << 20, 'a') + "\n");
  add("a table twice", true, "[case]\ninput = \"ct.nii\"\n[case]\nname = \"y\"\n");
  add("an unknown stage", true, "[case]\ninput = \"ct.nii\"\n[stages.nope]\nx = 1\n");
  add("an unknown organ", true, "[case]\ninput = \"ct.nii\"\n[[organ]]\nname = \"spleen\"\n");
  add("a seed with NaN", true, "[case]\ninput = \"ct.nii\"\n[[organ]]\nname = \"gallbladder\"\nseed_lps_mm = [nan, 0, 0]\n");
  add("a seed far outside", true, "[case]\ninput = \"ct.nii\"\n[[organ]]\nname = \"gallbladder\"\nseed_lps_mm = [1e9, 0, 0]\n",
      "segment");
  add("a negative voxel seed", true, "[case]\ninput = \"ct.nii\"\n[[organ]]\nname = \"gallbladder\"\nseed_ijk = [-1, 0, 0]\n",
      "segment");
  add("an organ registry that is missing", true, "[case]\ninput = \"ct.nii\"\norgans = \"missing.toml\"\n");
  write_text(root / "bad_registry.toml", "[organ.liver\nlabel = 3\n");
  add("an organ registry with a syntax error", true, "[case]\ninput = \"ct.nii\"\norgans = \"bad_registry.toml\"\n",
      "ingest", root / "bad_registry.toml");
  add("a material from a missing params.json", true,
      "[case]\ninput = \"ct.nii\"\n[materials]\ngallbladder_wall = \"missing/params.json\"\n");
  add("a private-use character", true, "[case]\ninput = \"ct.nii\"\nname = \"\xee\x80\x80\"\n");
  add("NUL bytes", true, std::string("[case]\ninput = \"ct.nii\"\0\0\nname = 1\n", 32));
  return cases;
}

std::vector<CorpusCase> csv_corpus(const fs::path& root, std::mt19937& rng) {
  std::vector<CorpusCase> cases;
  int n = 0;
  auto add = [&](const std::string& command, const std::string& name, const std::string& text) {
    const fs::path f = root / ("c" + std::to_string(n++) + ".csv");
    write_text(f, text);
    const fs::path out = root / ("o" + std::to_string(n));
    std::string args;
    if (command == "calibrate") args = "calibrate --model mooney-rivlin --data " + quoted(f) + " --out " + quoted(out);
    else if (command == "degrade") args = "degrade --fit " + quoted(f) + " --out " + quoted(out);
    else args = "cohort " + quoted(f) + " --out " + quoted(out) + " --no-submit --engine slurm";
    cases.push_back({"csv", command + ": " + name, args, f, out, f, true});
  };
  const std::vector<std::pair<std::string, std::string>> curves = {
      {"NaN stress", "stretch,stress_pa\n1.0,0\n1.1,nan\n1.2,40\n1.3,90\n"},
      {"inf stretch", "stretch,stress_pa\n1.0,0\n1.1,10\ninf,40\n1.3,90\n"},
      {"text", "stretch,stress_pa\n1.0,0\n1.1,abc\n1.2,40\n1.3,90\n"},
      {"empty", ""},
      {"header only", "stretch,stress_pa\n"},
      {"one row", "stretch,stress_pa\n1.1,10\n"},
      {"stretch not increasing", "stretch,stress_pa\n1.0,0\n1.2,10\n1.1,40\n1.3,90\n"},
      {"negative stretch", "stretch,stress_pa\n-1.0,0\n-1.1,10\n-1.2,40\n"},
      {"a missing column", "stretch,stress_pa\n1.0,0\n1.1\n1.2,40\n1.3,90\n"},
      {"unknown columns", "a,b\n1,2\n3,4\n5,6\n"},
      {"1e308 stress", "stretch,stress_pa\n1.0,0\n1.1,1e308\n1.2,1e308\n1.3,1e308\n"},
      {"a NUL byte", std::string("stretch,stress_pa\n1.0,0\n1.1,\0\n1.2,40\n", 38)},
      {"an unclosed quote", "stretch,stress_pa\n1.0,0\n\"1.1,10\n1.2,40\n"}};
  for (const auto& [name, text] : curves) add("calibrate", name, text);
  const std::vector<std::pair<std::string, std::string>> masses = {
      {"NaN mass", "t_days,mass_fraction\n0,1\n10,nan\n20,0.5\n"},
      {"t 1e12 days", "t_days,mass_fraction\n0,1\n1e12,0.9\n2e12,0.5\n"},
      {"time going back", "t_days,mass_fraction\n0,1\n20,0.8\n10,0.5\n"},
      {"mass above 1", "t_days,mass_fraction\n0,1\n10,3\n20,5\n"},
      {"negative mass", "t_days,mass_fraction\n0,1\n10,-0.5\n20,-1\n"},
      {"empty", ""},
      {"header only", "t_days,mass_fraction\n"},
      {"one row", "t_days,mass_fraction\n0,1\n"},
      {"text", "t_days,mass_fraction\n0,1\nten,0.9\n20,0.5\n"},
      {"wrong header", "x,y\n0,1\n10,0.9\n20,0.5\n"}};
  for (const auto& [name, text] : masses) add("degrade", name, text);
  {  // 10⁶ rows of a falling mass: refused or fitted, but within the time limit
    std::string big = "t_days,mass_fraction\n";
    for (int i = 0; i < 1000000; ++i) big += std::to_string(i) + ",0.5\n";
    add("degrade", "10^6 rows, constant", big);
  }
  const std::vector<std::pair<std::string, std::string>> cohorts = {
      {"empty", ""},
      {"header only", "id,input\n"},
      {"no input column", "id,name\na,b\n"},
      {"duplicate ids", "id,input\na,x.nii\na,y.nii\n"},
      {"an id with a slash", "id,input\n../evil,x.nii\n"},
      {"an unknown option column", "id,input,stages.mesh.nope\na,x.nii,3\n"},
      {"a bad option value", "id,input,stages.mesh.edge_mm\na,x.nii,abc\n"},
      {"random bytes", [&] {
         std::string s(300, '\0');
         for (auto& c : s) c = char(rng());
         return s;
       }()}};
  for (const auto& [name, text] : cohorts) add("cohort", name, text);
  // Past the size limit of a table read whole (65 MiB of comment lines: refused by size before
  // anything is read), and a directory where the file should be.
  const std::string padding = [] {
    std::string line = "#" + std::string(1022, 'x') + "\n", big;
    big.reserve(std::size_t(65) << 20);
    while (big.size() < (std::size_t(65) << 20)) big += line;
    return big;
  }();
  for (const char* command : {"calibrate", "degrade", "cohort"}) {
    add(command, "65 MiB", padding);
    add(command, "a directory", "");
    fs::remove(cases.back().named);
    fs::create_directories(cases.back().named);
  }
  return cases;
}

std::vector<CorpusCase> output_path_corpus(const fs::path& root, std::mt19937&) {
  // An input and a user's folder for each command; every trap must leave both as they were.
  std::vector<float> ct(16 * 16 * 8, 40.0f), labels(16 * 16 * 16, 0.0f);
  std::vector<CorpusCase> cases;
  int n = 0;
  for (const std::string command : {"segment", "mesh", "phantom", "calibrate"}) {
    const fs::path dir = root / ("c" + std::to_string(n++));
    const fs::path input = command == "mesh" ? dir / "in" / "labels.nii" : dir / "in" / "ct.nii";
    write_text(input, command == "mesh" ? nifti_bytes(16, 16, 16, 2, labels) : nifti_bytes(16, 16, 8, 4, ct));
    write_text(dir / "in" / "notes.txt", "my notes\n");
    write_text(dir / "user" / "thesis.tex", "\\chapter{}\n");
    write_text(dir / "afile", "a user's file\n");
    const std::vector<std::pair<std::string, fs::path>> traps = {
        {"--out is the input's folder", dir / "in"},       {"--out is above the input", dir},
        {"--out is a regular file", dir / "afile"},        {"--out passes through a file", dir / "afile" / "x"},
        {"--out is a user's folder", dir / "user"},        {"--out is in /proc", "/proc/organsmith-corpus"},
        {"--out is the input file", input}};
    for (const auto& [name, out] : traps) {
      std::string args;
      if (command == "segment") args = "segment " + quoted(input) + " --organ trachea";
      else if (command == "mesh") args = "mesh " + quoted(input);
      else if (command == "phantom") args = "phantom --size 64";
      else args = "calibrate --model mooney-rivlin --data " + quoted(dir / "in" / "notes.txt");
      cases.push_back({"output-path", command + ": " + name, args + " --out " + quoted(out), {}, {}, dir, true});
    }
  }
  return cases;
}

}  // namespace organsmith::testing
