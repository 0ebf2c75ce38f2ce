#!/usr/bin/env bash
# The tests that run threads, under ThreadSanitizer: the kd-tree's and the wide BVH's parallel
# builds, the lazy BVH (nodes split by whichever ray arrives first), the two-level scene, the tiled
# renderer and Whitted shading, the occlusion's hole filling and refinement, the compositor and the
# export pipeline (reading on its own thread): the tests that compare thread counts, a stopped
# export, a real ONI recording composited. Fails on the first report. (The suite's long
# brute-force tests are left out: 10-20x slower under TSan.)
#
#   scripts/tsan.sh [GTEST_FILTER]
#
# Builds build-tsan/ (-DARTRACE_SANITIZE=thread, -O1, tests only) once. oneTBB's own library is
# not instrumented; .ci/tsan.supp lists what is suppressed and why.
set -euo pipefail
cd "$(dirname "$0")/.."
filter=${1:-'Renderer.*:Whitted.*:Occlusion.HoleFillingMatchesItsDefinitionForAnyThreadCount:Occlusion.RefinementMatchesItsDefinitionPixelByPixel:Compositor.*:ArRuntime.*:KdTree.BuildIsIdenticalForAnyThreadCount:WideBvh.BuildIsIdenticalForAnyThreadCount:WideBvh.SameHitsAsTheKdTree:Bvh.LazyBuildIsDeterministicAcrossThreads:Bvh.LazyAndFullMatchBruteForce:TwoLevelScene.PacketsEqualSingleRays:TwoLevelScene.ScrambledDeformingMeshStaysCorrect:Export.SameFramesForAnyThreadCount:Export.StoppedExportLeavesNoFile:Export.RealOniRecordingThroughTheArPath:RealScene.AnchorsSitOnTheFloorAndTheTable:FrameReader.*'}
if [ ! -f build-tsan/build.ninja ]; then
  cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g -DNDEBUG" \
    -DARTRACE_SANITIZE=thread -DARTRACE_BUILD_TOOLS=OFF -DARTRACE_WITH_EMBREE=OFF > /dev/null
fi
cmake --build build-tsan --target artrace_tests
TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$PWD/.ci/tsan.supp" \
  ./build-tsan/tests/artrace_tests --gtest_filter="$filter" --gtest_brief=1
