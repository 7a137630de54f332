#pragma once
// Synthetic closed surfaces for the haptics tests and benchmark.

#include "core/geometry.h"

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <utility>
#include <vector>

namespace organsmith::physics::testing {

/// The unit sphere as an icosahedron subdivided `subdivisions` times (20·4^s triangles),
/// triangles counter-clockwise seen from outside.
inline SurfaceMesh unit_icosphere(int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  SurfaceMesh m;
  for (auto v : std::vector<Eigen::Vector3d>{{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                             {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}})
    m.vertices_lps_mm.push_back(v.normalized());
  m.triangles = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                 {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
                 {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.vertices_lps_mm.push_back((m.vertices_lps_mm[std::size_t(a)] + m.vertices_lps_mm[std::size_t(b)]).normalized());
      return mid[key] = int(m.vertices_lps_mm.size()) - 1;
    };
    std::vector<std::array<std::int32_t, 3>> tris;
    for (const auto& tr : m.triangles) {
      const int a = midpoint(tr[0], tr[1]), b = midpoint(tr[1], tr[2]), c = midpoint(tr[2], tr[0]);
      tris.push_back({tr[0], a, c});
      tris.push_back({tr[1], b, a});
      tris.push_back({tr[2], c, b});
      tris.push_back({a, b, c});
    }
    m.triangles = tris;
  }
  return m;
}

}  // namespace organsmith::physics::testing
