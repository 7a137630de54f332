// Material patch tests in CalculiX: a unit cube of each exported material (the INP writer's own
// *MATERIAL block, quadratic tetrahedra), stretched uniaxially and equibiaxially to the top of the
// law's calibrated range. The solver's nominal stress is compared with the calibrated law at ten
// stretches. Needs Debian's calculix-ccx (scripts/install-deps); skipped with a message without it.

#include "meshing/export.h"
#include "physics/materials/solver_fit.h"
#include "pipeline/case/organ_registry.h"

#include "tests/support/test_support.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>

namespace fs = std::filesystem;
using namespace organsmith;
using namespace organsmith::physics;

namespace {

bool have_ccx() { return std::system("command -v ccx > /dev/null 2>&1") == 0; }

/// A unit cube (mm) of six tetrahedra around the diagonal 0–6, as an organ with one solid region.
OrganMesh unit_cube() {
  OrganMesh o;
  o.spec.name = "cube";
  o.spec.model = OrganModel::solid;
  o.region_names = {{100, "cube"}};
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) o.volume.vertices_lps_mm.emplace_back(i, j, k);
  // Corner ids: (i, j, k) → i + 2 j + 4 k; the six Kuhn tetrahedra share the diagonal 0–7.
  const std::array<std::array<int, 4>, 6> t = {{{0, 1, 3, 7}, {0, 3, 2, 7}, {0, 2, 6, 7}, {0, 6, 4, 7}, {0, 4, 5, 7}, {0, 5, 1, 7}}};
  for (const auto& q : t) {
    o.volume.tets.push_back({q[0], q[1], q[2], q[3]});
    o.volume.region_ids.push_back(100);
  }
  return o;
}

/// Node ids (1-based) of the model whose coordinate `axis` equals `value`.
std::string nodes_at(const SolverModel& m, int axis, double value) {
  std::string s;
  int n = 0;
  for (std::size_t v = 0; v < m.nodes_lps_mm.size(); ++v)
    if (std::abs(m.nodes_lps_mm[v][axis] - value) < 1e-9) s += (n++ % 8 ? ", " : (n > 1 ? "\n" : "")) + std::to_string(v + 1);
  return s + "\n";
}

/// Runs the cube to `stretch_max` in ten equal increments; returns the nominal stress along x (Pa)
/// at each increment.
std::vector<double> run_cube(const SolverMaterial& mat, double stretch_max, bool equibiaxial, const fs::path& dir) {
  const SolverModel m = build_solver_model(unit_cube());
  const fs::path inp = dir / "cube.inp";
  write_inp(m, {{"cube", mat}}, SolverScenario{}, inp);
  std::ofstream f(inp, std::ios::app);
  f << "*NSET, NSET=X0\n" << nodes_at(m, 0, 0) << "*NSET, NSET=Y0\n" << nodes_at(m, 1, 0) << "*NSET, NSET=Z0\n"
    << nodes_at(m, 2, 0) << "*NSET, NSET=X1\n" << nodes_at(m, 0, 1) << "*NSET, NSET=Y1\n" << nodes_at(m, 1, 1);
  f << "*STEP, NLGEOM, INC=100\n*STATIC, DIRECT\n0.1, 1.0\n*BOUNDARY\nX0, 1, 1\nY0, 2, 2\nZ0, 3, 3\n"
    << "X1, 1, 1, " << (stretch_max - 1) << "\n";
  if (equibiaxial) f << "Y1, 2, 2, " << (stretch_max - 1) << "\n";
  f << "*NODE PRINT, NSET=X1, TOTALS=ONLY\nRF\n*END STEP\n";
  f.close();
  const std::string cmd = "cd " + organsmith::testing::quoted(dir.string()) + " && OMP_NUM_THREADS=1 ccx -i cube > ccx.log 2>&1";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << organsmith::testing::read_file(dir / "ccx.log");
  std::ifstream dat(dir / "cube.dat");
  std::vector<double> stress;
  std::string line;
  while (std::getline(dat, line)) {
    if (line.find("total force") == std::string::npos) continue;
    while (std::getline(dat, line) && line.find_first_not_of(' ') == std::string::npos) {
    }
    double fx = 0;
    std::istringstream(line) >> fx;
    stress.push_back(fx * 1e6);  // N over the 1 mm² reference face → MPa → Pa
  }
  return stress;
}

}  // namespace

