// Over 400 lines: the Embree scene (RAII, built once, then queried) and the contact force with
// its stress lookup, which share the scene's internals.
#include "physics/haptics/contact.h"

#include "core/errors.h"
#include "physics/materials/presets.h"

#include <Eigen/Geometry>
#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <unordered_map>

namespace organsmith::physics {

namespace {

/// Which feature of a triangle the closest point lies on.
enum class Feature : std::uint8_t { face, edge01, edge12, edge20, vertex0, vertex1, vertex2 };

struct TrianglePoint {
  Eigen::Vector3d point;
  Feature feature = Feature::face;
};

/// Closest point of triangle (a, b, c) to p, with the feature it lies on (Voronoi regions of the
/// vertices, edges and face, tested in that order).
TrianglePoint closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                  const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {a, Feature::vertex0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {b, Feature::vertex1};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return {a + (d1 / (d1 - d3)) * ab, Feature::edge01};
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {c, Feature::vertex2};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return {a + (d2 / (d2 - d6)) * ac, Feature::edge20};
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return {b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b), Feature::edge12};
  const double denom = 1.0 / (va + vb + vc);
  if (!std::isfinite(denom)) return {a, Feature::vertex0};  // degenerate triangle
  return {a + ab * (vb * denom) + ac * (vc * denom), Feature::face};
}

struct Surface {
  SurfaceMesh mesh;
  std::vector<Eigen::Vector3d> face_normal;    ///< unit
  std::vector<Eigen::Vector3d> vertex_normal;  ///< angle-weighted pseudo-normal, unit
  std::vector<std::array<Eigen::Vector3d, 3>> edge_normal;  ///< per triangle edge 01, 12, 20
};

Surface prepare(SurfaceMesh mesh, std::size_t index) {
  const std::string which = "surface " + std::to_string(index) + " (" + std::to_string(mesh.triangles.size()) + " triangles)";
  if (mesh.triangles.empty() || mesh.vertices_lps_mm.empty())
    throw InputError(ExitCode::unsupported_input, "an organ surface for contact has no triangle", {},
                     "give the closed organ surfaces the mesh stage wrote");
  const auto nv = std::int64_t(mesh.vertices_lps_mm.size());
  for (const auto& v : mesh.vertices_lps_mm)
    if (!v.allFinite()) throw InputError(ExitCode::unsupported_input, which + " has a non-finite vertex", {});
  for (const auto& t : mesh.triangles)
    for (auto i : t)
      if (i < 0 || i >= nv) throw InputError(ExitCode::unsupported_input, which + " has a vertex index out of range", {});
  Surface s;
  s.face_normal.resize(mesh.triangles.size());
  s.vertex_normal.assign(mesh.vertices_lps_mm.size(), Eigen::Vector3d::Zero());
  s.edge_normal.resize(mesh.triangles.size());
  std::unordered_map<std::uint64_t, Eigen::Vector3d> edge_sum;
  edge_sum.reserve(mesh.triangles.size() * 2);
  auto key = [](std::int32_t a, std::int32_t b) {
    if (a > b) std::swap(a, b);
    return (std::uint64_t(std::uint32_t(a)) << 32) | std::uint32_t(b);
  };
  const auto& V = mesh.vertices_lps_mm;
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    Eigen::Vector3d n = (V[t[1]] - V[t[0]]).cross(V[t[2]] - V[t[0]]);
    const double len = n.norm();
    n = len > 0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
    s.face_normal[f] = n;
    for (int k = 0; k < 3; ++k) {
      const auto i = t[k], j = t[(k + 1) % 3], l = t[(k + 2) % 3];
      const Eigen::Vector3d e1 = (V[j] - V[i]).normalized(), e2 = (V[l] - V[i]).normalized();
      const double angle = std::acos(std::clamp(e1.dot(e2), -1.0, 1.0));
      if (std::isfinite(angle)) s.vertex_normal[std::size_t(i)] += angle * n;
      // (operator[] would leave a new Eigen vector uninitialised)
      edge_sum.try_emplace(key(i, j), Eigen::Vector3d::Zero()).first->second += n;
    }
  }
  for (auto& v : s.vertex_normal) {
    const double l = v.norm();
    if (l > 0) v /= l;
  }
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d e = edge_sum.at(key(t[k], t[(k + 1) % 3]));
      const double l = e.norm();
      s.edge_normal[f][std::size_t(k)] = l > 0 ? Eigen::Vector3d(e / l) : s.face_normal[f];
    }
  }
  s.mesh = std::move(mesh);
  return s;
}

