#include "pipeline/stages/guide_stage.h"
#include "core/file_io.h"

#include "core/errors.h"
#include "meshing/export.h"
#include "physics/haptics/contact.h"
#include "pipeline/io/image_io.h"
#include "pipeline/output/output_layout.h"
#include "viewer/mesh_files.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <memory>

namespace organsmith {

namespace fs = std::filesystem;

GuideFiles read_guide_inputs(const fs::path& out_dir, bool ras) {
  const OutputLayout layout{out_dir};
  GuideFiles f;
  fs::path labels_file = layout.labels();
  if (!fs::exists(labels_file) && fs::exists(layout.phantom_truth())) labels_file = layout.phantom_truth();
  if (!fs::exists(labels_file))
    throw InputError(ExitCode::input_not_found, "no label map in the output directory", layout.labels(),
                     "run `organsmith run` (or `organsmith segment`) into this directory first");
  f.labels = read_label_map(labels_file);
  if (fs::exists(layout.phantom_truth())) f.truth = read_label_map(layout.phantom_truth());
  f.surface = [layout, ras](const std::string& organ, const std::string& name) {
    // The .vtp holds the mesh stage's coordinates exactly (shortest round-trip decimals), as
    // the run hands them over in memory; the float32 .stl only when no .vtp was written.
    SurfaceMesh m;
    if (const fs::path vtp = layout.surface(organ, name, "vtp"); fs::exists(vtp)) {
      m = read_mesh_file(vtp).surface;
    } else if (const fs::path stl = layout.surface(organ, name, "stl"); fs::exists(stl)) {
      m = read_stl(stl);
    } else {
      throw InputError(ExitCode::input_not_found, "missing organ surface " + name + " (.vtp or .stl)", vtp,
                       "run the mesh stage (`organsmith run`, or `organsmith mesh " + layout.root.string() + "`) first");
    }
    if (ras)  // written in RAS on request: back to LPS
      for (auto& v : m.vertices_lps_mm) v = Eigen::Vector3d(-v.x(), -v.y(), v.z());
    return m;
  };
  return f;
}

namespace {

/// The label map the bed organ (the registry's `bed_organ` of `organ`) is taken from: the label
/// map's own, else the phantom's ground truth's, with the options' bed label set from the
/// registry; null when neither holds it or the organ has no bed organ.
const LabelMap* bed_labels(const GuideInputs& in, const OrganRegistry& registry, const OrganInfo& organ,
                           physics::DissectionOptions& dopt) {
  const OrganInfo* bed_info = organ.bed_organ.empty() ? nullptr : registry.find(organ.bed_organ);
  if (!bed_info) return nullptr;
  dopt.liver_label = bed_info->label;
  // The phantom's ground truth is in the same patient frame (LPS mm); its grid may differ.
  if (in.labels && in.labels->count(dopt.liver_label) > 0) return in.labels;
  if (in.truth && in.truth->count(dopt.liver_label) > 0) return in.truth;
  return nullptr;
}

}  // namespace

LiverBedForSolver liver_bed_for_solver(const SurfaceMesh& gb, const GuideInputs& in, const GuideStageOptions& options,
                                       const OrganRegistry& registry, const OrganInfo& organ) {
  physics::DissectionOptions dopt = options.dissection;
  const LabelMap* liver = bed_labels(in, registry, organ, dopt);
  const Volume* ct = !liver && dopt.bed_from_ct && in.ct ? in.ct() : nullptr;
  physics::LiverBedScore bed = physics::liver_bed_score(gb, liver, dopt, ct);
  auto index = std::make_shared<physics::SurfaceIndex>(std::vector<SurfaceMesh>{gb});
  auto score = std::make_shared<std::vector<double>>(std::move(bed.vertex_score));
  LiverBedForSolver out;
  out.source = bed.source;
  out.score = [index, score](const Eigen::Vector3d& q) {
    const physics::ClosestPoint c = index->closest(q);
    if (!c.found) return 0.0;
    const SurfaceMesh& m = index->surface(0);
    const auto& t = m.triangles[std::size_t(c.triangle)];
    const Eigen::Vector3d &a = m.vertices_lps_mm[std::size_t(t[0])], &b = m.vertices_lps_mm[std::size_t(t[1])],
                          &d = m.vertices_lps_mm[std::size_t(t[2])];
    // Barycentric weights of the closest point (on the triangle).
    const Eigen::Vector3d n = (b - a).cross(d - a);
    const double n2 = n.squaredNorm();
    if (n2 <= 0) return (*score)[std::size_t(t[0])];
    const double wb = (c.point_lps_mm - a).cross(d - a).dot(n) / n2, wd = (b - a).cross(c.point_lps_mm - a).dot(n) / n2;
    return (1 - wb - wd) * (*score)[std::size_t(t[0])] + wb * (*score)[std::size_t(t[1])] + wd * (*score)[std::size_t(t[2])];
  };
  return out;
}

GuidePaths write_guidance_paths(const GuideInputs& in, const fs::path& dest_dir, const GuideStageOptions& options,
                                const OrganRegistry& registry) {
  const std::vector<std::string> names = registry.path_names();
  for (const auto& n : options.only)
    if (std::find(names.begin(), names.end(), n) == names.end()) {
      std::string known;
      for (const auto& k : names) known += (known.empty() ? "" : ", ") + k;
      throw UsageError("unknown path '" + n + "'", "paths of the organ registry: " + known);
    }
  const LabelMap& labels = *in.labels;
  auto wanted = [&](const std::string& n, std::uint8_t label) {
    if (!options.only.empty()) return std::find(options.only.begin(), options.only.end(), n) != options.only.end();
    return labels.count(label) > 0;
  };
  fs::create_directories(dest_dir);
  GuidePaths written;
  auto emit = [&](const Polyline& line, const std::vector<std::pair<std::string, double>>& props,
                  const std::vector<std::pair<std::string, std::string>>& notes = {}) {
    const fs::path json = dest_dir / (line.name + ".json");
    const std::string text = physics::path_json(line, props, notes);
    write_file_atomic(json, text);
    write_file_atomic(dest_dir / (line.name + ".vtp"), physics::path_vtp(line));
    written.files.push_back(line.name + ".json");
    written.files.push_back(line.name + ".vtp");
    // The path as its file holds it (4 decimals), through the file's reader.
    written.paths.push_back(physics::read_path_text(text, json));
  };
  auto named = [](Polyline line, const std::string& name) {
    line.name = name;
    return line;
  };
  auto make_tube_paths = [&](const OrganInfo& tube, bool want_centerline, bool want_incision) {
    physics::CenterlineOptions co = options.centerline;
    co.label = tube.label;
    co.organ = tube.name;
    const physics::Centerline cl = physics::trachea_centerline(labels, co);
    if (want_centerline)
      emit(named(cl.line, tube.name + "_centerline"), {{"cranial_extension_mm", cl.end_extension_mm[0]},
                     {"caudal_extension_mm", cl.end_extension_mm[1]},
                     {"spacing_mm", options.centerline.spacing_mm}});
    if (want_incision) {
      const physics::SurfaceIndex wall({in.surface(tube.name, tube.wall_surface())});
      const physics::IncisionPath inc = physics::trachea_incision_path(cl, wall, options.incision);
      emit(named(inc.line, tube.name + "_incision"), {{"length_mm", inc.length_mm},
                      {"first_ring", double(inc.first_ring)},
                      {"last_ring", double(inc.last_ring)},
                      {"ring_pitch_mm", options.incision.ring_pitch_mm},
                      {"start_along_centerline_mm", inc.start_arc_mm},
                      {"end_along_centerline_mm", inc.end_arc_mm},
                      {"max_wall_distance_mm", inc.max_wall_distance_mm}});
    }
  };
  auto make_dissection = [&](const OrganInfo& organ) {
    const SurfaceMesh gb = in.surface(organ.name, organ.surfaces().front());
    physics::DissectionOptions dopt = options.dissection;
    const LabelMap* liver = bed_labels(in, registry, organ, dopt);
    const Volume* ct = nullptr;
    if (!liver && dopt.bed_from_ct && in.ct) ct = in.ct();
    const physics::DissectionPath d = physics::gallbladder_dissection_path(gb, liver, dopt, ct);
    const std::string source =
        d.bed_source + (d.bed_source == "liver label" && liver != &labels ? " of the phantom ground truth" : "");
    spdlog::info("guide: {} {} bed from the {}: {:.0f} % of its surface, rim {:.0f} mm turning {:.0f}° "
                 "(at most {:.1f}°/mm)",
                 organ.name, organ.bed_organ.empty() ? "its" : organ.bed_organ, source, 100.0 * d.covered_fraction, d.length_mm, d.total_turning_deg, d.max_turn_deg_per_mm);
    std::vector<std::pair<std::string, double>> props = {
        {"bed_area_mm2", d.bed_area_mm2},
        {"covered_fraction", d.covered_fraction},
        {"bed_from_liver_label", d.bed_source == "liver label" ? 1.0 : 0.0},
        {"bed_from_ct", d.bed_source == "CT intensity" ? 1.0 : 0.0},
        {"max_surface_distance_mm", d.max_surface_distance_mm},
        {"min_self_distance_mm", d.min_self_distance_mm},
        {"rim_loops", double(d.rim_loops)},
        {"spacing_mm", dopt.spacing_mm},
        {"total_turning_deg", d.total_turning_deg},
        {"max_turn_deg_per_mm", d.max_turn_deg_per_mm},
        {"smoothing_passes", double(d.smoothing_passes)},
        {"mean_drift_mm", d.mean_drift_mm},
        {"max_drift_mm", d.max_drift_mm}};
    if (!d.ct_estimate.reason.empty() || !d.ct_estimate.score.empty()) {
      props.push_back({"ct_bile_hu", d.ct_estimate.bile_hu});
      props.push_back({"ct_liver_hu", d.ct_estimate.liver_hu});
      props.push_back({"ct_band_lo_hu", d.ct_estimate.band_lo_hu});
      props.push_back({"ct_band_hi_hu", d.ct_estimate.band_hi_hu});
      props.push_back({"ct_liver_region_ml", d.ct_estimate.liver_region_ml});
    }
    emit(named(d.line, organ.name + "_dissection"), props, {{"bed_source", source}});
  };
  // The registry says which organ has which paths (`paths`): the airway's centreline and
  // incision on a tube, the dissection around a wall_body's bed.
  auto has = [](const OrganInfo& o, const char* kind) { return std::find(o.paths.begin(), o.paths.end(), kind) != o.paths.end(); };
  for (const OrganInfo& organ : registry.organs) {
    const bool want_centerline = has(organ, "centerline") && wanted(organ.name + "_centerline", organ.label);
    const bool want_incision = has(organ, "incision") && wanted(organ.name + "_incision", organ.label);
    if (want_centerline || want_incision) make_tube_paths(organ, want_centerline, want_incision);
    if (has(organ, "dissection") && wanted(organ.name + "_dissection", organ.label)) make_dissection(organ);
  }
  return written;
}

}  // namespace organsmith
