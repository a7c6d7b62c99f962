#!/usr/bin/env python3
"""The distributed pipelines (make mpi-check): heatvox distance and heatvox
extend under mpirun -n 1..4 with --backend petsc against the single-process
commands, against exact answers, and their HDF5 output read back with h5py.

usage: pipelines.py HEATVOX MPIRUN...   (run from any directory; works in a
temporary one)"""
import json
import os
import subprocess
import sys
import tempfile

import h5py
import numpy as np
import pyopenvdb as vdb

HEATVOX = os.path.abspath(sys.argv[1])
MPIRUN = sys.argv[2:]
RANKS = (1, 2, 3, 4)
failures = []


def check(ok, what):
    print(("ok   " if ok else "FAIL ") + what, flush=True)
    if not ok:
        failures.append(what)


def run(args, ranks=0):
    cmd = ([*MPIRUN, "-n", str(ranks)] if ranks else []) + [HEATVOX, *args]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode:
        sys.exit("command failed (%d): %s\n%s%s" % (r.returncode, " ".join(cmd), r.stdout, r.stderr))
    return r.stdout


def read_dense(path, name, n):
    """Grid `name` of a VDB file on the block 0..n-1 (background elsewhere)."""
    g = vdb.read(path, name)
    vec = "Vec3" in type(g).__name__
    a = np.zeros(tuple(n) + ((3,) if vec else ()), dtype=np.float32)
    g.copyToArray(a, ijk=(0, 0, 0))
    return a  # indexed [i, j, k]


# ---- distance: a point source in a box with a wall, and no obstacles ----------

def distance_case(tmp, label, args, exact=None):
    ref = os.path.join(tmp, label + "-mg.vdb")
    js = json.loads(run(["distance", *args, "-o", ref, "--backend", "mg", "--stages", "whole"]))
    n, h = js["grid"], js["h"]
    a = read_dense(ref, "distance", n)
    fin = np.isfinite(a)
    for p in RANKS:
        out = os.path.join(tmp, "%s-%d.vdb" % (label, p))
        h5 = os.path.join(tmp, "%s-%d.h5" % (label, p))
        run(["distance", *args, "-o", out, "--backend", "petsc", "-q"], p)
        run(["distance", *args, "-o", h5, "--backend", "petsc", "-q"], p)
        b = read_dense(out, "distance", n)
        same_inf = np.array_equal(fin, np.isfinite(b))
        dv = np.abs(a[fin] - b[fin]).max() / h if same_inf else np.inf
        rel = (np.abs(a[fin] - b[fin]) / np.maximum(np.abs(a[fin]), h)).max() if same_inf else np.inf
        check(same_inf and dv <= 1e-3 and rel <= 1e-5,
              "distance %s, %d ranks: equals the single-process mg result: %.2g voxel, %.2g "
              "relative (<= 1e-3, 1e-5)" % (label, p, dv, rel))
        with h5py.File(h5, "r") as f:
            d = f["distance"]
            c = d[...].transpose(2, 1, 0)  # (z, y, x) -> [i, j, k]
            ok = (d.shape == (n[2], n[1], n[0]) and np.allclose(d.attrs["spacing"], [h] * 3)
                  and np.array_equal(np.isfinite(c), fin)
                  and np.abs(c[fin] - b[fin]).max() <= 1e-6 * max(1, np.abs(b[fin]).max()))
            org = d.attrs["origin"]
        xmf = open(h5[:-3] + ".xmf").read()
        ok = ok and ('Dimensions="%d %d %d"' % (n[2] + 1, n[1] + 1, n[0] + 1)) in xmf \
            and os.path.basename(h5) + ":/distance" in xmf
        check(ok, "distance %s, %d ranks: HDF5 reads back with h5py (shape %s, spacing, values) "
              "and the XDMF sidecar names it" % (label, p, d.shape))
        if exact is not None:
            e = exact(org)
            err = np.abs(b - e)[fin].mean() / h
            check(err < 0.5, "distance %s, %d ranks: mean error against the exact distance %.3f "
                  "voxels (< 0.5)" % (label, p, err))


# ---- extension: a velocity off a sphere and a torus ---------------------------

N, H = 48, 1.0 / 48


def centres():
    x = (np.arange(N) + 0.5) * H
    return np.meshgrid(x, x, x, indexing="ij")


def sphere(X, Y, Z):
    c = np.stack([X - 0.5, Y - 0.5, Z - 0.5], -1)
    r = np.linalg.norm(c, axis=-1)
    phi = r - 0.3
    cp = 0.5 + c * (0.3 / np.maximum(r, 1e-12))[..., None]
    return phi, cp