const Eigen::Vector3d& feature_normal(const Surface& s, std::size_t f, Feature feature) {
  const auto& t = s.mesh.triangles[f];
  switch (feature) {
    case Feature::face: return s.face_normal[f];
    case Feature::edge01: return s.edge_normal[f][0];
    case Feature::edge12: return s.edge_normal[f][1];
    case Feature::edge20: return s.edge_normal[f][2];
    case Feature::vertex0: return s.vertex_normal[std::size_t(t[0])];
    case Feature::vertex1: return s.vertex_normal[std::size_t(t[1])];
    case Feature::vertex2: return s.vertex_normal[std::size_t(t[2])];
  }
  return s.face_normal[f];
}

struct QueryState {
  const std::vector<Surface>* surfaces;
  Eigen::Vector3d q;
  double best_d2;
  std::int32_t surface, triangle;
  TrianglePoint tp;
};

bool point_query_callback(RTCPointQueryFunctionArguments* args) {
  auto* st = static_cast<QueryState*>(args->userPtr);
  const Surface& s = (*st->surfaces)[args->geomID];
  const auto& t = s.mesh.triangles[args->primID];
  const auto& V = s.mesh.vertices_lps_mm;
  // The distance to the triangle's plane is a lower bound of the distance to the triangle: a
  // cheap rejection of most candidates of a large query ball.
  const double plane = s.face_normal[args->primID].dot(st->q - V[std::size_t(t[0])]);
  if (plane * plane > st->best_d2) return false;
  const TrianglePoint tp = closest_on_triangle(st->q, V[std::size_t(t[0])], V[std::size_t(t[1])], V[std::size_t(t[2])]);
  const double d2 = (tp.point - st->q).squaredNorm();
  if (d2 < st->best_d2 || (d2 == st->best_d2 && (std::int32_t(args->geomID) < st->surface ||
                                                 (std::int32_t(args->geomID) == st->surface &&
                                                  std::int32_t(args->primID) < st->triangle)))) {
    st->best_d2 = d2;
    st->surface = std::int32_t(args->geomID);
    st->triangle = std::int32_t(args->primID);
    st->tp = tp;
    // Shrink the search ball (rounded up so that float rounding never drops an equal candidate).
    const float r = std::nextafter(float(std::sqrt(d2)), std::numeric_limits<float>::infinity());
    if (r < args->query->radius) {
      args->query->radius = r;
      return true;
    }
  }
  return false;
}

ClosestPoint finish(const std::vector<Surface>& surfaces, const QueryState& st) {
  ClosestPoint c;
  if (st.surface < 0) return c;
  const Surface& s = surfaces[std::size_t(st.surface)];
  c.found = true;
  c.surface = st.surface;
  c.triangle = st.triangle;
  c.point_lps_mm = st.tp.point;
  const Eigen::Vector3d& n = feature_normal(s, std::size_t(st.triangle), st.tp.feature);
  c.outward_normal = n;
  const double d = std::sqrt(st.best_d2);
  // Bærentzen–Aanæs: the sign of (q − c) · pseudo-normal of the closest feature is the side.
  c.signed_distance_mm = (st.q - st.tp.point).dot(n) < 0.0 ? -d : d;
  return c;
}

}  // namespace

struct SurfaceIndex::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::vector<Surface> surfaces;
  std::size_t triangles = 0;
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

