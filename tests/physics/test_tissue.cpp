// The real-time tissue model's mechanics: the Ogden point against finite differences (energy →
// stress → tangent, with coinciding stretches and the gallbladder's α = 30 term), the assembled
// model's force and held-set stiffness against finite differences, work = stored energy along a
// quasi-static press, and a released organ coming back to rest.

#include "physics/tissue/ogden_solid.h"
#include "physics/tissue/realtime_tissue.h"
#include "physics/tissue/tissue_model.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <map>
#include <memory>

#include <cmath>

using namespace organsmith::physics;

namespace {

// The gallbladder wall's fitted law in N/mm² (an INP the mesh stage wrote: μ_i, α_i, K).
OgdenSolid wall_law() { return {{4.43497518e-05, 4.78705382e-05, 3.91486476e-06}, {10.5680239, 12.8545186, 30.0}, 0.233852}; }
OgdenSolid mooney_rivlin_law() { return {{2 * 0.01, 2 * 0.004}, {2.0, -2.0}, 1.0}; }

double energy_at(const OgdenSolid& law, const Eigen::Matrix3d& F) {
  SolidPoint p;
  EXPECT_TRUE(evaluate_ogden(law, F, p, false));
  return p.energy;
}

void check_point(const OgdenSolid& law, const Eigen::Matrix3d& F, bool check_energy = true) {
  SolidPoint p;
  ASSERT_TRUE(evaluate_ogden(law, F, p, true));
  // P = ∂W/∂F = F S, by central differences (not at rest, where the energy's differences are
  // round-off).
  const Eigen::Matrix3d P = F * p.S;
  const double h = 1e-6;
  double scale = P.cwiseAbs().maxCoeff() + 1e-12;
  for (int i = 0; i < 3 && check_energy; ++i)
    for (int j = 0; j < 3; ++j) {
      Eigen::Matrix3d Fp = F, Fm = F;
      Fp(i, j) += h;
      Fm(i, j) -= h;
      const double fd = (energy_at(law, Fp) - energy_at(law, Fm)) / (2 * h);
      EXPECT_NEAR(fd, P(i, j), 2e-5 * scale) << "P(" << i << "," << j << ")";
    }
  // δS = D : δE for δF in several directions, δE = sym(Fᵀ δF).
  const double scaleD = p.D.cwiseAbs().maxCoeff();
  for (int trial = 0; trial < 6; ++trial) {
    Eigen::Matrix3d dF = Eigen::Matrix3d::Zero();
    dF(trial % 3, (trial * 2 + 1) % 3) = 1.0;
    dF(trial / 2, trial % 3) += 0.5;
    SolidPoint a, b;
    ASSERT_TRUE(evaluate_ogden(law, F + h * dF, a, false));
    ASSERT_TRUE(evaluate_ogden(law, F - h * dF, b, false));
    const Eigen::Matrix3d dS = (a.S - b.S) / (2 * h);
    const Eigen::Matrix3d dE = 0.5 * (F.transpose() * dF + dF.transpose() * F);
    Voigt6 e;
    e << dE(0, 0), dE(1, 1), dE(2, 2), 2 * dE(0, 1), 2 * dE(1, 2), 2 * dE(2, 0);
    const Voigt6 s = p.D * e;
    const double got[6] = {dS(0, 0), dS(1, 1), dS(2, 2), dS(0, 1), dS(1, 2), dS(2, 0)};
    for (int k = 0; k < 6; ++k) EXPECT_NEAR(got[k], s[k], 1e-4 * scaleD) << "direction " << trial << " component " << k;
  }
}

}  // namespace

