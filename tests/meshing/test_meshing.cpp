// Over 400 lines: the meshing tests share one phantom meshed once (PhantomMeshes fixture); splitting
// them would mesh it again per file.
// Properties of organsmith's meshes: the surface guarantees (closed, 2-manifold, outward,
// no self-intersections or degenerate faces, edge lengths, angles, volume, HD95), the wall
// bodies, the tetrahedral quality gate, exporter round trips checked by independent readers,
// determinism, and clear errors on bad input.

#include "meshing/export.h"
#include "meshing/mesh.h"
#include "meshing/tube_regions.h"
#include "meshing/quality.h"
#include "meshing/detail.h"
#include "meshing/tet_improve.h"
#include "pipeline/io/image_io.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/phantom/phantom.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>

using namespace organsmith;
namespace fs = std::filesystem;
using organsmith::testing::ScratchDir;

namespace {

/// The organs as the pipeline meshes them: from the built-in organ registry (data/organs.toml).
std::vector<MeshOrganSpec> registry_organs(std::initializer_list<const char*> names = {"gallbladder", "trachea"}) {
  std::vector<MeshOrganSpec> specs;
  for (const char* n : names) specs.push_back(mesh_spec(builtin_organ_registry().at(n)));
  return specs;
}

/// Independent of CGAL: every undirected edge is used by exactly two triangles, in opposite
/// directions (closed, edge-manifold and consistently oriented).
bool closed_and_consistent(const SurfaceMesh& m) {
  std::map<std::pair<int, int>, int> directed;
  for (const auto& t : m.triangles)
    for (int e = 0; e < 3; ++e) ++directed[{t[e], t[(e + 1) % 3]}];
  for (const auto& [e, n] : directed) {
    if (n != 1) return false;
    const auto it = directed.find({e.second, e.first});
    if (it == directed.end() || it->second != 1) return false;
  }
  return true;
}

void expect_guarantees(const NamedSurface& s) {
  SCOPED_TRACE(s.name);
  const SurfaceQuality& q = s.quality;
  EXPECT_TRUE(q.closed);
  EXPECT_TRUE(q.manifold);
  EXPECT_TRUE(q.outward);
  EXPECT_FALSE(q.self_intersecting);
  EXPECT_EQ(q.degenerate_faces, 0);
  EXPECT_EQ(q.components, 1);
  EXPECT_GE(q.edge_within_tolerance, 0.90) << "edges within ±25 % of the target";
  EXPECT_GE(q.angle_min_deg, 25.0);
  // Fold gate of a smooth organ's boundary without cut faces (the gallbladder): no staircase crease.
  if (s.name == "gallbladder") EXPECT_LE(q.fold_max_deg, 60.0);
  EXPECT_TRUE(closed_and_consistent(s.mesh));
  EXPECT_GT(s.mesh.signed_volume_mm3(), 0.0);
  if (q.reference_volume_mm3 > 0) {
    EXPECT_LE(std::abs(q.volume_error), 0.03) << "mesh volume vs label volume";
    EXPECT_GE(q.hd95_mm, 0.0);
    EXPECT_LE(q.hd95_mm, q.hd_tolerance_mm) << "symmetric HD95 to the label boundary vs one voxel diagonal";
  }
  // measure_surface itself must agree with an independent re-measurement of the mesh.
  const SurfaceQuality again = measure_surface(s.mesh, q.target_edge_mm);
  EXPECT_EQ(again.triangles, q.triangles);
  EXPECT_NEAR(again.volume_mm3, s.mesh.signed_volume_mm3(), 1e-6 * std::abs(again.volume_mm3) + 1e-9);
}

/// The tetrahedral quality gate, as the project states it: every tet's smallest dihedral angle
/// ≥ 10°, radius-edge ratio ≤ 2, none inverted or flat. CGAL Mesh_3 (perturb to 8°, exude to
/// 12°) leaves 0.1–0.5 % of the tets below it, nearly all with every vertex on the boundary or
/// the wall/body interface; organsmith's repair (slides on the surface, moves, flips, edge
/// splits; see tet_improve.cpp) aims at 11° / 1.9 and reaches 10.7–11.3° / ≤ 1.905 on the
/// phantom and the real references.
void expect_tet_gate(const TetQuality& q) {
  EXPECT_EQ(q.inverted_or_flat, 0);
  EXPECT_GE(q.dihedral_min_deg, 10.0);
  EXPECT_LE(q.radius_edge_max, 2.0);
  EXPECT_EQ(q.below_min_dihedral, 0) << "tets below 10°";
  EXPECT_EQ(q.above_max_radius_edge, 0) << "tets above radius-edge 2";
  EXPECT_TRUE(q.ok());
}

const NamedSurface* find_surface(const OrganMesh& o, const std::string& name) {
  for (const auto& s : o.surfaces)
    if (s.name == name) return &s;
  return nullptr;
}

const OrganMesh* find_organ(const OrganMeshes& m, const std::string& name) {
  for (const auto& o : m.organs)
    if (o.spec.name == name) return &o;
  return nullptr;
}

/// Phantom ground truth meshed once for the whole suite (quality gate reported, not thrown, so
/// that each test can name the figure that fails).
class PhantomMeshes : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    NullProgress progress;
    const Phantom ph = synthesize_phantom(PhantomOptions{}, progress);
    labels_ = new LabelMap(ph.truth);
    MeshOptions o;
    o.organs = registry_organs();
    o.enforce_quality = false;
    meshes_ = new OrganMeshes(mesh_organs(*labels_, o, progress));
  }
  static void TearDownTestSuite() {
    delete meshes_;
    delete labels_;
  }
  static LabelMap* labels_;
  static OrganMeshes* meshes_;
};
LabelMap* PhantomMeshes::labels_ = nullptr;
OrganMeshes* PhantomMeshes::meshes_ = nullptr;

}  // namespace