SurfaceIndex::SurfaceIndex(std::vector<SurfaceMesh> meshes) : impl_(std::make_unique<Impl>()) {
  if (meshes.empty())
    throw InputError(ExitCode::unsupported_input, "no organ surface to find contacts with", {},
                     "give at least one closed organ surface");
  for (std::size_t i = 0; i < meshes.size(); ++i) {
    impl_->surfaces.push_back(prepare(std::move(meshes[i]), i));
    impl_->triangles += impl_->surfaces.back().mesh.triangles.size();
  }
  impl_->device = rtcNewDevice(nullptr);
  if (!impl_->device) throw Error(ExitCode::internal, "cannot initialise Embree (rtcNewDevice failed)");
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
  for (std::size_t i = 0; i < impl_->surfaces.size(); ++i) {
    const SurfaceMesh& m = impl_->surfaces[i].mesh;
    RTCGeometry g = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                          3 * sizeof(float), m.vertices_lps_mm.size()));
    auto* t = static_cast<unsigned*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                             3 * sizeof(unsigned), m.triangles.size()));
    if (!v || !t) {
      rtcReleaseGeometry(g);
      throw Error(ExitCode::internal, "Embree could not allocate geometry buffers");
    }
    for (std::size_t k = 0; k < m.vertices_lps_mm.size(); ++k)
      for (int c = 0; c < 3; ++c) v[3 * k + std::size_t(c)] = float(m.vertices_lps_mm[k][c]);
    for (std::size_t k = 0; k < m.triangles.size(); ++k)
      for (int c = 0; c < 3; ++c) t[3 * k + std::size_t(c)] = unsigned(m.triangles[k][std::size_t(c)]);
    rtcCommitGeometry(g);
    const unsigned id = rtcAttachGeometry(impl_->scene, g);
    rtcReleaseGeometry(g);
    if (id != i) throw Error(ExitCode::internal, "Embree geometry ids are not sequential");
  }
  rtcCommitScene(impl_->scene);
  if (rtcGetDeviceError(impl_->device) != RTC_ERROR_NONE)
    throw Error(ExitCode::internal, "Embree could not build the contact scene");
}

SurfaceIndex::~SurfaceIndex() = default;
SurfaceIndex::SurfaceIndex(SurfaceIndex&&) noexcept = default;
SurfaceIndex& SurfaceIndex::operator=(SurfaceIndex&&) noexcept = default;

std::size_t SurfaceIndex::surface_count() const { return impl_->surfaces.size(); }
const SurfaceMesh& SurfaceIndex::surface(std::size_t i) const { return impl_->surfaces.at(i).mesh; }
std::size_t SurfaceIndex::triangle_count() const { return impl_->triangles; }

ClosestPoint SurfaceIndex::closest(const Eigen::Vector3d& q, double max_distance_mm) const noexcept {
  QueryState st{&impl_->surfaces, q, std::numeric_limits<double>::infinity(), -1, -1, {}};
  if (!q.allFinite()) return {};
  if (std::isfinite(max_distance_mm)) st.best_d2 = max_distance_mm * max_distance_mm;
  RTCPointQuery query;
  query.x = float(q.x());
  query.y = float(q.y());
  query.z = float(q.z());
  query.time = 0.f;
  query.radius = std::isfinite(max_distance_mm) ? std::nextafter(float(max_distance_mm), std::numeric_limits<float>::infinity())
                                                : std::numeric_limits<float>::infinity();
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(impl_->scene, &query, &context, point_query_callback, &st);
  return finish(impl_->surfaces, st);
}

ClosestPoint SurfaceIndex::closest_brute_force(const Eigen::Vector3d& q) const noexcept {
  QueryState st{&impl_->surfaces, q, std::numeric_limits<double>::infinity(), -1, -1, {}};
  for (std::size_t s = 0; s < impl_->surfaces.size(); ++s) {
    const auto& m = impl_->surfaces[s].mesh;
    for (std::size_t f = 0; f < m.triangles.size(); ++f) {
      const auto& t = m.triangles[f];
      const auto& V = m.vertices_lps_mm;
      const TrianglePoint tp = closest_on_triangle(q, V[std::size_t(t[0])], V[std::size_t(t[1])], V[std::size_t(t[2])]);
      const double d2 = (tp.point - q).squaredNorm();
      if (d2 < st.best_d2) st.best_d2 = d2, st.surface = std::int32_t(s), st.triangle = std::int32_t(f), st.tp = tp;
    }
  }
  return finish(impl_->surfaces, st);
}

