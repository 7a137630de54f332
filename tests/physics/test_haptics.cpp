// Over 400 lines: the tests of the whole haptics target (paths, guidance field, contact, loop),
// sharing its synthetic scenes.
// Guidance paths, the staged guidance field, the reaction force and the force loop (issue 6).

#include "core/errors.h"
#include "physics/haptics/contact.h"
#include "physics/haptics/guidance.h"
#include "physics/haptics/haptic_loop.h"
#include "physics/haptics/paths.h"
#include "physics/materials/presets.h"
#include "pipeline/phantom/phantom.h"
#include "tests/physics/synthetic_meshes.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <random>
#include <thread>

using namespace organsmith;
using namespace organsmith::physics;
namespace fs = std::filesystem;

namespace {

Polyline random_walk(int n, std::uint64_t seed, bool closed = false) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> N(0.0, 1.0);
  Polyline p;
  p.closed = closed;
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) {
    p.points_lps_mm.push_back(x);
    x += Eigen::Vector3d(N(rng), N(rng), N(rng)) * 2.0;
  }
  return p;
}

/// Closed triangulated sphere (icosahedron subdivided), outward triangles.
SurfaceMesh icosphere(double radius, int subdivisions, Eigen::Vector3d centre = Eigen::Vector3d::Zero()) {
  SurfaceMesh m = organsmith::physics::testing::unit_icosphere(subdivisions);
  for (auto& v : m.vertices_lps_mm) v = centre + radius * v;
  return m;
}

/// Closed box [lo, hi] with each face split into n×n quads (2 triangles each), outward.
SurfaceMesh box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, int n) {
  SurfaceMesh m;
  std::map<std::array<long, 3>, int> ids;
  auto vid = [&](const Eigen::Vector3d& p) {
    const std::array<long, 3> k{std::lround(p.x() * 1000), std::lround(p.y() * 1000), std::lround(p.z() * 1000)};
    auto it = ids.find(k);
    if (it != ids.end()) return it->second;
    m.vertices_lps_mm.push_back(p);
    return ids[k] = int(m.vertices_lps_mm.size()) - 1;
  };
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          auto corner = [&](int a, int b) {
            Eigen::Vector3d p;
            p[axis] = side ? hi[axis] : lo[axis];
            p[u] = lo[u] + (hi[u] - lo[u]) * a / n;
            p[v] = lo[v] + (hi[v] - lo[v]) * b / n;
            return vid(p);
          };
          const int a = corner(i, j), b = corner(i + 1, j), c = corner(i + 1, j + 1), d = corner(i, j + 1);
          // (u, v, axis) is right-handed: counter-clockwise in (u, v) faces +axis.
          if (side) m.triangles.push_back({a, b, c}), m.triangles.push_back({a, c, d});
          else m.triangles.push_back({a, c, b}), m.triangles.push_back({a, d, c});
        }
    }
  return m;
}

/// A label map holding a curved tube (lumen) along z: centre x = 3 sin(z/40), radius r.
LabelMap tube_labels(double radius_mm, double z0, double z1, Eigen::Vector3d spacing = {0.8, 0.8, 2.0}) {
  LabelMap lm;
  lm.grid.spacing_mm = spacing;
  lm.grid.size_vox = {64, 64, 80};
  lm.grid.origin_lps_mm = {-25.6, -25.6, -80.0};
  lm.labels.assign(std::size_t(lm.grid.voxel_count()), 0);
  for (std::int64_t k = 0; k < 80; ++k)
    for (std::int64_t j = 0; j < 64; ++j)
      for (std::int64_t i = 0; i < 64; ++i) {
        const Eigen::Vector3d p = lm.grid.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k)));
        if (p.z() < z0 || p.z() > z1) continue;
        const double cx = 3.0 * std::sin(p.z() / 40.0);
        if (std::hypot(p.x() - cx, p.y()) < radius_mm) lm.labels[std::size_t(lm.grid.offset(i, j, k))] = 2;
      }
  return lm;
}