TEST_F(PhantomMeshes, SurfacesMeetEveryGuarantee) {
  ASSERT_EQ(meshes_->organs.size(), 2u);
  for (const auto& organ : meshes_->organs)
    for (const auto& s : organ.surfaces) expect_guarantees(s);
}

TEST_F(PhantomMeshes, OrganVolumeMatchesLabelVolume) {
  const OrganMesh* gb = find_organ(*meshes_, "gallbladder");
  ASSERT_NE(gb, nullptr);
  const double label_mm3 = labels_->volume_ml(1) * 1000.0;
  // Every label voxel is meshed but those one voxel thin (MeshOptions::drop_thin_voxels): a few
  // on the phantom's voxel surface, none of its body.
  EXPECT_NEAR(gb->label_volume_mm3 + gb->dropped_volume_mm3, label_mm3, 1e-6 * label_mm3);
  EXPECT_LT(gb->dropped_volume_mm3, 0.005 * label_mm3);
  const NamedSurface* outer = find_surface(*gb, "gallbladder");
  ASSERT_NE(outer, nullptr);
  EXPECT_NEAR(outer->mesh.signed_volume_mm3(), label_mm3, 0.03 * label_mm3);
}

TEST_F(PhantomMeshes, GallbladderHasWallAndBodyRegions) {
  const OrganMesh* gb = find_organ(*meshes_, "gallbladder");
  ASSERT_NE(gb, nullptr);
  const NamedSurface* outer = find_surface(*gb, "gallbladder");
  const NamedSurface* inner = find_surface(*gb, "gallbladder_wall_inner");
  ASSERT_NE(outer, nullptr);
  ASSERT_NE(inner, nullptr);
  // Wall volume between the surfaces ≈ area × thickness (less on the inside, curved), and the
  // tetrahedral regions carry the same split.
  const double shell = outer->mesh.signed_volume_mm3() - inner->mesh.signed_volume_mm3();
  const double area_t = outer->quality.area_mm2 * gb->spec.wall_mm;
  EXPECT_GT(shell, 0.7 * area_t);
  EXPECT_LT(shell, 1.05 * area_t);
  std::map<std::int32_t, double> regions(gb->volume_quality.region_volumes_mm3.begin(),
                                         gb->volume_quality.region_volumes_mm3.end());
  ASSERT_EQ(regions.size(), 2u);
  ASSERT_TRUE(regions.count(kRegionGallbladderBody) && regions.count(kRegionGallbladderWall));
  EXPECT_NEAR(regions[kRegionGallbladderWall], shell, 0.1 * shell);
  EXPECT_NEAR(regions[kRegionGallbladderBody], inner->mesh.signed_volume_mm3(), 0.05 * inner->mesh.signed_volume_mm3());
  EXPECT_EQ(gb->region_names.at(kRegionGallbladderWall), "gallbladder_wall");
  EXPECT_EQ(gb->region_names.at(kRegionGallbladderBody), "gallbladder_body");
}

