#!/usr/bin/env bash
# A real one-node SLURM (Debian slurm-wlm + munge) on this machine, for tests and trials.
#
#   bash scripts/slurm_local.sh install          Debian packages (munge slurmctld slurmd slurm-client)
#   bash scripts/slurm_local.sh start [DIR]      configure and start munged, slurmctld, slurmd
#   bash scripts/slurm_local.sh stop  [DIR]      SIGTERM to the daemons, by the pids in DIR
#   bash scripts/slurm_local.sh status [DIR]     sinfo of the running cluster
#
# Everything lives in DIR (default /tmp/sliders-slurm): slurm.conf, the munge
# socket, pid files, state, logs.  Nothing under /etc is changed, so several
# clusters (one per test session) can run side by side: each has its own munge
# socket (AuthInfo=socket=...) and its own free ports.  Clients reach it with
#   export SLURM_CONF=DIR/slurm.conf
# which `start` prints as its last line.  Needs root (slurmd runs as root,
# munged as the munge user, slurmctld as the slurm user).  No systemd needed.
set -euo pipefail

PACKAGES=(munge slurmctld slurmd slurm-client)
cmd=${1:-}
DIR=${2:-${SLIDERS_SLURM_DIR:-/tmp/sliders-slurm}}
die() { echo "slurm_local.sh: $*" >&2; exit 1; }

need_root() { [ "$(id -u)" -eq 0 ] || die "must run as root (slurmd runs as root)"; }

pid_of() { cat "$DIR/$1.pid" 2>/dev/null || true; }
# a zombie (state Z) has stopped: it only waits for a parent that may never reap it
running() { [ -n "$1" ] && kill -0 "$1" 2>/dev/null && [ "$(awk '{print $3}' "/proc/$1/stat" 2>/dev/null)" != Z ]; }
alive() { running "$(pid_of "$1")"; }

free_port_pair() {  # two consecutive free TCP ports on localhost
  python3 - <<'EOF'
import socket
for base in range(16817, 30000, 2):
    socks = []
    try:
        for p in (base, base + 1):
            s = socket.socket(); s.bind(("127.0.0.1", p)); socks.append(s)
    except OSError:
        continue
    finally:
        for s in socks: s.close()
    print(base); break
EOF
}

write_conf() {
  local host=$1 port=$2 cpus
  cpus=$(getconf _NPROCESSORS_ONLN)  # the machine's, whatever OMP_NUM_THREADS says (nproc reads it)
  # MinJobAge=5: a finished job's record is kept 5 s (its state is read right after it leaves
  # the queue), and `sbatch --wait` polls every 2 s instead of 2, 8, then 32 s (Slurm 22.05
  # lengthens its poll while the poll is under MinJobAge/2): a 12 s job returned after 42 s.
  cat > "$DIR/slurm.conf" <<EOF
# Written by scripts/slurm_local.sh: one node on localhost, no accounting, no cgroups.
ClusterName=sliders-local
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=slurm
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$DIR/munge/munge.socket.2
MpiDefault=pmi2
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MailProg=/bin/true
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd.pid
StateSaveLocation=$DIR/ctld
SlurmdSpoolDir=$DIR/slurmd
SlurmctldLogFile=$DIR/slurmctld.log
SlurmdLogFile=$DIR/slurmd.log
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=5
KillWait=5
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
}

wait_for() {  # wait_for SECONDS command...: poll until the command succeeds
  local t=$1; shift
  for _ in $(seq $((t * 10))); do "$@" >/dev/null 2>&1 && return 0; sleep 0.1; done
  return 1
}

case "$cmd" in
  install)
    missing=()
    for p in "${PACKAGES[@]}"; do
      dpkg-query -W -f='${db:Status-Abbrev}' "$p" 2>/dev/null | grep -q '^ii' || missing+=("$p")
    done
    if ((${#missing[@]})); then
      SUDO=(); [ "$(id -u)" -eq 0 ] || SUDO=(sudo)
      "${SUDO[@]}" apt-get update -qq
      "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
        --no-install-recommends "${PACKAGES[@]}"
    fi
    ;;
  start)
    need_root
    for b in munged slurmctld slurmd sinfo; do
      command -v "$b" >/dev/null || die "$b not found; run: bash scripts/slurm_local.sh install"
    done
    if alive slurmctld && alive slurmd; then
      echo "export SLURM_CONF=$DIR/slurm.conf"; exit 0
    fi
    host=$(hostname -s)
    mkdir -p "$DIR/munge" "$DIR/ctld" "$DIR/slurmd"
    chmod 755 "$DIR"
    chown munge:munge "$DIR/munge"; chmod 755 "$DIR/munge"
    chown slurm:slurm "$DIR/ctld"
    : > "$DIR/slurmctld.log"; chown slurm:slurm "$DIR/slurmctld.log"
    # slurmctld writes its pid file after dropping to SlurmUser
    touch "$DIR/slurmctld.pid"; chown slurm:slurm "$DIR/slurmctld.pid"
    port=$(free_port_pair)
    [ -n "$port" ] || die "no free TCP port pair on localhost"
    write_conf "$host" "$port"
    export SLURM_CONF=$DIR/slurm.conf
    # munged refuses to run as root; it daemonises and writes its pid file
    runuser -u munge -- munged --socket="$DIR/munge/munge.socket.2" \
      --pid-file="$DIR/munge/munged.pid" --log-file="$DIR/munge/munged.log" \
      || die "munged did not start (see $DIR/munge/munged.log)"
    ln -sf munge/munged.pid "$DIR/munged.pid"
    wait_for 10 sh -c "munge -S '$DIR/munge/munge.socket.2' -n | unmunge -S '$DIR/munge/munge.socket.2'" \
      || die "munge does not answer on $DIR/munge/munge.socket.2"
    slurmctld || die "slurmctld did not start (see $DIR/slurmctld.log)"
    wait_for 20 scontrol ping || die "slurmctld does not answer (see $DIR/slurmctld.log)"
    slurmd || die "slurmd did not start (see $DIR/slurmd.log)"
    wait_for 30 sh -c "sinfo -h -N -o %t | grep -qx idle" \
      || die "node $host is not idle after 30 s: $(sinfo -h -N -o '%N %t %E' 2>&1) (see $DIR/slurmd.log)"
    echo "export SLURM_CONF=$DIR/slurm.conf"
    ;;
  stop)
    # by their pids, slurmd first (it reports to slurmctld), munged last
    for d in slurmd slurmctld munged; do
      p=$(pid_of "$d")
      running "$p" || continue
      kill -TERM "$p"
      for _ in $(seq 100); do running "$p" || break; sleep 0.1; done
      if running "$p"; then echo "slurm_local.sh: $d (pid $p) did not stop within 10 s" >&2; fi
    done
    ;;
  status)
    export SLURM_CONF=$DIR/slurm.conf
    sinfo
    ;;
  *) die "usage: $0 install | start [DIR] | stop [DIR] | status [DIR]" ;;
esac