std::optional<RayHit> SurfaceIndex::first_hit(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                                              double max_t_mm) const noexcept {
  const double len = direction.norm();
  if (!(len > 0) || !origin.allFinite() || !direction.allFinite()) return std::nullopt;
  const Eigen::Vector3d d = direction / len;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh{};
  rh.ray.org_x = float(origin.x());
  rh.ray.org_y = float(origin.y());
  rh.ray.org_z = float(origin.z());
  rh.ray.dir_x = float(d.x());
  rh.ray.dir_y = float(d.y());
  rh.ray.dir_z = float(d.z());
  rh.ray.tnear = 0.f;
  rh.ray.tfar = std::isfinite(max_t_mm) ? float(max_t_mm) : std::numeric_limits<float>::infinity();
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;
  RayHit h;
  h.surface = std::int32_t(rh.hit.geomID);
  h.triangle = std::int32_t(rh.hit.primID);
  // Recompute the hit in double precision on the triangle's plane.
  const Surface& s = impl_->surfaces[rh.hit.geomID];
  const auto& t = s.mesh.triangles[rh.hit.primID];
  const auto& V = s.mesh.vertices_lps_mm;
  const Eigen::Vector3d& n = s.face_normal[rh.hit.primID];
  const double denom = n.dot(d);
  double tt = double(rh.ray.tfar);
  if (std::abs(denom) > 1e-12) tt = n.dot(V[std::size_t(t[0])] - origin) / denom;
  h.t_mm = tt;
  h.point_lps_mm = origin + tt * d;
  return h;
}

int SurfaceIndex::crossings(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                            double* first_hit_mm) const noexcept {
  int n = 0;
  Eigen::Vector3d o = origin;
  const Eigen::Vector3d d = direction.normalized();
  if (first_hit_mm) *first_hit_mm = std::numeric_limits<double>::infinity();
  for (int guard = 0; guard < 10000; ++guard) {
    const auto h = first_hit(o, d);
    if (!h) break;
    if (n == 0 && first_hit_mm) *first_hit_mm = h->t_mm;
    ++n;
    o = o + (h->t_mm + 1e-4) * d;
  }
  return n;
}

// ---- stress table --------------------------------------------------------------------------------

StressTable::StressTable(const Model& model, std::span<const double> p, double max_strain, int samples, LoadCase load) {
  if (!(max_strain > 0.0) || !std::isfinite(max_strain) || samples < 2)
    throw UsageError("stress table: max_strain must be positive and samples ≥ 2");
  max_strain_ = max_strain;
  step_ = max_strain / (samples - 1);
  inv_step_ = 1.0 / step_;
  stress_.resize(std::size_t(samples));
  for (int i = 0; i < samples; ++i) {
    const double strain = i * step_;
    const double s = i == 0 ? 0.0 : model.respond_one(LoadPoint{1.0 + strain, 1.0, load}, p);
    if (!std::isfinite(s) || s < 0.0 || (i > 0 && s < stress_[std::size_t(i - 1)]))
      throw UsageError("the law '" + std::string(model.name()) + "' is not finite, non-negative and increasing up to strain " +
                           std::to_string(strain),
                       "check the organ's material parameters, or lower the table's maximum strain");
    stress_[std::size_t(i)] = s;
  }
}

StressTable StressTable::from_material(const Material& material, const ModelOptions& options, double max_strain,
                                       int samples) {
  const auto model = make_model(material.model, options);
  const std::vector<double> p = parameter_values(*model, material.parameters);
  return StressTable(*model, p, max_strain, samples);
}

