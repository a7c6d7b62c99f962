#!/bin/sh
# Accuracy and speed report for `heatvox sdf` (tests/bench_sdf.c); slow, so not
# part of make check. Usage: tools/bench/bench_sdf.sh [res] [all|timing|analytic|real|defects]
# Needs the test meshes in $HEATVOX_TEST_DATA (default ../shared/meshes).
set -e
cd "$(dirname "$0")/../.."
make -s build/tests/bench_sdf
HEATVOX_TEST_DATA=${HEATVOX_TEST_DATA:-../shared/meshes} build/tests/bench_sdf "${1:-128}" "${2:-all}"