/// The wall of a straight tube along z (outer radius ro, inner ri, z in [z0, z1]): one closed
/// genus-1 surface (outer tube, annular caps, inner tube facing the lumen).
SurfaceMesh tube_wall(double ri, double ro, double z0, double z1, int around = 96, int along = 60) {
  SurfaceMesh m;
  auto ring = [&](double r, double z) {
    const int base = int(m.vertices_lps_mm.size());
    for (int a = 0; a < around; ++a) {
      const double th = 2 * std::numbers::pi * a / around;
      m.vertices_lps_mm.emplace_back(r * std::cos(th), r * std::sin(th), z);
    }
    return base;
  };
  std::vector<int> outer, inner;
  for (int k = 0; k <= along; ++k) outer.push_back(ring(ro, z0 + (z1 - z0) * k / along));
  for (int k = 0; k <= along; ++k) inner.push_back(ring(ri, z0 + (z1 - z0) * k / along));
  auto quad = [&](int a, int b, int c, int d) {  // counter-clockwise seen from outside the solid
    m.triangles.push_back({a, b, c});
    m.triangles.push_back({a, c, d});
  };
  for (int k = 0; k < along; ++k)
    for (int a = 0; a < around; ++a) {
      const int a1 = (a + 1) % around;
      quad(outer[std::size_t(k)] + a, outer[std::size_t(k)] + a1, outer[std::size_t(k + 1)] + a1, outer[std::size_t(k + 1)] + a);
      quad(inner[std::size_t(k)] + a, inner[std::size_t(k + 1)] + a, inner[std::size_t(k + 1)] + a1, inner[std::size_t(k)] + a1);
    }
  for (int a = 0; a < around; ++a) {
    const int a1 = (a + 1) % around;
    quad(outer[std::size_t(along)] + a, outer[std::size_t(along)] + a1, inner[std::size_t(along)] + a1, inner[std::size_t(along)] + a);
    quad(outer[0] + a, inner[0] + a, inner[0] + a1, outer[0] + a1);
  }
  return m;
}

StressTable wall_table() {
  const MaterialLibrary lib = builtin_material_library();
  const MaterialPreset& p = lib.find("fung-wall/table-5.1.1/mean")  /* a steep law: the gallbladder wall's (data/organs.toml) */;
  return StressTable::from_material(p.material, model_options_for(p), 0.6);
}

}  // namespace

// ---- guidance ------------------------------------------------------------------------------------

TEST(HapticsGuidance, NearestPointMatchesBruteForce) {
  for (bool closed : {false, true}) {
    const PathIndex index(random_walk(700, 3, closed));
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> U(-60, 60);
    double worst = 0.0;
    int same_segment = 0;
    for (int i = 0; i < 20000; ++i) {
      const Eigen::Vector3d q(U(rng), U(rng), U(rng));
      const NearestPoint a = index.nearest(q), b = index.nearest_brute_force(q);
      worst = std::max(worst, std::abs(a.distance_mm - b.distance_mm));
      same_segment += a.segment == b.segment;
      ASSERT_NEAR((a.point_lps_mm - q).norm(), a.distance_mm, 1e-9);
    }
    EXPECT_EQ(worst, 0.0) << "closed=" << closed;
    EXPECT_EQ(same_segment, 20000);
  }
}

TEST(HapticsGuidance, ForceIsMinusXiTimesOffsetExactly) {
  const PathIndex index(random_walk(200, 11));
  const GuidanceOptions o;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> U(-40, 40);
  for (int i = 0; i < 5000; ++i) {
    const Eigen::Vector3d q(U(rng), U(rng), U(rng));
    const GuidanceSample g = guidance_force(index, q, o);
    const NearestPoint ref = index.nearest_brute_force(q);
    ASSERT_EQ(g.goal.distance_mm, ref.distance_mm);
    const double xi = o.xi_N_per_mm[std::size_t(xi_band(ref.distance_mm, o))];
    const Eigen::Vector3d expected = -xi * (q - ref.point_lps_mm);
    ASSERT_EQ(g.force_N, expected);  // exact, not approximately
    // The force is minus the gradient of the (continuous) staged potential: central differences.
    const double h = 1e-5;
    for (int a = 0; a < 3; ++a) {
      Eigen::Vector3d dq = Eigen::Vector3d::Zero();
      dq[a] = h;
      const double up = guidance_force(index, q + dq, o).potential_mJ, dn = guidance_force(index, q - dq, o).potential_mJ;
      if (xi_band(guidance_force(index, q + dq, o).goal.distance_mm, o) != g.band ||
          xi_band(guidance_force(index, q - dq, o).goal.distance_mm, o) != g.band)
        continue;  // straddles a band edge: the gradient jumps there
      ASSERT_NEAR(-(up - dn) / (2 * h), g.force_N[a], 1e-5 * (1 + g.force_N.norm()));
    }
  }
}

