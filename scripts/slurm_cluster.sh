#!/usr/bin/env bash
# A one-node Slurm cluster on this machine (munged, slurmctld and slurmd started by hand, no
# systemd), for the workflow's Slurm test (workflow/tests/test_workflow.py) and for trying
# workflow/profiles/slurm without a cluster. Needs root and Debian's slurmctld, slurmd,
# slurm-client and munge (scripts/deps.d/70-slurm.sh installs them).
#
#   scripts/slurm_cluster.sh [--dir DIR] -- COMMAND [ARG...]
#       brings the cluster up, runs COMMAND with SLURM_CONF set, tears the cluster down and exits
#       with COMMAND's status
#   scripts/slurm_cluster.sh [--dir DIR]
#       brings the cluster up, prints "slurm_cluster: ready SLURM_CONF=FILE pids=..." (the
#       daemons' process ids) on stdout, keeps it up until its standard input closes or until
#       SIGINT/SIGTERM/SIGHUP, then tears it down
#
# Everything (config, munge key, spool and state directories, logs) goes into DIR, a new
# directory (default: a fresh one under ${TMPDIR:-/tmp}), removed at the end unless --keep is
# given; only munged's socket is in /run/munge, where slurmd looks before it has the config. The config is served configless (slurmd --conf-server): a job's inner srun,
# which runs without SLURM_CONF, finds it in slurmd's cache (/run/slurm/conf). Only loopback is
# used: the controller and the node listen on 127.0.0.1 (--port P: slurmctld on P, slurmd on
# P+1; default 6817). The daemons are stopped by their process ids on any exit, after every job
# of the cluster is cancelled and has left the node.
set -euo pipefail

die() { echo "slurm_cluster: error: $*" >&2; exit 1; }

DIR=
KEEP=0
PORT=6817
while [ $# -gt 0 ]; do
  case "$1" in
    --dir) [ $# -ge 2 ] || die "--dir needs a directory"; DIR=$2; shift 2 ;;
    --keep) KEEP=1; shift ;;
    --port) [ $# -ge 2 ] || die "--port needs a number"; PORT=$2; shift 2 ;;
    --) shift; break ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown option '$1' (see --help)" ;;
  esac
done
[[ "$PORT" =~ ^[0-9]+$ ]] && [ "$PORT" -ge 1024 ] && [ "$PORT" -le 65000 ] || die "--port: expected a port number 1024-65000, got '$PORT'"

[ "$(id -u)" = 0 ] || die "needs root (slurmd starts every job as its user)"
for tool in munged slurmctld slurmd sinfo squeue scancel scontrol; do
  command -v "$tool" >/dev/null || die "$tool is missing; run scripts/deps.sh (or apt-get install slurmctld slurmd slurm-client munge)"
