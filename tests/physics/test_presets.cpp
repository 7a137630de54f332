// The embedded thesis parameter sets: complete, consistent with the models, and with their source.

#include "core/errors.h"
#include "physics/materials/presets.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

using namespace organsmith::physics;

TEST(PhysicsPresets, EveryPresetMatchesItsModel) {
  const auto lib = builtin_material_library();
  ASSERT_GE(lib.materials.size(), 10u);
  std::set<std::string> ids;
  for (const auto& p : lib.materials) {
    EXPECT_TRUE(ids.insert(p.id).second) << "duplicate id " << p.id;
    EXPECT_FALSE(p.material.source.empty()) << p.id;
    const auto m = make_model(p.material.model, model_options_for(p));
    const auto v = parameter_values(*m, p.material.parameters);
    EXPECT_EQ(p.material.parameters.size(), m->parameter_count()) << p.id;
    for (const auto& q : p.material.parameters) {
      bool found = false;
      for (const auto& info : m->parameters())
        if (info.name == q.name) {
          found = true;
          EXPECT_EQ(q.unit, info.unit) << p.id << " " << q.name;
        }
      EXPECT_TRUE(found) << p.id << " has unknown parameter " << q.name;
    }
    for (const auto& [kind, s] : p.spreads) EXPECT_EQ(parameter_values(*m, s).size(), v.size()) << p.id << " " << kind;
  }
}

TEST(PhysicsPresets, CitesEveryTableTheIssueNames) {
  const auto lib = builtin_material_library();
  for (const char* table : {"Table 4.1.1", "Table 4.1.4", "Table 4.1.5", "Table 5.1.1", "Table 5.1.2", "Table 4.2.2"}) {
    bool found = false;
    for (const auto& p : lib.materials) found = found || p.material.source.find(table) != std::string::npos;
    EXPECT_TRUE(found) << table;
  }
  EXPECT_EQ(lib.derivative_tables.size(), 2u);
  EXPECT_DOUBLE_EQ(lib.find("fung-organ/table-5.1.2/mean").constants.at("bulk_modulus_Pa"), 39000.0);
  // Every region's preset exists: checked where regions are assigned (the organ registry,
  // tests/pipeline/test_organ_registry.cpp).
}

// The printed means of Tables 5.1.1 and 5.1.2 are the averages of their five specimen rows
// (to the printed rounding) — a check that the rows were transcribed correctly.
TEST(PhysicsPresets, SpecimenRowsAverageToPrintedMeans) {
  const auto lib = builtin_material_library();
  for (const char* base : {"fung-wall/table-5.1.1", "fung-organ/table-5.1.2"}) {
    const auto& mean = lib.find(std::string(base) + "/mean");
    for (const auto& q : mean.material.parameters) {
      double s = 0;
      for (int k = 1; k <= 5; ++k) s += *lib.find(std::string(base) + "/specimen-" + std::to_string(k)).material.parameter(q.name);
      EXPECT_NEAR(s / 5, q.value, 0.011) << base << " " << q.name;
    }
  }
}

TEST(PhysicsPresets, MalformedLibraryIsACaseFileError) {
  EXPECT_THROW(parse_material_library("[[material]]\nid = 3\n", "bad.toml"), organsmith::CaseFileError);
  EXPECT_THROW(parse_material_library("[[material", "bad.toml"), organsmith::CaseFileError);
  EXPECT_THROW(builtin_material_library().find("nope"), organsmith::UsageError);
}
