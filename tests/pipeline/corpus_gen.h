#pragma once
// A seeded generator of malformed and hostile inputs for the CLI (the corpus suite,
// test_corpus.cpp): DICOM series, NIfTI, NRRD and MetaImage files, label maps for meshing, case
// files, CSV files and output-path traps. Each case is a command line with what its result must
// respect; the same seed gives the same cases.

#include <filesystem>
#include <random>
#include <string>
#include <vector>

namespace organsmith::testing {

struct CorpusCase {
  std::string kind;                ///< dicom, nifti, text-header, label-map, case-file, csv, output-path
  std::string name;                ///< what was done to the input, for the report
  std::string args;                ///< the organsmith command line (arguments shell-quoted)
  std::filesystem::path named;     ///< a failure's message must name this file (its file name); empty: no check
  std::filesystem::path out;       ///< the output directory the command writes into; empty: none
  std::filesystem::path guarded;   ///< a file or directory that must be left exactly as it was
  bool must_fail = false;          ///< built to be invalid: exit 0 would be a garbage read
};

/// Every generator writes its inputs under `root` (one sub-folder per case).
std::vector<CorpusCase> dicom_corpus(const std::filesystem::path& root, std::mt19937& rng);
std::vector<CorpusCase> nifti_corpus(const std::filesystem::path& root, std::mt19937& rng);
std::vector<CorpusCase> text_header_corpus(const std::filesystem::path& root, std::mt19937& rng);
std::vector<CorpusCase> label_map_corpus(const std::filesystem::path& root, std::mt19937& rng);
std::vector<CorpusCase> case_file_corpus(const std::filesystem::path& root, std::mt19937& rng,
                                         const std::string& default_case);
std::vector<CorpusCase> csv_corpus(const std::filesystem::path& root, std::mt19937& rng);
std::vector<CorpusCase> output_path_corpus(const std::filesystem::path& root, std::mt19937& rng);

/// A raw NIfTI-1 file (348-byte header, 4 bytes of extension flag, data): `datatype` 4 (int16),
/// 16 (float32) or 2 (uint8); `values` are converted to it.
std::string nifti_bytes(int nx, int ny, int nz, short datatype, const std::vector<float>& values,
                        float spacing_mm = 1.0f);

}  // namespace organsmith::testing
