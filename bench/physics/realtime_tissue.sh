#!/usr/bin/env bash
# Real-time tissue model against mesh size (issue 38): the phantom's gallbladder meshed at three
# tetrahedral edges (the default 4.5 mm among them), each pressed by `haptics --indent` (5 mm/s to
# the probe depth, held, withdrawn, 1 s at rest) on the linear real-time model with its threads
# running. Prints nodes, FE update p50/p99, the force loop's rate, tick p99 and jitter p99, and
# each figure as a ratio of its budget (update 16.7 ms at 60 fps; force tick 100 µs; 1 kHz).
# Run alone on the machine (timings): bash bench/physics/realtime_tissue.sh [BUILD_DIR]
set -euo pipefail
build=${1:-build}
cli=$(realpath "$build/pipeline/organsmith")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
printf '%-8s %6s %9s %9s %10s %10s %12s %12s %10s\n' edge_mm nodes upd_p50 upd_p99 p99/16.7 force_Hz tick_p99_us jitter_p99 rest/depth
for edge in 6.0 4.5 3.5; do
  d="$work/e$edge"
  mkdir -p "$d"
  printf '[case]\ninput = "phantom"\n[[organ]]\nname = "gallbladder"\n[stages.mesh]\ntet_edge_mm = %s\n' "$edge" >"$d/case.toml"
  "$cli" run "$d/case.toml" --out "$d/out" --until attach >"$d/run.log" 2>&1
  "$cli" haptics "$d/out" --indent gallbladder --fe-elements linear --out "$d/r.json" >"$d/h.log" 2>&1
  python3 - "$edge" "$d/r.json" <<'PY'
import json, sys
f = json.load(open(sys.argv[2]))["fe"]
print(f"{sys.argv[1]:<8} {f['nodes']:>6} {f['update_ms_p50']:>9.2f} {f['update_ms_p99']:>9.2f} {f['update_ms_p99'] / 16.7:>10.2f} "
      f"{f['force_rate_hz']:>10.1f} {f['force_tick_us_p99']:>12.2f} {f['force_jitter_us_p99']:>12.1f} {f['press']['rest_fraction_of_depth']:>10.2e}")
PY
done
