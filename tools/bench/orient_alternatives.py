#!/usr/bin/python3
"""orient_alternatives: the orientation heatvox kept for clouds without normals
(its --orient recover: neighbourhood axes, a minimum spanning tree, heat
rounds) against the alternatives docs/METHOD.md names, measured on the same
points, one JSON line per cloud and method.

    orient_alternatives.py [--res N] [--t T] CLOUD.xyz... [--plate]

CLOUD.xyz: x y z nx ny nz, the normals the truth (write them with
`heatvox bench points MESH --n N --keep DIR`). --plate adds a plate 1.5
voxels thick, points on both faces. The methods (numpy and scipy, on a block
of N cells along the longest side, heatvox's voxel):

- axes: each point's direction from its 96 nearest within 2 voxels,
  weighted (1 - d^2/rho^2)^2 (heatvox's step 0, unsigned);
- linefield: those directions splatted as the tensor a n n^T (6 components,
  trilinear), one backward-Euler heat step per component with t = T h^2
  (default 1; exact, by DCT), the principal eigenvector at each point
  (unsigned);
- z2: a Z2 synchronisation of the line field's cells: the cells holding a
  line (anisotropy > 0.5), an edge between face neighbours weighted by both
  anisotropies and |d_i . d_j| with the sign of d_i . d_j, the leading
  eigenvector of the normalized matrix (scipy's eigsh), the whole turned
  outward (the sum of a d . (x - c) positive), each point signed by its cell;
- heatvox: heatvox's own (points_surface with orient="recover": the points
  against the file's normals are its report's orient_disagree).

Rows: cloud, method, points, seconds, and for the unsigned ones
mean_angle_deg and over_30deg (the fraction more than 30 degrees off the
true line), for the signed ones true_side (the fraction on the true
normal's side).
"""
import json
import sys
import time

import numpy as np

PROG = "orient_alternatives"


def block(pts, res):
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    h = (hi - lo).max() / (res - 8)
    n = np.ceil((hi - lo) / h).astype(int) + 8
    origin = (lo + hi) / 2 - n * h / 2
    return n, h, origin


def axes(pts, h):
    from scipy.spatial import cKDTree
    d, idx = cKDTree(pts).query(pts, k=96)
    rho = 2 * h
    w = np.clip(1 - (d / rho) ** 2, 0, None) ** 2
    w[:, 0] = np.maximum(w[:, 0], 1e-12)
    off = pts[idx] - pts[:, None, :]
    sw = w.sum(axis=1)[:, None]
    c = (w[:, :, None] * off).sum(axis=1) / sw
    cov = np.einsum("nk,nka,nkb->nab", w, off, off) / sw[:, :, None] - c[:, :, None] * c[:, None, :]
    return np.linalg.eigh(cov)[1][:, :, 0]


def trilinear(pts, n, h, origin):
    """Cells and weights of each point's trilinear stencil (cell centres)."""
    g = (pts - origin) / h - 0.5
    i0 = np.clip(np.floor(g).astype(int), 0, n - 2)
    f = np.clip(g - i0, 0, 1)
    cells, weights = [], []
    for c in range(8):
        o = np.array([(c >> a) & 1 for a in range(3)])
        cells.append(np.ravel_multi_index((i0 + o).T, n))
        weights.append(np.prod(np.where(o, f, 1 - f), axis=1))
    return np.stack(cells, 1), np.stack(weights, 1)


def heat_step(u, n, t_h2):
    """(I - t Laplacian) v = u with Neumann walls, exactly (DCT-II)."""
    from scipy.fft import dctn, idctn
    lam = 0
    for a in range(3):
        k = np.arange(n[a])
        shape = [1, 1, 1]
        shape[a] = n[a]
        lam = lam + (2 - 2 * np.cos(np.pi * k / n[a])).reshape(shape)
    return idctn(dctn(u.reshape(n), type=2) / (1 + t_h2 * lam), type=2).ravel()


def linefield(pts, dirs, n, h, origin, t_h2):
    cells, w = trilinear(pts, n, h, origin)
    comp = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
    T = np.zeros((6, int(np.prod(n))))
    for k, (a, b) in enumerate(comp):
        np.add.at(T[k], cells.ravel(), (w * (dirs[:, a] * dirs[:, b])[:, None]).ravel())
        T[k] = heat_step(T[k], n, t_h2)
    return T