TEST(SolverPatch, EveryPresetInCalculixFollowsItsCalibratedLaw) {
  if (!have_ccx()) GTEST_SKIP() << "CalculiX (ccx) not installed: apt-get install calculix-ccx (scripts/install-deps)";
  const MaterialLibrary lib = builtin_material_library();
  organsmith::testing::ScratchDir dir("solver-patch");
  std::printf("%-42s %-11s %7s %11s %11s %11s %8s %8s\n", "preset", "path", "λ", "law Pa", "fit Pa", "ccx Pa",
              "ccx/law", "ccx/fit");
  int presets = 0;
  for (const auto& p : lib.materials) {
    if (p.material.model != "fung-wall" && p.material.model != "fung-organ") continue;  // the region laws
    ++presets;
    SolverFitOptions fo;
    fo.samples = 10;  // the law sampled at the ten increments of the cube's step
    const SolverFit fit = fit_solver_material(region_law_from_preset(lib, p.id), fo);
    const LawCurve& law = fit.curves.front();  // the fitted uniaxial path (direction mean for the membranes)
    for (bool equi : {false, true}) {
      const fs::path d = dir.path() / (std::to_string(presets) + (equi ? "e" : "u"));
      fs::create_directories(d);
      const auto ccx = run_cube(fit.material, law.stretch.back(), equi, d);
      ASSERT_EQ(ccx.size(), 10u) << p.id;
      for (std::size_t i = 0; i < 10; ++i) {
        const double l = law.stretch[i];
        const double fitted = ogden_nominal_Pa(fit.material, l, equi);
        // The law itself along the same path: uniaxial as fitted; equibiaxial as the membrane law gives it.
        double law_Pa = law.nominal_stress_Pa[i];
        if (equi)
          for (const auto& c : fit.curves)
            if (c.name == "equibiaxial circumferential") law_Pa = 0.5 * c.nominal_stress_Pa[i];
        if (equi)
          for (const auto& c : fit.curves)
            if (c.name == "equibiaxial longitudinal") law_Pa += 0.5 * c.nominal_stress_Pa[i];
        if (i % 3 == 0 || i == 9)
          std::printf("%-42s %-11s %7.3f %11.4g %11.4g %11.4g %8.3f %8.3f\n", p.id.c_str(), equi ? "equibiaxial" : "uniaxial", l,
                      law_Pa, fitted, ccx[i], ccx[i] / law_Pa, ccx[i] / fitted);
        // The solver reproduces the exported solid (within the compressibility of its K).
        EXPECT_NEAR(ccx[i] / fitted, 1.0, 0.03) << p.id << (equi ? " equibiaxial" : " uniaxial") << " at " << l;
        if (!equi) EXPECT_NEAR(ccx[i] / law_Pa, 1.0, 0.05) << p.id << " uniaxial at " << l;
      }
    }
  }
  EXPECT_EQ(presets, 12);  // the fung-wall and fung-organ presets: mean and five specimens each
}

