#!/bin/bash
# A private one-node Slurm cluster for the cohort tests, entirely inside a fresh directory:
#   slurm_cluster.sh start DIR   writes DIR/slurm.conf, starts munged, slurmctld and slurmd (PIDs in
#                                DIR/run/*.pid) and waits until the node is idle; clients then need
#                                only SLURM_CONF=DIR/slurm.conf (the munge socket is named in it)
#   slurm_cluster.sh stop DIR    cancels every job, stops the daemons by PID and waits until gone
#   slurm_cluster.sh stop-controller DIR / start-controller DIR
#                                stops slurmctld alone (jobs go on running on the node) / starts it
#                                again on its saved state and waits until the node answers
# Needs Debian's slurm-wlm and munge (scripts/install-deps) and root (the daemons run as root).
# No cgroups: processes are tracked by process group, memory by polling /proc.
set -euo pipefail
source "$(dirname "$0")/free_port.sh"
cmd=${1:?usage: slurm_cluster.sh start|stop|stop-controller|start-controller DIR}
DIR=$(realpath -m "${2:?usage: slurm_cluster.sh start|stop|stop-controller|start-controller DIR}")
export SLURM_CONF=$DIR/slurm.conf
alive() { [ -d "/proc/$1" ] && ! grep -q '^State:[[:space:]]*Z' "/proc/$1/status" 2>/dev/null; }

# Stops daemon $1 by the PID in DIR/run/$1.pid (TERM, then KILL after 15 s) and waits until it is gone.
stop_daemon() {
  local name=$1 pf=$DIR/run/$1.pid pid
  [ -s "$pf" ] || return 0
  pid=$(cat "$pf")
  if alive "$pid" && grep -qx "$name" "/proc/$pid/comm" 2>/dev/null; then
    kill -TERM "$pid" 2>/dev/null || true
    local end=$(( $(date +%s) + 15 ))
    while alive "$pid"; do
      [ "$(date +%s)" -ge $end ] && { kill -KILL "$pid" 2>/dev/null || true; end=$(( end + 5 )); }
      sleep 0.05
    done
  fi
  rm -f "$pf"
}

# -D keeps each daemon in the foreground, so $! is its PID; setsid keeps a Ctrl-C aimed at the
# caller away from them. -i: a state file cut short by a stop is not fatal.
start_controller() {
  setsid slurmctld -D -i -f "$SLURM_CONF" >> "$DIR/log/slurmctld.out" 2>&1 < /dev/null &
  echo $! > "$DIR/run/slurmctld.pid"
}

# Waits (60 s at most) until the node answers in one of the states given as a pattern.
wait_for_node() {
  local want=$1 deadline=$(( $(date +%s) + 60 )) host
  host=$(hostname -s)
  until [[ "$(sinfo -h -N -n "$host" -o %T 2>/dev/null || true)" =~ ^($want)$ ]]; do
    alive "$(cat "$DIR/run/slurmctld.pid")" || { echo "slurm_cluster.sh: slurmctld died" >&2; return 1; }
    [ "$(date +%s)" -ge $deadline ] && { echo "slurm_cluster.sh: the node does not answer after 60 s" >&2; return 1; }
    sleep 0.1
  done
}

