#!/bin/bash
# Cohort engines against the reference a user would write: a shell loop over `organsmith run`.
# One run measures, on the same 8 small phantom studies (64² × 40 slices, gallbladder and
# trachea, phantom seeds 1–3 and 5–9; at 64² seed 4's gallbladder is too small to find): wall time of the loop, of `cohort --engine local` and of
# `cohort --engine slurm` (a private one-node Slurm, tests/support/slurm_cluster.sh), the
# engine's overhead per study (wall time × parallel studies − the studies' own run times, ÷ N),
# and peak memory (the engine process itself, and the largest study).
#   bash bench/pipeline/cohort_bench.sh [BUILD_DIR]      (make bench runs it)
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
exe=$(realpath "${1:-$here/build}")/pipeline/organsmith
[ -x "$exe" ] || { echo "cohort_bench: build first ($exe missing)" >&2; exit 1; }
work=$(mktemp -d /tmp/osm-cbench-XXXXXX)
cluster=$work/cluster
cleanup() { "$here/tests/support/slurm_cluster.sh" stop "$cluster" >/dev/null 2>&1 || true; rm -rf "$work"; }
trap cleanup EXIT
N=8
printf '[case]\ninput = "phantom"\n[phantom]\nsize = 64\nslice_mm = 10\n[[organ]]\nname = "gallbladder"\n[[organ]]\nname = "trachea"\n' > "$work/shared.toml"
echo "id,input,phantom.seed" > "$work/cohort.csv"
SEEDS="1 2 3 5 6 7 8 9"
for i in $SEEDS; do echo "s$i,phantom,$i" >> "$work/cohort.csv"; done

now() { date +%s.%N; }

# Reference: a shell loop, one study after the other (each run uses every core).
t0=$(now)
for i in $SEEDS; do
  sed "s/^size = 64/seed = $i\nsize = 64/" "$work/shared.toml" > "$work/case_$i.toml"
  "$exe" -q run "$work/case_$i.toml" --out "$work/loop/s$i" > /dev/null 2>&1 || echo "loop: study s$i failed"
done
loop_s=$(echo "$(now) - $t0" | bc)

run_engine() {  # engine out_dir → wall seconds
  local t0 rc=0  # exit 80 = some studies failed: reported, still measured
  t0=$(now)
  "$exe" -q cohort "$work/cohort.csv" --case "$work/shared.toml" --engine "$1" \
    --poll-s 0.2 --out "$2" > "$2.log" 2>&1 || rc=$?
  [ $rc -eq 0 ] || [ $rc -eq 80 ] || { echo "cohort --engine $1: exit $rc" >&2; cat "$2.log" >&2; }
  echo "$(now) - $t0" | bc
}
local_s=$(run_engine local "$work/local")
"$here/tests/support/slurm_cluster.sh" start "$cluster" > /dev/null
export SLURM_CONF=$cluster/slurm.conf
slurm_s=$(run_engine slurm "$work/slurm")

python3 - "$work" "$N" "$loop_s" "$local_s" "$slurm_s" <<'PY'
import json, sys
work, n, loop_s, local_s, slurm_s = sys.argv[1], int(sys.argv[2]), *map(float, sys.argv[3:])
import os
cores = os.cpu_count()
def summary(d):
    s = json.load(open(f"{work}/{d}/cohort.json"))["studies"]
    return sum(x["seconds"] for x in s), max(x["peak_rss_mib"] for x in s), sum(x["state"] == "done" for x in s)
def engine_mib(d):
    return json.load(open(f"{work}/{d}/cohort.json"))["engine_peak_rss_mib"]
def loop_stats():
    tot, peak = 0.0, 0.0
    for i in (1, 2, 3, 5, 6, 7, 8, 9):
        m = json.load(open(f"{work}/loop/s{i}/manifest.json"))
        tot += sum(st["seconds"] for st in m["stages"]); peak = max(peak, max(st["peak_rss_mib"] for st in m["stages"]))
    return tot, peak
lt, lp = loop_stats()
print(f"cohort bench: {n} phantom studies (64² × 40, gallbladder + trachea) on {cores} cores")
print(f"{'engine':<12}{'wall s':>9}{'studies s':>11}{'done':>6}{'overhead s/study':>18}{'engine MiB':>12}{'study MiB':>11}{'vs loop':>9}")
print(f"{'shell loop':<12}{loop_s:>9.1f}{lt:>11.1f}{n:>6}{(loop_s - lt) / n:>18.2f}{'-':>12}{lp:>11.0f}{1.0:>9.2f}")
for name, wall in (("local", local_s), ("slurm", slurm_s)):
    tot, peak, done = summary(name)
    jobs = min(cores, n)  # both engines run one single-threaded study per core here
    print(f"{name:<12}{wall:>9.1f}{tot:>11.1f}{done:>6}{(wall * jobs - tot) / n:>18.2f}{engine_mib(name):>12.0f}{peak:>11.0f}{wall / loop_s:>9.2f}")
PY