TEST(HapticsGuidance, BandsSwitchAtConfiguredDistances) {
  Polyline line;
  line.points_lps_mm = {{0, 0, -100}, {0, 0, 100}};
  const PathIndex index(line);
  GuidanceOptions o;
  o.band_edges_mm = {1.5, 4.0};
  o.xi_N_per_mm = {3.0, 6.0, 9.0};
  const double eps = 1e-9;
  for (auto [d, band] : std::vector<std::pair<double, int>>{{0.0, 0}, {1.5 - eps, 0}, {1.5, 1}, {4.0 - eps, 1}, {4.0, 2}, {30, 2}}) {
    const GuidanceSample g = guidance_force(index, Eigen::Vector3d(d, 0, 0), o);
    EXPECT_EQ(g.band, band) << d;
    EXPECT_EQ(g.xi_N_per_mm, o.xi_N_per_mm[std::size_t(band)]);
    EXPECT_DOUBLE_EQ(g.force_N.x(), -o.xi_N_per_mm[std::size_t(band)] * d);
  }
  // The potential is continuous across the edges and equals ½ ξ0 d² in the inner band.
  for (double e : o.band_edges_mm) EXPECT_NEAR(staged_potential_mJ(e - 1e-9, o), staged_potential_mJ(e + 1e-9, o), 1e-7);
  EXPECT_DOUBLE_EQ(staged_potential_mJ(1.0, o), 0.5 * 3.0 * 1.0);
  GuidanceOptions bad = o;
  bad.band_edges_mm = {4.0, 1.5};
  EXPECT_THROW(validate(bad), UsageError);
}

TEST(HapticsGuidance, GradientDescentPullsToThePath) {
  const PathIndex index(random_walk(100, 2));
  const GuidanceOptions o;
  Eigen::Vector3d q(15, -12, 9);
  double u = guidance_force(index, q, o).potential_mJ;
  const double alpha = 0.8;  // α ξ < 1 in every band
  for (int i = 0; i < 60; ++i) {
    q = gradient_descent_step(index, q, alpha, o);
    const double un = guidance_force(index, q, o).potential_mJ;
    ASSERT_LE(un, u + 1e-12);
    u = un;
  }
  EXPECT_LT(index.nearest(q).distance_mm, 1e-3);
}

TEST(HapticsGuidance, EmptyPathIsAnError) {
  try {
    PathIndex index{Polyline{}};
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.code(), ExitCode::unsupported_input);
  }
}

// ---- contact -------------------------------------------------------------------------------------

TEST(HapticsContact, ClosestPointAndSideMatchBruteForceAndParity) {
  const SurfaceIndex index({icosphere(20.0, 3), icosphere(8.0, 2, {50, 0, 0})});
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> U(-35, 70);
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d q(U(rng), U(rng) * 0.5, U(rng) * 0.5);
    const ClosestPoint a = index.closest(q), b = index.closest_brute_force(q);
    ASSERT_TRUE(a.found);
    ASSERT_NEAR(a.signed_distance_mm, b.signed_distance_mm, 1e-9);
    const bool inside_by_parity = index.crossings(q, Eigen::Vector3d(0.3, 0.5, 0.81)) % 2 == 1;
    if (std::abs(a.signed_distance_mm) > 1e-3) ASSERT_EQ(a.signed_distance_mm < 0, inside_by_parity) << q.transpose();
  }
}

TEST(HapticsContact, ZeroOutsideMonotoneAndMatchesTheLaw) {
  const Eigen::Vector3d lo(-50, -50, -50), hi(50, 50, 50);
  ContactOptions o;
  o.tool_radius_mm = 2.0;
  o.reference_length_mm = 5.0;
  const StressTable table = wall_table();
  const ContactModel contact(SurfaceIndex({box(lo, hi, 8)}), {table}, o);
  // The law itself, evaluated directly (not through the table).
  const MaterialLibrary lib = builtin_material_library();
  const MaterialPreset& preset = lib.find("fung-wall/table-5.1.1/mean")  /* a steep law: the gallbladder wall's (data/organs.toml) */;
  const auto model = make_model(preset.material.model, model_options_for(preset));
  const auto p = parameter_values(*model, preset.material.parameters);
  double prev = -1.0;
  for (double delta = -3.0; delta <= 6.0; delta += 0.01) {
    // Tool centre above the +z face, sunk by delta (penetration of the sphere = delta).
    const Eigen::Vector3d q(3.3, -7.1, 50.0 + o.tool_radius_mm - delta);
    const ContactSample c = contact.evaluate(q);
    if (delta <= 0) {
      ASSERT_FALSE(c.contact);
      ASSERT_EQ(c.force_N, Eigen::Vector3d::Zero());
      continue;
    }
    ASSERT_TRUE(c.contact);
    ASSERT_NEAR(c.penetration_mm, delta, 1e-9);
    ASSERT_NEAR(c.normal.z(), 1.0, 1e-12);
    const double f = c.force_N.norm();
    ASSERT_GE(f, prev);
    prev = f;
    const double a2 = delta < 2.0 ? 2 * 2.0 * delta - delta * delta : 4.0;
    const double law = model->respond_one(LoadPoint{1.0 + delta / 5.0, 1.0, LoadCase::uniaxial_circumferential}, p);
    if (delta / 5.0 <= table.max_strain()) ASSERT_NEAR(f, law * std::numbers::pi * a2 * 1e-6, 2e-4 * f + 1e-12) << delta;
    ASSERT_NEAR(f, indentation_force_N(table, c.penetration_mm, o), 1e-12 * f);
  }
  // Deep inside (beyond the search margin): still found, pushed out.
  const ContactSample deep = contact.evaluate(Eigen::Vector3d(0, 0, 30));
  EXPECT_TRUE(deep.contact);
  EXPECT_NEAR(deep.penetration_mm, 22.0, 1e-9);
  EXPECT_GT(deep.force_N.z(), 0.0);
}

