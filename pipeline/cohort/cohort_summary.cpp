#include "pipeline/cohort/cohort_summary.h"

#include "core/csv.h"
#include "pipeline/output/json_file.h"
#include "core/errors.h"
#include "core/file_io.h"
#include "core/format.h"
#include "core/memory.h"
#include "pipeline/case/case_file.h"
#include "pipeline/io/image_io.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/output/read_manifest.h"
#include "viewer/contact_sheet.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <set>

namespace fs = std::filesystem;

namespace organsmith {

namespace {

/// Dice of the study's label `label` against the reference's nonzero voxels. The reference may
/// lie on another grid (axis order, flips): each study voxel looks up the reference voxel at its
/// centre (nearest), and reference voxels outside the study's grid count as missed.
nlohmann::json dice(const fs::path& labels_file, std::uint8_t label, const fs::path& reference) {
  try {
    const LabelMap a = read_label_map(labels_file), b = read_label_map(reference);
    const auto& na_vox = a.grid.size_vox;
    const auto& nb_vox = b.grid.size_vox;
    std::int64_t both = 0, in_a = 0, in_b = 0;
    for (std::int64_t k = 0; k < nb_vox[2]; ++k)
      for (std::int64_t j = 0; j < nb_vox[1]; ++j)
        for (std::int64_t i = 0; i < nb_vox[0]; ++i) in_b += b.at(i, j, k) != 0;
    for (std::int64_t k = 0; k < na_vox[2]; ++k)
      for (std::int64_t j = 0; j < na_vox[1]; ++j)
        for (std::int64_t i = 0; i < na_vox[0]; ++i) {
          const bool x = a.at(i, j, k) == label;
          in_a += x;
          if (!x) continue;
          const Eigen::Vector3d r = b.grid.lps_mm_to_index(a.grid.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k))));
          const std::int64_t ri = std::llround(r.x()), rj = std::llround(r.y()), rk = std::llround(r.z());
          both += ri >= 0 && rj >= 0 && rk >= 0 && ri < nb_vox[0] && rj < nb_vox[1] && rk < nb_vox[2] && b.at(ri, rj, rk) != 0;
        }
    if (a.grid.spacing_mm.prod() <= 0 || b.grid.spacing_mm.prod() <= 0) return nullptr;
    // Overlap counted in the study's voxels, the reference's size in its own voxels: both in mm³.
    const double va = double(in_a) * a.grid.spacing_mm.prod(), vb = double(in_b) * b.grid.spacing_mm.prod();
    const double vboth = double(both) * a.grid.spacing_mm.prod();
    return va + vb > 0 ? 2.0 * vboth / (va + vb) : 1.0;
  } catch (const Error& e) {
    return std::string("not computed: ") + e.message();
  }
}

nlohmann::json organ_figures(const OutputLayout& out, const std::string& organ) {
  nlohmann::json f = nlohmann::json::object();
  const auto q = read_json_or_null(out.quality(organ));
  if (q.is_object()) {
    f["label_volume_ml"] = q.value("label_volume_mm3", 0.0) / 1000.0;
    f["mesh_passed"] = q.value("passed", false);
    double min_angle = 180;
    if (q.contains("surfaces"))
      for (const auto& [name, s] : q["surfaces"].items()) min_angle = std::min(min_angle, s.value("min_angle_deg", 180.0));
    f["surface_min_angle_deg"] = min_angle;
    if (q.contains("tetrahedra")) {
      const auto& t = q["tetrahedra"];
      f["tetrahedra"] = t.value("tetrahedra", 0);
      f["tet_min_dihedral_deg"] = t.value("min_dihedral_deg", 0.0);
      f["tet_max_radius_edge"] = t.value("max_radius_edge_ratio", 0.0);
      f["mesh_volume_ml"] = t.value("volume_mm3", 0.0) / 1000.0;
    }
  }
  const auto sim = read_json_or_null(out.simulation(organ, "json"));
  if (sim.is_object()) {
    f["sim_converged"] = sim.value("converged", false);
    f["sim_max_displacement_mm"] = sim.value("max_displacement_mm", 0.0);
    f["sim_lumen_volume_change_ml"] = sim.value("lumen_volume_change_mm3", 0.0) / 1000.0;
  }
  return f;
}

std::string cell(const nlohmann::json& v) {
  if (v.is_null()) return "";
  if (v.is_string()) return csv_field(v.get<std::string>());
  if (v.is_boolean()) return v.get<bool>() ? "true" : "false";
  if (v.is_number_integer()) return std::to_string(v.get<long long>());
  if (v.is_number()) return format_g(v.get<double>(), 6);
  return csv_field(v.dump());
}

}  // namespace

