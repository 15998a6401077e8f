#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, from Debian's packages: munge (authentication),
# slurmctld (controller) and slurmd (compute daemon) for partition `debug` with every CPU of this
# machine. Used by CI for the Slurm sweep test (tests/slurm.rs); also handy to try
# `sonoflow sweep --executor slurm` on a workstation. Needs root. Idempotent: daemons already
# running are left alone. No systemd needed (containers): the daemons are started directly.
#
# Usage: sudo bash .ci/slurm-single-node.sh        then: sinfo; sbatch --wrap hostname
#        sudo bash .ci/slurm-single-node.sh stop   stops the daemons again
set -euo pipefail

if [ "$(id -u)" != 0 ]; then
  echo "slurm-single-node: run as root (installs packages, writes /etc/slurm, starts daemons)" >&2
  exit 1
fi

if [ "${1:-}" = stop ]; then
  pkill -x slurmd || true
  pkill -x slurmctld || true
  pkill -x munged || true
  exit 0
fi

if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v sbatch >/dev/null \
   || ! command -v munged >/dev/null; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q >/dev/null
  apt-get install -y -q --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null
fi

# The daemons' users (the packages create them; made here if a minimal image lacks them).
for u in munge slurm; do
  id "$u" >/dev/null 2>&1 || useradd --system --no-create-home --shell /usr/sbin/nologin "$u"
done

# munge: a key (the package usually makes one), its folders owned by the munge user.
if [ ! -s /etc/munge/munge.key ]; then
  if command -v mungekey >/dev/null; then mungekey --create --force; else
    dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key status=none
  fi
fi
mkdir -p /run/munge /var/log/munge /var/lib/munge
chown -R munge:munge /etc/munge /run/munge /var/log/munge /var/lib/munge
chmod 0700 /etc/munge /var/log/munge /var/lib/munge
chmod 0755 /run/munge
chmod 0400 /etc/munge/munge.key
if ! pgrep -x munged >/dev/null; then
  runuser -u munge -- /usr/sbin/munged
fi
munge -n | unmunge >/dev/null

# slurm.conf for this one node: its real CPU count and memory, processes tracked without cgroups
# (containers often have no writable cgroup tree), consumable cores so that tasks share the node.
host=$(hostname -s)
cpus=$(nproc)
mem_mb=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 * 9 / 10 ))
mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
chown -R slurm:slurm /var/spool/slurmctld /var/log/slurm 2>/dev/null || true
cat > /etc/slurm/slurm.conf <<EOF
# Written by sonoflow's .ci/slurm-single-node.sh: a one-node cluster for tests.
ClusterName=sonoflow-ci
SlurmctldHost=${host}
SlurmUser=slurm
AuthType=auth/munge
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
SlurmdTimeout=300
MaxArraySize=1001
NodeName=${host} CPUs=${cpus} RealMemory=${mem_mb} State=UNKNOWN
PartitionName=debug Nodes=${host} Default=YES MaxTime=INFINITE State=UP
EOF
chmod 0644 /etc/slurm/slurm.conf

if ! pgrep -x slurmctld >/dev/null; then
  /usr/sbin/slurmctld
fi
if ! pgrep -x slurmd >/dev/null; then
  /usr/sbin/slurmd
fi

# Wait until the node takes jobs.
for _ in $(seq 1 60); do
  state=$(sinfo -h -n "$host" -o %t 2>/dev/null || true)
  case "$state" in
    idle*|mix*|alloc*) break ;;
    down*|drain*) scontrol update NodeName="$host" State=RESUME 2>/dev/null || true ;;
  esac
  sleep 1
done
state=$(sinfo -h -n "$host" -o %t 2>/dev/null || true)
case "$state" in
  idle*|mix*|alloc*) echo "slurm-single-node: node $host ($cpus CPUs) is $state in partition debug" ;;
  *)
    echo "slurm-single-node: node $host did not come up (state '$state'); logs:" >&2
    tail -20 /var/log/slurm/slurmctld.log /var/log/slurm/slurmd.log >&2 || true
    exit 1 ;;
esac