TEST_F(PhantomMeshes, TracheaIsATubeWithFlatCapsAndAClosedLumen) {
  const OrganMesh* tr = find_organ(*meshes_, "trachea");
  ASSERT_NE(tr, nullptr);
  const NamedSurface* lumen = find_surface(*tr, "trachea_lumen");
  const NamedSurface* wall = find_surface(*tr, "trachea_wall");
  ASSERT_NE(lumen, nullptr);
  ASSERT_NE(wall, nullptr);
  // The phantom's trachea reaches the last slice: a warning says it was capped.
  bool warned = false;
  for (const auto& w : tr->warnings) warned |= w.find("image border") != std::string::npos;
  EXPECT_TRUE(warned);
  // The wall is one closed surface of genus 1 (a tube with annular caps): V − E + F = 0.
  std::set<std::pair<int, int>> edges;
  for (const auto& t : wall->mesh.triangles)
    for (int e = 0; e < 3; ++e) edges.insert(std::minmax(t[e], t[(e + 1) % 3]));
  EXPECT_EQ(std::int64_t(wall->mesh.vertices_lps_mm.size()) - std::int64_t(edges.size()) +
                std::int64_t(wall->mesh.triangles.size()),
            0);
  // Flat caps: the lumen and the wall end on the same two slice planes (phantom: k is S).
  double zmin = 1e300, zmax = -1e300, wmin = 1e300, wmax = -1e300;
  for (const auto& v : lumen->mesh.vertices_lps_mm) zmin = std::min(zmin, v.z()), zmax = std::max(zmax, v.z());
  for (const auto& v : wall->mesh.vertices_lps_mm) wmin = std::min(wmin, v.z()), wmax = std::max(wmax, v.z());
  EXPECT_NEAR(wmin, zmin, 1e-6);
  EXPECT_NEAR(wmax, zmax, 1e-6);
  std::size_t on_caps = 0;
  for (const auto& v : wall->mesh.vertices_lps_mm) on_caps += std::abs(v.z() - wmin) < 1e-6 || std::abs(v.z() - wmax) < 1e-6;
  EXPECT_GT(on_caps, 20u);
  // The wall is built from the lumen surface (its inner tube is the lumen, vertex for vertex)
  // and the outer offset surface, not sampled again on its own.
  for (const auto& w : tr->warnings) EXPECT_EQ(w.find("wall sampled on its own"), std::string::npos) << w;
  std::set<std::array<double, 3>> wall_points;
  for (const auto& v : wall->mesh.vertices_lps_mm) wall_points.insert({v.x(), v.y(), v.z()});
  std::size_t lumen_side = 0, shared = 0;
  for (const auto& v : lumen->mesh.vertices_lps_mm) {
    if (std::abs(v.z() - zmin) < 1e-6 || std::abs(v.z() - zmax) < 1e-6) continue;  // lumen caps are not in the wall
    ++lumen_side;
    shared += wall_points.count({v.x(), v.y(), v.z()});
  }
  EXPECT_GT(lumen_side, 1000u);
  EXPECT_EQ(shared, lumen_side) << "lumen vertices missing from the wall's inner tube";
  // The wall encloses (outer − lumen) ≈ perimeter × thickness × length; at least it is positive
  // and smaller than the full outer tube.
  EXPECT_GT(wall->mesh.signed_volume_mm3(), 0.5 * lumen->quality.area_mm2 * tr->spec.wall_mm);
  ASSERT_FALSE(tr->volume.tets.empty());
  // Cartilage rings and the membrane between and behind them (data/organs.toml [trachea] rings).
  std::size_t cartilage = 0, membrane = 0;
  for (auto r : tr->volume.region_ids) {
    ASSERT_TRUE(r == kRegionTubeCartilage || r == kRegionTubeMembrane) << r;
    (r == kRegionTubeCartilage ? cartilage : membrane) += 1;
  }
  EXPECT_GT(cartilage, tr->volume.tets.size() / 4);
  EXPECT_GT(membrane, tr->volume.tets.size() / 10);
  EXPECT_NEAR(tr->volume.volume_mm3(), wall->mesh.signed_volume_mm3(), 0.03 * wall->mesh.signed_volume_mm3());
}

TEST_F(PhantomMeshes, TetrahedraArePositiveAndMeetTheQualityGate) {
  for (const auto& organ : meshes_->organs) {
    SCOPED_TRACE(organ.spec.name);
    const TetQuality& q = organ.volume_quality;
    ASSERT_GT(q.tets, 1000);
    for (std::size_t t = 0; t < organ.volume.tets.size(); ++t) ASSERT_GT(organ.volume.tet_volume_mm3(t), 0.0);
    expect_tet_gate(q);
  }
}

TEST(TetRepair, RepairKeepsFacesFlatEdgesStraightAndTheVolume) {
  // A 6×6×6 block of cubes (1 mm), each split into 6 tets around its main diagonal, with every
  // vertex jittered: interior ones in 3D, face vertices within their face, edge and corner
  // vertices not at all. The repair may move interior vertices anywhere and face vertices only
  // within their face (the block's faces are flat: a tangential slide must leave them there);
  // edges and corners are creases and must stay put.
  const int n = 6;
  TetMesh m;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-0.3, 0.3);
  auto id = [&](int i, int j, int k) { return std::int32_t(i + (n + 1) * (j + (n + 1) * k)); };
  std::vector<int> on_faces;  // how many of the block's faces each vertex lies on
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        const int c[3] = {i, j, k};
        Eigen::Vector3d p(i, j, k);
        int faces = 0;
        for (int a = 0; a < 3; ++a) faces += (c[a] == 0 || c[a] == n);
        for (int a = 0; a < 3; ++a)
          if (!(c[a] == 0 || c[a] == n) && faces <= 1) p[a] += jitter(rng);
        m.vertices_lps_mm.push_back(p);
        on_faces.push_back(faces);
      }
  static const int kCube[6][4] = {{0, 1, 3, 7}, {0, 3, 2, 7}, {0, 2, 6, 7}, {0, 6, 4, 7}, {0, 4, 5, 7}, {0, 5, 1, 7}};
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        std::int32_t c[8];
        for (int b = 0; b < 8; ++b) c[b] = id(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1));
        for (const auto& t : kCube) {
          std::array<std::int32_t, 4> tet{c[t[0]], c[t[1]], c[t[2]], c[t[3]]};
          m.tets.push_back(tet);
          if (m.tet_volume_mm3(m.tets.size() - 1) < 0) std::swap(m.tets.back()[2], m.tets.back()[3]);
          m.region_ids.push_back(1);
        }
      }
  for (std::size_t t = 0; t < m.tets.size(); ++t) ASSERT_GT(m.tet_volume_mm3(t), 0.0) << "set-up";
  const TetMesh before = m;
  TetGuarantees g;
  const TetQuality q0 = measure_tets(m, g);
  ASSERT_GT(q0.below_min_dihedral + q0.above_max_radius_edge, 0) << "the set-up must start below the gate";

  const auto stats = meshing_detail::improve_tets(m, 10.0, 2.0);
  EXPECT_GT(stats.moved_vertices, 0);
  EXPECT_EQ(stats.peeled_tets, 0) << "a block's tets have at most one face on its boundary";
  ASSERT_EQ(m.vertices_lps_mm.size(), before.vertices_lps_mm.size());
  for (std::size_t v = 0; v < m.vertices_lps_mm.size(); ++v) {
    const Eigen::Vector3d &p = m.vertices_lps_mm[v], &p0 = before.vertices_lps_mm[v];
    if (on_faces[v] >= 2) {
      EXPECT_EQ(p, p0) << "edge or corner vertex " << v << " moved";
    } else if (on_faces[v] == 1) {
      for (int a = 0; a < 3; ++a)
        if (p0[a] == 0.0 || p0[a] == double(n)) EXPECT_NEAR(p[a], p0[a], 1e-12) << "face vertex " << v << " left its face";
    }
  }
  for (std::size_t t = 0; t < m.tets.size(); ++t) EXPECT_GT(m.tet_volume_mm3(t), 0.0);
  EXPECT_NEAR(m.volume_mm3(), double(n * n * n), 1e-9);
  const TetQuality q1 = measure_tets(m, g);
  EXPECT_LT(q1.below_min_dihedral + q1.above_max_radius_edge, q0.below_min_dihedral + q0.above_max_radius_edge);
  EXPECT_GE(q1.dihedral_min_deg, q0.dihedral_min_deg);
}