TEST(TissuePoint, OgdenStressAndTangentMatchFiniteDifferences) {
  Eigen::Matrix3d general;
  general << 1.12, 0.05, -0.02, 0.03, 0.93, 0.04, -0.01, 0.02, 1.01;
  const Eigen::Matrix3d equal_pair = Eigen::Vector3d(1.1, 1.1, 0.85).asDiagonal();
  for (const auto& law : {wall_law(), mooney_rivlin_law()}) {
    check_point(law, general);
    check_point(law, equal_pair);
    check_point(law, Eigen::Matrix3d::Identity() + 1e-9 * general, false);  // three equal stretches
  }
  // At rest: no stress; the small-strain shear modulus is Σ μ_i.
  SolidPoint p;
  ASSERT_TRUE(evaluate_ogden(wall_law(), Eigen::Matrix3d::Identity(), p, true));
  EXPECT_LT(p.S.norm(), 1e-15);
  EXPECT_NEAR(p.D(3, 3), wall_law().initial_shear(), 1e-9 * wall_law().initial_shear());
  EXPECT_NEAR(p.D(0, 1), wall_law().bulk - 2.0 / 3.0 * wall_law().initial_shear(), 1e-9 * wall_law().bulk);
  // Inverted: refused.
  EXPECT_FALSE(evaluate_ogden(wall_law(), Eigen::Matrix3d(Eigen::Vector3d(1, 1, -0.5).asDiagonal()), p, true));
}

namespace {

// A block of 2×2×4 cubes of `h` mm, each cut into six tetrahedra (4 or 10 nodes), fixed at
// z = 0, held on the top face.
struct Block {
  TissueMesh mesh;
  std::vector<std::int32_t> bottom, top;
};

Block make_block(bool quadratic, const OgdenSolid& law, double h = 2.0) {
  Block b;
  const int nx = 2, ny = 2, nz = 4;
  auto id = [&](int i, int j, int k) { return std::int32_t((k * (ny + 1) + j) * (nx + 1) + i); };
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        b.mesh.nodes_mm.emplace_back(i * h, j * h, k * h);
        if (k == 0) b.bottom.push_back(id(i, j, k));
        if (k == nz) b.top.push_back(id(i, j, k));
      }
  b.mesh.laws = {law};
  const int cube[6][4] = {{0, 1, 3, 7}, {0, 1, 7, 5}, {0, 5, 7, 4}, {0, 3, 2, 7}, {0, 2, 6, 7}, {0, 6, 4, 7}};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const std::int32_t c[8] = {id(i, j, k), id(i + 1, j, k), id(i, j + 1, k), id(i + 1, j + 1, k),
                                   id(i, j, k + 1), id(i + 1, j, k + 1), id(i, j + 1, k + 1), id(i + 1, j + 1, k + 1)};
        for (const auto& t : cube) {
          std::array<std::int32_t, 10> e;
          e.fill(-1);
          for (int a = 0; a < 4; ++a) e[a] = c[t[a]];
          const Eigen::Vector3d& x0 = b.mesh.nodes_mm[e[0]];
          if ((b.mesh.nodes_mm[e[1]] - x0).cross(b.mesh.nodes_mm[e[2]] - x0).dot(b.mesh.nodes_mm[e[3]] - x0) < 0) std::swap(e[1], e[2]);
          b.mesh.elements.push_back(e);
          b.mesh.law_of_element.push_back(0);
        }
      }
  b.mesh.nodes_per_element = 4;
  if (!quadratic) return b;
  // Mid-edge nodes, shared between elements.
  std::map<std::pair<int, int>, std::int32_t> mid;
  const int edge[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
  for (auto& e : b.mesh.elements)
    for (int m = 0; m < 6; ++m) {
      const auto key = std::minmax(e[edge[m][0]], e[edge[m][1]]);
      auto it = mid.find({key.first, key.second});
      if (it == mid.end()) {
        const std::int32_t nid = std::int32_t(b.mesh.nodes_mm.size());
        const Eigen::Vector3d p = 0.5 * (b.mesh.nodes_mm[key.first] + b.mesh.nodes_mm[key.second]);
        b.mesh.nodes_mm.push_back(p);
        if (p.z() == 0) b.bottom.push_back(nid);
        if (p.z() == nz * h) b.top.push_back(nid);
        it = mid.insert({{key.first, key.second}, nid}).first;
      }
      e[4 + m] = it->second;
    }
  b.mesh.nodes_per_element = 10;
  return b;
}

}  // namespace

