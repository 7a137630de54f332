// Local repair of the tetrahedra Mesh_3 leaves below the quality gate (see tet_improve.h).

#include "meshing/tet_improve.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <vector>

namespace organsmith::meshing_detail {
namespace {

/// Gate score of one tet: ≥ 1 passes; ≤ 0 inverted or flat.
double score(const Eigen::Vector3d p[4], double min_dih, double max_re) {
  const Eigen::Vector3d a = p[1] - p[0], b = p[2] - p[0], c = p[3] - p[0];
  const double vol = a.dot(b.cross(c)) / 6.0;
  double lmin = 1e300, lmax = 0;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) {
      const double l = (p[i] - p[j]).norm();
      lmin = std::min(lmin, l);
      lmax = std::max(lmax, l);
    }
  if (vol <= 1e-12 * lmax * lmax * lmax) return -1.0;
  static const int faces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  Eigen::Vector3d n[4];
  for (int f = 0; f < 4; ++f) n[f] = (p[faces[f][1]] - p[faces[f][0]]).cross(p[faces[f][2]] - p[faces[f][0]]).normalized();
  double dmin = 180;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j)
      dmin = std::min(dmin, 180.0 - std::acos(std::clamp(n[i].dot(n[j]), -1.0, 1.0)) * 180.0 / M_PI);
  const Eigen::Vector3d num = a.squaredNorm() * b.cross(c) + b.squaredNorm() * c.cross(a) + c.squaredNorm() * a.cross(b);
  const double re = num.norm() / (12.0 * vol) / lmin;
  return std::min(dmin / min_dih, max_re / re);
}

double tet_score(const TetMesh& m, std::size_t t, double min_dih, double max_re) {
  const auto& T = m.tets[t];
  const Eigen::Vector3d p[4] = {m.vertices_lps_mm[T[0]], m.vertices_lps_mm[T[1]], m.vertices_lps_mm[T[2]],
                                m.vertices_lps_mm[T[3]]};
  return score(p, min_dih, max_re);
}

using Face = std::array<std::int32_t, 3>;
Face key(std::int32_t a, std::int32_t b, std::int32_t c) {
  Face f{a, b, c};
  std::sort(f.begin(), f.end());
  return f;
}
const int kFaces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};

}  // namespace

TetImproveStats improve_tets(TetMesh& m, double min_dih, double max_re) {
  TetImproveStats stats;
  const std::size_t nv = m.vertices_lps_mm.size();

  // Vertices that must not move: on the boundary or on an interface between regions.
  std::map<Face, std::vector<std::size_t>> face_tets;
  for (std::size_t t = 0; t < m.tets.size(); ++t)
    for (const auto& f : kFaces) face_tets[key(m.tets[t][f[0]], m.tets[t][f[1]], m.tets[t][f[2]])].push_back(t);
  std::vector<char> fixed(nv, 0);
  for (const auto& [f, ts] : face_tets)
    if (ts.size() == 1 || (ts.size() == 2 && m.region_ids[ts[0]] != m.region_ids[ts[1]]))
      for (auto v : f) fixed[v] = 1;
  std::vector<std::vector<std::size_t>> star(nv);
  for (std::size_t t = 0; t < m.tets.size(); ++t)
    for (auto v : m.tets[t]) star[v].push_back(t);

  auto star_score = [&](std::int32_t v) {
    double s = 1e300;
    for (auto t : star[v]) s = std::min(s, tet_score(m, t, min_dih, max_re));
    return s;
  };

  for (int pass = 0; pass < 6; ++pass) {
    std::vector<std::int32_t> candidates;
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      if (tet_score(m, t, min_dih, max_re) < 1.0)
        for (auto v : m.tets[t])
          if (!fixed[v]) candidates.push_back(v);
    std::sort(candidates.begin(), candidates.end());
    candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
    if (candidates.empty()) break;
    int moved = 0;
    for (auto v : candidates) {
      Eigen::Vector3d& p = m.vertices_lps_mm[v];
      const Eigen::Vector3d start = p;
      double best = star_score(v);
      Eigen::Vector3d best_p = p;
      // Star centroid (Laplacian) and partial steps towards it.
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
      double mean_edge = 0;
      int count = 0;
      for (auto t : star[v])
        for (auto w : m.tets[t])
          if (w != v) {
            centroid += m.vertices_lps_mm[w];
            mean_edge += (m.vertices_lps_mm[w] - start).norm();
            ++count;
          }
      centroid /= count;
      mean_edge /= count;
      std::vector<Eigen::Vector3d> tries;
      for (double s : {1.0, 0.5, 0.25}) tries.push_back(start + s * (centroid - start));
      for (double step : {0.15, 0.05})
        for (int a = 0; a < 3; ++a)
          for (int sgn : {-1, 1}) {
            Eigen::Vector3d q = start;
            q[a] += sgn * step * mean_edge;
            tries.push_back(q);
          }
      for (const auto& q : tries) {
        p = q;
        const double s = star_score(v);
        if (s > best + 1e-9) best = s, best_p = q;
      }
      p = best_p;
      if (best_p != start) ++moved;
    }
    stats.moved_vertices += moved;
    if (moved == 0) break;
  }

  // Peel failing tets lying on the outer boundary with two or more of their faces.
  for (int pass = 0; pass < 3; ++pass) {
    std::map<Face, int> count;
    for (const auto& T : m.tets)
      for (const auto& f : kFaces) ++count[key(T[f[0]], T[f[1]], T[f[2]])];
    std::vector<char> drop(m.tets.size(), 0);
    int peeled = 0;
    for (std::size_t t = 0; t < m.tets.size(); ++t) {
      if (tet_score(m, t, min_dih, max_re) >= 1.0) continue;
      int boundary = 0;
      for (const auto& f : kFaces) boundary += count[key(m.tets[t][f[0]], m.tets[t][f[1]], m.tets[t][f[2]])] == 1;
      if (boundary >= 2) drop[t] = 1, ++peeled;
    }
    if (peeled == 0) break;
    std::vector<std::array<std::int32_t, 4>> tets;
    std::vector<std::int32_t> regions;
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      if (!drop[t]) tets.push_back(m.tets[t]), regions.push_back(m.region_ids[t]);
    m.tets.swap(tets);
    m.region_ids.swap(regions);
    stats.peeled_tets += peeled;
  }

  // Drop vertices no tet uses any more.
  std::vector<std::int32_t> remap(nv, -1);
  std::vector<Eigen::Vector3d> vertices;
  for (auto& T : m.tets)
    for (auto& v : T) {
      if (remap[v] < 0) {
        remap[v] = std::int32_t(vertices.size());
        vertices.push_back(m.vertices_lps_mm[v]);
      }
      v = remap[v];
    }
  m.vertices_lps_mm.swap(vertices);
  return stats;
}

}  // namespace organsmith::meshing_detail