TEST(TetRepair, FlipReplacesTwoFlatTetsByThreeBetterOnesKeepingVolumeAndBoundary) {
  // A flat bipyramid: triangle abc (side 10 mm) with apexes 1.2 mm above and below. Split along
  // abc its two tets have radius-edge ratios of 2.46; split around the axis de (a 2-3 flip) the
  // three tets have 2.35. Every vertex is on the boundary, so only a flip can change anything.
  TetMesh m;
  const double r = 10.0 / std::sqrt(3.0);
  for (int i = 0; i < 3; ++i)
    m.vertices_lps_mm.emplace_back(r * std::cos(2 * M_PI * i / 3), r * std::sin(2 * M_PI * i / 3), 0.0);
  m.vertices_lps_mm.emplace_back(0, 0, 1.2);
  m.vertices_lps_mm.emplace_back(0, 0, -1.2);
  m.tets = {{0, 1, 2, 3}, {0, 2, 1, 4}};
  m.region_ids = {7, 7};
  for (std::size_t t = 0; t < 2; ++t) ASSERT_GT(m.tet_volume_mm3(t), 0.0);
  const double volume = m.tet_volume_mm3(0) + m.tet_volume_mm3(1);
  TetGuarantees g;
  g.min_dihedral_deg = 10.0;
  g.max_radius_edge = 2.0;
  const TetQuality before = measure_tets(m, g);
  ASSERT_GT(before.above_max_radius_edge, 0) << "the set-up must start below the gate";

  EXPECT_EQ(meshing_detail::flip_tets(m, 10.0, 2.0), 1);
  ASSERT_EQ(m.tets.size(), 3u);
  double after_volume = 0;
  for (std::size_t t = 0; t < m.tets.size(); ++t) {
    EXPECT_GT(m.tet_volume_mm3(t), 0.0);
    EXPECT_EQ(m.region_ids[t], 7);
    after_volume += m.tet_volume_mm3(t);
  }
  EXPECT_NEAR(after_volume, volume, 1e-9 * volume);
  const TetQuality after = measure_tets(m, g);
  EXPECT_LT(after.radius_edge_max, before.radius_edge_max);
  // The boundary is the same six triangles (as vertex sets).
  std::set<std::array<std::int32_t, 3>> boundary;
  std::map<std::array<std::int32_t, 3>, int> count;
  for (const auto& t : m.tets)
    for (int f = 0; f < 4; ++f) {
      std::array<std::int32_t, 3> k{t[(f + 1) % 4], t[(f + 2) % 4], t[(f + 3) % 4]};
      std::sort(k.begin(), k.end());
      ++count[k];
    }
  for (const auto& [k, c] : count)
    if (c == 1) boundary.insert(k);
  const std::set<std::array<std::int32_t, 3>> expected{{0, 1, 3}, {1, 2, 3}, {0, 2, 3}, {0, 1, 4}, {1, 2, 4}, {0, 2, 4}};
  EXPECT_EQ(boundary, expected);
}

TEST(TubeWall, JoinRefusesSurfacesWithoutCapsOnThePlanes) {
  // The join needs flat caps on the given planes; without them it must throw (mesh_organs then
  // samples the wall on its own and says so) rather than return an open or partial surface.
  SurfaceMesh tet;
  tet.vertices_lps_mm = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tet.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  SurfaceMesh big = tet;
  for (auto& v : big.vertices_lps_mm) v = 3.0 * v - Eigen::Vector3d::Constant(1.0);
  meshing_detail::RemeshParams rp;
  EXPECT_THROW(meshing_detail::tube_wall_from_surfaces(big, tet, {{2, 0.5}}, rp), std::runtime_error);
  EXPECT_THROW(meshing_detail::tube_wall_from_surfaces(big, tet, {}, rp), std::runtime_error);
}

