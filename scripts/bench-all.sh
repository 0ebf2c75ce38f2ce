#!/usr/bin/env bash
# Every benchmark figure of docs/benchmarks.md except Table 1 (report-bart, about 30 minutes: its
# command is in docs/benchmarks.md), written as JSON into docs/bench/ (or OUT). Run after the
# README's build, on an otherwise idle machine; it takes about 10 minutes on 2 cores.
#
#   scripts/bench-all.sh [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-docs/bench}
a=${ARTRACE:-./build/tools/artrace}
data=${ARTRACE_SHARED_DATA:-../shared/data}
kitchen=$data/bart/kitchen/aff/kitchen.aff robots=$data/bart/robots/aff/Robot.aff
fr1=$data/rgbd/tum-fr1-rpy tabletop=$data/rgbd/oni-kinect1-tabletop-4f/Captured.oni qvga=$data/rgbd/oni-qvga-cc-40f/test.oni
mkdir -p "$out"
run() { echo "== $*"; "$@"; }

# the core against Embree: 8- and 16-ray packets, kitchen at t=0 and t=10, robots at t=10
for lanes in 8 16; do
  sfx=$([ $lanes = 16 ] && echo _lanes16 || true)
  run "$a" bench-core --scene "$kitchen" --time 0  --threads 2 --runs 7 --lanes $lanes --reference embree --json "$out/kitchen_t0$sfx.json"
  run "$a" bench-core --scene "$kitchen" --time 10 --threads 2 --runs 7 --lanes $lanes --reference embree --json "$out/kitchen_t10$sfx.json"
  run "$a" bench-core --scene "$robots"  --time 10 --threads 2 --runs 7 --lanes $lanes --reference embree --json "$out/robots_t10$sfx.json"
done
# build scaling: the kitchen with every triangle split into 4^K
for k in 0 1 2; do run "$a" bench-core --scene "$kitchen" --threads 2 --runs 3 --subdivide $k --json "$out/scale$k.json"; done
# animated scenes through the update API
for s in kitchen robots; do
  scene=$([ $s = kitchen ] && echo "$kitchen" || echo "$robots")
  run "$a" bench-dynamic --scene "$scene" --frames 800 --threads 2 --config kdtree+bvh --json "$out/dynamic_${s}_kdtree_bvh.json"
  run "$a" bench-dynamic --scene "$scene" --frames 800 --threads 2 --config bvh        --json "$out/dynamic_${s}_bvh.json"
done
# reading recordings (one thread, decoding included)
run "$a" bench-io "$fr1"      --json "$out/io_fr1.json"
run "$a" bench-io "$tabletop" --json "$out/io_oni_tabletop.json"
run "$a" bench-io "$qvga"     --json "$out/io_oni_qvga.json"
# occlusion accuracy on the synthetic room with Kinect-like depth
run "$a" bench-occlusion --scene data/scenes/room.aff --frames 60 --fuse --json "$out/occlusion_room.json"
# the AR path end to end (bench-ar: reading overlapped, no encoding), then export with encoding
run "$a" bench-ar "$fr1"      --scene "$data/ar/fr1_desk.json" --threads 2 --json "$out/ar_fr1_desk.json"
run "$a" bench-ar "$tabletop" --scene data/ar/tabletop.json    --threads 2 --frames 120 --json "$out/ar_tabletop.json"
run "$a" bench-ar data/recordings/room --scene data/ar/demo.json --threads 2 --frames 120 --json "$out/ar_room_demo.json"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# models anchored on the real desk: contact steadiness with the raw depth and with the fused room
run "$a" fuse "$fr1" -o "$tmp/fr1_room.ply" -q --json "$out/fuse_fr1.json"
run "$a" bench-ar "$fr1" --scene data/ar/fr1_anchored.json --threads 2 --contact --json "$out/ar_fr1_anchored.json"
run "$a" bench-ar "$fr1" --scene data/ar/fr1_anchored.json --threads 2 --contact --room "$tmp/fr1_room.ply" --json "$out/ar_fr1_anchored_room.json"
# export, encoding included (its last lines: frames/s and the stages' medians)
echo "== $a export $fr1 --scene $data/ar/fr1_desk.json --threads 2 -o fr1_desk.mp4"
"$a" export "$fr1" --scene "$data/ar/fr1_desk.json" --threads 2 -o "$tmp/fr1_desk.mp4" 2>&1 | tr '\r' '\n' | tail -2 | tee "$out/export_fr1_desk.txt"
