#pragma once
// A constitutive model with its parameter values, units and provenance.

#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// One named parameter with its unit ("Pa", "1" for dimensionless, …).
struct MaterialParameter {
  std::string name;
  double value = 0.0;
  std::string unit;
};

/// A material: which model (e.g. "fung-wall", "mooney-rivlin"), its parameters, and where the
/// numbers come from (thesis table/equation, or a calibration run).
struct Material {
  std::string model;
  std::vector<MaterialParameter> parameters;
  std::string source;

  /// Value of parameter `name`, if present.
  std::optional<double> parameter(const std::string& name) const;
};

}  // namespace organsmith
