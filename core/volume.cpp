#include "core/volume.h"

#include <algorithm>

namespace organsmith {

std::string label_name(std::uint8_t value) {
  switch (static_cast<Label>(value)) {
    case Label::background: return "background";
    case Label::gallbladder: return "gallbladder";
    case Label::trachea: return "trachea";
    case Label::liver: return "liver";
    case Label::lungs: return "lungs";
    case Label::body: return "body";
  }
  return "label" + std::to_string(value);
}

std::int64_t LabelMap::count(std::uint8_t value) const {
  return std::count(labels.begin(), labels.end(), value);
}

double LabelMap::volume_ml(std::uint8_t value) const {
  const double voxel_mm3 = grid.spacing_mm.prod();
  return double(count(value)) * voxel_mm3 / 1000.0;
}

}  // namespace organsmith
