#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, without systemd, for trying `dispflow-vk sweep
# --slurm` and for CI's test of it against the real daemons (Debian 12: Slurm 22.05).
#
#   bash tools/slurm_local.sh install      # apt-get the daemons (slurmctld slurmd slurm-client munge)
#   bash tools/slurm_local.sh up DIR       # start munged, slurmctld and slurmd; state under DIR
#   source DIR/env                          # SLURM_CONF for sbatch/squeue/scontrol
#   bash tools/slurm_local.sh down DIR     # stop the three daemons started for DIR (by PID)
#
# Everything (munge key and socket, slurm.conf, spool, state, logs, pid files) lives under DIR,
# so it touches no system configuration and two clusters on one machine do not meet. Needs
# root (slurmd runs jobs as their submitter) or sudo.
set -euo pipefail

sudo=""
[ "$(id -u)" -ne 0 ] && sudo="sudo"

case "${1:-}" in
install)
  pkgs=(slurmctld slurmd slurm-client munge)
  missing=()
  for p in "${pkgs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    echo "slurm_local: installing ${missing[*]}"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends \
      "${missing[@]}" >/dev/null
  fi
  ;;
up)
  dir=$(realpath -m "${2:?usage: slurm_local.sh up DIR}")
  for c in munged mungekey slurmctld slurmd scontrol; do
    command -v "$c" >/dev/null || { echo "slurm_local: $c not found; run: bash tools/slurm_local.sh install" >&2; exit 1; }
  done
  mkdir -p "$dir"/{state,spool,log}
  # munged refuses a socket directory others can write to, and runs as its own user.
  $sudo install -d -m 0755 -o munge -g munge "$dir/munge"
  if [ ! -f "$dir/munge/munge.key" ]; then
    $sudo mungekey --create --keyfile="$dir/munge/munge.key" --force
    $sudo chown munge:munge "$dir/munge/munge.key"
    $sudo chmod 0400 "$dir/munge/munge.key"
  fi
  sock="$dir/munge/munge.socket"
  $sudo runuser -u munge -- munged -F --socket="$sock" --key-file="$dir/munge/munge.key" \
    --pid-file="$dir/munge/munged.pid" --log-file="$dir/munge/munged.log" \
    --seed-file="$dir/munge/munged.seed" >"$dir/log/munged.out" 2>&1 &
  echo $! >"$dir/munged.pid"
  for _ in $(seq 50); do [ -S "$sock" ] && break; sleep 0.1; done
  [ -S "$sock" ] || { echo "slurm_local: munged did not start (see $dir/log/munged.out, $dir/munge/munged.log)" >&2; exit 1; }

  host=$(hostname -s)
  node=$(slurmd -C | head -1)
  # Ports away from the defaults, so a system Slurm on this machine is not disturbed.
  port=${SLURM_LOCAL_PORT:-$((20000 + RANDOM % 20000))}
  cat >"$dir/slurm.conf" <<EOF
ClusterName=dispflow
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
AuthInfo=socket=$sock
CredType=cred/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pidfile
SlurmdPidFile=$dir/slurmd.pidfile
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
DependencyParameters=kill_invalid_depend
$node State=UNKNOWN
PartitionName=local Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
  echo "export SLURM_CONF=$dir/slurm.conf" >"$dir/env"
  export SLURM_CONF="$dir/slurm.conf"
  $sudo slurmctld -D -c -f "$SLURM_CONF" >"$dir/log/slurmctld.out" 2>&1 &
  echo $! >"$dir/slurmctld.pid"
  $sudo slurmd -D -f "$SLURM_CONF" >"$dir/log/slurmd.out" 2>&1 &
  echo $! >"$dir/slurmd.pid"
  for _ in $(seq 300); do
    state=$(sinfo -h -o %t 2>/dev/null | head -1 || true)
    case "$state" in idle | mix | alloc) break ;; esac
    sleep 0.1
  done
  case "${state:-}" in
  idle | mix | alloc) echo "slurm_local: node $host $state (SLURM_CONF=$SLURM_CONF)" ;;
  *)
    echo "slurm_local: the node did not come up (state '${state:-none}'); logs in $dir/log" >&2
    exit 1
    ;;
  esac
  ;;
down)
  dir=$(realpath -m "${2:?usage: slurm_local.sh down DIR}")
  for d in slurmd slurmctld munged; do
    f="$dir/$d.pid"
    [ -f "$f" ] || continue
    pid=$(cat "$f")
    # The recorded PID is a sudo/runuser wrapper or the daemon itself: stop the daemon too.
    for p in $(pgrep -P "$pid" 2>/dev/null) "$pid"; do $sudo kill "$p" 2>/dev/null || true; done
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    rm -f "$f"
  done
  ;;
*)
  sed -n '2,12p' "$0" >&2
  exit 2
  ;;
esac
