// Ingest speed: loading a 512×512×300 phantom CT series (decode, sort, validate, rescale to
// float HU) against merely reading the same files' bytes, in one run. Target: ratio ≤ 1.5.
//
// The series is written first, so the files are in the page cache ("cold-ish": no decoder state
// is warm, but the disk is not involved). Each variant runs several times, alternating, and the
// medians are compared. The byte reader uses the same TBB parallelism as ingest.

#include "core/progress.h"
#include "pipeline/io/dicom.h"
#include "pipeline/io/ingest.h"
#include "pipeline/phantom/phantom.h"

#include <fcntl.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <vector>

using namespace organsmith;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// The reference: every file's bytes read into one freshly allocated buffer (the same
/// allocator as the volume, so both pay the same first-touch cost), in parallel like ingest.
std::size_t read_all_bytes(const std::vector<fs::path>& files) {
  std::vector<std::size_t> offset(files.size() + 1, 0);
  for (std::size_t a = 0; a < files.size(); ++a) offset[a + 1] = offset[a] + std::size_t(fs::file_size(files[a]));
  VoxelBuffer<char> buf(offset.back());
  std::vector<std::size_t> got(files.size());
  tbb::parallel_for(std::size_t(0), files.size(), [&](std::size_t a) {
    std::ifstream in(files[a], std::ios::binary);
    in.read(buf.data() + offset[a], std::streamsize(offset[a + 1] - offset[a]));
    got[a] = std::size_t(in.gcount());
  });
  std::size_t total = 0;
  for (auto s : got) total += s;
  return total;
}

/// Drops the files from the page cache so the next read comes from the disk.
void evict(const std::vector<fs::path>& files) {
  for (const auto& f : files) {
    const int fd = open(f.c_str(), O_RDONLY);
    if (fd < 0) continue;
    fdatasync(fd);
    posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
    close(fd);
  }
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  const int slices = argc > 1 ? std::atoi(argv[1]) : 300;
  const fs::path dir = fs::temp_directory_path() / "organsmith-bench-ingest";
  fs::remove_all(dir);
  NullProgress np;
  PhantomOptions po;
  po.slice_mm = 2.5;
  po.extent_mm = 2.5 * slices;
  std::printf("writing a 512×512×%d phantom series to %s …\n", slices, dir.c_str());
  const Phantom ph = synthesize_phantom(po, np);
  DicomSeriesIds ids;
  ids.uid_seed = "bench";
  write_dicom_series(ph.ct, dir, ids, np);
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir)) files.push_back(e.path());

  std::size_t bytes = 0;
  for (const bool cold : {false, true}) {
    std::vector<double> t_bytes, t_ingest;
    for (int rep = 0; rep < 5; ++rep) {
      if (cold) evict(files);
      auto t0 = Clock::now();
      bytes = read_all_bytes(files);
      t_bytes.push_back(seconds_since(t0));
      if (cold) evict(files);
      t0 = Clock::now();
      const IngestResult r = ingest(dir, {}, np);
      t_ingest.push_back(seconds_since(t0));
      if (r.volume.grid.size_vox[2] != slices) {
        std::fprintf(stderr, "ingest read %lld slices, expected %d\n", (long long)r.volume.grid.size_vox[2], slices);
        return 1;
      }
    }
    const double b = median(t_bytes), i = median(t_ingest);
    std::printf("\n%s page cache: %zu files, %.1f MiB\n", cold ? "evicted (cold)" : "warm", files.size(),
                double(bytes) / (1 << 20));
    std::printf("  read bytes into memory:   median %.3f s (%.0f MiB/s)\n", b, double(bytes) / (1 << 20) / b);
    std::printf("  ingest (decode+sort+HU):  median %.3f s\n", i);
    std::printf("  ratio ingest / bytes:     %.2f (target <= 1.5)\n", i / b);
  }
  fs::remove_all(dir);
  return 0;
}