namespace {

/// A 20 × 20 × 40 mm block on a lattice of half-cells (5 mm cells, nodes every 2.5 mm), meshed as
/// C3D4, C3D10 (six Kuhn tetrahedra per cell; their mid-edge nodes are lattice points) or C3D20R
/// (the hexahedral reference), clamped at z = 0 and pulled 1 % at z = 40 (lateral motion held
/// there too: the constrained case where nearly incompressible tetrahedra lock). Returns the axial
/// reaction (N).
double block_reaction_N(const SolverMaterial& mat, const std::string& type, const fs::path& dir) {
  const int nx = 4, ny = 4, nz = 8;  // cells
  const double h = 5.0;
  auto id = [&](int i, int j, int k) { return 1 + i + (2 * nx + 1) * (j + (2 * ny + 1) * k); };  // half-cell lattice
  std::ostringstream s;
  s << "*NODE, NSET=ALL\n";
  for (int k = 0; k <= 2 * nz; ++k)
    for (int j = 0; j <= 2 * ny; ++j)
      for (int i = 0; i <= 2 * nx; ++i) s << id(i, j, k) << ", " << i * h / 2 << ", " << j * h / 2 << ", " << k * h / 2 << "\n";
  s << "*ELEMENT, TYPE=" << type << ", ELSET=BLOCK\n";
  int e = 0;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        // Corner c of the cell at lattice (2i + dx, 2j + dy, 2k + dz).
        auto c = [&](int dx, int dy, int dz) { return std::array<int, 3>{2 * i + 2 * dx, 2 * j + 2 * dy, 2 * k + 2 * dz}; };
        auto mid = [&](std::array<int, 3> a, std::array<int, 3> b) { return id((a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2); };
        auto at = [&](std::array<int, 3> a) { return id(a[0], a[1], a[2]); };
        if (type == "C3D20R") {
          const std::array<std::array<int, 3>, 8> v = {c(0, 0, 0), c(1, 0, 0), c(1, 1, 0), c(0, 1, 0),
                                                      c(0, 0, 1), c(1, 0, 1), c(1, 1, 1), c(0, 1, 1)};
          s << ++e;
          for (const auto& p : v) s << ", " << at(p);
          const int edges[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6}, {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
          for (int q = 0; q < 12; ++q) s << (q == 7 ? ",\n" : ", ") << mid(v[edges[q][0]], v[edges[q][1]]);  // 16 entries a line
          s << "\n";
          continue;
        }
        // Six tetrahedra around the diagonal (0,0,0)–(1,1,1), each positively oriented.
        const std::array<std::array<int, 3>, 6> path = {{{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}}};
        for (const auto& order : path) {
          std::array<std::array<int, 3>, 4> v;
          std::array<int, 3> d{0, 0, 0};
          v[0] = c(0, 0, 0);
          for (int q = 0; q < 3; ++q) {
            d[order[q]] = 1;
            v[q + 1] = c(d[0], d[1], d[2]);
          }
          // Orientation of this path's tet: the permutation's parity.
          const bool odd = (order[0] == 0 && order[1] == 2) || (order[0] == 1 && order[1] == 0) || (order[0] == 2 && order[1] == 1);
          if (odd) std::swap(v[1], v[2]);
          s << ++e;
          for (const auto& p : v) s << ", " << at(p);
          if (type == "C3D10")
            for (const auto& [a, b] : std::array<std::pair<int, int>, 6>{{{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}}})
              s << ", " << mid(v[a], v[b]);
          s << "\n";
        }
      }
  s << "*NSET, NSET=BOTTOM\n";
  int n = 0;
  for (int j = 0; j <= 2 * ny; ++j)
    for (int i = 0; i <= 2 * nx; ++i) s << id(i, j, 0) << (++n % 8 ? ", " : "\n");
  s << "\n*NSET, NSET=TOP\n";
  n = 0;
  for (int j = 0; j <= 2 * ny; ++j)
    for (int i = 0; i <= 2 * nx; ++i) s << id(i, j, 2 * nz) << (++n % 8 ? ", " : "\n");
  s << "\n*MATERIAL, NAME=M\n*HYPERELASTIC, OGDEN, N=3\n";
  for (int q = 0; q < 3; ++q) s << mat.ogden_mu_Pa[q] * 1e-6 << "," << mat.ogden_alpha[q] << ",";
  s << 2.0 / (mat.bulk_modulus_Pa * 1e-6) << ",1e20\n1e20\n*SOLID SECTION, ELSET=BLOCK, MATERIAL=M\n";
  s << "*STEP, NLGEOM\n*STATIC\n0.25, 1.0\n*BOUNDARY\nBOTTOM, 1, 3\nTOP, 1, 2\nTOP, 3, 3, 0.4\n"
       "*NODE PRINT, NSET=TOP, TOTALS=ONLY\nRF\n*END STEP\n";
  {
    std::ofstream f(dir / "block.inp");
    f << s.str();
  }
  const std::string cmd = "cd " + organsmith::testing::quoted(dir) + " && OMP_NUM_THREADS=1 ccx -i block > ccx.log 2>&1";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << organsmith::testing::read_file(dir / "ccx.log");
  std::ifstream dat(dir / "block.dat");
  std::string line;
  double fz = 0;
  while (std::getline(dat, line)) {
    if (line.find("total force") == std::string::npos) continue;
    while (std::getline(dat, line) && line.find_first_not_of(' ') == std::string::npos) {
    }
    double fx, fy;
    std::istringstream(line) >> fx >> fy >> fz;
  }
  return fz;
}

}  // namespace

TEST(SolverPatch, QuadraticTetrahedraDoNotLockWhereLinearOnesDo) {
  if (!have_ccx()) GTEST_SKIP() << "CalculiX (ccx) not installed: apt-get install calculix-ccx (scripts/install-deps)";
  organsmith::testing::ScratchDir dir("solver-locking");
  const SolverFit fit = fit_solver_material(region_law_from_preset(builtin_material_library(), "fung-wall/table-5.1.1/mean"));
  std::map<std::string, double> f;
  for (const char* type : {"C3D4", "C3D10", "C3D20R"}) {
    fs::create_directories(dir / type);
    f[type] = block_reaction_N(fit.material, type, dir / type);
  }
  std::printf("20x20x40 mm block of the exported gallbladder wall (K/mu0 = %.0f), clamped, pulled 1 %%: axial reaction "
              "C3D4 %.4g N, C3D10 %.4g N, C3D20R %.4g N (C3D4 %+.1f %%, C3D10 %+.2f %% from the hexahedra)\n",
              fit.material.bulk_modulus_Pa / (fit.material.ogden_mu_Pa[0] + fit.material.ogden_mu_Pa[1] + fit.material.ogden_mu_Pa[2]),
              f["C3D4"], f["C3D10"], f["C3D20R"], 100 * (f["C3D4"] / f["C3D20R"] - 1), 100 * (f["C3D10"] / f["C3D20R"] - 1));
  EXPECT_GT(f["C3D20R"], 0.0);
  EXPECT_NEAR(f["C3D10"] / f["C3D20R"], 1.0, 0.02);
  EXPECT_GT(f["C3D4"] / f["C3D20R"], 1.1) << "linear tetrahedra lock in this constrained case";
}
