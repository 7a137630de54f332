#include "viewer_fixture.h"

#include "pipeline/case/organ_registry.h"

#include "pipeline/io/image_io.h"
#include "pipeline/io/ingest.h"
#include "tests/support/test_support.h"
#include "viewer/label_surface.h"

#include <Eigen/Geometry>

#include <cmath>
#include <random>
#include <stdexcept>

namespace organsmith::testing {

namespace fs = std::filesystem;

fs::path small_phantom_dir() {
  const fs::path dir = fs::temp_directory_path() / "organsmith-test-viewer-phantom-128-v1";
  if (fs::exists(dir / "ground_truth.nii.gz") && fs::exists(dir / "dicom")) return dir;
  std::random_device rd;
  const fs::path staging = fs::temp_directory_path() / ("organsmith-test-viewer-phantom-" + std::to_string(rd()));
  const CliResult r = run_cli("phantom --out '" + staging.string() + "' --size 128");
  if (r.exit_code != 0) throw std::runtime_error("phantom failed: " + r.output);
  std::error_code ec;
  fs::rename(staging, dir, ec);  // another test process may have won the race: fine
  if (ec) fs::remove_all(staging, ec);
  return dir;
}

TetMesh voxel_tets(const LabelMap& labels, std::uint8_t label, int step) {
  const auto& g = labels.grid;
  TetMesh m;
  std::map<std::array<std::int64_t, 3>, std::int32_t> vid;
  auto vertex = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    const std::array<std::int64_t, 3> key{i, j, k};
    auto it = vid.find(key);
    if (it != vid.end()) return it->second;
    const auto id = std::int32_t(m.vertices_lps_mm.size());
    m.vertices_lps_mm.push_back(g.index_to_lps_mm(Eigen::Vector3d(i - 0.5, j - 0.5, k - 0.5)));
    vid.emplace(key, id);
    return id;
  };
  // Kuhn's six tets of a cube: paths from corner 0 to corner 7 along the axes.
  static const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (std::int64_t k = 0; k < g.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < g.size_vox[1]; j += step)
      for (std::int64_t i = 0; i < g.size_vox[0]; i += step) {
        if (labels.at(i, j, k) != label) continue;
        const std::array<std::int64_t, 3> base{i, j, k}, size{step, step, 1};
        for (const auto& p : perms) {
          std::array<std::int64_t, 3> c = base;
          std::array<std::int32_t, 4> t{};
          t[0] = vertex(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            c[p[s]] += size[p[s]];
            t[s + 1] = vertex(c[0], c[1], c[2]);
          }
          const auto& v = m.vertices_lps_mm;
          if ((v[t[1]] - v[t[0]]).dot((v[t[2]] - v[t[0]]).cross(v[t[3]] - v[t[0]])) < 0) std::swap(t[2], t[3]);
          m.tets.push_back(t);
          m.region_ids.push_back(1);
        }
      }
  return m;
}

