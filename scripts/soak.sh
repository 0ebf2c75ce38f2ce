#!/usr/bin/env bash
# A long run of the AR path: the bundled recording looped with the demo AR scene for 20,000 frames
# (bench-ar: reading on its own thread, compositing, no encoding), resident memory and frame time
# sampled every 200 frames. Fails when memory grows by 5% or more after the warm-up (the first
# tenth) or the frame time drifts by 10% or more (last quarter against the first after warm-up).
#
#   scripts/soak.sh [FRAMES] [OUT_PREFIX]      # defaults: 20000, docs/images/soak
#
# Writes OUT_PREFIX.csv, OUT_PREFIX_memory.png, OUT_PREFIX_frame_time.png and OUT_PREFIX.json.
set -euo pipefail
cd "$(dirname "$0")/.."
frames=${1:-20000}
prefix=${2:-docs/images/soak}
artrace=${ARTRACE:-./build/tools/artrace}
"$artrace" bench-ar data/recordings/room --scene data/ar/demo.json --frames "$frames" --threads 2 \
  --soak "$prefix" --json "$prefix.json"
python3 - "$prefix.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))["soak"]
ok = s["memory_growth"] < 0.05 and abs(s["frame_time_drift"]) < 0.10
print(f"soak: memory growth {100 * s['memory_growth']:+.2f}% (limit 5%), frame-time drift {100 * s['frame_time_drift']:+.2f}% (limit 10%): "
      + ("PASSED" if ok else "FAILED"))
sys.exit(0 if ok else 1)
PY
