#!/bin/bash
# Solver exports and runs, in one run on the default phantom:
#  1. the mesh stage (meshing + every export) with quadratic tetrahedra (C3D10/tet10, the default)
#     against linear ones (C3D4/tet4, [stages.mesh] linear_tets = true) as the reference: wall time
#     of the stage from the manifest and the bytes written;
#  2. `organsmith simulate` per organ on the coarse load-case meshes of the tests (edge 4 mm,
#     gallbladder 0.1 kPa, trachea 0.01 kPa): wall time, CalculiX's own time, increments and peak
#     memory (GNU time's maximum RSS over organsmith and the solver it waits for).
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

printf '[case]\ninput = "phantom"\n[[organ]]\nname = "gallbladder"\n[[organ]]\nname = "trachea"\n[stages.mesh]\nedge_mm = 4.0\npressure_kPa = { gallbladder = 0.1, trachea = 0.01 }\n' > "$work/sim.toml"
"$exe" -q run "$work/sim.toml" --out "$work/sim" --until attach > /dev/null
for organ in gallbladder trachea; do
  /usr/bin/time -v -o "$work/$organ.time" "$exe" -q simulate "$work/sim" --organ "$organ" --threads 2 > /dev/null
done

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
print(f"{'simulate (edge 4 mm)':<28}{'wall s':>8}{'ccx s':>8}{'incr':>6}{'peak MiB':>10}{'max disp mm':>13}")
for organ in ("gallbladder", "trachea"):
    t = open(f"{work}/{organ}.time").read()
    wall = re.search(r"Elapsed \(wall clock\) time.*: (?:(\d+):)?(\d+):([\d.]+)", t)
    h, m_, s_ = wall.groups()
    wall_s = (int(h) if h else 0) * 3600 + int(m_) * 60 + float(s_)
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
    r = json.load(open(f"{work}/sim/simulation/{organ}.json"))
    print(f"{organ:<28}{wall_s:>8.1f}{r['solver_seconds']:>8.1f}{r['increments']:>6}{rss:>10.0f}{r['max_displacement_mm']:>13.2f}")
PY
