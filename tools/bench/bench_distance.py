#!/usr/bin/python3
"""make bench: geodesic distance around obstacles against scikit-fmm, one JSON object per line.

usage: tools/bench/bench_distance.py [--heatvox PATH] [--n N ...] [--scene building|maze ...]
                                     [--stages tiles|whole ...] [--backend B]

`heatvox distance` (the heat method) against scikit-fmm's fast marching
(`skfmm.distance`, second order) on the same grid, the same solid cells and
the same source point, at N cells along the longest axis (default 128 256).

Scenes:
  building  scenes/distance/building.obj of `heatvox make-scenes` (boxes with a
            door, an inner doorway and a sealed closet), the source of its
            sources.txt, `--obstacle-mesh building.obj --res N`
  maze      an N^3 box of rooms (4 a side) behind one-voxel walls, doors cut in
            the walls along a spanning tree of the rooms (seeded), so every room
            is reached by one winding way; written as a bool .vdb mask and
            passed with `--obstacles`, one source point in a corner room

heatvox runs as a whole process (`-o OUT.vdb --npy OUT.npy`): seconds is its
wall time, peak_rss_mb its peak resident set (both commands are spawned from
a small launcher process, whose start is not counted). The distance is read from the
.npy (checked against the .vdb's `distance` grid), the solid cells from its
`obstacles` grid, the grid's placement from its transform.

The reference gets that grid and those solid cells as a masked array:
phi = |x - p| - h at each cell centre x (a ball of radius h around the source
point p, so at least one cell centre is inside), and the distance is
skfmm.distance(phi, dx=h, order=2) + h, about |x - p| wherever the straight
line is free (within a few tenths of a voxel next to p). It runs in a Python process of its own that loads phi and the
mask first: reference_seconds is the skfmm.distance call alone
(time.perf_counter), reference_peak_rss_mb that process's peak resident set
(interpreter, NumPy, phi and mask, the call), reference_call_rss_mb the rise of
that peak over the call (ru_maxrss before and after). per_cell_us: seconds per
cell of the whole grid (solid cells included), in microseconds.

Compared on the cells free and finite in both: the mean, 99th percentile and
largest absolute difference in voxels (difference / h), and mean_rel_diff, the
mean of |difference| / reference on the cells 2 voxels or more from p. Cells heatvox leaves
unreachable (inf) should be left unreached (masked) by the marching too:
reach_disagree counts the free cells where the two differ. Without skfmm or
pyopenvdb the rows are skipped with a note on stderr.

Other keys: grid (cells along x, y, z), h, backend and stages (from heatvox's
summary), stage_solves (--stages: tiles, the default, or whole), heatvox's
cells_solved_grids and its seconds per kind of work (set-up, splat,
diffusion, normalization, Poisson), per_cell_growth and
reference_per_cell_growth (time per cell against the previous --n's row),
device and host_bytes (--backend opencl: the device's name, and the bytes the
stages moved between host and device), reported_seconds (the seconds the summary gives), ratio (seconds /
reference_seconds), solid_cells, cells_compared, unreached_heatvox and
unreached_reference (free cells without a distance: a sealed room, and the
insides of solid boxes once they are thicker than two cells).
"""

import argparse
import importlib
import json
import os
import random
import subprocess
import sys
import tempfile

CHILD = r"""
import json, resource, sys, time
import numpy as np
import skfmm
phi = np.load(sys.argv[1])
solid = np.load(sys.argv[2])
h = float(sys.argv[3])
m = np.ma.MaskedArray(phi, solid)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
d = skfmm.distance(m, dx=h, order=2)
t1 = time.perf_counter()
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
out = np.ma.filled(np.ma.asarray(d).astype(np.float64), np.inf)
np.save(sys.argv[4], out)
print(json.dumps({"seconds": t1 - t0, "call_rss_mb": (after - before) / 1024.0}))
"""

