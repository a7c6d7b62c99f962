#!/bin/sh
# make bench: the benchmark set, one JSON object per line on stdout.
# Usage: tools/bench.sh path/to/heatvox
set -e
hv=${1:-build/heatvox}
dir=$(dirname "$hv")
wisdom="$dir/fftw.wisdom"
for n in 128 256; do
  for b in mg fftw; do
    "$hv" bench solve --n $n --t-scale 4 --backend $b --wisdom "$wisdom"
    "$hv" bench solve --n $n --poisson --backend $b --wisdom "$wisdom"
  done
done
for b in mg fftw; do
  "$hv" bench solve --n 2048 --dim 2 --t-scale 4 --backend $b --wisdom "$wisdom"
  "$hv" bench solve --n 2048 --dim 2 --poisson --backend $b --wisdom "$wisdom"
done
# Extension off a level set against OpenVDB tools::sdfToExt in the same run
# (velocity field; dense sphere, narrow-band stanford-bunny when the shared
# meshes are there).
for n in 128 256; do
  "$hv" bench extend --n $n --shape sphere
done
shared=${HEATVOX_SHARED:-../shared}
if [ -f "$shared/meshes/stanford-bunny.obj" ]; then
  "$hv" bench extend --n 128 --shape "mesh:$shared/meshes/stanford-bunny.obj"
else
  echo "bench extend: $shared/meshes/stanford-bunny.obj not found, skipped" >&2
fi
