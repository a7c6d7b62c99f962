#!/usr/bin/python3
"""bench_ref_open3d: Open3D's surface from points (Debian's python3-open3d,
0.16), the second reference of `heatvox bench points --unoriented`.

    bench_ref_open3d.py IN.xyz OUT.ply --h H [--unoriented]
    bench_ref_open3d.py --check

IN.xyz: one point a line, "x y z nx ny nz" ('#' starts a comment; with
--unoriented "x y z" will do and normals given are ignored). With
--unoriented the normals are Open3D's own, as its documentation does it:
estimate_normals (30 nearest neighbours, its default), then
orient_normals_consistent_tangent_plane(15) (a minimum spanning tree over 15
neighbours). The surface is create_from_point_cloud_poisson (Kazhdan and
Hoppe's screened Poisson reconstruction) at the octree depth whose cells are
nearest to H across the points' box widened by Open3D's default 1.1; the
mesh is kept whole (no density trimming), so that it stays closed.

OUT.ply: binary PLY, written under a temporary name and renamed when
complete. One JSON line on stdout: ref, points, triangles, h, depth,
normals_seconds and orient_seconds (--unoriented), poisson_seconds,
compute_seconds (all of those), seconds (the whole run, Python's start and
the imports included), peak_rss_mb. --check: exit 0 when open3d imports.
Exit codes: 0 success, 1 failure, 2 usage.
"""
import json
import math
import os
import sys
import time

T_START = time.monotonic()
PROG = "bench_ref_open3d"
USAGE = "usage: %s IN.xyz OUT.ply --h H [--unoriented] | --check" % PROG


class Fail(Exception):
    """A failure to report: the message names the file and the problem."""


def parse(argv):
    """IN, OUT, H and unoriented from argv; exits 2 with the usage if wrong."""
    pos, h, unoriented = [], None, False
    it = iter(argv)
    for a in it:
        if a == "--unoriented":
            unoriented = True
        elif a == "--h":
            v = next(it, None)
            try:
                h = float(v)
            except (TypeError, ValueError):
                h = None
            if h is None or not (h > 0) or not math.isfinite(h):
                usage("--h needs a positive number, got %r" % v)
        elif a in ("-h", "--help"):
            print(USAGE)
            sys.exit(0)
        elif a.startswith("-") and a != "-":
            usage("unknown option %r" % a)
        else:
            pos.append(a)
    if len(pos) != 2 or h is None:
        usage("one input, one output and --h H are required")
    return pos[0], pos[1], h, unoriented


def usage(why):
    print("%s: %s\n%s" % (PROG, why, USAGE), file=sys.stderr)
    sys.exit(2)


def read_xyz(np, path, unoriented):
    """The points (and normals, None with --unoriented) of path."""
    try:
        v = np.loadtxt(path, comments="#", ndmin=2, dtype=np.float64)
    except OSError as e:
        raise Fail("%s: cannot read: %s" % (path, e.strerror or e))
    except ValueError as e:
        raise Fail("%s: %s" % (path, e))
    if v.shape[1] not in ((3, 6) if unoriented else (6,)):
        raise Fail("%s: %d numbers a line, %s expected" %
                   (path, v.shape[1], "3 or 6" if unoriented else "6"))
    if len(v) < 4:
        raise Fail("%s: %d points; the reconstruction needs at least 4" % (path, len(v)))
    if not np.isfinite(v).all():
        raise Fail("%s: a value that is not a finite number" % path)
    return v[:, :3], (None if unoriented else v[:, 3:6])


def depth_for(pts, h):
    """The octree depth whose cells are nearest to h across 1.1 times the box."""
    extent = float((pts.max(axis=0) - pts.min(axis=0)).max())
    return max(1, round(math.log2(max(1.1 * extent / h, 2))))


def peak_rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024
    return 0.0


def write_ply(o3d, mesh, out):
    """mesh to out under a temporary name beside it, renamed when written."""
    d, base = os.path.split(out)
    tmp = os.path.join(d, ".%s.tmp-%d.ply" % (base, os.getpid()))
    try:
        if not o3d.io.write_triangle_mesh(tmp, mesh, write_ascii=False,
                                          write_vertex_normals=False,
                                          write_vertex_colors=False):
            raise Fail("%s: cannot write" % out)
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def run(inp, out, h, unoriented):
    import numpy as np
    import open3d as o3d
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    pts, normals = read_xyz(np, inp, unoriented)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    row = {"ref": "open3d-unoriented" if unoriented else "open3d-poisson",
           "points": len(pts)}
    t = {"normals": 0.0, "orient": 0.0}
    if unoriented:
        t0 = time.monotonic()
        pcd.estimate_normals()
        t["normals"] = time.monotonic() - t0
        t0 = time.monotonic()
        pcd.orient_normals_consistent_tangent_plane(15)
        t["orient"] = time.monotonic() - t0
    else:
        pcd.normals = o3d.utility.Vector3dVector(normals)
    depth = depth_for(pts, h)
    t0 = time.monotonic()
    mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=depth)
    t["poisson"] = time.monotonic() - t0
    if len(mesh.triangles) == 0:
        raise Fail("%s: the Poisson reconstruction made no triangle" % inp)
    write_ply(o3d, mesh, out)
    row.update(triangles=len(mesh.triangles), h=h, depth=depth)
    if unoriented:
        row.update(normals_seconds=round(t["normals"], 4), orient_seconds=round(t["orient"], 4))
    row.update(poisson_seconds=round(t["poisson"], 4),
               compute_seconds=round(sum(t.values()), 4),
               seconds=round(time.monotonic() - T_START, 4),
               peak_rss_mb=round(peak_rss_mb(), 1))
    print(json.dumps(row, separators=(",", ":")))


def main(argv):
    if argv == ["--check"]:
        try:
            import open3d  # noqa: F401
        except ImportError as e:
            print("%s: %s" % (PROG, e), file=sys.stderr)
            return 1
        return 0
    inp, out, h, unoriented = parse(argv)
    try:
        run(inp, out, h, unoriented)
    except Fail as e:
        print("%s: %s" % (PROG, e), file=sys.stderr)
        return 1
    except MemoryError:
        print("%s: %s: out of memory" % (PROG, inp), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
