#!/bin/sh
# make bench: the benchmark set, one JSON object per line on stdout.
# Usage: tools/bench/bench.sh path/to/heatvox
# Rows that need an OpenCL platform or ../shared/meshes are skipped (with a
# note on stderr) where those are missing.
set -e
hv=${1:-build/heatvox}
dir=$(dirname "$hv")
wisdom="$dir/fftw.wisdom"
meshes=${HEATVOX_TEST_DATA:-../shared/meshes}
export POCL_CACHE_DIR=${POCL_CACHE_DIR:-$(pwd)/$dir/pocl-cache}

backends="mg fftw"
if "$hv" devices -q >/dev/null 2>&1; then backends="$backends opencl"; else echo "bench: no OpenCL device, opencl rows skipped" >&2; fi

for n in 128 256; do
  for b in $backends; do
    "$hv" bench solve --n $n --t-scale 4 --backend $b --wisdom "$wisdom"
    "$hv" bench solve --n $n --poisson --backend $b --wisdom "$wisdom"
  done
done
for b in $backends; do
  "$hv" bench solve --n 2048 --dim 2 --t-scale 4 --backend $b --wisdom "$wisdom"
  "$hv" bench solve --n 2048 --dim 2 --poisson --backend $b --wisdom "$wisdom"
done
# With solid cells (PCG with the V-cycle inside); the reference is FFTW on the
# same box without them.
# A maze (walls on a lattice, a gap in each panel) is the hard case for
# geometric coarsening; every row reports the residual's reduction per
# iteration.
# Each with the geometric coarse levels and with aggregation (Galerkin
# operators that keep the walls; its set-up is in setup_seconds).
for o in ball baffles maze; do
  for c in geometric aggregation; do
    "$hv" bench solve --n 128 --t-scale 4 --obstacle $o --coarse $c --wisdom "$wisdom"
    "$hv" bench solve --n 128 --poisson --obstacle $o --coarse $c --wisdom "$wisdom"
  done
done
# Heat steps with walls at 256^3, against the plain box's heat step above.
for o in ball baffles maze; do
  "$hv" bench solve --n 256 --t-scale 4 --obstacle $o --coarse geometric --wisdom "$wisdom"
done
for o in baffles maze; do
  for c in geometric aggregation; do
    "$hv" bench solve --n 256 --poisson --obstacle $o --coarse $c --wisdom "$wisdom"
  done
done

