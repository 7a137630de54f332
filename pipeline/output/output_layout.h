#pragma once
// Every path under an output directory, named once. `run`, the single-stage commands and the
// readers (resume, `snapshot`, `preview`, `haptics`) all take their paths from here; a stage that
// writes into a staging folder uses the layout of that folder (the same relative paths).

#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <string>

namespace organsmith {

struct OutputLayout {
  std::filesystem::path root;

  std::filesystem::path manifest() const { return root / "manifest.json"; }
  // phantom stage (default case)
  std::filesystem::path phantom_dir() const { return root / "phantom"; }
  std::filesystem::path phantom_dicom() const { return phantom_dir() / "dicom"; }
  std::filesystem::path phantom_truth() const { return phantom_dir() / "ground_truth.nii.gz"; }
  std::filesystem::path phantom_seeds() const { return phantom_dir() / "seeds.json"; }
  // ingest
  std::filesystem::path ingest() const { return root / "ingest.json"; }
  // segment
  std::filesystem::path labels() const { return root / "labels.nii.gz"; }
  std::filesystem::path contours(const std::string& organ) const { return root / ("contours_" + organ + ".json"); }
  std::filesystem::path overlays_dir() const { return root / "overlays"; }
  // mesh (file names inside an organ's folder are export_meshes'; see meshing/export.h)
  std::filesystem::path meshes_dir() const { return root / "meshes"; }
  std::filesystem::path organ_dir(const std::string& organ) const { return meshes_dir() / organ; }
  /// A surface file, e.g. surface("trachea", "trachea_wall", "vtp").
  std::filesystem::path surface(const std::string& organ, const std::string& name, const std::string& ext) const {
    return organ_dir(organ) / (name + "." + ext);
  }
  /// An organ's tetrahedral mesh, e.g. volume("gallbladder", "vtu").
  std::filesystem::path volume(const std::string& organ, const std::string& ext) const {
    return organ_dir(organ) / (organ + "." + ext);
  }
  std::filesystem::path quality(const std::string& organ) const { return organ_dir(organ) / "quality.json"; }
  /// An organ's INP with a material band's variant ("p05", …) on its regions.
  std::filesystem::path band_input(const std::string& organ, const std::string& variant) const {
    return organ_dir(organ) / "band" / (organ + "." + variant + ".inp");
  }
  // attach
  std::filesystem::path materials() const { return root / "materials.json"; }
  // guide
  std::filesystem::path paths_dir() const { return root / "paths"; }
  std::filesystem::path path(const std::string& name, const std::string& ext) const {
    return paths_dir() / (name + "." + ext);
  }
  // snapshot
  std::filesystem::path simulation_dir() const { return root / "simulation"; }
  std::filesystem::path simulation(const std::string& organ, const std::string& ext) const {
    return simulation_dir() / (organ + "." + ext);
  }
  /// The solver's own files of an organ's run (input copy, log, .sta, .dat).
  /// The indentation's force against depth (an organ whose load case is the probe).
  std::filesystem::path indentation_plot(const std::string& organ) const { return simulation_dir() / (organ + "_indentation.png"); }
  std::filesystem::path simulation_work(const std::string& organ) const { return simulation_dir() / (organ + "_solver"); }
  /// The solver's log of a simulate run that failed (outside the manifest: the stage wrote nothing;
  /// removed when the organ next simulates).
  std::filesystem::path failed_solver_log(const std::string& organ) const {
    return root / "logs" / ("simulate_" + organ + "_solver.log");
  }

  std::filesystem::path snapshots_dir() const { return root / "snapshots"; }
};

/// `organsmith calibrate --out DIR`: the fitted parameters and the fit against the data. Names
/// relative to the folder (`*_name`) for writers that stage files by name.
struct CalibrateLayout {
  std::filesystem::path root;
  static constexpr const char* params_name = "params.json";
  static constexpr const char* fit_name = "fit.csv";
  std::filesystem::path params() const { return root / params_name; }
  std::filesystem::path fit() const { return root / fit_name; }
};

/// `organsmith uncertainty --out DIR`: per method, <method>.json and <method>.csv ("dc",
/// "imvfosm"); the Monte Carlo writes summary.json and cdf.csv.
struct UncertaintyLayout {
  std::filesystem::path root;
  static std::string json_name(const std::string& method) { return method + ".json"; }
  static std::string csv_name(const std::string& method) { return method + ".csv"; }
  static constexpr const char* mc_summary_name = "summary.json";
  static constexpr const char* mc_cdf_name = "cdf.csv";
  std::filesystem::path json(const std::string& method) const { return root / json_name(method); }
  std::filesystem::path csv(const std::string& method) const { return root / csv_name(method); }
  std::filesystem::path mc_summary() const { return root / mc_summary_name; }
  std::filesystem::path mc_cdf() const { return root / mc_cdf_name; }
};

/// `organsmith degrade --out DIR`: the clip's shapes (original, deployed, one per stage), its
/// mass over time and the summary; `degrade --fit` writes the fit's files; plots under snapshots/.
struct DegradeLayout {
  std::filesystem::path root;
  static constexpr const char* original_name = "original.vtp";
  /// Stage k (0 = deployed) at `weeks`: "stage_<k>_<weeks, 1 decimal>w.vtp".
  static std::string stage_name(std::size_t k, double weeks) {
    char name[64];
    std::snprintf(name, sizeof name, "stage_%zu_%.1fw.vtp", k, weeks);
    return name;
  }
  std::filesystem::path original() const { return root / original_name; }
  std::filesystem::path stage(std::size_t k, double weeks) const { return root / stage_name(k, weeks); }
  std::filesystem::path mass() const { return root / "mass.csv"; }
  std::filesystem::path summary() const { return root / "summary.json"; }
  std::filesystem::path fit_json() const { return root / "fit.json"; }
  std::filesystem::path fit_csv() const { return root / "fit.csv"; }
  std::filesystem::path model_mass() const { return root / "model_mass.csv"; }
  std::filesystem::path snapshots_dir() const { return root / "snapshots"; }
};

/// A cohort's output directory: one run's folder per study (laid out as OutputLayout), the
/// summary beside them, and the engine's working files under cohort/.
struct CohortLayout {
  std::filesystem::path root;

  std::filesystem::path study(const std::string& id) const { return root / id; }
  std::filesystem::path summary_csv() const { return root / "cohort.csv"; }
  std::filesystem::path summary_json() const { return root / "cohort.json"; }
  std::filesystem::path contact_sheet() const { return root / "cohort.png"; }
  std::filesystem::path work_dir() const { return root / "cohort"; }
  std::filesystem::path plan() const { return work_dir() / "plan.json"; }
  std::filesystem::path slurm_script() const { return work_dir() / "cohort.sbatch"; }
  std::filesystem::path status(const std::string& id) const { return work_dir() / "status" / (id + ".json"); }
  std::filesystem::path log(const std::string& id) const { return work_dir() / "logs" / (id + ".log"); }
  /// Slurm job arrays submitted and not yet collected (a rerun waits for their tasks).
  std::filesystem::path slurm_arrays() const { return work_dir() / "slurm_arrays.json"; }
  /// Slurm's own output file of array task `index` (what the task printed before it started).
  std::filesystem::path slurm_log_pattern() const { return work_dir() / "logs" / "slurm-%A_%a.out"; }
};

}  // namespace organsmith
