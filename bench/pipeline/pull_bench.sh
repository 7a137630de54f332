#!/bin/bash
# PACS pulls against reading the same series from disk, in one run: the 30-slice chest series
# (../shared/data/real/chest-dicom-8mm) is put into a private Orthanc on loopback
# (tests/support/orthanc_server.sh), then pulled into an empty cache by DICOMweb and by DIMSE
# C-GET (best of 3 each) and read from disk by `organsmith run --until ingest` (the reference).
# Prints MB/s of each and the pull's overhead in seconds over the disk read.
#   bash bench/pipeline/pull_bench.sh [BUILD_DIR]      (make bench runs it)
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
exe=$(realpath "${1:-$here/build}")/pipeline/organsmith
series=$here/../shared/data/real/chest-dicom-8mm/dicom
[ -x "$exe" ] || { echo "pull_bench: build first ($exe missing)" >&2; exit 1; }
[ -d "$series" ] || { echo "pull_bench: $series is absent (../shared/data/real)" >&2; exit 1; }
work=$(mktemp -d /tmp/osm-pbench-XXXXXX)
trap '"$here/tests/support/orthanc_server.sh" stop "$work/orthanc" > /dev/null 2>&1 || true; rm -rf "$work"' EXIT
read -r http dicom < <("$here/tests/support/orthanc_server.sh" start "$work/orthanc" bench bench-pw)
for f in "$series"/*; do curl -s -f -o /dev/null -u bench:bench-pw -X POST --data-binary @"$f" "http://127.0.0.1:$http/instances"; done
study=$(dcmdump -s +P 0020,000d "$(ls "$series"/* | head -1)" | sed -n 's/.*\[\(.*\)\].*/\1/p')
export ORGANSMITH_PACS_USER=bench ORGANSMITH_PACS_PASSWORD=bench-pw
mb=$(du -sb "$series" | awk '{print $1 / 1e6}')
now() { date +%s.%N; }
best() {  # best of 3 wall times of "$@", each into a fresh cache
  local b=999 t0 t
  for i in 1 2 3; do
    rm -rf "$work/cache"
    t0=$(now); "$@" > /dev/null 2>&1; t=$(echo "$(now) - $t0" | bc)
    b=$(echo "if ($t < $b) $t else $b" | bc)
  done
  echo "$b"
}
printf '[case]\ninput = "%s"\n' "$series" > "$work/disk.toml"
disk=$(best bash -c "rm -rf '$work/out'; '$exe' -q run '$work/disk.toml' --out '$work/out' --until ingest")
web=$(best "$exe" -q pull --pacs "http://127.0.0.1:$http/dicom-web" --study "$study" --cache "$work/cache")
dimse=$(best "$exe" -q pull --pacs "dicom://ORTHANCTEST@127.0.0.1:$dicom" --study "$study" --cache "$work/cache")
python3 - "$mb" "$disk" "$web" "$dimse" <<'PY'
import sys
mb, disk, web, dimse = map(float, sys.argv[1:])
print(f"pull bench: chest series, 30 instances, {mb:.1f} MB, Orthanc on loopback (best of 3)")
print(f"{'':<26}{'s':>8}{'MB/s':>9}{'vs disk read':>14}")
print(f"{'read from disk (ingest)':<26}{disk:>8.3f}{mb / disk:>9.1f}{1.0:>14.2f}")
for name, t in (("pull, DICOMweb", web), ("pull, DIMSE C-GET", dimse)):
    print(f"{name:<26}{t:>8.3f}{mb / t:>9.1f}{t / disk:>14.2f}")
PY