TEST(HapticsContact, DeformationIsLocalAndSmooth) {
  SurfaceDeformer d(icosphere(20.0, 4), 6.0);
  ContactSample c;
  c.contact = true;
  c.penetration_mm = 1.5;
  c.point_lps_mm = {0, 0, 20};
  c.normal = {0, 0, 1};
  const auto& v = d.update(c);
  double max_move = 0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const double r = (d.rest().vertices_lps_mm[i] - c.point_lps_mm).norm();
    const double move = (v[i] - d.rest().vertices_lps_mm[i]).norm();
    if (r >= 6.0) ASSERT_EQ(move, 0.0);
    else ASSERT_NEAR(move, 1.5 * std::pow(1 - r * r / 36.0, 2), 1e-12);
    max_move = std::max(max_move, move);
  }
  EXPECT_GT(d.moved_count(), 0u);
  EXPECT_GT(max_move, 1.3);
  c.contact = false;
  const auto& back = d.update(c);
  for (std::size_t i = 0; i < back.size(); ++i) ASSERT_EQ(back[i], d.rest().vertices_lps_mm[i]);
}

// ---- mixing and the loop -------------------------------------------------------------------------

TEST(HapticsLoop, ThreeModesMixAndClamp) {
  const Eigen::Vector3d G(0.4, -0.2, 0.1), R(-0.1, 0.3, 0.6);
  EXPECT_EQ(mix_forces(G, R, ForceMode::guidance, 10), G);
  EXPECT_EQ(mix_forces(G, R, ForceMode::reaction, 10), R);
  EXPECT_TRUE(mix_forces(G, R, ForceMode::mixed, 10).isApprox(0.5 * G + 0.5 * R, 1e-15));
  for (ForceMode m : {ForceMode::guidance, ForceMode::mixed, ForceMode::reaction}) {
    const ForceWeights w = weights(m);
    EXPECT_DOUBLE_EQ(w.guidance + w.reaction, 1.0);
    EXPECT_EQ(parse_force_mode(mode_name(m)), m);
  }
  const Eigen::Vector3d big(30, 40, 0);
  EXPECT_NEAR(mix_forces(big, big, ForceMode::mixed, 2.0).norm(), 2.0, 1e-12);
  EXPECT_TRUE(mix_forces(big, big, ForceMode::mixed, 2.0).normalized().isApprox(big.normalized()));
  const Eigen::Vector3d nan(std::nan(""), 0, 0);
  EXPECT_EQ(mix_forces(nan, R, ForceMode::mixed, 2.0), Eigen::Vector3d::Zero());
  EXPECT_EQ(mix_forces(nan, R, ForceMode::reaction, 2.0), R);  // a zero-weight term never leaks
  EXPECT_THROW(parse_force_mode("both"), UsageError);
}

