// CGAL Mesh_3 inside a closed triangle surface with protected sharp features: the tetrahedra
// of the trachea wall, whose flat end caps meet the tube in sharp rims that an implicit domain
// would round off. The second heavy CGAL translation unit.

#include "meshing/c3t3_to_tets.h"
#include "meshing/detail.h"
#include "meshing/mesh.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/Polyhedral_mesh_domain_with_features_3.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/boost/graph/helpers.h>
#include <CGAL/make_mesh_3.h>
#include <CGAL/refine_mesh_3.h>
#include <CGAL/Mesh_3/C3T3_helpers.h>
#include <CGAL/Mesh_3/Protect_edges_sizing_field.h>

#include <stdexcept>

namespace organsmith::meshing_detail {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using Domain = CGAL::Polyhedral_mesh_domain_with_features_3<K, Mesh>;
using Tr = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, CGAL::Sequential_tag>::type;
using C3t3 = CGAL::Mesh_complex_3_in_triangulation_3<Tr, Domain::Corner_index, Domain::Curve_index>;
using Criteria = CGAL::Mesh_criteria_3<Tr>;

/// Smallest protecting ball, as a fraction of the feature edge size.
constexpr double kSmallestBallFraction = 0.1;

}  // namespace

TetMesh mesh3_tets_polyhedral(const SurfaceMesh& closed, std::int32_t region, double feature_angle_deg,
                              const Mesh3Criteria& c) {
  namespace params = CGAL::parameters;
  Mesh mesh;
  std::vector<Mesh::Vertex_index> vs;
  vs.reserve(closed.vertices_lps_mm.size());
  for (const auto& p : closed.vertices_lps_mm) vs.push_back(mesh.add_vertex(Point(p.x(), p.y(), p.z())));
  for (const auto& t : closed.triangles)
    if (mesh.add_face(vs[t[0]], vs[t[1]], vs[t[2]]) == Mesh::null_face())
      throw MeshInputError("tetrahedral meshing: the surface is not a manifold triangle mesh",
      "check the label map (a mask a few voxels thin cannot be closed), or try another edge length (--edge-mm, [stages.mesh] edge_mm)");

  // Feature detection walks every vertex's fan: a surface with a border (a wall that did not
  // close) would send it off the mesh.
  if (!CGAL::is_closed(mesh))
    throw MeshInputError("tetrahedral meshing: the surface is not closed",
                         "check the label map (a mask a few voxels thin cannot be closed), or try another edge length "
                         "(--edge-mm, [stages.mesh] edge_mm)");
  CGAL::get_default_random() = CGAL::Random(0);
  Domain domain(mesh);
  domain.detect_features(feature_angle_deg);
  const double edge = c.edge_size_mm > 0 ? c.edge_size_mm : c.facet_size_mm;
  Criteria criteria(params::edge_size = edge, params::facet_angle = c.facet_angle_deg,
                    params::facet_size = c.facet_size_mm, params::facet_distance = c.facet_distance_mm,
                    params::cell_radius_edge_ratio = c.cell_radius_edge, params::cell_size = c.cell_size_mm);
  // make_mesh_3 protects the features with balls that may shrink without bound: where two
  // feature curves run close (rims of a coarsely sampled thin wall) the shrinking ran for over
  // 15 minutes or crashed inside the triangulation (bus error; a 10 mm edge on the 128 phantom's
  // trachea wall, Simulate.MaterialBandBracketsTheOrgansAnswer's 1.25× edge remedy). The
  // same steps are run here with a smallest ball radius: a ball that would shrink below it stays
  // at it (CGAL then accepts it touching its neighbours), and refinement continues.
  C3t3 c3t3;
  {
    using EdgeCriteria = Criteria::Edge_criteria;
    using Sizing = CGAL::Mesh_3::internal::Edge_criteria_sizing_field_wrapper<EdgeCriteria>;
    CGAL::Mesh_3::Protect_edges_sizing_field<C3t3, Domain, Sizing> protect(
        c3t3, domain, Sizing(criteria.edge_criteria_object()), kSmallestBallFraction * edge);
    protect(true);
    bool need_more = c3t3.triangulation().dimension() != 3;
    if (!need_more) {
      CGAL::Mesh_3::C3T3_helpers<C3t3, Domain> helper(c3t3, domain);
      helper.update_restricted_facets();
      need_more = c3t3.number_of_facets() == 0;
    }
    if (need_more) CGAL::Mesh_3::internal::init_c3t3(c3t3, domain, criteria, -1);
  }
  CGAL::refine_mesh_3(c3t3, domain, criteria, params::no_perturb(), params::no_exude(), params::no_reset_c3t3());
  if (c.odt_seconds > 0) CGAL::odt_optimize_mesh_3(c3t3, domain, params::time_limit = c.odt_seconds);
  if (c.perturb_bound_deg > 0)
    CGAL::perturb_mesh_3(c3t3, domain, params::time_limit = c.optimiser_seconds, params::sliver_bound = c.perturb_bound_deg);
  if (c.exude_bound_deg > 0)
    CGAL::exude_mesh_3(c3t3, params::time_limit = c.optimiser_seconds, params::sliver_bound = c.exude_bound_deg);

  return tets_from_c3t3(c3t3, [region](auto) { return region; });
}

}  // namespace organsmith::meshing_detail