TEST(TetRepair, WallOneTetThickIsRepairedBySlidingOnItsCurvedSurfaces) {
  // A curved wall one tet thick, like the gallbladder wall: a 12×8×1 block of unit cubes (6 tets
  // each) bent onto a cylinder shell (inner radius 4 mm, 1 mm thick; neighbouring surface
  // triangles bend by ≈ 14°). Every vertex lies on the boundary, so only slides on the smooth
  // surfaces, flips and splits can repair it. The inner and outer surface vertices are jittered
  // along their cylinders; the rims (where the cylinders meet the flat sides) and the sides are not.
  const int nx = 12, ny = 8;
  const double R = 4.0;
  TetMesh m;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> jitter(-0.3, 0.3);
  std::vector<char> on_side;  // on a flat side (a rim vertex): must not move
  auto id = [&](int i, int j, int k) { return std::int32_t(i + (nx + 1) * (j + (ny + 1) * k)); };
  for (int k = 0; k <= 1; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        const bool side = i == 0 || i == nx || j == 0 || j == ny;
        const double a = (i + (side ? 0.0 : jitter(rng))) / R, y = j + (side ? 0.0 : jitter(rng));
        const double r = R + k;
        m.vertices_lps_mm.emplace_back(r * std::cos(a), y, r * std::sin(a));
        on_side.push_back(side);
      }
  static const int kCube[6][4] = {{0, 1, 3, 7}, {0, 3, 2, 7}, {0, 2, 6, 7}, {0, 6, 4, 7}, {0, 4, 5, 7}, {0, 5, 1, 7}};
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      std::int32_t c[8];
      for (int b = 0; b < 8; ++b) c[b] = id(i + (b & 1), j + ((b >> 1) & 1), (b >> 2) & 1);
      for (const auto& t : kCube) {
        m.tets.push_back({c[t[0]], c[t[1]], c[t[2]], c[t[3]]});
        if (m.tet_volume_mm3(m.tets.size() - 1) < 0) std::swap(m.tets.back()[2], m.tets.back()[3]);
        m.region_ids.push_back(2);
      }
    }
  for (std::size_t t = 0; t < m.tets.size(); ++t) ASSERT_GT(m.tet_volume_mm3(t), 0.0) << "set-up";
  const TetMesh before = m;
  const TetQuality q0 = measure_tets(m, TetGuarantees{});
  ASSERT_GT(q0.below_min_dihedral + q0.above_max_radius_edge, 10) << "the set-up must start well below the gate";

  const auto stats = meshing_detail::improve_tets(m, 10.0, 2.0);
  EXPECT_EQ(stats.peeled_tets, 0);
  const TetQuality q1 = measure_tets(m, TetGuarantees{});
  EXPECT_TRUE(q1.ok()) << q1.below_min_dihedral << " tets below 10° (smallest " << q1.dihedral_min_deg << "°), "
                       << q1.above_max_radius_edge << " above radius-edge 2 (largest " << q1.radius_edge_max << ")";
  // The original vertices keep their numbers (splits append); rim vertices stay put; surface
  // vertices stay on the triangles they started on, i.e. within the chord height (≈ 0.06 mm
  // for 1.4 mm triangle edges on a 4 mm radius) of their cylinder.
  ASSERT_GE(m.vertices_lps_mm.size(), before.vertices_lps_mm.size());
  for (std::size_t v = 0; v < before.vertices_lps_mm.size(); ++v) {
    const Eigen::Vector3d &p = m.vertices_lps_mm[v], &p0 = before.vertices_lps_mm[v];
    if (on_side[v]) {
      EXPECT_EQ(p, p0) << "rim vertex " << v << " moved";
      continue;
    }
    const double r0 = std::hypot(p0.x(), p0.z()), r = std::hypot(p.x(), p.z());
    EXPECT_NEAR(r, r0, 0.07) << "surface vertex " << v << " left its cylinder";
  }
  EXPECT_NEAR(m.volume_mm3(), before.volume_mm3(), 0.01 * before.volume_mm3());
}

