#!/usr/bin/env bash
# A one-node SLURM cluster on 127.0.0.1 (munge + slurmctld + slurmd), to try the cluster path of
# docs/scaling.md on one machine before a real cluster; the SLURM tests (tests/test_slurm.py) use it.
#
#   sudo bash scripts/local_slurm.sh start    # install slurm-wlm + munge with apt if absent, configure, start
#   sudo bash scripts/local_slurm.sh status   # daemons, node state (exit 0 when jobs can run)
#   sudo bash scripts/local_slurm.sh stop     # stop the daemons this script started
#
# The node gets all of `nproc` CPUs and 90% of the machine's memory. start is idempotent: daemons
# already running are left alone, a changed configuration restarts them. The configuration is
# /etc/slurm/slurm.conf (where sinfo, sbatch and submitit look for it); a slurm.conf this script
# did not write is never overwritten. State, logs and pid files: $LOCAL_SLURM_DIR
# (default /var/lib/rlgrasp-slurm). No accounting database: sacct answers "accounting storage is
# disabled"; hydra/launcher=slurm asks scontrol for its jobs' states instead (rlgrasp/slurm.py).
set -euo pipefail

STATE_DIR=${LOCAL_SLURM_DIR:-/var/lib/rlgrasp-slurm}
CONF=/etc/slurm/slurm.conf
MARKER="# Written by rlgrasp scripts/local_slurm.sh"
PARTITION=debug

die() { echo "local_slurm: $*" >&2; exit 1; }
say() { echo "local_slurm: $*"; }

pid_alive() {  # pid_alive <pid file>: the process it names is running
    [[ -s $1 ]] && kill -0 "$(cat "$1")" 2>/dev/null
}

need_root() {
    [[ $(id -u) -eq 0 ]] || die "must run as root (munged and slurmd start as root): sudo bash $0 $1"
}

