#!/usr/bin/env bash
# Sharded export on one machine: the same clip (tum-fr1-rpy, 120 frames, with fr1_desk.json)
# rendered as 1, 2 and 4 shards run side by side by `artrace batch` (threads split between them),
# each shard a folder of PNGs, then joined into one .mp4. Prints wall times, frames/s and the
# join's cost per frame; writes OUT/shards.json.
#
#   scripts/bench-shards.sh [OUT]      # default docs/bench
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-docs/bench}
a=$(realpath "${ARTRACE:-./build/tools/artrace}")
data=$(realpath "${ARTRACE_SHARED_DATA:-../shared/data}")
rec=$data/rgbd/tum-fr1-rpy scene=$data/ar/fr1_desk.json frames=120 cores=$(nproc)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
results=()
calc() { awk "BEGIN { print $1 }"; }
for n in 1 2 4; do
  jobs=""
  for ((k = 0; k < n; ++k)); do
    a0=$((frames * k / n)) b0=$((frames * (k + 1) / n))
    jobs+="${jobs:+,}{\"recording\": \"$rec\", \"scene\": \"$scene\", \"output\": \"s$n/shard$k\", \"frames\": \"$a0:$b0\"}"
  done
  echo "{\"jobs\": [$jobs]}" > "$work/m$n.json"
  threads=$(( cores / n > 0 ? cores / n : 1 ))
  t0=$(date +%s.%N)
  "$a" batch "$work/m$n.json" --parallel $n --threads $threads > "$work/batch$n.log" 2>&1
  t1=$(date +%s.%N)
  "$a" join "$work"/s$n/shard* -o "$work/clip$n.mp4" -q
  t2=$(date +%s.%N)
  render=$(calc "$t1 - $t0") join=$(calc "$t2 - $t1")
  printf '%d shard(s), %d thread(s) each: render %.2f s (%.1f frames/s), join %.2f s (%.2f ms a frame), together %.1f frames/s\n' \
    $n $threads "$render" "$(calc "$frames / $render")" "$join" "$(calc "1000 * $join / $frames")" \
    "$(calc "$frames / ($render + $join)")"
  results+=("{\"shards\": $n, \"threads_each\": $threads, \"render_s\": $render, \"join_s\": $join, \"frames\": $frames}")
done
mkdir -p "$out"
( IFS=,; echo "{\"recording\": \"tum-fr1-rpy\", \"scene\": \"fr1_desk.json\", \"cores\": $cores, \"runs\": [${results[*]}]}" ) > "$out/shards.json"