bunny="$meshes/stanford-bunny.obj"
if [ -f "$bunny" ]; then
  for n in 128 256; do
    "$hv" bench sdf "$bunny" --n $n
  done
  # The narrow band alone (`heatvox sdf -o X.vdb`, tiles) against OpenVDB's
  # meshToLevelSet and write, whole processes with their peak RSS; the dense
  # block's band beside it up to 512^3.
  for n in 256 512; do
    "$hv" bench band "$bunny" --n $n --dense
  done
  for n in 1024 2048; do
    "$hv" bench band "$bunny" --n $n
  done
  # The same band on the device (kernels/tiles.cl): its stages' device
  # times, the bytes that cross, and the device's copy bandwidth beside.
  case " $backends " in *" opencl "*)
    for n in 256 512 1024 2048; do
      "$hv" bench band "$bunny" --n $n --backend opencl
    done ;;
  esac
  # 4096^3: the band streamed into the .vdb and packed as it is computed
  # (about 30 s and 1.4 GB on 2 cores) against OpenVDB's 117 s and 8.5 GB.
  "$hv" bench band "$bunny" --n 4096
  # A mesh left open by the repair (knot): the sign from the winding number
  # (auto) and, on request, from the heat method, which leaks out of openings.
  knot="$meshes/knot.obj"
  if [ -f "$knot" ]; then
    "$hv" bench sdf "$knot" --n 256
    "$hv" bench sdf "$knot" --n 256 --sign heat
  fi
  # The zero level set as a mesh (sdf --mesh-out), against the distance itself.
  "$hv" bench mesh "$bunny" --n 256
  # Surfaces from oriented points drawn on the bunny (heatvox sdf PTS.xyz
  # --mesh-out) against CGAL's Poisson reconstruction of the same points
  # ($dir/bench_ref_cgal, built by make bench; its rows are skipped without
  # it), clean and with scan defects, scored against the bunny.
  # --unoriented adds each set without its normals: heatvox's recovered
  # orientation against CGAL's (jet normals, mst_orient_normals) and
  # Open3D's (estimate_normals, orient_normals_consistent_tangent_plane)
  # from the same points, each with its Poisson reconstruction; about 16
  # minutes on 2 cores, the references' for the most part.
  o3d="$(dirname "$0")/bench_ref_open3d.py"
  keep="$dir/bench-points-keep"
  "$hv" bench points "$bunny" --n 128 --count 200000 --unoriented --open3d "$o3d" --keep "$keep"
  # The orientation's alternatives (the diffused line field, a Z2
  # synchronisation of its cells) on three of those clouds and a thin plate,
  # beside heatvox's own (numpy and scipy; about 3 minutes).
  if /usr/bin/python3 -c 'import scipy' 2>/dev/null; then
    PYTHONPATH="$(dirname "$0")/../../python" HEATVOX_LIBRARY="$dir/libheatvox.so" \
      /usr/bin/python3 "$(dirname "$0")/orient_alternatives.py" --t 0.25 --plate \
      "$keep/clean.xyz" "$keep/noise-0.5.xyz" "$keep/hole.xyz"
  else
    echo "bench: /usr/bin/python3 cannot import scipy, orientation alternatives skipped" >&2
  fi
  rm -rf "$keep"
  spot="$meshes/spot.obj"
  if [ -f "$spot" ]; then
    "$hv" bench points "$spot" --n 128 --count 200000 --unoriented --open3d "$o3d" \
      --scenario clean --scenario density-4 --scenario noise-0.5 --scenario all
  fi
  "$hv" bench points "$bunny" --n 64 --count 20000 --scenario clean --scenario noise-0.5
  # A million points to a 512^3 narrow band and its mesh (heatvox sdf
  # PTS.xyz -o X.vdb --mesh-out S.ply), with their normals and recovered,
  # against the bunny's own band and mesh in the same run.
  "$hv" bench points "$bunny" --n 512 --count 1000000 --scenario clean --scenario noise-0.5 \
    --band --unoriented
else
  echo "bench: $bunny not found, sdf, mesh and points rows skipped" >&2
fi

# 2D curves: 1M small closed paths (some nested), the repair against
# --no-repair on the same SVG.
"$hv" bench sdf2d --n 1000000

# Extension off a level set against OpenVDB tools::sdfToExt in the same run
# (velocity field; dense sphere, narrow-band stanford-bunny when the shared
# meshes are there).
for n in 128 256; do
  "$hv" bench extend --n $n --shape sphere
done
# the same on the OpenCL device (weights, solves and evaluation there)
case " $backends " in
  *" opencl "*) "$hv" bench extend --n 128 --shape sphere --backend opencl ;;
esac
if [ -f "$meshes/stanford-bunny.obj" ]; then
  for n in 128 256; do
    "$hv" bench extend --n $n --shape "mesh:$meshes/stanford-bunny.obj"
  done
else
  echo "bench extend: $meshes/stanford-bunny.obj not found, skipped" >&2
fi
# The extension on a narrow band as whole commands (heatvox extend -o X.vdb
# against OpenVDB sdfToExt reading and writing the same files), with peak RSS.
if [ -f "$meshes/stanford-bunny.obj" ]; then
  for n in 256 512 1024; do
    "$hv" bench extend-band "$meshes/stanford-bunny.obj" --n $n
  done
  # The same on the device (kernels/bandext.cl): its stages' device times,
  # the bytes that cross, and the device's copy bandwidth beside.
  case " $backends " in *" opencl "*)
    for n in 256 512 1024; do
      "$hv" bench extend-band "$meshes/stanford-bunny.obj" --n $n --backend opencl
    done ;;
  esac