TEST(HapticsLoop, ScriptedDeviceValidatesItsTrajectory) {
  const fs::path dir = fs::temp_directory_path() / "organsmith_haptics_traj";
  fs::create_directories(dir);
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    return dir / name;
  };
  auto code = [&](const fs::path& f) {
    try {
      ScriptedDevice::read_csv(f);
    } catch (const InputError& e) {
      return int(e.code());
    }
    return 0;
  };
  EXPECT_EQ(code(write("ok.csv", "t_s,x,y,z\n0,0,0,0\n0.5,1,0,0\n1.0,1,1,0\n")), 0);
  EXPECT_EQ(code(write("nan.csv", "t_s,x,y,z\n0,0,0,0\n0.5,nan,0,0\n")), 18);
  EXPECT_EQ(code(write("time.csv", "t_s,x,y,z\n0,0,0,0\n0.5,1,0,0\n0.5,2,0,0\n")), 18);
  EXPECT_EQ(code(write("back.csv", "t_s,x,y,z\n0,0,0,0\n0.5,1,0,0\n0.4,2,0,0\n")), 18);
  EXPECT_EQ(code(write("header.csv", "a,b,c\n0,0,0\n")), 18);
  EXPECT_EQ(code(write("one.csv", "t_s,x,y,z\n0,0,0,0\n")), 18);
  EXPECT_EQ(code(dir / "missing.csv"), 3);
  try {
    ScriptedDevice::read_csv(dir / "time.csv");
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("line 4"), std::string::npos) << e.what();
  }
  ScriptedDevice d = ScriptedDevice::read_csv(dir / "ok.csv");
  EXPECT_TRUE(d.position_lps_mm(0.25).isApprox(Eigen::Vector3d(0.5, 0, 0)));
  EXPECT_TRUE(d.position_lps_mm(0.75).isApprox(Eigen::Vector3d(1, 0.5, 0)));
  EXPECT_TRUE(d.position_lps_mm(5.0).isApprox(Eigen::Vector3d(1, 1, 0)));
  fs::remove_all(dir);
}

TEST(HapticsLoop, SeqLockNeverTearsAValue) {
  struct Value {
    std::array<double, 12> v;
  };
  SeqLock<Value> lock;
  // The writer runs until the reader has read 200 000 times (a fixed number of writes could all
  // be over before a descheduled reader starts, and nothing would be tested).
  std::atomic<bool> stop{false};
  std::atomic<int> last{0};
  std::thread writer([&] {
    int i = 0;
    while (!stop.load(std::memory_order_relaxed)) {
      Value x;
      x.v.fill(double(++i));
      lock.write(x);
    }
    last = i;
  });
  while (lock.read().v[0] == 0.0) std::this_thread::yield();  // the writer has started
  long torn = 0;
  for (long reads = 0; reads < 200000; ++reads) {
    const Value x = lock.read();
    for (double e : x.v) torn += e != x.v[0];
  }
  stop = true;
  writer.join();
  EXPECT_EQ(torn, 0);
  EXPECT_EQ(lock.read().v[5], double(last.load()));
}

namespace {
/// A path along the top of a box-shaped organ, and a device wobbling ±4 mm around it for 2 s.
struct WobbleScene {
  Polyline path;
  std::unique_ptr<ContactModel> contact;
  std::unique_ptr<PathIndex> index;
  WobbleScene() {
    for (int i = 0; i <= 60; ++i) path.points_lps_mm.emplace_back(-30.0 + i, 0.0, 20.0 + 5.0 * std::sin(i / 10.0));
    index = std::make_unique<PathIndex>(path);
    contact = std::make_unique<ContactModel>(SurfaceIndex({box({-40, -40, -40}, {40, 40, 18}, 10)}),
                                             std::vector<StressTable>{wall_table()});
  }
  ScriptedDevice device() const {
    std::vector<double> t;
    std::vector<Eigen::Vector3d> p;
    for (int i = 0; i <= 400; ++i) {
      const double s = 2.0 * i / 400;
      const Eigen::Vector3d on = path.points_lps_mm[std::size_t(std::lround(s * 30))];
      t.push_back(s);
      p.push_back(on + Eigen::Vector3d(0, 4.0 * std::sin(2 * std::numbers::pi * 3 * s), 2.0 * std::cos(2 * std::numbers::pi * 2 * s)));
    }
    return ScriptedDevice(t, p);
  }
};

double replay_rms(const WobbleScene& scene, ForceMode mode) {
  ScriptedDevice dev = scene.device();
  LoopOptions o;
  o.mode = mode;
  HapticLoop loop(dev, scene.index.get(), scene.contact.get(), o);
  double se = 0;
  int n = 0;
  for (int i = 0; i <= 2000; ++i) {
    const HapticState s = loop.tick(i * 1e-3);
    EXPECT_LE(to_eigen(s.force_N).norm(), o.force_limit_N + 1e-12);
    EXPECT_TRUE(to_eigen(s.force_N).allFinite());
    se += s.distance_mm * s.distance_mm;
    ++n;
  }
  return std::sqrt(se / n);
}
}  // namespace

TEST(HapticsLoop, GuidancePullsAWobblingToolCloserThanReaction) {
  const WobbleScene scene;
  const double guided = replay_rms(scene, ForceMode::guidance);
  const double mixed = replay_rms(scene, ForceMode::mixed);
  const double reaction = replay_rms(scene, ForceMode::reaction);
  RecordProperty("rms_guidance_mm", std::to_string(guided));
  RecordProperty("rms_reaction_mm", std::to_string(reaction));
  std::printf("wobble RMS path error: guidance %.3f mm, mixed %.3f mm, reaction %.3f mm\n", guided, mixed, reaction);
  EXPECT_LT(guided, reaction);
  EXPECT_LT(guided, mixed);
}

