#!/usr/bin/env bash
# A real single-node Slurm cluster, started here (munged, slurmctld, slurmd as root, no systemd,
# everything in a temporary folder), runs a sharded export of the bundled recording through
# scripts/slurm/submit.sh: an array of shard tasks and a join after them. The joined frames must
# equal a one-machine export's bit for bit, and a clip joined from the same shards must hold every
# frame. Then a shard is deleted, as a failed task leaves it, and submit.sh --resubmit must redo
# exactly that one. Exit 77 (skipped) only where Slurm cannot start, saying why.
#
#   tests/slurm/slurm_test.sh ARTRACE_BINARY SOURCE_DIR
set -euo pipefail
artrace=$(realpath "$1")
src=$(realpath "$2")
skip() { echo "SKIPPED: $*"; exit 77; }

[ "$(id -u)" = 0 ] || skip "the cluster's daemons run as root here, and this is uid $(id -u)"
for c in munged mungekey slurmctld slurmd sbatch squeue sinfo scontrol; do
  command -v "$c" > /dev/null || skip "$c is not installed (scripts/install-deps.sh installs slurm-wlm and munge)"
done

S=$(mktemp -d /tmp/artrace-slurm.XXXXXX)
mkdir -p "$S"/{state,spool,log,run,munge,out}
cleanup() {
  status=$?
  if [ -n "${SLURM_CONF:-}" ]; then scontrol shutdown > /dev/null 2>&1 || true; fi
  [ -f "$S/munge/pid" ] && kill "$(cat "$S/munge/pid")" 2> /dev/null || true
  sleep 1
  pkill -f "slurmd -f $S/slurm.conf" 2> /dev/null || true
  pkill -f "slurmctld -f $S/slurm.conf" 2> /dev/null || true
  if [ $status -ne 0 ] && [ $status -ne 77 ]; then
    echo "--- slurmctld log"; tail -n 30 "$S/log/slurmctld.log" 2> /dev/null || true
    echo "--- slurmd log"; tail -n 30 "$S/log/slurmd.log" 2> /dev/null || true
    for f in "$S"/out/*.shards/log/*.out; do echo "--- $f"; cat "$f"; done 2> /dev/null || true
  fi
  rm -rf "$S"
}
trap cleanup EXIT

# ports of our own, away from a cluster the machine may run
base=$(( 20000 + ($$ % 2000) * 2 ))
mungekey -c -k "$S/munge/munge.key" -f > /dev/null 2>&1 || skip "mungekey cannot make a key"
chmod 600 "$S/munge/munge.key"
munged --key-file="$S/munge/munge.key" --socket="$S/munge/sock" --pid-file="$S/munge/pid" \
       --log-file="$S/munge/log" --seed-file="$S/munge/seed" --force || skip "munged does not start: $(tail -n 3 "$S/munge/log" 2> /dev/null)"
H=$(hostname -s)
cpus=$(nproc)
cat > "$S/slurm.conf" <<EOF
ClusterName=artrace-test
SlurmctldHost=$H
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$S/munge/sock
CredType=cred/munge
StateSaveLocation=$S/state
SlurmdSpoolDir=$S/spool
SlurmctldPidFile=$S/run/slurmctld.pid
SlurmdPidFile=$S/run/slurmd.pid
SlurmctldPort=$base
SlurmdPort=$(( base + 1 ))
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
SlurmctldLogFile=$S/log/slurmctld.log
SlurmdLogFile=$S/log/slurmd.log
NodeName=$H CPUs=$cpus RealMemory=1000 State=UNKNOWN
PartitionName=debug Nodes=$H Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$S/slurm.conf
slurmctld -f "$SLURM_CONF" || skip "slurmctld does not start: $(tail -n 3 "$S/log/slurmctld.log" 2> /dev/null)"
slurmd -f "$SLURM_CONF" || skip "slurmd does not start: $(tail -n 3 "$S/log/slurmd.log" 2> /dev/null)"
for i in $(seq 60); do
  sinfo -h -o %t 2> /dev/null | grep -qE '^(idle|mix|alloc)' && break
  sleep 0.5
  [ "$i" = 60 ] && skip "the node did not come up in 30 s: $(sinfo 2>&1 | tail -n 2)"
done
echo "cluster up: $(sinfo -h -o '%P %a %D %t %N')"

wait_idle() {  # until the queue is empty (or 300 s)
  for _ in $(seq 600); do
    [ -z "$(squeue -h -o %i 2> /dev/null)" ] && return 0
    sleep 0.5
  done
  echo "FAIL: jobs still queued after 300 s:"; squeue; return 1
}

rec=$src/data/recordings/room
scene=$src/data/ar/demo.json
frames=$S/out/frames

# the one-machine export to compare with
"$artrace" export "$rec" --scene "$scene" -o "$S/whole" -q --threads 1 > /dev/null

submit=$src/scripts/slurm/submit.sh
out=$("$submit" "$rec" "$scene" "$frames" --shards 4 --cpus 1 --artrace "$artrace")
echo "$out"
array=$(awk '$1 == "array" {print $2}' <<< "$out")
# a clip from the same shards, encoded once, after the same array
sbatch --parsable --dependency="afterok:$array" -o "$S/log/clip_%j.out" \
       --wrap "$artrace join $frames.shards/shard_* -o $S/out/clip.mp4 -q" > /dev/null
wait_idle

compare() {
  [ -f "$frames/shard.json" ] || { echo "FAIL: no joined frames at $frames"; return 1; }
  n=0
  for f in "$S"/whole/frame_*.png; do
    cmp -s "$f" "$frames/$(basename "$f")" || { echo "FAIL: $(basename "$f") differs from the one-machine export"; return 1; }
    n=$((n + 1))
  done
  joined=$(ls "$frames"/frame_*.png | wc -l)
  [ "$joined" = "$n" ] || { echo "FAIL: $joined joined frames, the export has $n"; return 1; }
  echo "joined frames equal the one-machine export's, bit for bit: $n frames"
}
compare
[ -f "$S/out/clip.mp4" ] || { echo "FAIL: no clip"; cat "$S"/log/clip_*.out; exit 1; }
clip_frames=$("$artrace" info "$S/out/clip.mp4" | awk '$1 == "frames:" {print $2}')
whole_frames=$(ls "$S"/whole/frame_*.png | wc -l)
[ "$clip_frames" = "$whole_frames" ] || { echo "FAIL: the clip has $clip_frames frames, the export $whole_frames"; exit 1; }
echo "the joined clip has every frame: $clip_frames"

# a task that failed leaves no shard: --resubmit redoes that one and joins again
rm -rf "$frames.shards/shard_00002" "$frames"
out=$("$submit" --resubmit "$frames.shards" --cpus 1)
echo "$out"
grep -q "missing shards: 2$" <<< "$out" || { echo "FAIL: expected shard 2 alone to be resubmitted"; exit 1; }
wait_idle
compare
echo "PASSED"
