// Material patch tests in CalculiX: a unit cube of each exported material (the INP writer's own
// *MATERIAL block, quadratic tetrahedra), stretched uniaxially and equibiaxially to the top of the
// law's calibrated range. The solver's nominal stress is compared with the calibrated law at ten
// stretches. Needs Debian's calculix-ccx (scripts/install-deps); skipped with a message without it.

#include "meshing/export.h"
#include "physics/materials/solver_fit.h"
#include "pipeline/organ_registry.h"

#include "test_support.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
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
  EXPECT_EQ(presets, 13);
}
