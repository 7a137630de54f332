#!/bin/bash
# A private Orthanc PACS for the PACS tests, on loopback, entirely inside a fresh directory:
#   orthanc_server.sh start DIR USER PASSWORD   writes DIR/orthanc.json (authentication on, DICOMweb
#       and GDCM plugins, a DICOM port with AE title ORTHANCTEST that answers C-FIND and C-GET from
#       any AE title), starts Orthanc (PID in DIR/orthanc.pid), waits until it answers, and prints
#       "HTTP_PORT DICOM_PORT"
#   orthanc_server.sh stop DIR                 stops it by PID and waits until it is gone
# Needs Debian's orthanc, orthanc-dicomweb and orthanc-gdcm (scripts/install-deps).
set -euo pipefail
source "$(dirname "$0")/free_port.sh"
cmd=${1:?usage: orthanc_server.sh start DIR USER PASSWORD | stop DIR}
DIR=$(realpath -m "${2:?DIR}")
alive() { [ -d "/proc/$1" ] && ! grep -q '^State:[[:space:]]*Z' "/proc/$1/status" 2>/dev/null; }

if [ "$cmd" = stop ]; then
  [ -s "$DIR/orthanc.pid" ] || exit 0
  pid=$(cat "$DIR/orthanc.pid")
  if alive "$pid" && grep -qx Orthanc "/proc/$pid/comm" 2>/dev/null; then
    kill -TERM "$pid" 2>/dev/null || true
    end=$(( $(date +%s) + 15 ))
    while alive "$pid"; do
      [ "$(date +%s)" -ge $end ] && { kill -KILL "$pid" 2>/dev/null || true; end=$(( end + 5 )); }
      sleep 0.05
    done
  fi
  rm -f "$DIR/orthanc.pid"
  exit 0
fi
[ "$cmd" = start ] || { echo "usage: orthanc_server.sh start DIR USER PASSWORD | stop DIR" >&2; exit 2; }
USER_NAME=${3:?USER}; PASSWORD=${4:?PASSWORD}
command -v Orthanc >/dev/null || { echo "orthanc_server.sh: Orthanc not found (scripts/install-deps installs orthanc)" >&2; exit 3; }
PLUGINS=/usr/share/orthanc/plugins
for p in libOrthancDicomWeb.so libOrthancGdcm.so; do
  [ -f "$PLUGINS/$p" ] || { echo "orthanc_server.sh: $PLUGINS/$p missing (orthanc-dicomweb, orthanc-gdcm)" >&2; exit 3; }
done
mkdir -p "$DIR/db"
HTTP_PORT=$(free_port); DICOM_PORT=$(free_port "$HTTP_PORT")
NAME="organsmith-test-$$-$(date +%s%N)"   # tells our server from any other on the port
cat > "$DIR/orthanc.json" <<CONF
{
  "Name" : "$NAME",
  "StorageDirectory" : "$DIR/db",
  "IndexDirectory" : "$DIR/db",
  "SaveJobs" : false,
  "Plugins" : [ "$PLUGINS/libOrthancDicomWeb.so", "$PLUGINS/libOrthancGdcm.so" ],
  "HttpPort" : $HTTP_PORT,
  "RemoteAccessAllowed" : false,
  "AuthenticationEnabled" : true,
  "RegisteredUsers" : { "$USER_NAME" : "$PASSWORD" },
  "DicomServerEnabled" : true,
  "DicomAet" : "ORTHANCTEST",
  "DicomPort" : $DICOM_PORT,
  "DicomCheckCalledAet" : true,
  "DicomAlwaysAllowFind" : true,
  "DicomAlwaysAllowGet" : true,
  "DicomAlwaysAllowStore" : true,
  "DicomModalities" : {},
  "DicomWeb" : { "Enable" : true, "Root" : "/dicom-web/" },
  "Gdcm" : { "Enable" : true }
}
CONF
chmod 600 "$DIR/orthanc.json"
# TCP_NODELAY: without it every C-STORE of a C-GET waits for a delayed ACK (~40 ms).
( cd "$DIR" && TCP_NODELAY=1 exec setsid Orthanc "$DIR/orthanc.json" ) > "$DIR/orthanc.log" 2>&1 < /dev/null &
echo $! > "$DIR/orthanc.pid"
deadline=$(( $(date +%s) + 60 ))
until curl -s -f -u "$USER_NAME:$PASSWORD" --max-time 2 "http://127.0.0.1:$HTTP_PORT/system" 2>/dev/null | grep -q "\"$NAME\""; do
  alive "$(cat "$DIR/orthanc.pid")" || { echo "orthanc_server.sh: Orthanc exited:" >&2; tail -20 "$DIR/orthanc.log" >&2; exit 1; }
  [ "$(date +%s)" -ge $deadline ] && { echo "orthanc_server.sh: no answer after 60 s" >&2; "$0" stop "$DIR"; exit 1; }
  sleep 0.1
done
echo "$HTTP_PORT $DICOM_PORT"
