#!/bin/sh
# Accuracy and speed report for `heatvox sdf` (tests/bench_sdf.c); slow, so not
# part of make check. Usage: tools/bench_sdf.sh [res] [all|timing|analytic|real|defects]
# Needs the shared meshes in $HEATVOX_SHARED (default ../shared).
set -e
cd "$(dirname "$0")/.."
make -s build/libheatvox.a build/obj/tests/bench_sdf.o
# --whole-archive: the FFTW backend is only reached through a weak reference,
# which does not pull its object out of a static archive.
${CXX:-g++} -o build/tests/bench_sdf build/obj/tests/bench_sdf.o \
    -Wl,--whole-archive build/libheatvox.a -Wl,--no-whole-archive -fopenmp \
    -lopenvdb -ltbb -lImath-3_1 -lOpenEXRCore-3_1 -lpng -lfftw3_threads -lfftw3f_threads \
    -lfftw3 -lfftw3f -lOpenCL -lm -lpthread
HEATVOX_SHARED=${HEATVOX_SHARED:-../shared} OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive} \
    build/tests/bench_sdf "${1:-128}" "${2:-all}"
