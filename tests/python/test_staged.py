"""The package `make install` installs (make check stages an install into
BUILD/stage) imports with only the staged paths, loads the staged library
through the path recorded at install, and computes a signed distance."""

import glob
import json
import os
import subprocess
import sys
import unittest

import heatvox
import hvtest

SCRIPT = r"""
import json, os, sys
import heatvox
from heatvox import _install
d = os.getcwd()
with open("octa.obj", "w") as f:
    f.write("v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n"
            "f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n")
g = heatvox.sdf("octa.obj", res=16)
print(json.dumps({"file": heatvox.__file__, "lib": heatvox.library_path, "libdir": _install.LIBDIR,
                  "version": heatvox.__version__, "min": float(g.values.min()), "shape": g.shape,
                  "path": sys.path}))
"""


class Staged(unittest.TestCase):
    def test_the_staged_package_should_load_the_staged_library(self):
        stage = os.environ.get("HEATVOX_STAGE") or os.path.join(
            os.path.dirname(os.path.realpath(heatvox.library_path)), "stage")
        if not os.path.isdir(stage):
            if os.environ.get("HEATVOX_STAGE"):
                self.fail("%s missing: make check stages `make install` there first" % stage)
            self.skipTest("no staged install at %s (make check makes one)" % stage)
        pkgs = glob.glob(os.path.join(stage, "lib", "python3*", "dist-packages", "heatvox", "__init__.py"))
        self.assertEqual(len(pkgs), 1, "the heatvox package under %s/lib/python3*/dist-packages" % stage)
        site = os.path.dirname(os.path.dirname(pkgs[0]))
        self.assertIn("python%d.%d" % sys.version_info[:2], site)
        env = {k: v for k, v in os.environ.items()
               if k not in ("PYTHONPATH", "HEATVOX_LIBRARY", "LD_LIBRARY_PATH", "PYTHONHOME")}
        env["PYTHONPATH"] = site
        d = hvtest.tmpdir()
        p = subprocess.run([sys.executable, "-s", "-c", SCRIPT], cwd=d, env=env, capture_output=True,
                           text=True, timeout=120)
        self.assertEqual(p.returncode, 0, p.stderr)
        r = json.loads(p.stdout)
        self.assertTrue(r["file"].startswith(site), r["file"])
        self.assertEqual(os.path.realpath(r["libdir"]), os.path.realpath(os.path.join(stage, "lib")))
        self.assertEqual(os.path.realpath(r["lib"]), os.path.realpath(os.path.join(stage, "lib", "libheatvox.so.0")))
        self.assertEqual(r["version"], heatvox.__version__)
        self.assertEqual(r["shape"], [16, 16, 16])  # res 16 across the padded box
        self.assertTrue(-0.58 < r["min"] < -0.3, r["min"])  # inradius 1/sqrt(3), cell centres off 0
        self.assertFalse(any(os.path.join(hvtest.REPO, "python") == p for p in r["path"]))


if __name__ == "__main__":
    unittest.main()
