#!/usr/bin/python3
"""make bench: the Python package's cost against the command, one JSON object per line.

usage: tools/bench/bench_python.py path/to/heatvox [--n N] [--repeat R]

The signed distance of scenes/meshes/sphere_holes_flips.obj (from `heatvox
make-scenes`) at --res N (default 128) written as a .vdb and a .npy, by
`heatvox sdf MESH -o OUT.vdb --npy OUT.npy --res N` and by a Python process
doing read_mesh, sdf, write_vdb and write_npy with the package over the same
build's library. Each runs R times (default 3) alternately, each in a fresh
process; the best time counts, and peak RSS is that process's maximum
resident set. The two .npy files must be equal bit for bit ("same").

Rows:
  python_sdf          seconds: the Python calls alone (from read_mesh to the
                      written files, in the Python process), against the
                      command's whole run
  python_sdf_process  seconds: the whole Python process (interpreter start,
                      import numpy and heatvox, the calls), against the same
"""

import json
import os
import subprocess
import sys
import tempfile
import time

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import heatvox
t1 = time.perf_counter()
mesh, n, vdb, npy = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
v, f = heatvox.read_mesh(mesh)
g = heatvox.sdf(v, f, res=n)
g.write_vdb(vdb)
g.write_npy(npy)
t2 = time.perf_counter()
print(json.dumps({"import_seconds": t1 - t0, "call_seconds": t2 - t1, "backend": g.stats["backend"],
                  "grid": list(g.shape)}))
"""


def run_timed(argv, env=None):
    """Runs argv; returns (wall seconds, peak RSS in MB, stdout)."""
    t0 = time.perf_counter()
    p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    out = p.stdout.read()
    err = p.stderr.read()
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        sys.exit("bench_python: %s: exit %d: %s" % (" ".join(argv), p.returncode, err.decode(errors="replace")))
    return wall, ru.ru_maxrss / 1024.0, out.decode()


def main():
    args = sys.argv[1:]
    if not args or args[0].startswith("-"):
        sys.exit(__doc__)
    hv = os.path.abspath(args[0])
    n, repeat = 128, 3
    if "--n" in args:
        n = int(args[args.index("--n") + 1])
    if "--repeat" in args:
        repeat = int(args[args.index("--repeat") + 1])
    try:
        import numpy as np
    except ImportError:
        print("bench: %s has no NumPy, python rows skipped" % sys.executable, file=sys.stderr)
        return
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.path.join(root, "python")
    env.setdefault("HEATVOX_LIBRARY", os.path.join(os.path.dirname(hv), "libheatvox.so"))
    env.setdefault("GOMP_SPINCOUNT", "1000")  # what the command sets for itself

    with tempfile.TemporaryDirectory(prefix="hv_bench_py_") as d:
        subprocess.run([hv, "make-scenes", os.path.join(d, "scenes"), "-q"], check=True)
        mesh = os.path.join(d, "scenes", "meshes", "sphere_holes_flips.obj")
        cmd = [hv, "sdf", mesh, "-o", os.path.join(d, "c.vdb"), "--npy", os.path.join(d, "c.npy"),
               "--res", str(n), "-q"]
        py = [sys.executable, "-c", CHILD, mesh, str(n), os.path.join(d, "p.vdb"), os.path.join(d, "p.npy")]
        ref_s, ref_rss, proc_s, py_rss, call_s = [], [], [], [], []
        info = None
        for _ in range(repeat):
            w, r, _ = run_timed(cmd, env)
            ref_s.append(w)
            ref_rss.append(r)
            w, r, out = run_timed(py, env)
            info = json.loads(out)
            proc_s.append(w)
            py_rss.append(r)
            call_s.append(info["call_seconds"])
        a, b = np.load(os.path.join(d, "c.npy")), np.load(os.path.join(d, "p.npy"))
        same = a.shape == b.shape and a.tobytes() == b.tobytes()

    ref = min(ref_s)
    for bench, sec in (("python_sdf", min(call_s)), ("python_sdf_process", min(proc_s))):
        row = {"bench": bench, "n": n, "backend": info["backend"], "seconds": round(sec, 4),
               "peak_rss_mb": round(max(py_rss), 1), "reference": "heatvox sdf --npy",
               "reference_seconds": round(ref, 4), "ratio": round(sec / ref, 3),
               "reference_peak_rss_mb": round(max(ref_rss), 1), "grid": info["grid"], "same": same}
        if bench == "python_sdf_process":
            row["import_seconds"] = round(info["import_seconds"], 4)
        print(json.dumps(row))
    if not same:
        sys.exit("bench_python: the Python result differs from the command's")


if __name__ == "__main__":
    main()