double StressTable::stress_Pa(double strain) const noexcept {
  if (stress_.empty() || !(strain > 0.0)) return 0.0;
  const std::size_t n = stress_.size();
  const double x = strain * inv_step_;
  if (x >= double(n - 1)) {
    const double slope = (stress_[n - 1] - stress_[n - 2]) * inv_step_;
    return stress_[n - 1] + slope * (strain - max_strain_);
  }
  const auto i = std::size_t(x);
  const double f = x - double(i);
  return stress_[i] + f * (stress_[i + 1] - stress_[i]);
}

// ---- contact -------------------------------------------------------------------------------------

void validate(const ContactOptions& o) {
  if (!(o.tool_radius_mm > 0) || !std::isfinite(o.tool_radius_mm))
    throw UsageError("the tool radius must be positive (mm)");
  if (!(o.reference_length_mm > 0) || !std::isfinite(o.reference_length_mm))
    throw UsageError("the strain reference length must be positive (mm)");
  if (!(o.search_margin_mm >= 0) || !std::isfinite(o.search_margin_mm))
    throw UsageError("the contact search margin must be non-negative (mm)");
}

double indentation_force_N(const StressTable& table, double delta, const ContactOptions& o) noexcept {
  if (!(delta > 0.0)) return 0.0;
  const double r = o.tool_radius_mm;
  const double a2 = delta < r ? 2.0 * r * delta - delta * delta : r * r;
  const double area_mm2 = std::numbers::pi * a2;
  return table.stress_Pa(delta / o.reference_length_mm) * area_mm2 * 1e-6;
}

ContactModel::ContactModel(SurfaceIndex index, std::vector<StressTable> tables, const ContactOptions& options)
    : index_(std::move(index)), tables_(std::move(tables)), options_(options) {
  validate(options_);
  if (tables_.size() != index_.surface_count())
    throw UsageError("one stress table per contact surface is needed (" + std::to_string(index_.surface_count()) +
                     " surfaces, " + std::to_string(tables_.size()) + " tables)");
}

ContactSample ContactModel::evaluate(const Eigen::Vector3d& q) const noexcept {
  ContactSample c;
  if (!q.allFinite()) return c;
  const double r = options_.tool_radius_mm;
  // Small query balls are cheap (few triangles meet them): look within the tool radius first.
  ClosestPoint cp = index_.closest(q, r);
  if (!cp.found) {
    // Nothing within reach: either outside and out of contact, or sunk deeper than r. Parity of
    // the crossings of one ray tells which.
    double hit_mm = 0;
    if (index_.crossings(q, Eigen::Vector3d(0.5773502691896258, 0.5773502691896258, 0.5773502691896258), &hit_mm) % 2 == 0)
      return c;
    // Inside: the ray's first crossing bounds the distance to the surface, so one ball of that
    // radius holds the closest point (a wider one only if rounding lost it).
    for (double reach = std::isfinite(hit_mm) ? hit_mm * (1 + 1e-6) + 1e-4 : 2 * r + options_.search_margin_mm; !cp.found;
         reach *= 4)
      cp = index_.closest(q, reach > 1e6 ? std::numeric_limits<double>::infinity() : reach);
    cp.signed_distance_mm = -std::abs(cp.signed_distance_mm);
  }
  const double delta = r - cp.signed_distance_mm;
  if (!(delta > 0.0)) return c;
  c.contact = true;
  c.surface = cp.surface;
  c.penetration_mm = delta;
  c.point_lps_mm = cp.point_lps_mm;
  const Eigen::Vector3d v = q - cp.point_lps_mm;
  const double vl = v.norm();
  c.normal = vl > 1e-9 ? Eigen::Vector3d((cp.signed_distance_mm < 0 ? -v : v) / vl) : cp.outward_normal;
  const StressTable& table = tables_[std::size_t(cp.surface)];
  c.strain = delta / options_.reference_length_mm;
  c.stress_Pa = table.stress_Pa(c.strain);
  c.area_mm2 = std::numbers::pi * (delta < r ? 2.0 * r * delta - delta * delta : r * r);
  c.force_N = (c.stress_Pa * c.area_mm2 * 1e-6) * c.normal;
  return c;
}