# Runs a command and writes its wall time and peak RSS to argv[1]. A child's
# ru_maxrss starts from the peak of the process it was spawned from, so the
# commands are spawned from this small process, not from the one holding the
# fields.
LAUNCH = r"""
import json, os, subprocess, sys, time
t0 = time.perf_counter()
p = subprocess.Popen(sys.argv[2:])
_, status, ru = os.wait4(p.pid, 0)
wall = time.perf_counter() - t0
with open(sys.argv[1], "w") as f:
    json.dump({"seconds": wall, "peak_rss_mb": ru.ru_maxrss / 1024.0}, f)
sys.exit(os.waitstatus_to_exitcode(status))
"""

ROOMS = 4  # maze rooms along each axis
SEED = 1


def wait_timed(argv, d):
    """Runs argv through LAUNCH; returns (wall seconds, peak RSS in MB, stdout). Exits on failure."""
    res = os.path.join(d, "launch.json")
    p = subprocess.run([sys.executable, "-c", LAUNCH, res] + argv, capture_output=True)
    if p.returncode != 0:
        err = p.stderr.decode(errors="replace").strip() or "no message"
        sys.exit("bench_distance: %s: exit %d: %s" % (" ".join(argv), p.returncode, err))
    with open(res) as f:
        m = json.load(f)
    return m["seconds"], m["peak_rss_mb"], p.stdout.decode()


def maze_mask(n, np):
    """The maze's solid cells, an n^3 bool array indexed [x][y][z]."""
    w = [round(k * (n - 1) / ROOMS) for k in range(ROOMS + 1)]
    solid = np.zeros((n, n, n), bool)
    for a in range(3):
        for k in w:
            solid[(slice(None),) * a + (k,)] = True
    rng = random.Random(SEED)
    for room, nb, axis in spanning_tree(rng):
        cut_door(solid, w, room, nb, axis, rng)
    return solid, w


def spanning_tree(rng):
    """The doors of the maze: (room, neighbour, axis) along a random depth-first tree of the rooms."""
    seen, stack, doors = {(0, 0, 0)}, [(0, 0, 0)], []
    while stack:
        nbs = new_neighbours(stack[-1], seen)
        if not nbs:
            stack.pop()
            continue
        q, a = rng.choice(nbs)
        doors.append((stack[-1], q, a))
        seen.add(q)
        stack.append(q)
    return doors


def new_neighbours(r, seen):
    """The rooms next to room r not in seen, each with the axis between them."""
    nbs = []
    for a in range(3):
        for s in (-1, 1):
            q = tuple(r[b] + (s if b == a else 0) for b in range(3))
            if all(0 <= c < ROOMS for c in q) and q not in seen:
                nbs.append((q, a))
    return nbs


