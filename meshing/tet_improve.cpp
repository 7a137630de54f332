// Local repair of the tetrahedra Mesh_3 leaves below the quality gate (see tet_improve.h).

#include "meshing/tet_improve.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
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

double signed_volume(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                     const Eigen::Vector3d& d) {
  return (b - a).dot((c - a).cross(d - a)) / 6.0;
}

using Tet = std::array<std::int32_t, 4>;

/// Every face of every tet with the tet it belongs to, sorted: copies of a face are adjacent.
std::vector<std::pair<Face, std::size_t>> sorted_faces(const TetMesh& m) {
  std::vector<std::pair<Face, std::size_t>> f;
  f.reserve(4 * m.tets.size());
  for (std::size_t t = 0; t < m.tets.size(); ++t)
    for (const auto& k : kFaces) f.emplace_back(key(m.tets[t][k[0]], m.tets[t][k[1]], m.tets[t][k[2]]), t);
  std::sort(f.begin(), f.end());
  return f;
}

/// Calls `run(first, count)` for each group of equal faces in `f`.
template <class Run>
void for_each_face(const std::vector<std::pair<Face, std::size_t>>& f, Run run) {
  for (std::size_t i = 0; i < f.size();) {
    std::size_t j = i + 1;
    while (j < f.size() && f[j].first == f[i].first) ++j;
    run(i, j - i);
    i = j;
  }
}

}  // namespace

int flip_tets(TetMesh& m, double min_dih, double max_re) {
  const auto& P = m.vertices_lps_mm;
  auto vol_ok = [&](const Tet& t) {
    const Eigen::Vector3d &a = P[t[0]], &b = P[t[1]], &c = P[t[2]], &d = P[t[3]];
    double lmax = 0;
    for (const auto* x : {&a, &b, &c, &d})
      for (const auto* y : {&a, &b, &c, &d}) lmax = std::max(lmax, (*x - *y).norm());
    return signed_volume(a, b, c, d) > 1e-9 * lmax * lmax * lmax;
  };
  auto score_of = [&](const Tet& t) {
    const Eigen::Vector3d p[4] = {P[t[0]], P[t[1]], P[t[2]], P[t[3]]};
    return score(p, min_dih, max_re);
  };

  std::vector<Tet> tets = m.tets;
  std::vector<std::int32_t> regions = m.region_ids;
  std::vector<char> alive(tets.size(), 1);
  // Vertex stars (tets using each vertex); tets made by a flip are appended, dead ones stay and
  // are skipped. The tets around a face or an edge are the live tets in all of its stars.
  std::vector<std::vector<std::size_t>> star(P.size());
  for (std::size_t t = 0; t < tets.size(); ++t)
    for (auto v : tets[t]) star[v].push_back(t);
  auto add = [&](std::size_t t) {
    for (auto v : tets[t]) star[v].push_back(t);
  };
  auto around = [&](std::initializer_list<std::int32_t> verts) {
    std::vector<std::size_t> out;
    const std::int32_t first = *verts.begin();
    for (auto t : star[first]) {
      if (!alive[t]) continue;
      bool all = true;
      for (auto v : verts) all &= std::find(tets[t].begin(), tets[t].end(), v) != tets[t].end();
      if (all) out.push_back(t);
    }
    return out;
  };

  int flips = 0;
  const std::size_t n0 = tets.size();
  for (std::size_t t = 0; t < n0; ++t) {
    if (!alive[t] || score_of(tets[t]) >= 1.0) continue;
    double best_gain = 0;
    std::vector<std::size_t> best_old;
    std::vector<Tet> best_new;
    const double own = score_of(tets[t]);

    // 2-3 across each face.
    for (const auto& f : kFaces) {
      const Face k = key(tets[t][f[0]], tets[t][f[1]], tets[t][f[2]]);
      const auto pair = around({k[0], k[1], k[2]});
      if (pair.size() != 2) continue;
      const std::size_t o = pair[0] == t ? pair[1] : pair[0];
      if (regions[o] != regions[t]) continue;
      std::int32_t e = -1;
      for (auto v : tets[o])
        if (v != k[0] && v != k[1] && v != k[2]) e = v;
      const Tet& T = tets[t];
      std::vector<Tet> made;
      for (int i = 0; i < 4; ++i) {
        if (T[i] != k[0] && T[i] != k[1] && T[i] != k[2]) continue;
        Tet n = T;
        n[i] = e;  // replace one vertex of the shared face by the far vertex of the neighbour
        made.push_back(n);
      }
      if (made.size() != 3 || !std::all_of(made.begin(), made.end(), vol_ok)) continue;
      double worst_new = 1e300;
      for (const auto& n : made) worst_new = std::min(worst_new, score_of(n));
      const double gain = worst_new - std::min(own, score_of(tets[o]));
      if (gain > best_gain + 1e-9) best_gain = gain, best_old = {t, o}, best_new = made;
    }

    // 3-2 around each edge.
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) {
        const std::int32_t u = tets[t][i], v = tets[t][j];
        const auto ring = around({u, v});
        if (ring.size() != 3) continue;
        bool same_region = true;
        std::vector<std::int32_t> others;
        for (auto r : ring) {
          same_region &= regions[r] == regions[t];
          for (auto w : tets[r])
            if (w != u && w != v && std::find(others.begin(), others.end(), w) == others.end()) others.push_back(w);
        }
        // Exactly three other vertices: the ring closes around the edge (an interior edge).
        if (!same_region || others.size() != 3) continue;
        // Every face of the ring that contains the edge must be shared by two ring tets.
        bool closed = true;
        for (auto w : others) closed &= around({u, v, w}).size() == 2;
        if (!closed) continue;
        Tet a{others[0], others[1], others[2], u}, b{others[0], others[2], others[1], v};
        if (signed_volume(P[a[0]], P[a[1]], P[a[2]], P[a[3]]) < 0) std::swap(a[1], a[2]), std::swap(b[1], b[2]);
        if (!vol_ok(a) || !vol_ok(b)) continue;
        const double worst_new = std::min(score_of(a), score_of(b));
        double worst_old = 1e300;
        for (auto r : ring) worst_old = std::min(worst_old, score_of(tets[r]));
        const double gain = worst_new - worst_old;
        if (gain > best_gain + 1e-9) best_gain = gain, best_old = ring, best_new = {a, b};
      }

    if (best_new.empty()) continue;
    for (auto o : best_old) alive[o] = 0;
    for (const auto& n : best_new) {
      tets.push_back(n);
      regions.push_back(regions[t]);
      alive.push_back(1);
      add(tets.size() - 1);
    }
    ++flips;
  }

  m.tets.clear();
  m.region_ids.clear();
  for (std::size_t t = 0; t < tets.size(); ++t)
    if (alive[t]) m.tets.push_back(tets[t]), m.region_ids.push_back(regions[t]);
  return flips;
}