TEST(HapticsLoop, ThreadRunsPublishesAndSwitchesMode) {
  const WobbleScene scene;
  ScriptedDevice dev = scene.device();
  LoopOptions o;
  o.trace_capacity = 4000;
  HapticLoop loop(dev, scene.index.get(), scene.contact.get(), o);
  loop.start();
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  loop.set_mode(ForceMode::guidance);
  const HapticState s = loop.state();
  EXPECT_GT(s.tick, 0u);
  EXPECT_TRUE(to_eigen(s.tool_lps_mm).allFinite());
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_EQ(loop.state().mode, int(ForceMode::guidance));
  EXPECT_TRUE(loop.wait(10.0));  // the scripted device ends after 2 s
  const LoopStats st = loop.stats();
  EXPECT_GT(st.ticks, 0u);
  EXPECT_EQ(st.faults, 0u);
  EXPECT_GT(st.rate_Hz, 0.0);
  EXPECT_LE(st.compute_us.p50, st.compute_us.p99);
  EXPECT_LE(st.jitter_us.p99, st.jitter_us.p999);
  const auto trace = loop.trace();
  EXPECT_EQ(trace.size(), std::min<std::size_t>(st.ticks, 4000));
  for (const auto& t : trace) ASSERT_LE(to_eigen(t.force_N).norm(), o.force_limit_N + 1e-12);
}

// ---- paths ---------------------------------------------------------------------------------------

// The tubes these tests draw label their lumen 2, as the phantom labels its trachea.
const CenterlineOptions kLumen{.label = 2, .organ = "trachea"};

TEST(HapticsPaths, ResampleAndSmooth) {
  Polyline p = random_walk(50, 9);
  const Polyline r = resample_polyline(p, 1.0);
  // Evenly spaced along the original line: step L / round(L); chords never longer than the step.
  const double L = p.length_mm();
  const double step = L / std::round(L);
  ASSERT_EQ(r.points_lps_mm.size(), std::size_t(std::round(L)) + 1);
  const PathIndex original(p);
  for (std::size_t i = 0; i < r.points_lps_mm.size(); ++i) {
    ASSERT_NEAR(original.nearest(r.points_lps_mm[i]).arc_length_mm, double(i) * step, 1e-6);
    if (i) ASSERT_LE((r.points_lps_mm[i] - r.points_lps_mm[i - 1]).norm(), step + 1e-9);
  }
  EXPECT_EQ(r.points_lps_mm.front(), p.points_lps_mm.front());
  EXPECT_TRUE(r.points_lps_mm.back().isApprox(p.points_lps_mm.back(), 1e-12));
  const Polyline sm = smooth_polyline(r, 3.0);
  EXPECT_EQ(sm.points_lps_mm.front(), r.points_lps_mm.front());
  EXPECT_EQ(sm.points_lps_mm.back(), r.points_lps_mm.back());
  EXPECT_LT(sm.length_mm(), r.length_mm());  // smoothing shortens a wiggly line
  // A straight line stays straight, ends included.
  Polyline straight;
  for (int i = 0; i <= 40; ++i) straight.points_lps_mm.emplace_back(i * 0.5, 2.0 * i * 0.5, 1.0);
  for (const auto& q : smooth_polyline(straight, 4.0).points_lps_mm) ASSERT_NEAR(q.y(), 2.0 * q.x(), 1e-9);
}

TEST(HapticsPaths, CenterlineOfACurvedTubeReachesBothEnds) {
  const double z0 = -70.0, z1 = 60.0;
  const LabelMap lm = tube_labels(6.0, z0, z1);
  const Centerline cl = trachea_centerline(lm, kLumen);
  const auto& p = cl.line.points_lps_mm;
  ASSERT_GT(p.size(), 100u);
  // Lumen ends: the iso-surface lies half a slice beyond the first and last lumen slices.
  double zmin = 1e9, zmax = -1e9;
  for (std::int64_t k = 0; k < lm.grid.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < 64; ++j)
      for (std::int64_t i = 0; i < 64; ++i)
        if (lm.at(i, j, k) == 2) {
          const double z = lm.grid.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k))).z();
          zmin = std::min(zmin, z), zmax = std::max(zmax, z);
        }
  const double half = 0.5 * lm.grid.spacing_mm.z();
  EXPECT_GT(p.front().z(), p.back().z());  // cranial first
  EXPECT_NEAR(p.front().z(), zmax + half, 1.0);
  EXPECT_NEAR(p.back().z(), zmin - half, 1.0);
  // On the axis: within half a voxel of the true centre all along.
  double worst = 0;
  for (const auto& q : p) worst = std::max(worst, std::hypot(q.x() - 3.0 * std::sin(q.z() / 40.0), q.y()));
  EXPECT_LT(worst, 0.5);
  const auto s = cl.line.arc_length_mm();
  EXPECT_NEAR(s[1], 1.0, 0.01);
  std::printf("curved tube: end gaps %.3f / %.3f mm, worst off-axis %.3f mm\n", std::abs(p.front().z() - zmax - half),
              std::abs(p.back().z() - zmin + half), worst);
}

