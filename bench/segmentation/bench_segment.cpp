// Both organs on the 512×512×~320 phantom (1.25 mm slices): wall time of segment_organs.
// Target: ≤ 2 s on two cores (issue 15: robustness work must not slow it; was ≤ 10 s).

#include "core/progress.h"
#include "pipeline/phantom/phantom.h"
#include "segmentation/segment.h"

#include <chrono>
#include <cstdio>
#include <string>

using namespace organsmith;
using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  NullProgress np;
  PhantomOptions po;
  po.slice_mm = argc > 1 ? std::atof(argv[1]) : 1.25;
  const Phantom ph = synthesize_phantom(po, np);
  const auto& s = ph.ct.grid.size_vox;
  const std::vector<OrganRequest> req{{"gallbladder", ph.seeds_lps_mm.at("gallbladder"), {}}, {"trachea", {}, {}}};
  double best = 1e300;
  SegmentationResult r;
  for (int rep = 0; rep < 3; ++rep) {
    const auto t0 = Clock::now();
    r = segment_organs(ph.ct, req, {}, np);
    best = std::min(best, std::chrono::duration<double>(Clock::now() - t0).count());
  }
  std::printf("segment_organs, gallbladder + trachea on a %lld×%lld×%lld phantom (%.2f mm slices): %.2f s (best of 3)\n",
              (long long)s[0], (long long)s[1], (long long)s[2], po.slice_mm, best);
  for (const auto& o : r.organs)
    std::printf("  %-12s %3zu slices, %.2f ml\n", o.organ.c_str(), o.contours.contours.size(), o.volume_ml);
  std::printf("%s: %.2f s %s 2 s\n", best <= 2.0 ? "PASS" : "FAIL", best, best <= 2.0 ? "≤" : ">");
  // The gallbladder's 3-D surface on thick and thin slices of the same phantom: its own time and
  // working memory (segmentation.json's note).
  for (double slice : {5.0, 1.0}) {
    PhantomOptions p2 = po;
    p2.slice_mm = slice;
    const Phantom ph2 = synthesize_phantom(p2, np);
    double all = 1e300;
    std::string best_note;  // the 3-D stage's note (its time, box and memory) of the fastest run
    for (int rep = 0; rep < 3; ++rep) {
      const auto t0 = Clock::now();
      const SegmentationResult r2 = segment_organs(ph2.ct, {req[0]}, {}, np);
      const double t = std::chrono::duration<double>(Clock::now() - t0).count();
      if (t >= all) continue;
      all = t;
      for (const auto& n : r2.organs[0].notes)
        if (n.rfind("3-D surface", 0) == 0) best_note = n;
    }
    std::printf("  %.1f mm slices: gallbladder %.2f s in all (best of 3); %s\n", slice, all, best_note.c_str());
  }
  return best <= 2.0 ? 0 : 1;
}
