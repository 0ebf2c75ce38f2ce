#!/usr/bin/env bash
# Coverage-guided fuzzing of every reader with libFuzzer (Clang, ASan, UBSan), in process.
#
#   scripts/fuzz.sh [SECONDS_EACH] [HARNESS...]      # default 30 s each, every harness
#   RUNS=10000000 scripts/fuzz.sh 0 aff              # a campaign: a number of executions instead
#   ASAN_OPTIONS=malloc_context_size=0 RUNS=...      # campaigns: no allocation stacks kept
#                                                    # (fuzz_gltf: 3,100 to 3,900 executions/s, one
#                                                    # run each); rerun a finding without it
#   LANES=2 scripts/fuzz.sh 30                       # two harnesses at a time (one core each)
#   SEEDED=1 LANES=2 scripts/fuzz.sh          # CI: a fixed seed and a fixed number of
#                                                    # executions each (about 30 s on 2 cores)
#
# CI runs the seeded form: a fixed seed and a fixed amount of work a harness. libFuzzer still
# wanders a little from run to run (two runs on 2026-12-03 ended within 3% of each other's
# coverage), so CI can still meet something new; that is a real bug: fix it and add its input to
# the corpus. Wider exploration is the campaigns' job.
#
# Builds build-fuzz/ (CXX=clang++ -DARTRACE_FUZZ=ON) once, then runs each fuzz_<reader> on a copy
# of its seed corpus (tests/fuzz/corpus/<reader>, kept in the repository) with its dictionary, and fails
# on the first crash, leak, sanitizer report or hang (> 10 s on one input). The crashing input is
# kept as build-fuzz/findings/<reader>/crash-*; make it a regression test, fix, and run again.
# A summary line per harness (executions, executions/s, coverage) goes to build-fuzz/fuzz-summary.txt.
# The whole script is one block, read before it runs: a campaign runs for hours, and bash reads a
# script as it goes, so an edit made meanwhile would otherwise change what the running one does.
{
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-30}
shift || true
all=(aff ppm gltf ar_scene tum oni oni_codecs intrinsics png)
harnesses=("$@")
(( ${#harnesses[@]} )) || harnesses=("${all[@]}")
command -v clang++ > /dev/null || { echo "fuzz.sh: clang++ is missing (scripts/install-deps.sh installs clang)"; exit 1; }
if [ ! -f build-fuzz/build.ninja ]; then
  CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g" \
    -DARTRACE_FUZZ=ON -DARTRACE_BUILD_TESTS=OFF -DARTRACE_BUILD_TOOLS=OFF -DARTRACE_WITH_EMBREE=OFF > /dev/null
fi
cmake --build build-fuzz --target fuzzers
summary=build-fuzz/fuzz-summary.txt
: > "$summary"
dict_of() {
  case $1 in
    aff) echo tests/fuzz/dict/aff.dict ;;
    gltf|ar_scene) echo tests/fuzz/dict/json.dict ;;
    tum) echo tests/fuzz/dict/tum.dict ;;
    intrinsics) echo tests/fuzz/dict/intrinsics.dict ;;
    png) echo tests/fuzz/dict/png.dict ;;
  esac
}
# executions of the seeded (CI) run: about 30 s of each harness on a 2-core AMD EPYC with AVX2
ci_runs_of() {
  case $1 in
    aff) echo 100000 ;; ppm) echo 500000 ;; gltf) echo 90000 ;; ar_scene) echo 120000 ;;
    tum) echo 400000 ;; oni) echo 90000 ;; oni_codecs) echo 2000000 ;; intrinsics) echo 200000 ;; png) echo 100000 ;;
  esac
}
fuzz_one() {
  local h=$1 work findings args d log code execs rate cov line
  work=build-fuzz/corpus/$h findings=build-fuzz/findings/$h
  mkdir -p "$work" "$findings"
  cp -n tests/fuzz/corpus/"$h"/* "$work"/ 2> /dev/null || true
  args=(-timeout=10 -rss_limit_mb=2048 -max_len=65536 -print_final_stats=1 -artifact_prefix="$findings/")
  d=$(dict_of "$h")
  [ -n "$d" ] && args+=(-dict="$d")
  if [ -n "${SEEDED:-}" ]; then
    # a fixed seed and amount of work, with a time cap for a slow machine
    args+=(-seed=1 -runs="$(ci_runs_of "$h")" -max_total_time=120)
  elif [ -n "${RUNS:-}" ]; then args+=(-runs="$RUNS"); else args+=(-max_total_time="$seconds"); fi
  [ -n "${JOBS:-}" ] && args+=(-fork="$JOBS")
  log=build-fuzz/fuzz_$h.log
  if [ -n "${SEEDED:-}" ]; then echo "== fuzz_$h (seed 1, $(ci_runs_of "$h") executions)"
  elif [ -n "${RUNS:-}" ]; then echo "== fuzz_$h ($RUNS executions)"
  else echo "== fuzz_$h (${seconds} s)"; fi
  set +e
  ./build-fuzz/tests/fuzz/fuzz_"$h" "${args[@]}" "$work" > "$log" 2>&1
  code=$?
  set -e
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | tail -1 | grep -o '[0-9]*$' || true)
  rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$log" | tail -1 | grep -o '[0-9]*$' || true)
  cov=$(grep -oE 'cov: [0-9]+ ft: [0-9]+' "$log" | tail -1 || true)
  line="fuzz_$h: ${execs:-?} executions, ${rate:-?}/s, ${cov:-cov ?}, corpus $(ls "$work" | wc -l) files"
  if [ $code -ne 0 ]; then
    line="$line: FAILED (exit $code), see $log and $findings"
    grep -E 'ERROR|SUMMARY|runtime error' "$log" | head -5 || true
    echo "$line" | tee -a "$summary"
    return 1
  fi
  echo "$line" | tee -a "$summary"
}
status=0 running=0
for h in "${harnesses[@]}"; do
  if (( ${LANES:-1} > 1 )); then
    fuzz_one "$h" &
    if (( ++running >= LANES )); then wait -n || status=1; running=$((running - 1)); fi
  else
    fuzz_one "$h" || status=1
  fi
done
while (( running > 0 )); do wait -n || status=1; running=$((running - 1)); done
exit $status
}
