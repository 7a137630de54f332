#pragma once
// Internal to the CGAL translation units of meshing/ (mesh3_*.cpp): a Mesh_3 complex's cells
// as a core TetMesh. Includes no CGAL header itself but works on CGAL types: never include it
// from a public header.

#include "core/geometry.h"

#include <array>
#include <cstdint>
#include <unordered_map>
#include <utility>

namespace organsmith::meshing_detail {

/// The cells in the complex, vertices numbered in order of first use, each tet positively
/// oriented; region_of(cell iterator) gives its region id.
template <class C3t3, class RegionOf>
TetMesh tets_from_c3t3(const C3t3& c3t3, RegionOf region_of) {
  using Tr = typename C3t3::Triangulation;
  const Tr& tr = c3t3.triangulation();
  TetMesh out;
  std::unordered_map<typename Tr::Vertex_handle, std::int32_t> index;
  auto id = [&](typename Tr::Vertex_handle v) {
    auto [it, fresh] = index.emplace(v, std::int32_t(out.vertices_lps_mm.size()));
    if (fresh) {
      const auto p = tr.geom_traits().construct_point_3_object()(v->point());
      out.vertices_lps_mm.emplace_back(p.x(), p.y(), p.z());
    }
    return it->second;
  };
  for (auto cit = c3t3.cells_in_complex_begin(); cit != c3t3.cells_in_complex_end(); ++cit) {
    std::array<std::int32_t, 4> t{id(cit->vertex(0)), id(cit->vertex(1)), id(cit->vertex(2)), id(cit->vertex(3))};
    const auto& p = out.vertices_lps_mm;
    if ((p[t[1]] - p[t[0]]).dot((p[t[2]] - p[t[0]]).cross(p[t[3]] - p[t[0]])) < 0) std::swap(t[2], t[3]);
    out.tets.push_back(t);
    out.region_ids.push_back(std::int32_t(region_of(cit)));
  }
  return out;
}

}  // namespace organsmith::meshing_detail
