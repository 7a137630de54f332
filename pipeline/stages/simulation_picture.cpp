// The simulate stage's picture (see simulation_picture.h).

#include "pipeline/stages/simulation_picture.h"

#include "core/format.h"
#include "viewer/snapshot.h"

#include <algorithm>
#include <map>
#include <set>

namespace organsmith {

namespace {

/// One off-screen picture of `scene` at the given size.
void render_png(const SnapshotScene& scene, const std::string& view, int width_px, int height_px,
                const std::filesystem::path& png) {
  SnapshotOptions so;
  so.width_px = width_px;
  so.height_px = height_px;
  SnapshotRenderer renderer(so);
  renderer.render_to_png(scene, view, png);
}

/// Corner faces of tetrahedra, keyed by their sorted nodes: how many elements share each, and its
/// outward node order (from the last element that named it; a boundary face has one).
class BoundaryFaces {
 public:
  void add(const std::array<std::int32_t, 3>& outward) {
    std::array<std::int32_t, 3> key = outward;
    std::sort(key.begin(), key.end());
    auto& slot = faces_[key];
    ++slot.first;
    slot.second = outward;
  }
  /// The faces of one element only, as `d`'s two surfaces (the same triangles); `vertex(node, x,
  /// x_deformed, value)` fills each new vertex. Then `d` is drawn into `png`.
  template <typename Vertex>
  void draw(SceneDeformation d, Vertex&& vertex, const std::filesystem::path& png, int width_px, int height_px) const {
    std::map<std::int32_t, std::int32_t> index;  // node → vertex of the drawn surface
    for (const auto& [key, f] : faces_) {
      if (f.first != 1) continue;
      std::array<std::int32_t, 3> tri{};
      for (int k = 0; k < 3; ++k) {
        const std::int32_t node = f.second[std::size_t(k)];
        auto [it, fresh] = index.emplace(node, std::int32_t(index.size()));
        if (fresh) {
          Eigen::Vector3d x, xd;
          double value = 0.0;
          vertex(node, x, xd, value);
          d.undeformed.vertices_lps_mm.push_back(x);
          d.deformed.vertices_lps_mm.push_back(xd);
          d.values.push_back(value);
        }
        tri[std::size_t(k)] = it->second;
      }
      d.undeformed.triangles.push_back(tri);
    }
    d.deformed.triangles = d.undeformed.triangles;
    const std::string view = "simulation_" + d.organ;
    SnapshotScene scene;
    scene.deformations.push_back(std::move(d));
    render_png(scene, view, width_px, height_px, png);
  }

