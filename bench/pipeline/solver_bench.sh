#!/bin/bash
# Solver exports and runs, in one run on the default phantom:
#  1. the mesh stage (meshing + every export) with quadratic tetrahedra (C3D10/tet10, the default)
#     against linear ones (C3D4/tet4, [stages.mesh] linear_tets = true) as the reference: wall time
#     of the stage from the manifest and the bytes written;
#  2. `organsmith simulate` per organ and case at the defaults (gallbladder: the 5 mm probe;
#     trachea: 2 kPa) on the default phantom and, where ../shared/data/real is beside the checkout,
#     the 3 mm abdomen's gallbladder (seeded at its reference's centroid) and the 8 mm chest's
#     trachea: wall time, CalculiX's own time, increments, nodes, peak memory (GNU time's maximum
#     RSS over organsmith and the solver it waits for) and the answer (force at the deepest point,
#     or the largest displacement).
#   bash bench/pipeline/solver_bench.sh [BUILD_DIR]      (make bench runs it; ~10 min on 2 cores)
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
exe=$(realpath "${1:-$here/build}")/pipeline/organsmith
[ -x "$exe" ] || { echo "solver_bench: build first ($exe missing)" >&2; exit 1; }
command -v ccx > /dev/null || { echo "solver_bench: CalculiX (ccx) is not installed" >&2; exit 1; }
work=$(mktemp -d /tmp/osm-sbench-XXXXXX)
trap 'rm -rf "$work"' EXIT

for kind in tet10 tet4; do
  linear=$([ $kind = tet4 ] && echo true || echo false)
  printf '[case]\ninput = "phantom"\n[[organ]]\nname = "gallbladder"\n[[organ]]\nname = "trachea"\n[stages.mesh]\nlinear_tets = %s\n' "$linear" > "$work/$kind.toml"
  "$exe" -q run "$work/$kind.toml" --out "$work/$kind" --until mesh > /dev/null
done

# case name, case file body (organs to simulate follow from it)
sim_case() {
  printf '%b' "$2" > "$work/$1.toml"
  "$exe" -q run "$work/$1.toml" --out "$work/$1" --until attach > /dev/null
  for organ in gallbladder trachea; do
    [ -f "$work/$1/meshes/$organ/$organ.inp" ] || continue
    /usr/bin/time -v -o "$work/$1.$organ.time" "$exe" -q simulate "$work/$1" --organ "$organ" --threads 2 > /dev/null
  done
}
sim_case phantom '[case]\ninput = "phantom"\n[[organ]]\nname = "gallbladder"\n[[organ]]\nname = "trachea"\n'
real=$(realpath -m "$here/../shared/data/real")
if [ -d "$real" ]; then
  # abdomen-ct-3mm: the reference mask's centroid (LPS mm) as the seed
  sim_case abdomen-ct-3mm "[case]\ninput = \"$real/abdomen-ct-3mm/ct.nii.gz\"\n[[organ]]\nname = \"gallbladder\"\nseed_lps_mm = [-64.30, -211.87, 118.02]\n"
  sim_case chest-dicom-8mm "[case]\ninput = \"$real/chest-dicom-8mm/dicom\"\n[[organ]]\nname = \"trachea\"\n"
fi

python3 - "$work" <<'PY'
import json, os, re, sys
work = sys.argv[1]
def mesh_stage(kind):
    m = json.load(open(f"{work}/{kind}/manifest.json"))
    st = next(s for s in m["stages"] if s["name"] == "mesh")
    return st["seconds"], sum(o["bytes"] for o in st["outputs"]), st["peak_rss_mib"]
t10, b10, r10 = mesh_stage("tet10")
t4, b4, r4 = mesh_stage("tet4")
print("solver bench: default phantom (512² × 160), both organs, 2 cores")
print(f"{'mesh stage (all exports)':<28}{'s':>8}{'MB written':>12}{'peak MiB':>10}{'time vs tet4':>14}")
print(f"{'tet4 (reference)':<28}{t4:>8.1f}{b4 / 1e6:>12.1f}{r4:>10.0f}{1.0:>14.2f}")
print(f"{'tet10 (default)':<28}{t10:>8.1f}{b10 / 1e6:>12.1f}{r10:>10.0f}{t10 / t4:>14.2f}")
print()
print(f"{'simulate (defaults)':<34}{'wall s':>8}{'ccx s':>8}{'incr':>6}{'nodes':>8}{'peak MiB':>10}  answer")
import glob
for tf in sorted(glob.glob(f"{work}/*.*.time")):
    case, organ = os.path.basename(tf).rsplit(".", 2)[:2]
    t = open(tf).read()
    wall = re.search(r"Elapsed \(wall clock\) time.*: (?:(\d+):)?(\d+):([\d.]+)", t)
    h, m_, s_ = wall.groups()
    wall_s = (int(h) if h else 0) * 3600 + int(m_) * 60 + float(s_)
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
    r = json.load(open(f"{work}/{case}/simulation/{organ}.json"))
    inp = open(f"{work}/{case}/meshes/{organ}/{organ}.inp").read()
    nodes = inp.count("\n", inp.index("*NODE"), inp.index("*ELEMENT")) - 1
    if "indentation" in r:
        i = r["indentation"]
        answer = f"{i['probe_force_N'] * 1e3:.1f} mN at {i['depth_mm']:.2f} mm ({i['limited_by']})"
    else:
        answer = f"largest displacement {r['max_displacement_mm']:.3f} mm"
    if not r.get("converged", False):
        answer = "NOT CONVERGED: " + answer
    print(f"{case + ' ' + organ:<34}{wall_s:>8.1f}{r['solver_seconds']:>8.1f}{r['increments']:>6}{nodes:>8}{rss:>10.0f}  {answer}")
PY