stop() {
  [ -d "$DIR/run" ] || return 0
  if [ -s "$DIR/run/slurmctld.pid" ] && alive "$(cat "$DIR/run/slurmctld.pid")"; then
    scancel --partition=debug >/dev/null 2>&1 || true
    local end=$(( $(date +%s) + 10 ))
    while squeue -h -t R,CG 2>/dev/null | grep -q . && [ "$(date +%s)" -lt $end ]; do sleep 0.1; done
  fi
  for name in slurmd slurmctld munged; do stop_daemon "$name"; done
  # Job processes of this cluster that outlived their step (their environment names our SLURM_CONF).
  for p in /proc/[0-9]*; do
    p=${p#/proc/}
    [ "$p" = $$ ] && continue
    env=$( { tr '\0' '\n' < "/proc/$p/environ"; } 2>/dev/null ) || continue
    grep -qx "SLURM_CONF=$SLURM_CONF" <<< "$env" || continue
    grep -q '^SLURM_JOB_ID=' <<< "$env" && { kill -KILL "$p" 2>/dev/null || true; }
  done
}

if [ "$cmd" = stop ]; then stop; exit 0; fi
if [ "$cmd" = stop-controller ]; then stop_daemon slurmctld; exit 0; fi
if [ "$cmd" = start-controller ]; then
  [ -e "$DIR/slurm.conf" ] || { echo "slurm_cluster.sh: no cluster in $DIR" >&2; exit 2; }
  start_controller
  wait_for_node 'idle|mixed|allocated|completing'
  exit
fi
[ "$cmd" = start ] || { echo "usage: slurm_cluster.sh start|stop|stop-controller|start-controller DIR" >&2; exit 2; }
for tool in munged slurmctld slurmd sbatch; do
  command -v "$tool" >/dev/null || { echo "slurm_cluster.sh: $tool not found (scripts/install-deps installs slurm-wlm and munge)" >&2; exit 3; }
done
# Unix socket paths are limited to 107 bytes; slurmstepd's lie under DIR/spool.
[ ${#DIR} -le 60 ] || { echo "slurm_cluster.sh: DIR is too long for Slurm's sockets: $DIR" >&2; exit 2; }
[ -e "$DIR/slurm.conf" ] && { echo "slurm_cluster.sh: $DIR holds a cluster already" >&2; exit 2; }
fail() { echo "slurm_cluster.sh: $*" >&2; for f in "$DIR"/log/*; do [ -s "$f" ] && tail -n 20 "$f" >&2; done; stop; exit 1; }
trap 'fail "start-up failed"' ERR

mkdir -p "$DIR"/{munge,state,spool,log,run}
chmod 755 "$DIR/munge"
CTLD_PORT=$(free_port); SLURMD_PORT=$(free_port "$CTLD_PORT")
HOST=$(hostname -s)
HW=$(slurmd -C | sed -n 's/^NodeName=[^ ]* //p' | sed 's/ *RealMemory=[0-9]*//; s/ *UpTime=.*//')
MEM=$(slurmd -C | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p')

dd if=/dev/urandom of="$DIR/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$DIR/munge/munge.key"
munged --socket="$DIR/munge/munge.socket" --key-file="$DIR/munge/munge.key" --pid-file="$DIR/run/munged.pid" \
       --log-file="$DIR/log/munged.log" --seed-file="$DIR/munge/munged.seed" --num-threads=2 -f
: > "$DIR/plugstack.conf"
cat > "$DIR/slurm.conf" <<CONF
ClusterName=organsmith-test
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$DIR/munge/munge.socket
CredType=cred/munge
PlugStackConfig=$DIR/plugstack.conf
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/run/slurmctld.pidfile
SlurmdPidFile=$DIR/run/slurmd.pidfile
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
MailProg=/bin/true
MpiDefault=none
SwitchType=switch/none
ProctrackType=proctrack/pgid
TaskPlugin=task/none
JobContainerType=job_container/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
JobAcctGatherType=jobacct_gather/linux
JobAcctGatherFrequency=task=1
JobAcctGatherParams=OverMemoryKill
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$DIR/jobcomp.txt
MinJobAge=3600
SchedulerType=sched/backfill
SchedulerParameters=batch_sched_delay=0,sched_min_interval=0,bf_interval=1
KillWait=2
MessageTimeout=10
SlurmdTimeout=300
InactiveLimit=0
ReturnToService=2
SlurmdParameters=config_overrides
NodeName=$HOST NodeAddr=127.0.0.1 $HW RealMemory=$MEM State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
start_controller
setsid slurmd -D -f "$SLURM_CONF" > "$DIR/log/slurmd.out" 2>&1 < /dev/null &
echo $! > "$DIR/run/slurmd.pid"
deadline=$(( $(date +%s) + 60 ))
until [ "$(sinfo -h -N -n "$HOST" -o %T 2>/dev/null || true)" = idle ]; do
  for d in slurmctld slurmd; do alive "$(cat "$DIR/run/$d.pid")" || fail "$d died"; done
  [ "$(date +%s)" -ge $deadline ] && fail "the node is not idle after 60 s"
  sleep 0.1
done
trap - ERR