TEST(TissueModel, HeldStiffnessIsTheDerivativeOfTheHeldForce) {
  for (bool quadratic : {false, true}) {
    Block b = make_block(quadratic, wall_law());
    TissueModel m(b.mesh);
    m.set_boundary(b.bottom, b.top);
    const Eigen::Vector3d d(0.15, -0.1, -0.6);
    NewtonOptions tight;
    tight.force_tolerance_N = 1e-13;
    tight.relative_tolerance = 1e-12;
    for (int s = 1; s <= 4; ++s) ASSERT_TRUE(m.solve_static(d * s / 4.0, tight).converged) << "step " << s;
    const Eigen::Vector3d f0 = m.held_force_N();
    const Eigen::Matrix3d K = m.held_stiffness_N_per_mm();
    for (int k = 0; k < 3; ++k) {
      const double h = 1e-4;
      TissueModel mp(b.mesh);
      mp.set_boundary(b.bottom, b.top);
      for (int s = 1; s <= 4; ++s) ASSERT_TRUE(mp.solve_static(d * s / 4.0, tight).converged);
      ASSERT_TRUE(mp.solve_static(d + h * Eigen::Vector3d::Unit(k), tight).converged);
      const Eigen::Vector3d fd = (mp.held_force_N() - f0) / h;
      EXPECT_LT((fd - K.col(k)).norm(), 2e-3 * K.norm()) << (quadratic ? "tet10" : "tet4") << " column " << k;
    }
  }
}

// The response the display draws between equilibria: d(displacement)/d(held displacement) at a
// converged state, against a central difference of two converged solves.
TEST(TissueModel, HeldResponseIsTheDerivativeOfTheDisplacement) {
  for (bool quadratic : {false, true}) {
    Block b = make_block(quadratic, wall_law());
    NewtonOptions tight;
    tight.force_tolerance_N = 1e-13;
    tight.relative_tolerance = 1e-12;
    const Eigen::Vector3d d(0.1, 0.05, -0.5);
    auto solved = [&](const Eigen::Vector3d& at) {
      auto m = std::make_unique<TissueModel>(b.mesh);
      m->set_boundary(b.bottom, b.top);
      for (int s = 1; s <= 4; ++s) EXPECT_TRUE(m->solve_static(at * s / 4.0, tight).converged);
      return m;
    };
    const auto m = solved(d);
    const Eigen::MatrixXd R = m->held_response();
    ASSERT_EQ(R.rows(), m->displacement_mm().size());
    ASSERT_EQ(R.cols(), 3);
    for (int k = 0; k < 3; ++k) {
      const double h = 1e-4;
      const Eigen::VectorXd fd = (solved(d + h * Eigen::Vector3d::Unit(k))->displacement_mm() -
                                  solved(d - h * Eigen::Vector3d::Unit(k))->displacement_mm()) / (2 * h);
      EXPECT_LT((fd - R.col(k)).norm(), 1e-3 * fd.norm()) << (quadratic ? "tet10" : "tet4") << " column " << k;
    }
    for (std::int32_t i : b.bottom) EXPECT_EQ(R.row(3 * i).norm(), 0.0);
  }
}

