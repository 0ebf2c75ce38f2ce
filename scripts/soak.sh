#!/usr/bin/env bash
# A long run of the AR path: the bundled recording looped with the demo AR scene for 20,000 frames
# (bench-ar: reading on its own thread, compositing, no encoding), resident memory and frame time
# sampled every 200 frames. Then, in the same minutes, a fresh process runs 2,000 frames of the
# same: the shared machine's own speed moves by 10-20% over a soak's minutes, so the frame time at
# the soak's end is compared with the fresh run's, not only with the soak's start.
# Fails when memory grows by 5% or more after the warm-up (the first tenth), or when the soak's
# last quarter is 10% or more slower than the fresh run.
#
#   scripts/soak.sh [FRAMES] [OUT_PREFIX]      # defaults: 20000, docs/images/soak
#
# Writes OUT_PREFIX.csv, OUT_PREFIX_memory.png, OUT_PREFIX_frame_time.png, OUT_PREFIX.json and
# OUT_PREFIX_fresh.json.
set -euo pipefail
cd "$(dirname "$0")/.."
frames=${1:-20000}
prefix=${2:-docs/images/soak}
artrace=${ARTRACE:-./build/tools/artrace}
"$artrace" bench-ar data/recordings/room --scene data/ar/demo.json --frames "$frames" --threads 2 \
  --soak "$prefix" --json "$prefix.json"
"$artrace" bench-ar data/recordings/room --scene data/ar/demo.json --frames 2000 --threads 2 --json "${prefix}_fresh.json" > /dev/null
python3 - "$prefix.json" "${prefix}_fresh.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))["soak"]
fresh = json.load(open(sys.argv[2]))["frame_ms_median"]
vs_fresh = s["frame_ms_last_quarter"] / fresh - 1.0
ok = s["memory_growth"] < 0.05 and vs_fresh < 0.10
print(f"soak: memory growth {100 * s['memory_growth']:+.2f}% (limit 5%); frame time {s['frame_ms_first_quarter']:.2f} ms in the first quarter "
      f"after warm-up, {s['frame_ms_last_quarter']:.2f} ms in the last ({100 * s['frame_time_drift']:+.2f}%), a fresh process "
      f"{fresh:.2f} ms right after: the soak's end {100 * vs_fresh:+.2f}% (limit 10%): " + ("PASSED" if ok else "FAILED"))
sys.exit(0 if ok else 1)
PY