TEST(HapticsPaths, CenterlineReachesThePhantomLumenEnds) {
  PhantomOptions po;
  po.size_vox = 128;
  po.noise_hu = 0.0;
  NullProgress progress;
  const Phantom ph = synthesize_phantom(po, progress);
  const Centerline cl = trachea_centerline(ph.truth, kLumen);
  // Lumen ends of the ground truth: the first and last slices holding label 2, ± half a slice.
  const auto& g = ph.truth.grid;
  std::int64_t kmin = g.size_vox[2], kmax = -1;
  Eigen::Vector3d cmin = Eigen::Vector3d::Zero(), cmax = Eigen::Vector3d::Zero();
  for (std::int64_t k = 0; k < g.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < g.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < g.size_vox[0]; ++i)
        if (ph.truth.at(i, j, k) == 2) kmin = std::min(kmin, k), kmax = std::max(kmax, k);
  auto cap_centre = [&](std::int64_t k) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    int n = 0;
    for (std::int64_t j = 0; j < g.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < g.size_vox[0]; ++i)
        if (ph.truth.at(i, j, k) == 2) c += g.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k))), ++n;
    return Eigen::Vector3d(c / n);
  };
  cmax = cap_centre(kmax) + Eigen::Vector3d(0, 0, 0.5 * g.spacing_mm.z());
  cmin = cap_centre(kmin) - Eigen::Vector3d(0, 0, 0.5 * g.spacing_mm.z());
  const auto& p = cl.line.points_lps_mm;
  const double cranial_gap = std::abs(p.front().z() - cmax.z()), caudal_gap = std::abs(p.back().z() - cmin.z());
  std::printf("phantom (128²): centreline %.1f mm, cranial end %.3f mm from the lumen end plane (%.2f mm from the cap "
              "centre), caudal %.3f mm (%.2f mm)\n",
              cl.line.length_mm(), cranial_gap, (p.front() - cmax).norm(), caudal_gap, (p.back() - cmin).norm());
  EXPECT_LE(cranial_gap, 1.0);
  EXPECT_LE(caudal_gap, 1.0);
  // And the ends lie inside the cap (not on the rim): well within the 8.5 mm lumen radius.
  EXPECT_LT((p.front() - cmax).norm(), 3.0);
  EXPECT_LT((p.back() - cmin).norm(), 3.0);
}

TEST(HapticsPaths, IncisionLiesOnTheAnteriorWall) {
  const LabelMap lm = tube_labels(8.5, -70.0, 60.0, {0.8, 0.8, 1.0});
  Centerline cl = trachea_centerline(lm, kLumen);
  // A straight wall around the straight part of the axis is not what tube_labels made (it curves by
  // ±3 mm); use a straight tube for both.
  LabelMap straight = lm;
  for (std::int64_t k = 0; k < straight.grid.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < 64; ++j)
      for (std::int64_t i = 0; i < 64; ++i) {
        const Eigen::Vector3d p = straight.grid.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k)));
        straight.labels[std::size_t(straight.grid.offset(i, j, k))] =
            (p.z() >= -70 && p.z() <= 60 && std::hypot(p.x(), p.y()) < 8.5) ? 2 : 0;
      }
  cl = trachea_centerline(straight, kLumen);
  const SurfaceIndex wall({tube_wall(8.5, 11.0, -70.5, 60.5)});
  IncisionOptions o;
  const IncisionPath inc = trachea_incision_path(cl, wall, o);
  EXPECT_NEAR(inc.line.length_mm(), o.ring_count * o.ring_pitch_mm, 1.0);
  EXPECT_EQ(inc.first_ring, 3);
  EXPECT_EQ(inc.last_ring, 6);
  EXPECT_LE(inc.max_wall_distance_mm, 0.5);
  for (const auto& q : inc.line.points_lps_mm) {
    ASSERT_LT(q.y(), -10.5);  // anterior (−y) and on the outer surface (r = 11, polygon chord ≥ 10.99)
    ASSERT_LE(std::abs(wall.closest(q).signed_distance_mm), 0.5);
  }
  std::printf("incision: %.1f mm over rings %d–%d, max distance to the wall %.4f mm\n", inc.length_mm, inc.first_ring,
              inc.last_ring, inc.max_wall_distance_mm);
  o.first_ring = 30;
  EXPECT_THROW(trachea_incision_path(cl, wall, o), InputError);
}