// The equilibrium the real-time model publishes: BFGS on the last factorised tangent reaches the
// same state as Newton, in increments as the real-time thread takes them, and factorises less.
TEST(TissueModel, QuasiNewtonReachesNewtonsEquilibrium) {
  for (bool quadratic : {false, true}) {
    Block b = make_block(quadratic, wall_law());
    TissueModel newton(b.mesh), bfgs(b.mesh);
    newton.set_boundary(b.bottom, b.top);
    bfgs.set_boundary(b.bottom, b.top);
    NewtonOptions o;
    o.relative_tolerance = 1e-8;
    o.force_tolerance_N = 1e-12;
    o.max_iterations = 30;
    const Eigen::Vector3d d(0.05, 0.0, -0.8);
    int factorised = 0;
    for (int s = 1; s <= 8; ++s) {
      ASSERT_TRUE(newton.solve_static(d * s / 8.0, o).converged);
      const NewtonReport r = bfgs.solve_static_quasi_newton(d * s / 8.0, o);
      ASSERT_TRUE(r.converged) << (quadratic ? "tet10" : "tet4") << " increment " << s;
      factorised += r.refreshed;
    }
    EXPECT_LT((newton.displacement_mm() - bfgs.displacement_mm()).cwiseAbs().maxCoeff(), 1e-5);
    EXPECT_NEAR(bfgs.held_force_N().z(), newton.held_force_N().z(), 1e-5 * std::abs(newton.held_force_N().z()));
    EXPECT_LT(factorised, 8) << (quadratic ? "tet10" : "tet4") << ": one factorisation an increment is Newton's cost";
  }
}

TEST(TissueModel, WorkOfAQuasiStaticPressIsTheStoredEnergy) {
  for (bool quadratic : {false, true}) {
    Block b = make_block(quadratic, wall_law());
    TissueModel m(b.mesh);
    m.set_boundary(b.bottom, b.top);
    const Eigen::Vector3d dir(0.2, 0.1, -1.0);
    double work = 0.0, prev_f = 0.0;
    const int steps = 40;
    const double depth = 1.6, dd = depth / steps;
    for (int s = 1; s <= steps; ++s) {
      ASSERT_TRUE(m.solve_static(dir * (s * dd)).converged) << "step " << s;
      const double f = m.held_force_N().dot(dir);
      work += 0.5 * (f + prev_f) * dd;
      prev_f = f;
    }
    EXPECT_GT(work, 0);
    EXPECT_NEAR(work, m.strain_energy_mJ(), 5e-3 * work) << (quadratic ? "tet10" : "tet4");
  }
}

TEST(TissueModel, AReleasedBlockReturnsToRest) {
  Block b = make_block(false, wall_law());
  TissueModel m(b.mesh);
  m.set_boundary(b.bottom, b.top);
  const Eigen::Vector3d press(0, 0, -1.5);
  const double dt = 1.0 / 60;
  for (int s = 1; s <= 30; ++s) ASSERT_TRUE(m.step_dynamic(press * std::min(1.0, s / 20.0), dt).converged);
  m.set_boundary(b.bottom, {});  // released
  double t = 0;
  for (; t < 1.0; t += dt) ASSERT_TRUE(m.step_dynamic(Eigen::Vector3d::Zero(), dt).converged);
  EXPECT_LT(m.displacement_mm().cwiseAbs().maxCoeff(), 0.01 * 1.5);
}