std::unique_ptr<TestScene> make_test_scene() {
  auto t = std::make_unique<TestScene>();
  const fs::path dir = small_phantom_dir();
  NullProgress progress;
  t->ct = ingest(dir / "dicom", IngestOptions{}, progress).volume;
  t->labels = read_label_map(dir / "ground_truth.nii.gz");
  SnapshotScene& s = t->scene;
  s.case_name = "test phantom";
  s.ct = &t->ct;
  s.labels = &t->labels;
  s.labels_source = "phantom ground truth";
  s.organs = {{"gallbladder", 1, organ_colour("gallbladder")}, {"trachea", 2, organ_colour("trachea")}};
  for (const auto& o : s.organs) {
    SceneSurface surf;
    surf.name = surf.organ = o.name;
    surf.colour = organ_colour(o.name);
    surf.mesh = label_surface(t->labels, o.label);
    surf.source = "label-map isosurface";
    s.surfaces.push_back(std::move(surf));
  }
  SceneSurface liver;
  liver.name = liver.organ = "liver";
  liver.colour = organ_colour("liver");
  liver.opacity = 0.2;
  liver.context = true;
  liver.mesh = label_surface(t->labels, 3);
  s.surfaces.push_back(std::move(liver));
  s.tet_meshes.push_back({"gallbladder", voxel_tets(t->labels, 1, 1)});

  // A path along the trachea: the centroid of its voxels on every fourth slice.
  Polyline path;
  path.name = "trachea_centreline";
  const auto& g = t->labels.grid;
  for (std::int64_t k = 0; k < g.size_vox[2]; k += 4) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int n = 0;
    for (std::int64_t j = 0; j < g.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < g.size_vox[0]; ++i)
        if (t->labels.at(i, j, k) == 2) sum += Eigen::Vector3d(double(i), double(j), double(k)), ++n;
    if (n > 0) path.points_lps_mm.push_back(g.index_to_lps_mm(sum / n));
  }
  s.paths.push_back({path});
  SceneTool tool;
  tool.tip_lps_mm = s.surfaces[0].mesh.vertices_lps_mm.at(0);
  tool.force_N = Eigen::Vector3d(0.0, -1.5, 0.5);
  s.tool = tool;

  // A stress–strain fit and a CDF, as calibration and uncertainty produce them.
  Plot fit{"fit", "Gallbladder wall, uniaxial: measured vs fitted", "stretch", "stress (kPa)", {}};
  PlotSeries measured{"measured", {}, {}, true, {0.1, 0.1, 0.1}};
  PlotSeries fitted{"Fung fit", {}, {}, false, {0.85, 0.2, 0.1}};
  for (int i = 0; i <= 12; ++i) {
    const double lam = 1.0 + 0.025 * i;
    measured.x.push_back(lam);
    measured.y.push_back(2.0 * (std::exp(8.0 * (lam - 1)) - 1) * (1.0 + 0.03 * std::sin(i * 1.7)));
  }
  for (int i = 0; i <= 60; ++i) {
    const double lam = 1.0 + 0.005 * i;
    fitted.x.push_back(lam);
    fitted.y.push_back(2.0 * (std::exp(8.0 * (lam - 1)) - 1));
  }
  fit.series = {measured, fitted};
  Plot cdf{"cdf", "Monte Carlo CDF of the failure stress", "stress (kPa)", "probability", {}};
  PlotSeries mc{"Monte Carlo (1000)", {}, {}, false, {0.1, 0.3, 0.8}};
  for (int i = 0; i <= 100; ++i) {
    const double x = 20 + 0.6 * i;
    mc.x.push_back(x);
    mc.y.push_back(0.5 * (1 + std::erf((x - 50) / (8 * std::sqrt(2.0)))));
  }
  cdf.series = {mc};
  s.plots = {fit, cdf};
  return t;
}

double grey_variance(const RgbImage& img) {
  double sum = 0, sum2 = 0;
  const std::size_t n = std::size_t(img.width_px) * img.height_px;
  for (std::size_t i = 0; i < n; ++i) {
    const double g = (img.rgb[3 * i] + img.rgb[3 * i + 1] + img.rgb[3 * i + 2]) / 3.0;
    sum += g;
    sum2 += g * g;
  }
  const double mean = sum / double(n);
  return sum2 / double(n) - mean * mean;
}

std::size_t count_colour(const RgbImage& img, const Rgb& c, int tol) {
  const int r = int(std::lround(c.r * 255)), g = int(std::lround(c.g * 255)), b = int(std::lround(c.b * 255));
  std::size_t n = 0;
  for (std::size_t i = 0; i + 2 < img.rgb.size(); i += 3)
    if (std::abs(img.rgb[i] - r) <= tol && std::abs(img.rgb[i + 1] - g) <= tol && std::abs(img.rgb[i + 2] - b) <= tol) ++n;
  return n;
}

std::size_t count_hue(const RgbImage& img, const Rgb& c) {
  // The brightest channel of the organ colour must stay the brightest by a margin: shading
  // changes the brightness of a surface, not which channel dominates.
  const double ch[3] = {c.r, c.g, c.b};
  const int top = int(std::max_element(ch, ch + 3) - ch);
  std::size_t n = 0;
  for (std::size_t i = 0; i + 2 < img.rgb.size(); i += 3) {
    const int v[3] = {img.rgb[i], img.rgb[i + 1], img.rgb[i + 2]};
    bool ok = v[top] > 60;
    for (int k = 0; k < 3 && ok; ++k)
      if (k != top && v[top] - v[k] < 0.5 * 255 * (ch[top] - ch[k])) ok = false;
    n += ok ? 1 : 0;
  }
  return n;
}

Rgb organ_colour(const std::string& organ) {
  const auto& c = builtin_organ_registry().at(organ).colour_rgb;
  return {c[0], c[1], c[2]};
}

}  // namespace organsmith::testing