TEST_F(PhantomMeshes, ExportsRoundTripThroughIndependentReaders) {
  ScratchDir dir("meshing-export");
  ExportOptions eo;
  // The gallbladder wall with a membrane Fung law (Table 5.1.1 mean as FEBio's Fung orthotropic
  // form, physics/materials/solver_fit.h): the FEB takes the law with per-element axes. The other
  // regions keep placeholders.
  SolverMaterial wall;
  wall.ogden_mu_Pa = {1e-3, 100.0, 1.0};
  wall.ogden_alpha = {2.0, 20.0, 30.0};
  wall.bulk_modulus_Pa = 1e5;
  wall.febio_fung = FebioFungOrthotropic{300.111, 280.542, 0.326, 84.3, 84.3, 84.3, 0.386284, 0, 0, 19.11, 1e5, "test"};
  eo.materials["gallbladder_wall"] = wall;
  const auto files = export_meshes(*meshes_, dir.path(), eo);
  ASSERT_FALSE(files.empty());
  for (const auto& f : files) EXPECT_TRUE(fs::exists(dir.path() / f)) << f;
  const OrganMesh* gb = find_organ(*meshes_, "gallbladder");
  ASSERT_NE(gb, nullptr);
  // Own reader: STL back with the same triangles and volume (float precision).
  const SurfaceMesh stl = read_stl(dir.path() / "gallbladder" / "gallbladder.stl");
  const NamedSurface* outer = find_surface(*gb, "gallbladder");
  EXPECT_EQ(stl.triangles.size(), outer->mesh.triangles.size());
  EXPECT_EQ(stl.vertices_lps_mm.size(), outer->mesh.vertices_lps_mm.size());
  EXPECT_NEAR(stl.signed_volume_mm3(), outer->mesh.signed_volume_mm3(), 1e-4 * outer->mesh.signed_volume_mm3());
  // Gmsh 4.1 parsed by hand: node and element counts, one physical group per region.
  {
    std::ifstream in(dir.path() / "gallbladder" / "gallbladder.msh");
    std::string line;
    std::size_t nodes = 0, elements = 0, physicals = 0;
    while (std::getline(in, line)) {
      if (line == "$PhysicalNames") in >> physicals;
      if (line == "$Nodes") { std::size_t blocks; in >> blocks >> nodes; }
      if (line == "$Elements") { std::size_t blocks; in >> blocks >> elements; }
    }
    // Quadratic tets (10 nodes) by default, plus one tri6 per face of each named surface.
    const SolverModel sm = build_solver_model(*gb);
    std::set<std::pair<int, int>> distinct;  // each boundary face once, however many surfaces hold it
    for (const auto& [name, f] : sm.surfaces)
      for (const auto& x : f) distinct.insert({x.tet, x.face});
    const std::size_t faces = distinct.size();
    EXPECT_EQ(nodes, sm.nodes_lps_mm.size());
    EXPECT_GT(nodes, gb->volume.vertices_lps_mm.size());
    EXPECT_EQ(elements, gb->volume.tets.size() + faces);
    EXPECT_EQ(physicals, 2u + sm.surfaces.size());
  }
  // FEBio 4.0: parsed for the version, one SolidDomain and material per region, counts.
  {
    const std::string feb = organsmith::testing::read_file(dir.path() / "gallbladder" / "gallbladder.feb");
    EXPECT_NE(feb.find("<febio_spec version=\"4.0\">"), std::string::npos);
    auto count = [&](const std::string& needle) {
      std::size_t n = 0;
      for (auto p = feb.find(needle); p != std::string::npos; p = feb.find(needle, p + 1)) ++n;
      return n;
    };
    const SolverModel sm = build_solver_model(*gb);
    EXPECT_EQ(count("<node id="), sm.nodes_lps_mm.size());
    EXPECT_EQ(count("<elem id="), gb->volume.tets.size());
    EXPECT_EQ(count("<Elements type=\"tet10\""), 2u);
    EXPECT_EQ(count("<Surface name="), sm.surfaces.size());
    EXPECT_EQ(count("<SolidDomain "), 2u);
    EXPECT_EQ(count("<material id="), 2u);
    EXPECT_EQ(count("type=\"Fung-ortho-compressible\""), 1u);
    // One mat_axis per wall element; the checker below checks lids and orthonormality.
    std::size_t wall_tets = 0;
    for (std::size_t e = 0; e < sm.elements.size(); ++e) wall_tets += sm.region_names.at(sm.region_ids[e]) == "gallbladder_wall";
    EXPECT_EQ(count("<e lid="), wall_tets);
    EXPECT_LT(feb.find("</MeshDomains>"), feb.find("<MeshData>"));
  }
  // Independent readers: Debian's python3-meshio (STL OBJ PLY VTU MSH 4.1/2.2 INP), gmsh and
  // VTK (VTP, VTU), run by tests/meshing/check_exports.py when they are installed.
  const std::string script = std::string(ORGANSMITH_SOURCE_DIR) + "/tests/meshing/check_exports.py";
  const int rc = std::system(("/usr/bin/python3 " + script + " " + dir.path().string() + " > " +
                              (dir.path() / "readers.log").string() + " 2>&1").c_str());
  const std::string log = organsmith::testing::read_file(dir.path() / "readers.log");
  if (WEXITSTATUS(rc) == 77) GTEST_SKIP() << "independent readers not installed: " << log;
  EXPECT_EQ(WEXITSTATUS(rc), 0) << log;

  // FEBio 4.0 format rules (FEBio is not in Debian: structure-checked, not solved). The checker
  // must also catch a broken file: the same FEB with its load's surface renamed away.
  const std::string feb_check = std::string(ORGANSMITH_SOURCE_DIR) + "/tests/meshing/check_feb.py";
  const fs::path gb_feb = dir.path() / "gallbladder" / "gallbladder.feb", tr_feb = dir.path() / "trachea" / "trachea.feb";
  const int feb_rc = std::system(("/usr/bin/python3 " + feb_check + " " + gb_feb.string() + " " + tr_feb.string() + " > " +
                                  (dir.path() / "feb.log").string() + " 2>&1").c_str());
  EXPECT_EQ(WEXITSTATUS(feb_rc), 0) << organsmith::testing::read_file(dir.path() / "feb.log");
  std::string broken = organsmith::testing::read_file(gb_feb);
  // The probe's node set, which the indentation's prescribed displacement names.
  const std::string probe = "<NodeSet name=\"gallbladder_probe_nodes\">";
  const auto at = broken.find(probe);
  ASSERT_NE(at, std::string::npos);
  broken.replace(at, probe.size(), "<NodeSet name=\"somewhere_else\">");
  {
    std::ofstream b(dir.path() / "broken.feb");
    b << broken;
  }
  const int broken_rc = std::system(("/usr/bin/python3 " + feb_check + " " + (dir.path() / "broken.feb").string() + " > " +
                                     (dir.path() / "broken.log").string() + " 2>&1").c_str());
  EXPECT_EQ(WEXITSTATUS(broken_rc), 1) << organsmith::testing::read_file(dir.path() / "broken.log");
}