// The multirate model driven update by update (as its thread does): the tool sphere pressed into
// the block's top at 5 mm/s, held, withdrawn. The force it reports is the held set's quasi-static
// answer at the hold's end, the tool never passes the surface, the fixed face never moves, and the
// block is back at rest within a second of the tool leaving.
TEST(RealtimeTissue, APressFeelsTheStaticForceAndTheBlockComesBackToRest) {
  for (bool quadratic : {false, true}) {
    const char* kind = quadratic ? "tet10" : "tet4";
    Block b = make_block(quadratic, wall_law());
    const double top = 8.0;
    std::vector<std::int32_t> tri;  // top face, outward (+z)
    auto corner = [&](int i, int j) { return std::int32_t((4 * 3 + j) * 3 + i); };
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        for (std::int32_t v : {corner(i, j), corner(i + 1, j), corner(i + 1, j + 1)}) tri.push_back(v);
        for (std::int32_t v : {corner(i, j), corner(i + 1, j + 1), corner(i, j + 1)}) tri.push_back(v);
      }
    TissueModel m(b.mesh);
    RealtimeOptions o;
    RealtimeTissue rt(m, b.bottom, tri, o);
    const Eigen::Vector3d centre(2.0, 2.0, top), down(0, 0, -1);
    const Eigen::Vector3d start = centre - down * (o.tool_radius_mm + 0.5);
    const double dt = 1.0 / o.update_hz, speed = 5.0, depth = 1.0, travel = 0.5 + depth;
    Eigen::Vector3d tool = start, F = Eigen::Vector3d::Zero();
    for (double s = 0; s < travel + 1e-9; s += speed * dt) {
      tool = start + down * s;
      rt.set_tool(tool);
      rt.update_once();
      F = rt.tool_force_N(tool);
      // The tissue pushes the tool, never pulls it (the force is not monotone in the depth: so
      // soft a block rings at a few tens of Hz under a 5 mm/s tool, which the steps resolve).
      EXPECT_GE(F.z(), 0.0) << kind;
      // The touched node stays on the sphere: it is never inside it (by more than the
      // iterations' tolerance on a held node, a hundredth of a millimetre).
      const Eigen::VectorXd u = rt.displacement_mm();
      const std::int32_t c = corner(1, 1);
      const Eigen::Vector3d x = b.mesh.nodes_mm[c] + u.segment<3>(3 * c);
      EXPECT_GE((x - tool).norm(), o.tool_radius_mm - 1e-2) << kind << " at " << s << " mm";
    }
    for (int k = 0; k < 30; ++k) rt.update_once();  // half a second held
    F = rt.tool_force_N(tool);
    ASSERT_GT(F.z(), 0) << kind;
    // The same held set, pressed quasi-statically to where the tool holds it.
    const std::vector<std::int32_t> held = m.held_nodes();
    ASSERT_FALSE(held.empty());
    const Eigen::Vector3d u_held = m.displacement_mm().segment<3>(3 * held.front());
    TissueModel ref(b.mesh);
    ref.set_boundary(b.bottom, held);
    for (int s = 1; s <= 8; ++s) ASSERT_TRUE(ref.solve_static(u_held * s / 8.0).converged);
    const Eigen::Vector3d Fs = -ref.held_force_N();
    EXPECT_NEAR(F.z(), Fs.z(), 0.05 * Fs.z()) << kind << ": real-time " << F.z() << " N, static " << Fs.z() << " N";
    for (std::int32_t i : b.bottom) EXPECT_EQ(m.displacement_mm().segment<3>(3 * i).norm(), 0.0);
    // Withdrawn, then one second at rest.
    for (double s = travel; s > -1.0; s -= speed * dt) {
      tool = start + down * std::max(s, -1.0);
      rt.set_tool(tool);
      rt.update_once();
    }
    EXPECT_EQ(rt.tool_force_N(tool).norm(), 0.0) << kind << ": out of contact";
    for (int k = 0; k < int(o.update_hz); ++k) rt.update_once();
    EXPECT_LT(rt.displacement_mm().cwiseAbs().maxCoeff(), 0.01 * depth) << kind;
    // Pressed again and pulled straight out: the tool lets go, and the block is at rest in that one
    // update (it carries no load but the tool's), wherever the equilibrium was.
    for (double s = 0; s < travel + 1e-9; s += speed * dt) {
      rt.set_tool(start + down * s);
      rt.update_once();
    }
    ASSERT_GT(rt.displacement_mm().cwiseAbs().maxCoeff(), 0.1 * depth) << kind;
    const Eigen::Vector3d out = start - down * 1.0;
    rt.set_tool(out);
    rt.update_once();
    EXPECT_EQ(rt.displacement_mm().cwiseAbs().maxCoeff(), 0.0) << kind;
    EXPECT_EQ(rt.tool_force_N(out).norm(), 0.0) << kind;
  }
}