done
# A system Slurm config would win over the cache of ours inside every job.
[ ! -e /etc/slurm/slurm.conf ] || die "/etc/slurm/slurm.conf exists: a job's inner srun would read it instead of this cluster's config"
for p in "$PORT" "$((PORT + 1))"; do
  if (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null; then
    die "port $p on 127.0.0.1 is in use (another Slurm cluster?); choose others with --port"
  fi
done

if [ -n "$DIR" ]; then
  [ ! -e "$DIR" ] || [ -z "$(ls -A "$DIR")" ] || die "--dir $DIR exists and is not empty"
  mkdir -p "$DIR"
  DIR=$(cd "$DIR" && pwd)
else
  DIR=$(mktemp -d "${TMPDIR:-/tmp}/omniscan-slurm.XXXXXX")
fi
# munged checks that no one else can write to its socket's and key's directories, and Slurm's
# clients (any user's) must reach the socket: the tree is root's, searchable by all.
chmod 755 "$DIR"
mkdir -m 755 "$DIR/munge" "$DIR/log" "$DIR/state" "$DIR/spool"

NODE=$(hostname -s)
CONF=$DIR/slurm.conf
# slurmd fetches the config through munge before it could read a socket path from it: munged
# listens where every Slurm command looks by default.
MUNGE_RUN=/run/munge
MUNGE_SOCKET=$MUNGE_RUN/munge.socket.2
MUNGE_RUN_MADE=0
SLURM_RUN_MADE=0
[ -d /run/slurm ] || SLURM_RUN_MADE=1
MUNGED_PID=
CTLD_PID=
SLURMD_PID=
WATCH_PID=

export SLURM_CONF=$CONF

log_tails() {
  for f in "$DIR"/log/*.log; do
    [ -s "$f" ] || continue
    echo "--- last lines of $f:" >&2
    tail -n 20 "$f" >&2
  done
}

# Stops one daemon by its process id: SIGTERM, then SIGKILL after 10 s.
stop_pid() {
  local pid=$1 name=$2 i
  [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null || return 0
  kill -TERM "$pid" 2>/dev/null || true
  for i in $(seq 100); do
    kill -0 "$pid" 2>/dev/null || { wait "$pid" 2>/dev/null || true; return 0; }
    sleep 0.1
  done
  echo "slurm_cluster: $name (pid $pid) ignored SIGTERM for 10 s; killing it" >&2
  kill -KILL "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
}

teardown() {
  local status=$? i
  trap - EXIT INT TERM HUP
  stop_pid "$WATCH_PID" "the stdin watch"
  # Every job of this cluster is cancelled and must leave the node (its slurmstepd with it)
  # before slurmd goes.
  if [ -n "$CTLD_PID" ] && kill -0 "$CTLD_PID" 2>/dev/null; then
    if [ -n "$(squeue -h -o %i 2>/dev/null)" ]; then
      squeue -h -o %i 2>/dev/null | xargs -r scancel --quiet 2>/dev/null || true
      for i in $(seq 150); do
        [ -z "$(squeue -h -t running,completing,configuring,suspended -o %i 2>/dev/null)" ] && break
        sleep 0.2
      done
    fi
  fi
  stop_pid "$SLURMD_PID" slurmd
  stop_pid "$CTLD_PID" slurmctld
  stop_pid "$MUNGED_PID" munged
  if [ "$MUNGE_RUN_MADE" = 1 ]; then rm -rf "$MUNGE_RUN"; fi
  # slurmd's configless cache link, if it is ours.
  if [ -L /run/slurm/conf ] && [[ "$(readlink /run/slurm/conf)" == "$DIR"/* ]]; then
    rm -f /run/slurm/conf
  fi
  if [ "$SLURM_RUN_MADE" = 1 ]; then rmdir /run/slurm 2>/dev/null || true; fi
  if [ "$status" != 0 ]; then log_tails; fi
  if [ "$KEEP" = 1 ]; then
    echo "slurm_cluster: kept $DIR" >&2
  else
    rm -rf "$DIR"
  fi
  exit "$status"
}
trap teardown EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
trap 'exit 129' HUP

# The node as slurmd sees it (CPUs, sockets, cores, threads, memory): it drains a node whose
# config says more than it has.
HW=$(slurmd -C | sed -n 's/^NodeName=[^ ]* //p')
[[ "$HW" == CPUs=*RealMemory=* ]] || die "slurmd -C did not report the node's CPUs and memory"

cat >"$CONF" <<EOF
# A one-node test cluster written by scripts/slurm_cluster.sh; served configless to slurmd.
ClusterName=omniscan-test
SlurmctldHost=$NODE(127.0.0.1)
SlurmctldPort=$PORT
SlurmdPort=$((PORT + 1))
SlurmctldParameters=enable_configless
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd.pid
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
# The cgroup plugins fail in containers.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
# No slurmdbd: no accounting, so status comes from squeue (finished jobs stay MinJobAge seconds).
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
MinJobAge=300
MpiDefault=none
SchedulerType=sched/backfill
# A job submitted while the node is busy starts at the next scheduling pass (60 s by default).
SchedulerParameters=sched_interval=1,bf_interval=1
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
NodeName=$NODE NodeAddr=127.0.0.1 $HW State=UNKNOWN
PartitionName=test Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF

# munge: a fresh key, the pid and seed files and the log in DIR; the socket in /run/munge, whose
# directory every client must be able to search.
if [ -S "$MUNGE_SOCKET" ] && munge -n -S "$MUNGE_SOCKET" >/dev/null 2>&1; then
  die "a munged already listens on $MUNGE_SOCKET (a system Slurm?); stop it first"
fi
if [ ! -d "$MUNGE_RUN" ]; then mkdir -p "$MUNGE_RUN"; MUNGE_RUN_MADE=1; fi
chmod 755 "$MUNGE_RUN"
rm -f "$MUNGE_SOCKET" "$MUNGE_SOCKET.lock"
dd if=/dev/urandom of="$DIR/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$DIR/munge/munge.key"
munged --foreground --force --socket="$MUNGE_SOCKET" --key-file="$DIR/munge/munge.key" \
  --pid-file="$DIR/munge/munged.pid" --seed-file="$DIR/munge/munged.seed" \
  --log-file="$DIR/log/munged.log" --origin=127.0.0.1 </dev/null >>"$DIR/log/munged.out" 2>&1 &
MUNGED_PID=$!

wait_for() {  # wait_for SECONDS WHAT COMMAND...: polls COMMAND every 0.1 s
  local seconds=$1 what=$2 i
  shift 2
  for i in $(seq $((seconds * 10))); do
    "$@" >/dev/null 2>&1 && return 0
    for pid in "$MUNGED_PID" "$CTLD_PID" "$SLURMD_PID"; do
      [ -z "$pid" ] || kill -0 "$pid" 2>/dev/null || die "a daemon (pid $pid) exited while waiting for $what"
    done
    sleep 0.1
  done
  die "$what: not within $seconds s"
}
munge_up() { munge -n | unmunge; }
wait_for 10 "munged answering" munge_up

slurmctld -D -i -f "$CONF" </dev/null >>"$DIR/log/slurmctld.out" 2>&1 &
CTLD_PID=$!
wait_for 20 "slurmctld answering" scontrol ping
slurmd -D --conf-server "127.0.0.1:$PORT" </dev/null >>"$DIR/log/slurmd.out" 2>&1 &
SLURMD_PID=$!
node_idle() { [ "$(sinfo -h -n "$NODE" -o %T)" = idle ]; }
wait_for 30 "node $NODE idle" node_idle

if [ $# -gt 0 ]; then
  echo "slurm_cluster: node $NODE idle; running $*" >&2
  set +e
  "$@"
  status=$?
  set -e
  exit "$status"
fi

echo "slurm_cluster: ready SLURM_CONF=$CONF pids=munged:$MUNGED_PID,slurmctld:$CTLD_PID,slurmd:$SLURMD_PID"
# Until stdin closes (the test's pipe, or Ctrl-D) or a signal: the wait is in the background, so
# that a signal is handled at once.
cat <&0 >/dev/null &
WATCH_PID=$!
wait "$WATCH_PID" || true