// ---- display deformation -------------------------------------------------------------------------

SurfaceDeformer::SurfaceDeformer(SurfaceMesh rest, double falloff_radius_mm)
    : rest_(std::move(rest)), radius_mm_(falloff_radius_mm) {
  if (!(radius_mm_ > 0) || !std::isfinite(radius_mm_)) throw UsageError("the deformation fall-off radius must be positive (mm)");
  current_ = rest_.vertices_lps_mm;
  cell_mm_ = radius_mm_;
  if (current_.empty()) {
    dims_ = Eigen::Vector3i::Ones();
    grid_lo_.setZero();
    cell_start_.assign(2, 0);
    return;
  }
  Eigen::Vector3d lo = current_[0], hi = current_[0];
  for (const auto& v : current_) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  grid_lo_ = lo;
  for (int k = 0; k < 3; ++k) dims_[k] = std::max(1, int(std::floor((hi[k] - lo[k]) / cell_mm_)) + 1);
  const std::size_t cells = std::size_t(dims_.x()) * std::size_t(dims_.y()) * std::size_t(dims_.z());
  auto cell_of = [&](const Eigen::Vector3d& v) {
    Eigen::Vector3i c;
    for (int k = 0; k < 3; ++k) c[k] = std::clamp(int(std::floor((v[k] - grid_lo_[k]) / cell_mm_)), 0, dims_[k] - 1);
    return (std::size_t(c.z()) * std::size_t(dims_.y()) + std::size_t(c.y())) * std::size_t(dims_.x()) + std::size_t(c.x());
  };
  cell_start_.assign(cells + 1, 0);
  for (const auto& v : current_) ++cell_start_[cell_of(v) + 1];
  for (std::size_t c = 0; c < cells; ++c) cell_start_[c + 1] += cell_start_[c];
  cell_vertices_.resize(current_.size());
  std::vector<std::int32_t> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (std::size_t i = 0; i < current_.size(); ++i) cell_vertices_[std::size_t(fill[cell_of(current_[i])]++)] = std::int32_t(i);
}

const std::vector<Eigen::Vector3d>& SurfaceDeformer::update(const ContactSample& contact) {
  for (auto i : moved_) current_[std::size_t(i)] = rest_.vertices_lps_mm[std::size_t(i)];
  moved_.clear();
  if (!contact.contact || !(contact.penetration_mm > 0) || current_.empty()) return current_;
  const Eigen::Vector3d& p = contact.point_lps_mm;
  Eigen::Vector3i c;
  for (int k = 0; k < 3; ++k) c[k] = int(std::floor((p[k] - grid_lo_[k]) / cell_mm_));
  const double r2 = radius_mm_ * radius_mm_;
  for (int z = c.z() - 1; z <= c.z() + 1; ++z) {
    if (z < 0 || z >= dims_.z()) continue;
    for (int y = c.y() - 1; y <= c.y() + 1; ++y) {
      if (y < 0 || y >= dims_.y()) continue;
      for (int x = c.x() - 1; x <= c.x() + 1; ++x) {
        if (x < 0 || x >= dims_.x()) continue;
        const std::size_t cell = (std::size_t(z) * std::size_t(dims_.y()) + std::size_t(y)) * std::size_t(dims_.x()) + std::size_t(x);
        for (auto k = cell_start_[cell]; k < cell_start_[cell + 1]; ++k) {
          const auto i = std::size_t(cell_vertices_[std::size_t(k)]);
          const double d2 = (rest_.vertices_lps_mm[i] - p).squaredNorm();
          if (d2 >= r2) continue;
          const double w = (1.0 - d2 / r2) * (1.0 - d2 / r2);
          current_[i] = rest_.vertices_lps_mm[i] - contact.penetration_mm * w * contact.normal;
          moved_.push_back(std::int32_t(i));
        }
      }
    }
  }
  return current_;
}

}  // namespace organsmith::physics