TEST(HapticsPaths, DissectionFollowsTheLiverBedRim) {
  const SurfaceMesh gb = icosphere(15.0, 4);
  // Liver: every voxel with z > 5 mm (touching the upper cap of the sphere).
  LabelMap liver;
  liver.grid.spacing_mm = {1.0, 1.0, 1.0};
  liver.grid.size_vox = {50, 50, 50};
  liver.grid.origin_lps_mm = {-24.5, -24.5, -24.5};
  liver.labels.assign(std::size_t(liver.grid.voxel_count()), 0);
  for (std::int64_t k = 0; k < 50; ++k)
    for (std::int64_t j = 0; j < 50; ++j)
      for (std::int64_t i = 0; i < 50; ++i) {
        const Eigen::Vector3d p = liver.grid.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k)));
        if (p.z() > 5.0 && p.norm() > 15.0) liver.labels[std::size_t(liver.grid.offset(i, j, k))] = 3;
      }
  DissectionOptions o;
  o.liver_label = 3;
  o.bed_distance_mm = 1.5;
  const DissectionPath d = gallbladder_dissection_path(gb, &liver, o);
  EXPECT_EQ(d.bed_source, "liver label");
  EXPECT_TRUE(d.line.closed);
  EXPECT_LE(d.max_surface_distance_mm, 0.5);
  // The rim is a circle of the sphere near z ≈ 5 (minus the bed distance reach).
  for (const auto& q : d.line.points_lps_mm) {
    ASSERT_NEAR(q.norm(), 15.0, 0.5);
    ASSERT_GT(q.z(), 1.0);
    ASSERT_LT(q.z(), 6.0);
  }
  // Without the liver: the surface facing the configured direction (+z, 60°) → rim at z = 15 cos 60°.
  DissectionOptions f;
  f.bed_direction_lps = {0, 0, 1};
  const DissectionPath d2 = gallbladder_dissection_path(gb, nullptr, f);
  EXPECT_EQ(d2.bed_source, "surface facing the liver direction");
  for (const auto& q : d2.line.points_lps_mm) ASSERT_NEAR(q.z(), 7.5, 1.0);
}

TEST(HapticsPaths, FilesRoundTripAndBadPathsAreErrors) {
  const fs::path dir = fs::temp_directory_path() / "organsmith_haptics_paths";
  fs::create_directories(dir);
  Polyline p = resample_polyline(random_walk(20, 4), 1.0);
  p.name = "recorded";
  std::ofstream(dir / "p.json") << path_json(p, {{"length_mm", p.length_mm()}});
  const Polyline back = read_path_file(dir / "p.json");
  ASSERT_EQ(back.points_lps_mm.size(), p.points_lps_mm.size());
  for (std::size_t i = 0; i < p.points_lps_mm.size(); ++i) ASSERT_LT((back.points_lps_mm[i] - p.points_lps_mm[i]).norm(), 1e-4);
  std::ofstream(dir / "p.csv") << "t_s,x,y,z\n0,1,2,3\n1,4,5,6\n";
  EXPECT_EQ(read_path_file(dir / "p.csv").points_lps_mm.size(), 2u);
  const std::string vtp = path_vtp(p);
  EXPECT_NE(vtp.find("NumberOfLines=\"1\""), std::string::npos);
  auto code = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    try {
      read_path_file(dir / name);
    } catch (const InputError& e) {
      return int(e.code());
    }
    return 0;
  };
  EXPECT_EQ(code("empty.json", "{\"points_lps_mm\": []}"), 18);
  EXPECT_EQ(code("nan.csv", "x,y,z\n0,0,0\nnan,1,1\n"), 18);
  EXPECT_EQ(code("one.csv", "x,y,z\n0,0,0\n"), 18);
  EXPECT_EQ(code("bad.json", "{\"points_lps_mm\": [[1,2],[3,4,5]]}"), 18);
  ImageGrid g;
  g.size_vox = {100, 100, 100};
  Polyline far;
  far.points_lps_mm = {{10, 10, 10}, {10, 10, 900}};
  EXPECT_THROW(check_path_within(far, g, "far.csv"), InputError);
  far.points_lps_mm[1] = {20, 20, 20};
  EXPECT_NO_THROW(check_path_within(far, g, "near.csv"));
  fs::remove_all(dir);
}