ensure_packages() {
    local missing=()
    for bin in munged munge unmunge slurmctld slurmd sinfo sbatch scontrol; do
        command -v "$bin" >/dev/null 2>&1 || [[ -x /usr/sbin/$bin ]] || missing+=("$bin")
    done
    [[ ${#missing[@]} -eq 0 ]] && return 0
    command -v apt-get >/dev/null 2>&1 \
        || die "missing ${missing[*]} and no apt-get to install them: install SLURM (slurmctld, slurmd, client commands) and munge"
    say "installing slurm-wlm and munge with apt-get (missing: ${missing[*]})"
    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge; } \
        >"$STATE_DIR/apt.log" 2>&1 || die "apt-get install slurm-wlm munge failed; see $STATE_DIR/apt.log"
}

munge_ok() { munge -n 2>/dev/null | unmunge 2>/dev/null | grep -q 'STATUS: *Success'; }

start_munge() {
    if munge_ok; then
        return 0
    fi
    id munge >/dev/null 2>&1 || die "no munge user (is the munge package installed?)"
    install -d -o munge -g munge -m 0700 /etc/munge /var/log/munge /var/lib/munge
    install -d -o munge -g munge -m 0755 /run/munge
    if [[ ! -s /etc/munge/munge.key ]]; then
        head -c 1024 /dev/urandom >/etc/munge/munge.key
    fi
    chown munge:munge /etc/munge/munge.key
    chmod 0400 /etc/munge/munge.key
    su -s /bin/sh munge -c /usr/sbin/munged || die "munged did not start; see /var/log/munge/munged.log"
    touch "$STATE_DIR/munged.ours"
    for _ in $(seq 50); do munge_ok && return 0; sleep 0.1; done
    die "munged runs but 'munge -n | unmunge' fails; see /var/log/munge/munged.log"
}

write_conf() {  # prints "changed" when the configuration file was (re)written
    local host cpus mem_mb conf
    host=$(hostname -s)
    cpus=$(nproc)
    mem_mb=$(( $(awk '/^MemTotal:/ {print $2}' /proc/meminfo) / 1024 * 9 / 10 ))
    conf="$MARKER (start|stop|status); edits are overwritten.
ClusterName=local
SlurmctldHost=$host(127.0.0.1)
AuthType=auth/munge
CredType=cred/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$STATE_DIR/slurmctld
SlurmdSpoolDir=$STATE_DIR/slurmd
SlurmctldPidFile=$STATE_DIR/slurmctld.pid
SlurmdPidFile=$STATE_DIR/slurmd.pid
SlurmctldLogFile=$STATE_DIR/slurmctld.log
SlurmdLogFile=$STATE_DIR/slurmd.log
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
JobRequeue=1
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
SchedulerParameters=sched_interval=2
CommunicationParameters=NoCtldInAddrAny,NoInAddrAny
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=$PARTITION Nodes=$host Default=YES MaxTime=INFINITE State=UP"
    if [[ -e $CONF ]] && ! grep -qF "$MARKER" "$CONF"; then
        die "$CONF exists and was not written by this script; not overwriting it (move it away to use the local cluster)"
    fi
    if [[ -e $CONF ]] && [[ $(cat "$CONF") == "$conf" ]]; then
        return 0
    fi
    install -d -m 0755 /etc/slurm
    printf '%s\n' "$conf" >"$CONF"
    echo changed
}

stop_daemon() {  # stop_daemon <name> <pid file>
    local pid
    pid_alive "$2" || { rm -f "$2"; return 0; }
    pid=$(cat "$2")
    kill "$pid"
    for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || { rm -f "$2"; say "stopped $1 ($pid)"; return 0; }; sleep 0.1; done
    kill -9 "$pid" 2>/dev/null || true
    rm -f "$2"
    say "killed $1 ($pid)"
}

node_state() { sinfo -h -p "$PARTITION" -o '%T' 2>/dev/null | head -n1; }

cmd_start() {
    need_root start
    install -d -m 0755 "$STATE_DIR" "$STATE_DIR/slurmctld" "$STATE_DIR/slurmd"
    ensure_packages
    start_munge
    if [[ $(write_conf) == changed ]]; then
        say "wrote $CONF ($(nproc) CPUs, $(( $(awk '/^MemTotal:/ {print $2}' /proc/meminfo) / 1024 * 9 / 10 )) MB)"
        stop_daemon slurmd "$STATE_DIR/slurmd.pid"
        stop_daemon slurmctld "$STATE_DIR/slurmctld.pid"
    fi
    if ! pid_alive "$STATE_DIR/slurmctld.pid"; then
        /usr/sbin/slurmctld || die "slurmctld did not start; see $STATE_DIR/slurmctld.log"
    fi
    if ! pid_alive "$STATE_DIR/slurmd.pid"; then
        /usr/sbin/slurmd || die "slurmd did not start; see $STATE_DIR/slurmd.log"
    fi
    local state=""
    for _ in $(seq 60); do
        state=$(node_state)
        case $state in
            idle|mixed|allocated|completing) say "up: partition $PARTITION, node $(hostname -s) $state"; return 0 ;;
            down*|drain*) scontrol update NodeName="$(hostname -s)" State=RESUME >/dev/null 2>&1 || true ;;
        esac
        sleep 0.5
    done
    die "node not ready after 30 s (state: ${state:-no answer}); see $STATE_DIR/slurmctld.log and slurmd.log"
}

cmd_stop() {
    need_root stop
    stop_daemon slurmd "$STATE_DIR/slurmd.pid"
    stop_daemon slurmctld "$STATE_DIR/slurmctld.pid"
    if [[ -e $STATE_DIR/munged.ours ]]; then
        stop_daemon munged /run/munge/munged.pid
        rm -f "$STATE_DIR/munged.ours"
    fi
}

cmd_status() {
    local ok=0
    for d in slurmctld slurmd; do
        if pid_alive "$STATE_DIR/$d.pid"; then say "$d running ($(cat "$STATE_DIR/$d.pid"))"; else say "$d not running"; ok=1; fi
    done
    if command -v munge >/dev/null 2>&1 && munge_ok; then say "munge ok"; else say "munge not working"; ok=1; fi
    if command -v sinfo >/dev/null 2>&1 && sinfo >/dev/null 2>&1; then sinfo; else say "sinfo: no controller answers"; ok=1; fi
    return $ok
}

case ${1:-} in
    start) cmd_start ;;
    stop) cmd_stop ;;
    status) cmd_status ;;
    *) die "usage: bash $0 start|stop|status" ;;
esac
