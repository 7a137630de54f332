// CGAL Mesh_3 on a labeling function (the smoothed organ field): surface sampling and
// multi-region tetrahedra. This is one of the two heavy CGAL translation units; keep Mesh_3
// instantiations here and in mesh3_polyhedral.cpp only.

#include "meshing/c3t3_to_tets.h"
#include "meshing/detail.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Labeled_mesh_domain_3.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_error_code.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/make_mesh_3.h>

#include <unordered_map>

namespace organsmith::meshing_detail {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
using BaseDomain = CGAL::Labeled_mesh_domain_3<K>;

/// The labeled domain, but seeded from segments known to cross the surface. CGAL's default
/// seeding shoots rays from the centre of the bounding sphere and loops forever when that
/// centre and the sphere lie in the same subdomain (a tube wall, a bent gallbladder); seeding
/// from the field's own sign changes also reaches every component.
class SeededDomain : public BaseDomain {
 public:
  SeededDomain(const LabelFunction& f, const CGAL::Bbox_3& bbox, double error_bound, CGAL::Random* rng,
               std::vector<std::pair<Point, Point>> seeds)
      : BaseDomain([f](const Point& p) { return int(f(Eigen::Vector3d(p.x(), p.y(), p.z()))); }, bbox,
                   error_bound, CGAL::Null_subdomain_index(), rng),
        seeds_(std::move(seeds)) {}

  struct Construct_initial_points {
    const SeededDomain& d;
    template <class OutputIterator>
    OutputIterator operator()(OutputIterator pts, const int n = 12) const {
      int produced = 0;
      for (const auto& [a, b] : d.seeds_) {
        const K::Segment_3 s(a, b);
        const auto patch = d.do_intersect_surface_object()(s);
        if (!patch) continue;
        const Point p = std::get<0>(d.construct_intersection_object()(s));
        *pts++ = std::make_pair(p, d.index_from_surface_patch_index(*patch));
        ++produced;
      }
      // Fall back on CGAL's own seeding only when no seed crossed the surface.
      if (produced == 0) return BaseDomain::Construct_initial_points(d)(pts, n);
      return pts;
    }
  };
  Construct_initial_points construct_initial_points_object() const { return {*this}; }

 private:
  std::vector<std::pair<Point, Point>> seeds_;
};

using Concurrency = CGAL::Sequential_tag;  // deterministic; organs run in parallel instead
using Tr = CGAL::Mesh_triangulation_3<SeededDomain, CGAL::Default, Concurrency>::type;
using C3t3 = CGAL::Mesh_complex_3_in_triangulation_3<Tr>;
using Criteria = CGAL::Mesh_criteria_3<Tr>;

/// Seeds: pairs of lattice points (spacing ≈ facet size) whose labels differ.
std::vector<std::pair<Point, Point>> find_seeds(const LabelFunction& f, const Box& box, double step) {
  std::vector<std::pair<Point, Point>> seeds;
  const Eigen::Vector3d ext = box.hi - box.lo;
  std::array<int, 3> n{};
  for (int a = 0; a < 3; ++a) n[a] = std::max(2, int(std::ceil(ext[a] / step)) + 1);
  auto at = [&](int i, int j, int k) {
    return Eigen::Vector3d(box.lo.x() + ext.x() * i / (n[0] - 1), box.lo.y() + ext.y() * j / (n[1] - 1),
                           box.lo.z() + ext.z() * k / (n[2] - 1));
  };
  std::vector<int> lab(std::size_t(n[0]) * n[1] * n[2]);
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i) lab[i + n[0] * (j + std::size_t(n[1]) * k)] = f(at(i, j, k));
  auto P = [](const Eigen::Vector3d& v) { return Point(v.x(), v.y(), v.z()); };
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      for (int i = 0; i < n[0]; ++i) {
        const int l = lab[i + n[0] * (j + std::size_t(n[1]) * k)];
        if (i + 1 < n[0] && lab[i + 1 + n[0] * (j + std::size_t(n[1]) * k)] != l)
          seeds.emplace_back(P(at(i, j, k)), P(at(i + 1, j, k)));
        if (j + 1 < n[1] && lab[i + n[0] * (j + 1 + std::size_t(n[1]) * k)] != l)
          seeds.emplace_back(P(at(i, j, k)), P(at(i, j + 1, k)));
        if (k + 1 < n[2] && lab[i + n[0] * (j + std::size_t(n[1]) * (k + 1))] != l)
          seeds.emplace_back(P(at(i, j, k)), P(at(i, j, k + 1)));
      }
  // Enough seeds to touch every component; too many slows the start of refinement.
  const std::size_t keep = 400;
  if (seeds.size() > keep) {
    std::vector<std::pair<Point, Point>> thinned;
    const double stride = double(seeds.size()) / keep;
    for (std::size_t s = 0; s < keep; ++s) thinned.push_back(seeds[std::size_t(s * stride)]);
    seeds.swap(thinned);
  }
  return seeds;
}

/// The optimisers run one after another in CGAL's recommended order (ODT, perturb, exude), each
/// only when asked for.
template <class C3T3, class Domain>
void optimise(C3T3& c3t3, const Domain& domain, const Mesh3Criteria& c) {
  namespace params = CGAL::parameters;
  if (c.odt_seconds > 0)
    CGAL::odt_optimize_mesh_3(c3t3, domain, params::time_limit = c.odt_seconds);
  if (c.perturb_bound_deg > 0)
    CGAL::perturb_mesh_3(c3t3, domain, params::time_limit = c.optimiser_seconds,
                         params::sliver_bound = c.perturb_bound_deg);
  if (c.exude_bound_deg > 0)
    CGAL::exude_mesh_3(c3t3, params::time_limit = c.optimiser_seconds, params::sliver_bound = c.exude_bound_deg);
}