// Two calls in one process: the second sees a different heap, so any ordering that follows
// addresses (PMP::clip's output order did) shows up here. The tube of this label map is cut
// flat at both ends, which exercises that path.
TEST(MeshingDeterminism, SameInputGivesByteIdenticalExports) {
  // A small two-organ label map: the property does not depend on size.
  LabelMap lm;
  lm.grid.size_vox = {48, 44, 40};
  lm.grid.spacing_mm = {0.9, 0.9, 1.5};
  lm.labels.assign(std::size_t(lm.grid.voxel_count()), 0);
  for (std::int64_t k = 0; k < 40; ++k)
    for (std::int64_t j = 0; j < 44; ++j)
      for (std::int64_t i = 0; i < 48; ++i) {
        const double x = (i - 20) * 0.9, y = (j - 22) * 0.9, z = (k - 20) * 1.5;
        if (x * x / 100 + y * y / 64 + z * z / 225 < 1) lm.labels[lm.grid.offset(i, j, k)] = 1;
        const double tx = (i - 40) * 0.9, ty = (j - 22) * 0.9;
        if (k >= 5 && k <= 34 && tx * tx + ty * ty < 16) lm.labels[lm.grid.offset(i, j, k)] = 2;
      }
  MeshOptions o;
  o.organs = registry_organs();
  o.enforce_quality = false;
  NullProgress progress;
  ScratchDir a("meshing-det-a"), b("meshing-det-b");
  export_meshes(mesh_organs(lm, o, progress), a.path(), ExportOptions{});
  export_meshes(mesh_organs(lm, o, progress), b.path(), ExportOptions{});
  std::size_t compared = 0;
  for (const auto& e : fs::recursive_directory_iterator(a.path())) {
    if (!e.is_regular_file()) continue;
    const fs::path other = b.path() / fs::relative(e.path(), a.path());
    if (e.path().filename() == "quality.json") continue;  // holds run times
    EXPECT_TRUE(organsmith::testing::read_file(e.path()) == organsmith::testing::read_file(other))
        << e.path().filename() << " differs between two calls";
    ++compared;
  }
  EXPECT_GE(compared, 9u);
}

TEST(MeshingRealData, GallbladderReferenceMeetsEveryGuarantee) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const LabelMap lm = read_label_map(organsmith::testing::real_data_dir() / "abdomen-ct-3mm" / "gallbladder-reference.nii.gz");
  MeshOptions o;
  o.organs = registry_organs({"gallbladder"});
  o.enforce_quality = false;
  NullProgress progress;
  const OrganMeshes m = mesh_organs(lm, o, progress);
  ASSERT_EQ(m.organs.size(), 1u);
  for (const auto& s : m.organs[0].surfaces) expect_guarantees(s);
  expect_tet_gate(m.organs[0].volume_quality);
}

TEST(MeshingRealData, TracheaReferenceMeetsEveryGuarantee) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const LabelMap lm = read_label_map(organsmith::testing::real_data_dir() / "chest-dicom-8mm" / "trachea-reference.nii.gz");
  MeshOptions o;
  MeshOrganSpec trachea = registry_organs({"trachea"})[0];
  trachea.label = 1;  // the reference stores the lumen as 1
  o.organs = {trachea};
  o.enforce_quality = false;
  NullProgress progress;
  const OrganMeshes m = mesh_organs(lm, o, progress);
  ASSERT_EQ(m.organs.size(), 1u);
  for (const auto& s : m.organs[0].surfaces) expect_guarantees(s);
  expect_tet_gate(m.organs[0].volume_quality);
}

TEST(MeshingBadInput, ClearErrorsNamingTheOrgan) {
  NullProgress progress;
  LabelMap lm;
  lm.grid.size_vox = {20, 20, 20};
  lm.labels.assign(8000, 0);
  MeshOptions o;
  // No organ asked for: meshing knows none by itself.
  EXPECT_THROW(mesh_organs(lm, o, progress), UsageError);
  o.organs = registry_organs();
  // Empty: no organ present.
  try {
    mesh_organs(lm, o, progress);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::mesh_input);
  }
  // One voxel.
  lm.labels[lm.grid.offset(10, 10, 10)] = 1;
  o.organs = registry_organs({"gallbladder"});
  try {
    mesh_organs(lm, o, progress);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::mesh_input);
    EXPECT_NE(std::string(e.what()).find("gallbladder"), std::string::npos) << e.what();
  }
  // Organ absent, when asked not to skip.
  o.organs = registry_organs();
  o.skip_absent = false;
  try {
    mesh_organs(lm, o, progress);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::mesh_input);
    EXPECT_NE(std::string(e.what()).find("trachea"), std::string::npos) << e.what();
  }
  // Empty grid.
  LabelMap none;
  EXPECT_THROW(mesh_organs(none, o, progress), Error);
}