def cut_door(solid, w, room, nb, axis, rng):
    """Opens a square door, a third of the panel wide, in the wall between two rooms."""
    idx = []
    for b in range(3):
        if b == axis:
            idx.append(w[max(room[b], nb[b])])
            continue
        lo, hi = w[room[b]] + 1, w[room[b] + 1]  # free span [lo, hi)
        side = max(1, (hi - lo) // 3)
        start = rng.randrange(lo, hi - side + 1)
        idx.append(slice(start, start + side))
    solid[tuple(idx)] = False


def write_maze(d, n, np, vdb):
    """Writes the maze mask and its source; returns heatvox's arguments for it."""
    solid, w = maze_mask(n, np)
    h = 1.0 / n
    g = vdb.BoolGrid()
    g.copyFromArray(solid)
    g.transform = vdb.createLinearTransform(voxelSize=h)
    g.name = "maze"
    mask = os.path.join(d, "maze.vdb")
    vdb.write(mask, grids=[g])
    c = 0.5 * (w[0] + w[1])  # the corner room's centre, off the cell centres
    src = os.path.join(d, "maze_sources.txt")
    with open(src, "w") as f:
        f.write("%.9g %.9g %.9g\n" % ((c + 0.3) * h, (c - 0.2) * h, (c + 0.45) * h))
    return ["--sources", src, "--obstacles", mask]


def write_building(hv, d, n):
    """Writes the scenes of make-scenes; returns heatvox's arguments for the building."""
    wait_timed([hv, "make-scenes", "-q", d], d)
    s = os.path.join(d, "distance")
    return ["--sources", os.path.join(s, "sources.txt"), "--obstacle-mesh", os.path.join(s, "building.obj"),
            "--res", str(n)]


def source_points(path):
    """The world points of a sources file (lines `x y z` or `point x y z`)."""
    pts = []
    with open(path) as f:
        for line in f:
            t = line.split("#")[0].split()
            if t and t[0] == "point":
                t = t[1:]
            if not t:
                continue
            if len(t) != 3:
                sys.exit("bench_distance: %s: only world points are compared: %s" % (path, line.strip()))
            pts.append([float(v) for v in t])
    return pts


def grid_of(vdb, grids, name):
    """The grid of that name in a list read by pyopenvdb.readAll."""
    for g in grids:
        if g.name == name:
            return g
    sys.exit("bench_distance: no grid '%s' in heatvox's output" % name)


def read_output(vdb_path, npy_path, np, vdb):
    """heatvox's output: distance [x][y][z], solid [x][y][z], world of index lo, h."""
    grids, _ = vdb.readAll(vdb_path)
    dg = grid_of(vdb, grids, "distance")
    lo = tuple(dg.metadata.get("heatvox_block_min", dg.evalActiveVoxelBoundingBox()[0]))
    dist = np.load(npy_path).transpose(2, 1, 0)  # the .npy is [z][y][x]
    check = np.zeros(dist.shape, np.float32)
    dg.copyToArray(check, ijk=lo)
    if not np.array_equal(check, dist):
        sys.exit("bench_distance: the .npy differs from the .vdb's distance grid")
    solid = np.zeros(dist.shape, bool)
    grid_of(vdb, grids, "obstacles").copyToArray(solid, ijk=lo)
    h = dg.transform.voxelSize()[0]
    return np.ascontiguousarray(dist), solid, np.array(dg.transform.indexToWorld(lo)), h


def ball_phi(shape, origin, h, pts, np):
    """phi = |x - p| - h over the cell centres x, the nearest source point p."""
    axes = [origin[a] + h * np.arange(shape[a]) for a in range(3)]
    phi = np.full(shape, np.inf)
    for p in pts:
        r2 = sum(np.square(axes[a] - p[a]).reshape([-1 if b == a else 1 for b in range(3)]) for a in range(3))
        phi = np.minimum(phi, np.sqrt(r2) - h)
    return phi


def reference(d, phi, solid, h, np):
    """skfmm.distance on phi masked by solid, in a process of its own; returns (distance, stats)."""
    files = [os.path.join(d, f) for f in ("phi.npy", "solid.npy", "fmm.npy")]
    np.save(files[0], phi)
    np.save(files[1], solid)
    _, rss, out = wait_timed([sys.executable, "-c", CHILD, files[0], files[1], repr(h), files[2]], d)
    stats = json.loads(out)
    stats["peak_rss_mb"] = rss
    return np.load(files[2]) + h, stats


def compare(hv, ref, solid, h, np):
    """The differences in voxels on the cells free and finite in both, and the reach disagreements."""
    free = ~solid
    a, b = np.isfinite(hv) & free, np.isfinite(ref) & free
    both = a & b
    diff = np.abs(hv[both].astype(np.float64) - ref[both]) / h
    far = ref[both] >= 2 * h
    rel = diff[far] * h / ref[both][far]
    return {
        "cells_compared": int(both.sum()),
        "mean_diff_voxels": float(diff.mean()) if diff.size else None,
        "p99_diff_voxels": float(np.percentile(diff, 99)) if diff.size else None,
        "max_diff_voxels": float(diff.max()) if diff.size else None,
        "mean_rel_diff": float(rel.mean()) if rel.size else None,
        "reach_disagree": int((a != b).sum()),
        "unreached_heatvox": int((free & ~a).sum()),
        "unreached_reference": int((free & ~b).sum()),
    }


def bench(hv, scene, n, stages, backend, d, np, vdb):
    """One row: heatvox and skfmm on one scene at n cells along the longest axis."""
    args = write_building(hv, d, n) if scene == "building" else write_maze(d, n, np, vdb)
    out_vdb, out_npy = os.path.join(d, "out.vdb"), os.path.join(d, "out.npy")
    cmd = [hv, "distance"] + args + ["-o", out_vdb, "--npy", out_npy, "--stages", stages]
    if backend:
        cmd += ["--backend", backend]
    wall, rss, out = wait_timed(cmd, d)
    summary = json.loads(out.strip().splitlines()[-1])
    dist, solid, origin, h = read_output(out_vdb, out_npy, np, vdb)
    phi = ball_phi(dist.shape, origin, h, source_points(args[1]), np)
    ref, rs = reference(d, phi, solid, h, np)
    cells = dist.size
    row = {"bench": "distance", "scene": scene, "n": max(dist.shape), "grid": list(dist.shape), "h": h,
           "backend": summary.get("backend"), "seconds": wall, "peak_rss_mb": rss,
           "stages": summary.get("stages"), "stage_solves": stages,
           "reported_seconds": summary.get("seconds"),
           "solid_cells": int(solid.sum()), "reference": "scikit-fmm",
           "reference_seconds": rs["seconds"], "reference_peak_rss_mb": rs["peak_rss_mb"],
           "reference_call_rss_mb": rs["call_rss_mb"], "ratio": wall / rs["seconds"],
           "per_cell_us": wall / cells * 1e6, "reference_per_cell_us": rs["seconds"] / cells * 1e6}
    for k in SUMMARY_KEYS:
        row[k] = summary.get(k)
    for k in ("device", "host_bytes"):  # the opencl backend's
        if k in summary:
            row[k] = summary[k]
    row.update(compare(dist, ref, solid, h, np))
    return row


# From heatvox's JSON summary: where its time went and how many cells its stages solved.
SUMMARY_KEYS = ("cells_solved_grids", "setup_seconds", "splat_seconds", "diffuse_seconds",
                "normalize_seconds", "poisson_seconds")


def add_growth(row, prev):
    """Time per cell against the previous grid size's row (same scene and stages)."""
    if prev:
        row["per_cell_growth"] = row["per_cell_us"] / prev["per_cell_us"]
        row["reference_per_cell_growth"] = row["reference_per_cell_us"] / prev["reference_per_cell_us"]
    return row


def imports():
    """numpy, pyopenvdb and a check that skfmm imports; None where one is missing."""
    try:
        import numpy as np
        import pyopenvdb as vdb
        importlib.import_module("skfmm")  # the reference runs in a process of its own
    except ImportError as e:
        print("bench distance: %s: %s, distance rows skipped" % (sys.executable, e), file=sys.stderr)
        return None
    return np, vdb


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--heatvox", default="build/heatvox")
    ap.add_argument("--n", type=int, nargs="+", action="extend")
    ap.add_argument("--scene", choices=["building", "maze"], action="append")
    ap.add_argument("--stages", choices=["tiles", "whole"], nargs="+", action="extend")
    ap.add_argument("--backend", default=None, help="heatvox's --backend (default: its own choice)")
    a = ap.parse_args()
    mods = imports()
    if mods is None:
        return
    hv = os.path.abspath(a.heatvox)
    if not os.access(hv, os.X_OK):
        sys.exit("bench_distance: no heatvox at %s" % hv)
    for scene in a.scene or ["building", "maze"]:
        for stages in a.stages or ["tiles"]:
            prev = None
            for n in a.n or [128, 256]:
                with tempfile.TemporaryDirectory(prefix="hv_bench_dist_") as d:
                    prev = add_growth(bench(hv, scene, n, stages, a.backend, d, *mods), prev)
                print(json.dumps(prev), flush=True)


if __name__ == "__main__":
    main()
