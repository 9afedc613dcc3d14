#!/usr/bin/env bash
# A real Slurm on this one machine, for tests and CI: a controller and two emulated
# nodes (n1, n2, 8 cores each as declared) under one scratch folder; no munge
# (auth/none), no accounting, no systemd. Needs the packages slurmctld, slurmd and
# slurm-client, and root (the daemons run as root).
#
#   scripts/slurm-local.sh start DIR   writes DIR/slurm.conf, starts the daemons, waits
#                                      until both nodes are idle (exit 1 if not in 30 s)
#   scripts/slurm-local.sh stop DIR    stops the daemons by their pid files
#
# Between the two, `export SLURM_CONF=DIR/slurm.conf` points sbatch, squeue and srun at it.
set -euo pipefail
usage="usage: $0 start|stop DIR"
command=${1:?$usage}
dir=$(realpath -m "${2:?$usage}")
case $command in
start)
    mkdir -p "$dir"/state "$dir"/log "$dir"/spool/n{1,2} "$dir"/tmp/n{1,2}
    host=$(hostname)
    # TmpFS per node: two emulated nodes must not share PMIx's folder ("File exists").
    # config_overrides: the nodes may declare more CPUs than the host has.
    cat >"$dir/slurm.conf" <<CONF
ClusterName=collide
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=16817
AuthType=auth/none
CredType=cred/none
SlurmUser=root
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool/%n
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd-%n.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd-%n.log
TmpFS=$dir/tmp/%n
ProctrackType=proctrack/linuxproc
TaskPlugin=task/affinity
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SlurmdParameters=config_overrides
ReturnToService=2
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
NodeName=n1 NodeHostname=$host NodeAddr=127.0.0.1 Port=17001 Sockets=2 CoresPerSocket=4 ThreadsPerCore=1
NodeName=n2 NodeHostname=$host NodeAddr=127.0.0.1 Port=17002 Sockets=2 CoresPerSocket=4 ThreadsPerCore=1
PartitionName=debug Nodes=n[1-2] Default=YES MaxTime=INFINITE State=UP
CONF
    export SLURM_CONF=$dir/slurm.conf
    slurmctld -i
    slurmd -N n1
    slurmd -N n2
    for _ in $(seq 60); do
        if [[ $(sinfo -h -o '%t' 2>/dev/null | sort -u) == idle ]]; then
            echo "slurm: n1 and n2 idle; export SLURM_CONF=$SLURM_CONF"
            exit 0
        fi
        sleep 0.5
    done
    echo "slurm: the nodes are not idle after 30 s; see $dir/log/" >&2
    sinfo >&2 || true
    exit 1
    ;;
stop)
    for pid_file in "$dir"/slurmd-n1.pid "$dir"/slurmd-n2.pid "$dir"/slurmctld.pid; do
        if [[ -f $pid_file ]]; then
            kill "$(cat "$pid_file")" 2>/dev/null || true
        fi
    done
    ;;
*)
    echo "$usage" >&2
    exit 2
    ;;
esac