 private:
  std::map<std::array<std::int32_t, 3>, std::pair<int, std::array<std::int32_t, 3>>> faces_;
};

}  // namespace

void draw_simulation(const Simulation& sim, const std::filesystem::path& png, int width_px, int height_px) {
  const SolverModel& m = sim.input.model;
  // The boundary of the tetrahedra: corner faces that belong to one element only, turned so that
  // their normals point out (a face's node order points into its element).
  BoundaryFaces faces;
  for (std::size_t e = 0; e < m.elements.size(); ++e)
    for (std::int32_t f = 0; f < 4; ++f) {
      const auto n = m.face_nodes(SolverFace{std::int32_t(e), f});
      faces.add({n[0], n[2], n[1]});
    }
  SceneDeformation d;
  d.organ = sim.result.organ;
  const SimulationResult& r = sim.result;
  d.value_title = "von Mises, Pa";
  // Set names without the organ and "_nodes": "trachea_cuts_nodes" → "cuts".
  auto bare = [&](std::string n) {
    if (n.rfind(d.organ + "_", 0) == 0) n = n.substr(d.organ.size() + 1);
    if (n.size() > 6 && n.compare(n.size() - 6, 6, "_nodes") == 0) n.resize(n.size() - 6);
    std::replace(n.begin(), n.end(), '_', ' ');
    return n;
  };
  if (r.indentation)
    d.detail = format_g(r.indentation->probe.diameter_mm, 3) + " mm probe pressed " + format_g(r.indentation->range_depth_mm, 3) +
               " mm, " + format_g(1e3 * r.indentation->curve.back()[1], 3) + " mN, " + bare(sim.input.fixed_node_set) +
               " fixed  |  largest displacement " + format_g(r.max_displacement_mm, 3) + " mm  |  " +
               std::to_string(r.increments) + " increments";
  else
    d.detail = format_g(sim.input.pressure_MPa * 1e3, 3) + " kPa in the " + bare(sim.input.pressure_surface) + ", " +
               bare(sim.input.fixed_node_set) + " fixed  |  largest displacement " + format_g(r.max_displacement_mm, 3) +
               " mm  |  " + std::to_string(r.increments) + " increments";
  faces.draw(
      std::move(d),
      [&](std::int32_t node, Eigen::Vector3d& x, Eigen::Vector3d& xd, double& value) {
        x = m.nodes_lps_mm[std::size_t(node)];
        const auto& u = sim.frd.displacement_mm[std::size_t(node)];
        xd = x + Eigen::Vector3d(u[0], u[1], u[2]);
        value = 1e6 * von_mises(sim.frd.stress_MPa[std::size_t(node)]);
      },
      png, width_px, height_px);
}

void draw_deformed_tets(const std::string& organ, const std::vector<Eigen::Vector3d>& X,
                        const std::vector<std::array<std::int32_t, 10>>& elements, const std::vector<double>& u,
                        const std::vector<double>& element_values, const std::string& value_title, const std::string& detail,
                        const std::filesystem::path& png, int width_px, int height_px) {
  static constexpr int kFace[4][4] = {{0, 1, 2, 3}, {0, 1, 3, 2}, {1, 2, 3, 0}, {0, 2, 3, 1}};  // three corners, the opposite one
  BoundaryFaces faces;
  std::vector<double> node_sum(X.size(), 0.0), node_n(X.size(), 0.0);
  for (std::size_t e = 0; e < elements.size(); ++e) {
    const auto& el = elements[e];
    for (const auto& f : kFace) {
      std::array<std::int32_t, 3> n{el[f[0]], el[f[1]], el[f[2]]};
      // Outward: away from the element's fourth corner.
      if ((X[n[1]] - X[n[0]]).cross(X[n[2]] - X[n[0]]).dot(X[el[f[3]]] - X[n[0]]) > 0) std::swap(n[1], n[2]);
      faces.add(n);
    }
    for (int a = 0; a < 4; ++a) node_sum[el[a]] += element_values[e], node_n[el[a]] += 1.0;
  }
  SceneDeformation d;
  d.organ = organ;
  d.value_title = value_title;
  d.detail = detail;
  faces.draw(
      std::move(d),
      [&](std::int32_t node, Eigen::Vector3d& x, Eigen::Vector3d& xd, double& value) {
        x = X[std::size_t(node)];
        xd = x + Eigen::Vector3d(u[3 * node], u[3 * node + 1], u[3 * node + 2]);
        value = node_n[node] > 0 ? node_sum[node] / node_n[node] : 0.0;
      },
      png, width_px, height_px);
}

void draw_indentation_plot(const Simulation& sim, const std::vector<std::array<double, 2>>& reference,
                           const std::string& reference_name, const std::filesystem::path& png, int width_px, int height_px) {
  const IndentationResult& ind = *sim.result.indentation;
  Plot plot;
  plot.name = "indentation_" + sim.result.organ;
  plot.title = sim.result.organ + ": force against depth under a " + format_g(ind.probe.diameter_mm, 3) + " mm probe";
  plot.x_label = "depth, mm";
  plot.y_label = "force, mN";
  plot.note = "CalculiX on the patient's mesh; the curve ends where " +
              (ind.range_region.empty() ? std::string("the step ends") : ind.range_region + " reaches its calibrated stretch");
  PlotSeries fe;
  fe.name = "finite elements (" + std::to_string(ind.curve.size() - 1) + " increments)";
  for (const auto& [d, f] : ind.curve) fe.x.push_back(d), fe.y.push_back(1e3 * f);
  plot.series.push_back(fe);
  PlotSeries marks = fe;
  marks.points = true;
  marks.in_legend = false;
  plot.series.push_back(marks);
  if (!reference.empty()) {
    PlotSeries ref;
    ref.name = reference_name;
    ref.colour = {0.8, 0.3, 0.1};
    ref.dashed = true;
    for (const auto& [d, f] : reference) ref.x.push_back(d), ref.y.push_back(1e3 * f);
    plot.series.push_back(ref);
  }
  SnapshotScene scene;
  scene.plots.push_back(std::move(plot));
  render_png(scene, "plot_indentation_" + sim.result.organ, width_px, height_px, png);
}

}  // namespace organsmith
