#!/usr/bin/env bash
# Submits a sharded export to Slurm: a job array of shard tasks (shard.sbatch), sized from the
# recording's frame count, and a join (join.sbatch) that runs once every task has succeeded.
#
#   submit.sh RECORDING SCENE OUTPUT [--shards N | --shard-frames K] [--work DIR] [--artrace BIN]
#             [--cpus C] [--partition P] [--export-args "..."] [--sbatch-args "..."] [--setup "CMD"]
#   submit.sh --manifest MANIFEST.json [--artrace BIN] [--cpus C] [--partition P] [--setup "CMD"]
#   submit.sh --resubmit WORK       # shard tasks whose shard is missing, and a new join
#
# RECORDING, SCENE, OUTPUT and WORK must be on a filesystem every node sees. Prints the job ids
# ("array JID", "join JID"). A task that fails leaves no shard; --resubmit submits exactly the
# missing ones again (the first submission's settings are kept in WORK/submit.env). Node failures
# requeue tasks on their own (--requeue). --setup runs CMD in every task before artrace (a site's
# environment, e.g. --setup "module load opencv tbb"; it is kept for --resubmit too).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
artrace=${ARTRACE:-$(command -v artrace || echo "$here/../../build/tools/artrace")}
shards=0 shard_frames=0 work="" cpus=2 partition="" export_args="" sbatch_args="" manifest="" resubmit="" setup=""
positional=()
while (( $# )); do
  case $1 in
    --shards) shards=$2; shift 2 ;;
    --shard-frames) shard_frames=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --artrace) artrace=$2; shift 2 ;;
    --cpus) cpus=$2; shift 2 ;;
    --partition) partition=$2; shift 2 ;;
    --export-args) export_args=$2; shift 2 ;;
    --sbatch-args) sbatch_args=$2; shift 2 ;;
    --manifest) manifest=$2; shift 2 ;;
    --resubmit) resubmit=$2; shift 2 ;;
    --setup) setup=$2; shift 2 ;;
    -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
    *) positional+=("$1"); shift ;;
  esac
done
abs() { realpath -m "$1"; }
common=(--parsable --cpus-per-task="$cpus")
[ -n "$partition" ] && common+=(--partition="$partition")
# shellcheck disable=SC2206
[ -n "$sbatch_args" ] && common+=($sbatch_args)

submit_join() {  # $1: dependency job id
  sbatch "${common[@]}" --dependency="afterok:$1" --kill-on-invalid-dep=yes -o "$WORK/log/join_%j.out" \
    --export=ALL,SUBMIT_ENV="$WORK/submit.env" "$here/join.sbatch"
}

if [ -n "$manifest" ]; then
  export SETUP=$setup
  manifest=$(abs "$manifest")
  jobs=$(python3 -c 'import json,sys; print(len(json.load(open(sys.argv[1]))["jobs"]))' "$manifest")
  mkdir -p "$(dirname "$manifest")/log"
  jid=$(sbatch "${common[@]}" --array="0-$((jobs - 1))" -o "$(dirname "$manifest")/log/batch_%A_%a.out" \
        --export=ALL,ARTRACE="$(abs "$artrace")",MANIFEST="$manifest" "$here/manifest.sbatch")
  echo "array $jid"
  exit 0
fi

if [ -n "$resubmit" ]; then
  # shellcheck disable=SC1091
  source "$(abs "$resubmit")/submit.env"
  missing=()
  for (( id = 0; id < TASKS; id++ )); do
    [ -f "$(printf '%s/shard_%05d/shard.json' "$WORK" "$id")" ] || missing+=("$id")
  done
  if (( ${#missing[@]} == 0 )); then
    echo "every shard is complete"
    jid=$(sbatch "${common[@]}" -o "$WORK/log/join_%j.out" --export=ALL,SUBMIT_ENV="$WORK/submit.env" "$here/join.sbatch")
    echo "join $jid"
    exit 0
  fi
  list=$(IFS=,; echo "${missing[*]}")
  echo "missing shards: $list"
else
  (( ${#positional[@]} == 3 )) || { echo "usage: submit.sh RECORDING SCENE OUTPUT [options] (see --help)" >&2; exit 2; }
  RECORDING=$(abs "${positional[0]}") SCENE=$(abs "${positional[1]}") OUTPUT=$(abs "${positional[2]}")
  ARTRACE=$(abs "$artrace")
  [ -x "$ARTRACE" ] || { echo "submit.sh: $ARTRACE is not an executable (--artrace BIN)" >&2; exit 2; }
  TOTAL_FRAMES=$("$ARTRACE" info "$RECORDING" | awk '$1 == "frames:" {print $2}')
  [[ $TOTAL_FRAMES =~ ^[0-9]+$ ]] && (( TOTAL_FRAMES > 0 )) || { echo "submit.sh: cannot tell how many frames $RECORDING has" >&2; exit 1; }
  if (( shard_frames <= 0 )); then
    (( shards > 0 )) || shards=4
    shard_frames=$(( (TOTAL_FRAMES + shards - 1) / shards ))
  fi
  SHARD_FRAMES=$shard_frames
  TASKS=$(( (TOTAL_FRAMES + SHARD_FRAMES - 1) / SHARD_FRAMES ))
  WORK=$(abs "${work:-$OUTPUT.shards}")
  EXPORT_ARGS=$export_args SETUP=$setup
  mkdir -p "$WORK/log"
  declare -p RECORDING SCENE OUTPUT ARTRACE TOTAL_FRAMES SHARD_FRAMES TASKS WORK EXPORT_ARGS SETUP > "$WORK/submit.env"
  list="0-$((TASKS - 1))"
  echo "$TOTAL_FRAMES frames in $TASKS shards of $SHARD_FRAMES"
fi
jid=$(sbatch "${common[@]}" --array="$list" -o "$WORK/log/shard_%A_%a.out" --export=ALL,SUBMIT_ENV="$WORK/submit.env" \
      "$here/shard.sbatch")
echo "array $jid"
echo "join $(submit_join "$jid")"