nlohmann::json cohort_summary_json(const CohortPlan& plan, const CohortResult& result) {
  const CohortLayout layout{plan.out_dir};
  nlohmann::json studies = nlohmann::json::array();
  std::size_t done = 0, failed = 0, reused = 0;
  for (std::size_t i = 0; i < plan.studies.size(); ++i) {
    const CohortStudy& s = plan.studies[i];
    const StudyOutcome& o = result.studies[i];
    done += o.state == "done";
    reused += o.state == "reused";
    failed += o.state == "failed";
    nlohmann::json st = {{"id", s.id}, {"state", o.state}, {"exit_code", o.exit_code}, {"attempts", o.attempts},
                         {"message", o.message}};
    const OutputLayout out{layout.study(s.id)};
    const auto manifest = read_manifest(out.root).value_or(nlohmann::json());
    double seconds = 0, rss = 0;
    nlohmann::json stages = nlohmann::json::object();
    if (manifest.is_object() && manifest.contains("stages"))
      for (const auto& r : manifest["stages"]) {
        stages[r.value("name", "?")] = r.value("seconds", 0.0);
        seconds += r.value("seconds", 0.0);
        rss = std::max(rss, r.value("peak_rss_mib", 0.0));
      }
    st["stage_seconds"] = stages;
    st["seconds"] = seconds;
    st["peak_rss_mib"] = rss;
    nlohmann::json organs = nlohmann::json::object();
    std::optional<CaseFile> c;
    try {
      c = parse_case(s.case_toml, s.case_origin);
    } catch (const Error&) {
    }
    if (c)
      for (const auto& spec : c->organs) {
        nlohmann::json f = organ_figures(out, spec.name);
        if (auto ref = s.references.find(spec.name); ref != s.references.end()) {
          const OrganInfo* info = c->registry.find(spec.name);
          f["dice"] = o.state == "failed" || !info ? nlohmann::json(nullptr) : dice(out.labels(), info->label, ref->second);
        }
        organs[spec.name] = f;
      }
    st["organs"] = organs;
    studies.push_back(st);
  }
  return {{"studies", studies},
          {"counts", {{"total", plan.studies.size()}, {"done", done}, {"reused", reused}, {"failed", failed}}},
          {"seconds", result.seconds},
          {"engine_peak_rss_mib", peak_rss_mib()},
          {"slurm_jobs", result.slurm_jobs}};
}

void write_cohort_summary(const CohortPlan& plan, const CohortResult& result, const fs::path& dir, Progress& progress) {
  progress.report(0.0, "cohort summary");
  const nlohmann::json summary = cohort_summary_json(plan, result);
  const CohortLayout out{dir};
  write_file_atomic(out.summary_json(), summary.dump(2) + "\n");

  // CSV: fixed columns, then each organ's figures (the union over studies, in a stable order).
  std::vector<std::string> organs, figures;
  std::set<std::string> seen_organ, seen_figure;
  for (const auto& st : summary["studies"])
    for (const auto& [organ, f] : st["organs"].items()) {
      if (seen_organ.insert(organ).second) organs.push_back(organ);
      for (const auto& [k, v] : f.items())
        if (seen_figure.insert(k).second) figures.push_back(k);
    }
  std::string csv = "id,state,exit_code,attempts,seconds,peak_rss_mib";
  for (const auto& organ : organs)
    for (const auto& k : figures) csv += "," + organ + "_" + k;
  csv += ",message\n";
  for (const auto& st : summary["studies"]) {
    csv += cell(st["id"]) + "," + cell(st["state"]) + "," + cell(st["exit_code"]) + "," + cell(st["attempts"]) + "," +
           cell(st["seconds"]) + "," + cell(st["peak_rss_mib"]);
    for (const auto& organ : organs)
      for (const auto& k : figures) {
        const auto& f = st["organs"];
        csv += "," + (f.contains(organ) && f[organ].contains(k) ? cell(f[organ][k]) : std::string());
      }
    csv += "," + cell(st["message"]) + "\n";
  }
  write_file_atomic(out.summary_csv(), csv);

  std::vector<SheetTile> tiles;
  const CohortLayout layout{plan.out_dir};
  for (const auto& st : summary["studies"]) {
    const std::string id = st["id"], state = st["state"];
    SheetTile t;
    t.image = OutputLayout{layout.study(id)}.snapshots_dir() / "3d_overview.png";
    t.caption = id + ": " + state + (state == "failed" ? " (exit " + std::to_string(st["exit_code"].get<int>()) + ")" : "");
    t.ok = state != "failed";
    tiles.push_back(t);
  }
  write_png(contact_sheet(tiles), out.contact_sheet());
  progress.report(1.0, "cohort summary");
}

}  // namespace organsmith