C3t3 run_mesh3(const LabelFunction& f, const Box& box, const Mesh3Criteria& c, bool cells) {
  namespace params = CGAL::parameters;
  // Mesh_3 draws from CGAL's default random generator (thread-local); resetting it makes
  // each run reproduce byte for byte.
  CGAL::get_default_random() = CGAL::Random(0);
  CGAL::Random rng(0);
  const CGAL::Bbox_3 bbox(box.lo.x(), box.lo.y(), box.lo.z(), box.hi.x(), box.hi.y(), box.hi.z());
  const double diag = (box.hi - box.lo).norm();
  SeededDomain domain(f, bbox, 1e-6, &rng, find_seeds(f, box, std::max(0.5 * c.facet_size_mm, 0.25)));
  CGAL::Mesh_error_code error = CGAL::CGAL_MESH_3_NO_ERROR;
  auto throw_budget = [&] {
    throw MeshBudgetExceeded("refinement passed " + std::to_string(c.max_vertices) + " vertices (facet distance " +
                             std::to_string(c.facet_distance_mm) + " mm)");
  };
  if (cells) {
    Criteria criteria(params::facet_angle = c.facet_angle_deg, params::facet_size = c.facet_size_mm,
                      params::facet_distance = c.facet_distance_mm,
                      params::facet_topology = CGAL::FACET_VERTICES_ON_SAME_SURFACE_PATCH,
                      params::cell_radius_edge_ratio = c.cell_radius_edge, params::cell_size = c.cell_size_mm);
    C3t3 c3t3 = CGAL::make_mesh_3<C3t3>(
        domain, criteria, params::no_perturb(), params::no_exude(),
        params::mesh_3_options(params::maximal_number_of_vertices = c.max_vertices,
                               params::pointer_to_error_code = &error));
    if (error == CGAL::CGAL_MESH_3_MAXIMAL_NUMBER_OF_VERTICES_REACHED) throw_budget();
    optimise(c3t3, domain, c);
    return c3t3;
  }
  (void)diag;
  Criteria criteria(params::facet_angle = c.facet_angle_deg, params::facet_size = c.facet_size_mm,
                    params::facet_distance = c.facet_distance_mm,
                    params::facet_topology = CGAL::FACET_VERTICES_ON_SAME_SURFACE_PATCH);
  C3t3 c3t3 = CGAL::make_mesh_3<C3t3>(domain, criteria, params::no_perturb(), params::no_exude(), params::manifold(),
                                      params::mesh_3_options(params::maximal_number_of_vertices = c.max_vertices,
                                                             params::pointer_to_error_code = &error));
  if (error == CGAL::CGAL_MESH_3_MAXIMAL_NUMBER_OF_VERTICES_REACHED) throw_budget();
  return c3t3;
}

Eigen::Vector3d to_eigen(const Tr& tr, const Tr::Vertex_handle v) {
  const Point p = tr.geom_traits().construct_point_3_object()(v->point());
  return {p.x(), p.y(), p.z()};
}

}  // namespace

SurfaceMesh mesh3_surface(const LabelFunction& f, const Box& box, const Mesh3Criteria& c) {
  const C3t3 c3t3 = run_mesh3(f, box, c, false);
  const Tr& tr = c3t3.triangulation();
  SurfaceMesh out;
  std::unordered_map<Tr::Vertex_handle, std::int32_t> index;
  auto id = [&](Tr::Vertex_handle v) {
    auto [it, fresh] = index.emplace(v, std::int32_t(out.vertices_lps_mm.size()));
    if (fresh) out.vertices_lps_mm.push_back(to_eigen(tr, v));
    return it->second;
  };
  for (auto fit = c3t3.facets_in_complex_begin(); fit != c3t3.facets_in_complex_end(); ++fit) {
    Tr::Cell_handle cell = fit->first;
    int i = fit->second;
    // Orient from the inside cell: the facet normal must point away from the opposite vertex.
    if (!c3t3.is_in_complex(cell)) {
      const Tr::Cell_handle other = cell->neighbor(i);
      i = other->index(cell);
      cell = other;
    }
    std::array<Tr::Vertex_handle, 3> v;
    for (int m = 0; m < 3; ++m) v[m] = cell->vertex(Tr::vertex_triple_index(i, m));
    std::array<std::int32_t, 3> t{id(v[0]), id(v[1]), id(v[2])};
    const Eigen::Vector3d a = out.vertices_lps_mm[t[0]], b = out.vertices_lps_mm[t[1]], d = out.vertices_lps_mm[t[2]];
    const Eigen::Vector3d opposite = to_eigen(tr, cell->vertex(i));
    if ((b - a).cross(d - a).dot(opposite - a) > 0) std::swap(t[1], t[2]);
    out.triangles.push_back(t);
  }
  return out;
}

TetMesh mesh3_tets_implicit(const LabelFunction& f, const Box& box, const Mesh3Criteria& c) {
  const C3t3 c3t3 = run_mesh3(f, box, c, true);
  return tets_from_c3t3(c3t3, [&](auto cell) { return c3t3.subdomain_index(cell); });
}

}  // namespace organsmith::meshing_detail