TetImproveStats improve_tets(TetMesh& m, double min_dih, double max_re) {
  TetImproveStats stats;
  const std::size_t nv = m.vertices_lps_mm.size();

  // Vertices on the boundary or on an interface between regions do not move freely. Where that
  // surface is smooth around the vertex (not a cap rim, not where an interface meets the
  // boundary) they may slide a little in its tangent plane: slide[v] is the unit normal there,
  // zero where the vertex stays put. The normal comes from Σ n nᵀ over the surface triangles
  // around the vertex; a second eigenvalue above 2 % of the first marks a crease or corner.
  std::vector<char> fixed(nv, 0);
  std::vector<Eigen::Vector3d> slide(nv, Eigen::Vector3d::Zero());
  {
    const auto faces = sorted_faces(m);
    std::vector<Eigen::Matrix3d> nn(nv, Eigen::Matrix3d::Zero());
    for_each_face(faces, [&](std::size_t i, std::size_t n) {
      if (n == 1 || (n == 2 && m.region_ids[faces[i].second] != m.region_ids[faces[i + 1].second])) {
        const auto& f = faces[i].first;
        const Eigen::Vector3d normal = (m.vertices_lps_mm[f[1]] - m.vertices_lps_mm[f[0]])
                                           .cross(m.vertices_lps_mm[f[2]] - m.vertices_lps_mm[f[0]])
                                           .normalized();
        for (auto v : f) fixed[v] = 1, nn[v] += normal * normal.transpose();
      }
    });
    for (std::size_t v = 0; v < nv; ++v) {
      if (!fixed[v]) continue;
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(nn[v]);
      const Eigen::Vector3d ev = es.eigenvalues();  // ascending
      if (ev[2] > 0 && ev[1] < 0.02 * ev[2]) slide[v] = es.eigenvectors().col(2);
    }
  }
  // Vertex relocation (the stars change after flips, so they are rebuilt each time).
  auto smooth = [&] {
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
            if (!fixed[v] || slide[v].squaredNorm() > 0) candidates.push_back(v);
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
        if (fixed[v]) {
          // Sliding on the surface: tangential, and at most a tenth of an edge (on a surface
          // curved with radius R the vertex leaves it by ≤ d²/2R, about 0.001 mm at 1.5 mm edges and
          // R = 10 mm).
          const Eigen::Vector3d n = slide[v];
          for (auto& q : tries) {
            Eigen::Vector3d d = q - start;
            d -= n * n.dot(d);
            const double limit = 0.1 * mean_edge;
            if (d.norm() > limit) d *= limit / d.norm();
            q = start + d;
          }
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
  };

  smooth();
  for (int round = 0; round < 4; ++round) {
    const int flips = flip_tets(m, min_dih, max_re);
    stats.flips += flips;
    if (flips == 0) break;
    smooth();
  }

  // Peel failing tets lying on the outer boundary with two or more of their faces.
  for (int pass = 0; pass < 3; ++pass) {
    std::vector<int> boundary(m.tets.size(), 0);
    const auto faces = sorted_faces(m);
    for_each_face(faces, [&](std::size_t i, std::size_t n) {
      if (n == 1) ++boundary[faces[i].second];
    });
    std::vector<char> drop(m.tets.size(), 0);
    int peeled = 0;
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      if (boundary[t] >= 2 && tet_score(m, t, min_dih, max_re) < 1.0) drop[t] = 1, ++peeled;
    if (peeled == 0) break;
    std::vector<std::array<std::int32_t, 4>> tets;
    std::vector<std::int32_t> regions;
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      if (!drop[t]) tets.push_back(m.tets[t]), regions.push_back(m.region_ids[t]);
    m.tets.swap(tets);
    m.region_ids.swap(regions);
    stats.peeled_tets += peeled;
  }

  // Drop vertices no tet uses any more (peeled tets can leave some), keeping the others' order.
  std::vector<char> used(nv, 0);
  for (const auto& T : m.tets)
    for (auto v : T) used[v] = 1;
  std::vector<std::int32_t> remap(nv, -1);
  std::vector<Eigen::Vector3d> vertices;
  for (std::size_t v = 0; v < nv; ++v)
    if (used[v]) remap[v] = std::int32_t(vertices.size()), vertices.push_back(m.vertices_lps_mm[v]);
  for (auto& T : m.tets)
    for (auto& v : T) v = remap[v];
  m.vertices_lps_mm.swap(vertices);
  return stats;
}

}  // namespace organsmith::meshing_detail
