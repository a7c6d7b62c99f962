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