else
  echo "bench extend-band: $meshes/stanford-bunny.obj not found, skipped" >&2
fi
# A simulation's loop: one extender, a moving sphere's level set as tiles.
"$hv" bench extend-loop --n 256
case " $backends " in *" opencl "*)
  for n in 256 512; do
    "$hv" bench extend-loop --n $n --backend opencl
  done ;;
esac
# The petsc backend (make mpi) under mpirun on 1 and 2 ranks, against mg on
# the same grid in the same run; skipped without build-mpi/heatvox.
mpi_hv=$(dirname "$hv")/../build-mpi/heatvox
if [ -x "$mpi_hv" ]; then
  for r in 1 2; do
    for n in 128 256; do
      for o in none baffles; do
        OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 \
          mpirun --oversubscribe -n $r "$mpi_hv" bench solve --n $n --t-scale 4 --backend petsc --obstacle $o --tol 1e-10
        OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 \
          mpirun --oversubscribe -n $r "$mpi_hv" bench solve --n $n --poisson --backend petsc --obstacle $o --tol 1e-10
      done
    done
    # The other preconditioners on the thin walls.
    for pc in pfmg gamg; do
      for p in "--t-scale 4" "--poisson"; do
        OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 \
          mpirun --oversubscribe -n $r "$mpi_hv" bench solve --n 128 $p --backend petsc --pc $pc --obstacle baffles --tol 1e-10 --repeat 1
      done
    done
    # The extension on a DMDA and the distance, against one process in the same run.
    for n in 128 256; do
      OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 \
        mpirun --oversubscribe -n $r "$(dirname "$mpi_hv")/bench_mpi" extend --n $n
    done
    # Every cell: closest points past the ghost layer read from their owners
    # (--corner: a small sphere in a corner, most of them).
    for s in "" --corner; do
      OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 \
        mpirun --oversubscribe -n $r "$(dirname "$mpi_hv")/bench_mpi" extend --n 128 --out-band 0 $s
    done
    # Two calls of one object: its solvers made in each call, or kept.
    for keep in false true; do
      OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 \
        mpirun --oversubscribe -n $r "$(dirname "$mpi_hv")/bench_mpi" distance --n 128 --calls 2 \
          -hv_distance_keep_solvers $keep
    done
  done
else
  echo "bench: no $mpi_hv (make mpi), petsc rows skipped" >&2
fi
# Geodesic distance around obstacles (the building, a 3D maze) against
# scikit-fmm's fast marching on the same grid, solid cells and source.
if /usr/bin/python3 -c 'import skfmm, pyopenvdb' 2>/dev/null; then
  /usr/bin/python3 "$(dirname "$0")/bench_distance.py" --heatvox "$hv" --n 128 256 512 --scene building
  /usr/bin/python3 "$(dirname "$0")/bench_distance.py" --heatvox "$hv" --n 128 256 --scene building --stages whole
  /usr/bin/python3 "$(dirname "$0")/bench_distance.py" --heatvox "$hv" --n 64 128 --scene maze
  # The stages on the device (fields there, the tiles chosen on the host).
  case " $backends " in *" opencl "*)
    /usr/bin/python3 "$(dirname "$0")/bench_distance.py" --heatvox "$hv" --n 128 256 --scene building --backend opencl;;
  esac
else
  echo "bench: /usr/bin/python3 cannot import skfmm or pyopenvdb, distance rows skipped" >&2
fi
if [ -x /usr/bin/python3 ]; then /usr/bin/python3 "$(dirname "$0")/bench_python.py" "$hv"; else echo "bench: no /usr/bin/python3, python rows skipped" >&2; fi