def torus(X, Y, Z):
    R, r0 = 0.28, 0.1
    x, y, z = X - 0.5, Y - 0.5, Z - 0.5
    q = np.sqrt(x * x + y * y)
    ring = np.stack([x * R / q, y * R / q, np.zeros_like(q)], -1)
    d = np.stack([x, y, z], -1) - ring
    dn = np.linalg.norm(d, axis=-1)
    phi = dn - r0
    cp = 0.5 + ring + d * (r0 / np.maximum(dn, 1e-12))[..., None]
    return phi, cp


def velocity(p):
    """A smooth field on the surface, read at the closest point."""
    return np.stack([np.sin(3 * p[..., 0]) + p[..., 2], np.cos(2 * p[..., 1]),
                     p[..., 0] * p[..., 1] - 0.5 * p[..., 2]], -1)


def extend_case(tmp, label, shape):
    phi, cp = shape(*centres())
    exact = velocity(cp).astype(np.float32)
    near = np.abs(phi) < 1.5 * H
    v0 = np.where(near[..., None], exact, 5.0).astype(np.float32)  # wrong away from the surface
    inp = os.path.join(tmp, label + ".vdb")
    tr = vdb.createLinearTransform(voxelSize=H)
    ls = vdb.FloatGrid(background=3 * H)
    ls.copyFromArray(phi.astype(np.float32), ijk=(0, 0, 0))
    ls.name, ls.transform = "phi", tr
    ls.gridClass = vdb.GridClass.LEVEL_SET
    vg = vdb.Vec3SGrid()
    vg.copyFromArray(v0, ijk=(0, 0, 0))
    vg.name, vg.transform = "v", tr
    vdb.write(inp, grids=[ls, vg])
    args = ["extend", inp, "--levelset", "phi", "--field", "v", "--dense"]
    band = np.abs(phi) < 4 * H
    mg = os.path.join(tmp, label + "-mg.vdb")
    run([*args, "--out-band", "4", "-o", mg, "--backend", "mg", "-q"])
    err_mg = np.abs(read_dense(mg, "v", (N, N, N)) - exact)[band].max()
    # The distributed path (--out-band): rank 0 reads, each rank extends its
    # box, rank 0 writes; against mg in one process.
    a = read_dense(mg, "v", (N, N, N))
    for p in RANKS:
        out = os.path.join(tmp, "%s-%d.vdb" % (label, p))
        js = run([*args, "--out-band", "4", "-o", out, "--backend", "petsc"], p)
        b = read_dense(out, "v", (N, N, N))
        rel = np.abs(a - b).max() / np.abs(a[band]).max()
        check('"dense-distributed"' in js and rel <= 1e-5,
              "extend %s, %d ranks, each on its box: equals the single-process result: %.2g "
              "relative (<= 1e-5)" % (label, p, rel))
        err = np.abs(b - exact)[band].max()
        check(err <= 0.03, "extend %s, %d ranks: max error against the exact extension %.4f "
              "(<= 0.03; single-process mg: %.4f)" % (label, p, err, err_mg))
        if p in (2, 3):  # HDF5 from the distributed path: rank 0's result, written by all
            h5 = os.path.join(tmp, "%s-%d.h5" % (label, p))
            run([*args, "--out-band", "4", "-o", h5, "--backend", "petsc", "-q"], p)
            with h5py.File(h5, "r") as f:
                c = np.stack([f["v_" + x][...].transpose(2, 1, 0) for x in "xyz"], -1)
                ls_ok = np.abs(f["phi"][...].transpose(2, 1, 0) - phi).max() <= 1e-6
            d5 = np.abs(c - b)[band].max()
            check(ls_ok and d5 <= 1e-6, "extend %s, %d ranks, each on its box, -o .h5: the "
                  "datasets phi and v_x, v_y, v_z equal the VDB output (%.2g)" % (label, p, d5))
    # A NaN in the field where it is read: every rank stops (no hang), exit 1,
    # the message names the file, nothing written.
    if label == "sphere":
        bad_in = os.path.join(tmp, "nan.vdb")
        vn = v0.copy()
        i, j, k = np.argwhere(near)[len(np.argwhere(near)) // 2]
        vn[i, j, k, 0] = np.nan
        vg2 = vdb.Vec3SGrid()
        vg2.copyFromArray(vn, ijk=(0, 0, 0))
        vg2.name, vg2.transform = "v", tr
        vdb.write(bad_in, grids=[ls, vg2])
        bad_out = os.path.join(tmp, "nan-out.vdb")
        try:
            r = subprocess.run([*MPIRUN, "-n", "3", HEATVOX, "extend", bad_in, "--levelset", "phi",
                                "--field", "v", "--dense", "--out-band", "4", "-o", bad_out,
                                "--backend", "petsc", "-q"], capture_output=True, text=True,
                               timeout=120)
            ok = r.returncode != 0 and "nan.vdb" in r.stderr and not os.path.exists(bad_out)
            what = "exit %d" % r.returncode
        except subprocess.TimeoutExpired:
            ok, what = False, "hung"
        check(ok, "extend, 3 ranks, a NaN in the field: every rank fails (%s), names the file, "
              "writes nothing" % what)
    # Without --out-band: every cell, each rank on its box, the closest points
    # past its ghost layer read from the ranks that own them. Where phi is a
    # distance (all of the sphere's cells but its centre's, the torus's but
    # its axis'), equal to one process; cells read at themselves may settle a
    # diffusion level apart (extend_dmda.c).
    one = os.path.join(tmp, label + "-whole-mg.vdb")
    run([*args, "-o", one, "--backend", "mg", "-q"])
    a = read_dense(one, "v", (N, N, N))
    X, Y, Z = centres()
    off_axis = (np.hypot(X - 0.5, Y - 0.5) > 3 * H) if label == "torus" else \
        (np.sqrt((X - 0.5) ** 2 + (Y - 0.5) ** 2 + (Z - 0.5) ** 2) > 3 * H)
    err_one = np.abs(a - exact)[off_axis].max()
    for p in (1, 2, 3):
        out = os.path.join(tmp, "%s-whole-%d.vdb" % (label, p))
        js = run([*args, "-o", out, "--backend", "petsc"], p)
        b = read_dense(out, "v", (N, N, N))
        rel = np.abs(a - b)[off_axis].max() / np.abs(a).max()
        err = np.abs(b - exact)[off_axis].max()
        check('"dense-distributed"' in js and rel <= 1e-5 and err <= err_one + 1e-4,
              "extend %s, %d ranks, every voxel, each rank on its box: equals the "
              "single-process result off the %s: %.2g relative (<= 1e-5); max error %.4f "
              "(one process %.4f)" % (label, p, "axis" if label == "torus" else "centre", rel,
                                      err, err_one))


def main():
    with tempfile.TemporaryDirectory() as tmp:
        src = os.path.join(tmp, "src.txt")
        with open(src, "w") as f:
            f.write("0.31 0.52 0.47\n")
        h = 1.0 / 40
        bbox = ["--bbox", "0", "0", "0", "1", "1", "1", "--res", "40"]

        def exact(org):
            x = org[0] + (np.arange(40) + 0.5) * h
            X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
            return np.sqrt((X - 0.31) ** 2 + (Y - 0.52) ** 2 + (Z - 0.47) ** 2)

        distance_case(tmp, "point", ["--sources", src, *bbox, "--obstacles", "none"], exact)
        run(["make-scenes", os.path.join(tmp, "scenes")])  # the generated inputs
        scn = os.path.join(tmp, "scenes", "distance")
        distance_case(tmp, "walls", ["--sources", os.path.join(scn, "sources.txt"),
                                     "--obstacles", os.path.join(scn, "walls.vdb")])
        # A mesh of obstacles, rasterized on rank 0, its mask scattered; a
        # sealed closet no source reaches (inf on the same cells).
        distance_case(tmp, "building", ["--sources", os.path.join(scn, "sources.txt"),
                                        "--obstacle-mesh", os.path.join(scn, "building.obj"),
                                        "--res", "48"])
        # A bad output: every rank fails, the message names the file, nothing is left.
        bad = os.path.join(tmp, "no-such-dir", "d.h5")
        r = subprocess.run([*MPIRUN, "-n", "2", HEATVOX, "distance", "--sources", src, *bbox,
                            "--obstacles", "none", "-o", bad, "--backend", "petsc", "-q"],
                           capture_output=True, text=True)
        check(r.returncode != 0 and bad in r.stderr and not os.path.exists(os.path.dirname(bad)),
              "distance -o into a missing directory, 2 ranks: fails (exit %d) naming the file"
              % r.returncode)
        leftovers = [x for x in os.listdir(tmp) if ".tmp-" in x]
        check(not leftovers, "no temporary files left behind: %s" % leftovers)
        extend_case(tmp, "sphere", sphere)
        extend_case(tmp, "torus", torus)
    if failures:
        sys.exit("pipelines: %d failed" % len(failures))
    print("pipelines: all passed")


main()