TEST(MeshingBadInput, LabelTouchingTheBorderIsCappedWithAWarning) {
  LabelMap lm;
  lm.grid.size_vox = {40, 40, 30};
  lm.grid.spacing_mm = {1.0, 1.0, 1.5};
  lm.labels.assign(std::size_t(lm.grid.voxel_count()), 0);
  for (std::int64_t k = 0; k < 30; ++k)
    for (std::int64_t j = 0; j < 40; ++j)
      for (std::int64_t i = 0; i < 40; ++i) {
        const double x = i - 20.0, y = j - 20.0, z = (k - 8.0) * 1.5;
        if (x * x + y * y + z * z < 196) lm.labels[lm.grid.offset(i, j, k)] = 1;  // cut by k = 0
      }
  MeshOptions o;
  o.organs = {{"blob", 1, OrganModel::solid, 0.0}};
  o.tetrahedra = false;
  o.enforce_quality = false;
  NullProgress progress;
  const OrganMeshes m = mesh_organs(lm, o, progress);
  ASSERT_EQ(m.organs.size(), 1u);
  bool warned = false;
  for (const auto& w : m.organs[0].warnings) warned |= w.find("blob touches the image border") != std::string::npos;
  EXPECT_TRUE(warned);
  expect_guarantees(m.organs[0].surfaces[0]);
}

TEST(MeshingCli, WritesEveryFormatAndRejectsNonNifti) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  ScratchDir dir("meshing-cli");
  const fs::path labels = organsmith::testing::real_data_dir() / "abdomen-ct-3mm" / "gallbladder-reference.nii.gz";
  // Surfaces alone pass the enforced gate: exit 0.
  const auto surfaces = organsmith::testing::run_cli("mesh " + labels.string() + " --organ gallbladder=1 --no-tets --out " +
                                                     (dir.path() / "surfaces").string());
  ASSERT_EQ(surfaces.exit_code, 0) << surfaces.output;
  EXPECT_TRUE(fs::exists(dir.path() / "surfaces" / "gallbladder" / "gallbladder.stl"));
  // With tetrahedra the enforced gate (10° / 2) passes too: exit 0 without any override.
  const auto r = organsmith::testing::run_cli("mesh " + labels.string() + " --organ gallbladder=1 --out " +
                                              (dir.path() / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* f : {"gallbladder.stl", "gallbladder.obj", "gallbladder.ply", "gallbladder.vtp", "gallbladder.vtu",
                        "gallbladder.msh", "gallbladder.v22.msh", "gallbladder.inp", "gallbladder.feb", "quality.json"})
    EXPECT_TRUE(fs::exists(dir.path() / "out" / "gallbladder" / f)) << f;
  std::ifstream qf(dir.path() / "out" / "gallbladder" / "quality.json");
  const auto q = nlohmann::json::parse(qf);
  for (const auto& [name, sq] : q.at("surfaces").items()) EXPECT_TRUE(sq.at("passed").get<bool>()) << name;
  EXPECT_GT(q.at("tetrahedra").at("tetrahedra").get<int>(), 1000);
  EXPECT_TRUE(q.at("tetrahedra").at("passed").get<bool>());
  // Not a label map: clear error, nothing written.
  std::ofstream(dir.path() / "notes.txt") << "not an image\n";
  const auto bad = organsmith::testing::run_cli("mesh " + (dir.path() / "notes.txt").string() + " --out " +
                                                (dir.path() / "bad").string());
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_FALSE(fs::exists(dir.path() / "bad"));
}

// CalculiX reads at most 20 characters per field of a data line: the shortest round trip of a
// small coordinate (-1.3633504295285093e-05, 23 characters) stopped a 0.7×-edge phantom run with
// "*ERROR reading *NODE". Every field the INP writer puts on a data line fits.
TEST(SolverExport, InpDataFieldsFitCalculixsTwentyCharacters) {
  SolverModel m;
  m.organ = "cube";
  m.quadratic = false;
  m.nodes_lps_mm = {{0, 0, 0}, {10.000000000000002, 0, 0}, {0, 9.999999999999998, 0}, {0, 0, -1.3633504295285093e-05 - 10}};
  m.nodes_lps_mm[0].z() = -1.3633504295285093e-05;
  m.elements = {{0, 1, 2, 3, 0, 0, 0, 0, 0, 0}};
  m.region_ids = {1};
  m.region_names = {{1, "cube_body"}};
  ScratchDir dir("inp-fields");
  write_inp(m, {}, SolverScenario{}, dir.path() / "cube.inp");
  std::ifstream in(dir.path() / "cube.inp");
  int data_lines = 0;
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '*') continue;
    ++data_lines;
    std::stringstream fields(line);
    for (std::string f; std::getline(fields, f, ',');) {
      f.erase(0, f.find_first_not_of(' '));
      EXPECT_LE(f.size(), 20u) << line;
    }
  }
  EXPECT_GE(data_lines, 5);  // four nodes and the element (and the placeholder material)
}