def tensor_at(T, cells, w):
    v = (T[:, cells] * w[None]).sum(axis=2)  # (6, npts)
    m = np.empty((v.shape[1], 3, 3))
    for k, (a, b) in enumerate([(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]):
        m[:, a, b] = m[:, b, a] = v[k]
    return m


def principal(m):
    val, vec = np.linalg.eigh(m)
    aniso = (val[:, 2] - val[:, 1]) / np.maximum(val[:, 2], 1e-300)
    return vec[:, :, 2], aniso


def unsigned_row(name, method, d, truth, seconds):
    c = np.abs((d * truth).sum(axis=1)).clip(0, 1)
    ang = np.degrees(np.arccos(c))
    return {"cloud": name, "method": method, "points": len(d), "seconds": round(seconds, 3),
            "mean_angle_deg": round(float(ang.mean()), 3),
            "over_30deg": round(float((ang > 30).mean()), 5)}


def z2(T, n, h, origin, pts, dirs):
    """Signs of the points from a Z2 synchronisation of the line field's cells."""
    from scipy.sparse import coo_matrix, diags
    from scipy.sparse.linalg import eigsh
    ncell = T.shape[1]
    trace = T[0] + T[1] + T[2]
    live = np.flatnonzero(trace > 1e-3 * trace.max())
    d, a = principal(tensor_at(T, live[:, None], np.ones((len(live), 1))))
    keep = a > 0.5
    live, d, a = live[keep], d[keep], a[keep]
    place = np.full(ncell, -1)
    place[live] = np.arange(len(live))
    ijk = np.array(np.unravel_index(live, n)).T
    rows, cols, vals = [], [], []
    for ax in range(3):
        nb = ijk.copy()
        nb[:, ax] += 1
        ok = nb[:, ax] < n[ax]
        j = np.full(len(live), -1)
        j[ok] = place[np.ravel_multi_index(nb[ok].T, n)]
        ok &= j >= 0
        i, j = np.flatnonzero(ok), j[ok]
        dot = (d[i] * d[j]).sum(axis=1)
        wgt = a[i] * a[j] * np.abs(dot) * np.sign(dot)
        rows += [i, j]
        cols += [j, i]
        vals += [wgt, wgt]
    S = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                   shape=(len(live), len(live))).tocsr()
    deg = np.asarray(abs(S).sum(axis=1)).ravel() + 1e-12
    Dm = diags(1 / np.sqrt(deg))
    _, x = eigsh(Dm @ S @ Dm, k=1, which="LA", tol=1e-6, maxiter=5000)
    od = d * np.sign(x[:, 0])[:, None]
    x_c = (np.array(ijk) + 0.5) * h + origin
    if ((od * (x_c - x_c.mean(axis=0))).sum(axis=1) * a).sum() < 0:
        od = -od
    # each point signed by the nearest live cell's oriented direction
    from scipy.spatial import cKDTree
    _, near = cKDTree(x_c).query(pts, k=1)
    s = np.sign((od[near] * dirs).sum(axis=1))
    return dirs * s[:, None], len(live)


def heatvox_row(name, pts, truth, res):
    import heatvox
    t0 = time.perf_counter()
    _, _, rep = heatvox.points_surface(pts, truth, res=res, orient="recover")
    return {"cloud": name, "method": "heatvox", "points": len(pts),
            "seconds": round(time.perf_counter() - t0, 3),
            "orientation_seconds": round(rep["t_orient"], 3),
            "true_side": round(1 - rep["orient_disagree"] / len(pts), 5)}


def run(name, pts, truth, res, t_h2):
    truth = truth / np.linalg.norm(truth, axis=1)[:, None]
    n, h, origin = block(pts, res)
    t0 = time.perf_counter()
    d = axes(pts, h)
    t_axes = time.perf_counter() - t0
    yield unsigned_row(name, "axes", d, truth, t_axes)
    t0 = time.perf_counter()
    T = linefield(pts, d, n, h, origin, t_h2)
    cells, w = trilinear(pts, n, h, origin)
    dl, _ = principal(tensor_at(T, cells, w))
    yield unsigned_row(name, "linefield", dl, truth, t_axes + time.perf_counter() - t0)
    t0 = time.perf_counter()
    od, live = z2(T, n, h, origin, pts, d)
    row = {"cloud": name, "method": "z2", "points": len(pts), "cells": int(live),
           "seconds": round(time.perf_counter() - t0, 3),
           "true_side": round(float(((od * truth).sum(axis=1) > 0).mean()), 5)}
    yield row
    yield heatvox_row(name, pts, truth, res)


def plate(res, rng, m=200000):
    """m points on the faces of a plate 2 x 2 x 1.5 voxels, outward normals."""
    th = 0.75 * 2.0 / (res - 8)
    lo, hi = np.array([-1, -1, -th]), np.array([1, 1, th])
    ext = hi - lo
    area = np.array([ext[1] * ext[2], ext[0] * ext[2], ext[0] * ext[1]]).repeat(2)
    face = rng.choice(6, m, p=area / area.sum())
    x = lo + rng.random((m, 3)) * ext
    nrm = np.zeros((m, 3))
    for k in range(6):
        a, sel = k // 2, face == k
        x[sel, a] = lo[a] if k % 2 == 0 else hi[a]
        nrm[sel, a] = -1 if k % 2 == 0 else 1
    return x, nrm


def main(argv):
    res, files, with_plate, t_h2 = 128, [], False, 1.0
    it = iter(argv)
    for a in it:
        if a == "--res":
            res = int(next(it))
        elif a == "--t":
            t_h2 = float(next(it))
        elif a == "--plate":
            with_plate = True
        elif a.startswith("-"):
            print("%s: unknown option %r" % (PROG, a), file=sys.stderr)
            return 2
        else:
            files.append(a)
    clouds = []
    for f in files:
        v = np.loadtxt(f, comments="#")
        if v.ndim != 2 or v.shape[1] != 6:
            print("%s: %s: x y z nx ny nz expected" % (PROG, f), file=sys.stderr)
            return 1
        clouds.append((f.rsplit("/", 1)[-1], v[:, :3], v[:, 3:]))
    if with_plate:
        p, q = plate(res, np.random.default_rng(5))
        clouds.append(("plate-1.5", p, q))
    for name, p, q in clouds:
        for row in run(name, p, q, res, t_h2):
            row["t_h2"] = t_h2
            print(json.dumps(row, separators=(",", ":")), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
