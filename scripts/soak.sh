#!/usr/bin/env bash
# A long run of the replay viewer: the bundled recording looped with the demo AR scene for 20,000
# views at full speed (replay --loop --speed 100: reading on its own thread, compositing, the
# head-up display, the window), under a virtual display (Xvfb) when there is none. Resident memory
# and the time of a view (composited and shown) are sampled every 200 views. Then, in the same
# minutes, a fresh process shows 2,000 views of the same: the shared machine's own speed moves by
# 10-20% over a soak's minutes, so the time at the soak's end is compared with the fresh run's, not
# only with the soak's start.
# Fails when memory grows by 5% or more after the warm-up (the first tenth), or when the soak's
# last quarter is 10% or more slower than the fresh run.
#
#   scripts/soak.sh [VIEWS] [OUT_PREFIX]      # defaults: 20000, docs/images/soak
#
# Writes OUT_PREFIX.csv, OUT_PREFIX_memory.png, OUT_PREFIX_frame_time.png, OUT_PREFIX.json and
# OUT_PREFIX_fresh.json.
set -euo pipefail
cd "$(dirname "$0")/.."
views=${1:-20000}
prefix=${2:-docs/images/soak}
artrace=${ARTRACE:-./build/tools/artrace}
xvfb_pid=
if [ -z "${DISPLAY:-}" ]; then
  command -v Xvfb > /dev/null || { echo "soak.sh: no display and no Xvfb (scripts/install-deps.sh installs it)"; exit 1; }
  fd_file=$(mktemp)
  Xvfb -displayfd 3 -screen 0 1280x1024x24 -nolisten tcp 3> "$fd_file" 2> /dev/null &
  xvfb_pid=$!
  trap 'kill $xvfb_pid 2> /dev/null; rm -f "$fd_file"' EXIT
  for _ in $(seq 100); do [ -s "$fd_file" ] && break; sleep 0.05; done
  [ -s "$fd_file" ] || { echo "soak.sh: Xvfb did not start"; exit 1; }
  export DISPLAY=":$(cat "$fd_file")"
fi
replay=("$artrace" replay data/recordings/room --scene data/ar/demo.json --threads 2 --loop --speed 100)
"${replay[@]}" --frames "$views" --soak "$prefix" --json "$prefix.json" 2>&1 | sed '/^QStandardPaths/d'
"${replay[@]}" --frames 2000 --json "${prefix}_fresh.json" > /dev/null 2>&1
python3 - "$prefix.json" "${prefix}_fresh.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))["soak"]
fresh = json.load(open(sys.argv[2]))["view_ms_median"]
vs_fresh = s["frame_ms_last_quarter"] / fresh - 1.0
ok = s["memory_growth"] < 0.05 and vs_fresh < 0.10
print(f"soak: memory growth {100 * s['memory_growth']:+.2f}% (limit 5%); a view {s['frame_ms_first_quarter']:.2f} ms in the first quarter "
      f"after warm-up, {s['frame_ms_last_quarter']:.2f} ms in the last ({100 * s['frame_time_drift']:+.2f}%), a fresh process "
      f"{fresh:.2f} ms right after: the soak's end {100 * vs_fresh:+.2f}% (limit 10%): " + ("PASSED" if ok else "FAILED"))
sys.exit(0 if ok else 1)
PY
