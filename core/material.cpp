#include "core/material.h"

namespace organsmith {

std::optional<double> Material::parameter(const std::string& name) const {
  for (const auto& p : parameters)
    if (p.name == name) return p.value;
  return std::nullopt;
}

}  // namespace organsmith
