"""The Python package installed with pip, as a user installs it: `pip wheel`
builds a platform wheel with libheatvox inside; a fresh virtual environment
(--system-site-packages, for Debian's NumPy) installs it with --no-index;
from another directory, without PYTHONPATH or HEATVOX_LIBRARY, the package
loads its bundled library and computes the signed distance of a cube, which
matches the analytic one, with the man pages and the bash completion under
the environment's prefix; `pip uninstall` leaves nothing of heatvox in the
environment. Then the same for `pip install --no-build-isolation --no-index .`
from the source tree.

The wheel is built from the build under test (HEATVOX_BUILD=BUILD for
setup.py, whose make is up to date after make check's `all`). A build whose
library carries a sanitizer's runtime (make sanitize) skips: Python loads it
only with that runtime preloaded, and the wheel would hand it on. No venv,
pip, setuptools, wheel or NumPy for Debian's /usr/bin/python3
($HEATVOX_PYTHON) skips too, naming the package (make check installs them
through mk/deps.mk). Prints one line per check, "SKIP: " lines, and a
closing line in the test framework's format.

Usage: tests/check_pip.py BUILD   (make's BUILD, relative to the repository root)
"""
import glob
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
import zipfile

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
PYTHON = os.environ.get("HEATVOX_PYTHON") or "/usr/bin/python3"
MAX_WHEEL = 20 * 1024 * 1024
SONAME = "libheatvox.so.0"

CHECKS = [
    "pip_wheel_should_build_a_platform_wheel_holding_the_library",
    "the_wheel_should_be_at_most_20_mb",
    "the_installed_wheel_should_give_the_analytic_distance_of_a_cube_from_another_directory",
    "pip_uninstall_of_the_wheel_should_leave_nothing_of_heatvox",
    "pip_install_from_the_source_tree_should_load_its_bundled_library",
    "pip_uninstall_after_a_source_install_should_leave_nothing_of_heatvox",
]

# Run by the environment's Python from another directory: the package's
# file, the library it loaded, and the signed distance of the cube
# [-0.5, 0.5]^3 (12 outward triangles) at res 32 against the box's analytic
# distance, over the cells within two voxels of the surface and over all.
PROBE = r"""
import json, os, sys
import numpy as np
import heatvox
v = np.array([[x, y, z] for x in (-.5, .5) for y in (-.5, .5) for z in (-.5, .5)], float)
f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
              [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.uint32)
g = heatvox.sdf(v, f, res=32)
h = g.voxel_size
nz, ny, nx = g.shape
axes = [g.origin[a] + (np.arange(n) + 0.5) * h for a, n in enumerate((nx, ny, nz))]
z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
q = np.abs(np.stack([x, y, z])) - 0.5
exact = np.linalg.norm(np.maximum(q, 0), axis=0) + np.minimum(q.max(axis=0), 0)
err = np.abs(g.values.astype(np.float64) - exact)
near = np.abs(exact) < 2 * h
print(json.dumps({
    "file": os.path.realpath(heatvox.__file__),
    "library": os.path.realpath(heatvox.library_path),
    "version": heatvox.__version__,
    "voxel_size": h,
    "near_max_error": float(err[near].max()),
    "max_error": float(err.max()),
    "sign_wrong": int(((g.values < 0) != (exact < 0))[np.abs(exact) > h].sum()),
}))
"""


class Failed(Exception):
    pass


def clean_env(**extra):
    """This environment without what would point Python at another heatvox or
    pip at an index, and with bytecode written (so that uninstall is checked
    to remove what imports leave)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "PYTHONUSERBASE", "PYTHONDONTWRITEBYTECODE",
                        "HEATVOX_LIBRARY", "VIRTUAL_ENV", "PIP_INDEX_URL", "PIP_EXTRA_INDEX_URL", "PIP_FIND_LINKS")}
    env.update(PIP_DISABLE_PIP_VERSION_CHECK="1", PIP_NO_INPUT="1", PIP_NO_CACHE_DIR="1")
    env.update(extra)
    return env


def shown(cmd):
    """The command for a message (the probe's code as "...")."""
    return " ".join(a if len(a) < 100 else "..." for a in cmd)


def run(cmd, cwd, env, timeout, what):
    t0 = time.time()
    try:
        p = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise Failed("%s: no end after %d s: %s" % (what, timeout, shown(cmd)))
    if p.returncode != 0:
        tail = (p.stdout + p.stderr).strip().splitlines()[-25:]
        raise Failed("%s: exit %d: %s\n      %s" % (what, p.returncode, shown(cmd), "\n      ".join(tail)))
    print("    %s: %.1f s" % (what, time.time() - t0))
    return p.stdout


def why_skip(build):
    """The reason the checks cannot run here, or None."""
    lib = os.path.join(build, "libheatvox.so")
    try:
        ldd = subprocess.run(["ldd", lib], capture_output=True, text=True).stdout
    except OSError:
        ldd = ""
    for rt in ("libasan", "libtsan"):
        if rt in ldd:
            return "%s is sanitized (%s): Python loads it only with that runtime preloaded; make check tests the wheel" % (lib, rt)
    if not os.access(PYTHON, os.X_OK):
        return "no %s" % PYTHON
    for module, pkg in (("numpy", "python3-numpy"), ("venv", "python3-venv"), ("ensurepip", "python3-venv"),
                        ("pip", "python3-pip"), ("setuptools", "python3-setuptools"), ("wheel", "python3-wheel")):
        if subprocess.run([PYTHON, "-c", "import " + module], capture_output=True).returncode != 0:
            return "%s has no %s (Debian's %s)" % (PYTHON, module, pkg)
    return None


def site_packages(venv):
    found = glob.glob(os.path.join(venv, "lib", "python3*", "site-packages"))
    if len(found) != 1:
        raise Failed("%s: %d site-packages folders" % (venv, len(found)))
    return found[0]


def leftovers(venv):
    """Every path under the environment whose name speaks of heatvox."""
    left = []
    for dirpath, dirnames, filenames in os.walk(venv):
        for name in dirnames + filenames:
            if "heatvox" in name.lower():
                left.append(os.path.relpath(os.path.join(dirpath, name), venv))
    return sorted(left)


class Run:
    def __init__(self, build_arg, tmp):
        self.tmp = tmp
        # as make has it: setup.py passes it on to make unchanged
        self.env = clean_env(HEATVOX_BUILD=build_arg)
        self.venv = os.path.join(tmp, "venv")
        self.elsewhere = os.path.join(tmp, "elsewhere")
        os.mkdir(self.elsewhere)
        self.wheel = None
        self.version = None

    def probe(self):
        """The probe's findings, checked to come from this environment."""
        out = run([os.path.join(self.venv, "bin", "python"), "-c", PROBE], self.elsewhere, clean_env(), 120,
                  "the probe")
        r = json.loads(out.strip().splitlines()[-1])
        pkg = os.path.join(os.path.realpath(site_packages(self.venv)), "heatvox")
        if r["file"] != os.path.join(pkg, "__init__.py"):
            raise Failed("heatvox imported from %s, not from %s" % (r["file"], pkg))
        if r["library"] != os.path.join(pkg, SONAME):
            raise Failed("heatvox loaded %s, not the bundled %s" % (r["library"], os.path.join(pkg, SONAME)))
        return r

    def uninstall(self):
        vpy = os.path.join(self.venv, "bin", "python")
        run([vpy, "-m", "pip", "uninstall", "-y", "heatvox"], self.elsewhere, clean_env(), 120, "pip uninstall")
        left = leftovers(self.venv)
        if left:
            raise Failed("left in the environment after pip uninstall: " + ", ".join(left))

    def pip_wheel_should_build_a_platform_wheel_holding_the_library(self):
        out = os.path.join(self.tmp, "wheels")
        run([PYTHON, "-m", "pip", "wheel", "--no-build-isolation", "--no-index", "--no-deps", "-w", out, ROOT],
            ROOT, self.env, 600, "pip wheel")
        wheels = glob.glob(os.path.join(out, "*.whl"))
        if len(wheels) != 1:
            raise Failed("pip wheel made %d wheels: %s" % (len(wheels), ", ".join(map(os.path.basename, wheels))))
        self.wheel = wheels[0]
        name = os.path.basename(self.wheel)
        plat = sysconfig.get_platform().replace("-", "_").replace(".", "_")
        parts = name[:-4].split("-")
        if len(parts) != 5 or parts[0] != "heatvox" or parts[2:] != ["py3", "none", plat]:
            raise Failed("%s: not heatvox-VERSION-py3-none-%s.whl" % (name, plat))
        self.version = parts[1]
        with zipfile.ZipFile(self.wheel) as z:
            names = set(z.namelist())
            info = "heatvox-%s.dist-info/" % self.version
            wheel_meta = z.read(info + "WHEEL").decode()
            meta = z.read(info + "METADATA").decode()
            lib = z.read("heatvox/" + SONAME) if "heatvox/" + SONAME in names else b""
        for need in ("heatvox/__init__.py", "heatvox/_lib.py", "heatvox/" + SONAME):
            if need not in names:
                raise Failed("%s has no %s" % (name, need))
        data = "heatvox-%s.data/data/" % self.version
        for need in ("share/man/man1/heatvox.1", "share/man/man1/heatvox-sdf.1",
                     "share/bash-completion/completions/heatvox"):
            if data + need not in names:
                raise Failed("%s has no %s" % (name, data + need))
        stray = sorted(n for n in names if not n.startswith(("heatvox/", info, data)))
        if stray:
            raise Failed("%s holds files outside the package: %s" % (name, ", ".join(stray)))
        if "Root-Is-Purelib: false" not in wheel_meta:
            raise Failed("%s: WHEEL does not say Root-Is-Purelib: false" % name)
        if "Requires-Dist: numpy" not in meta:
            raise Failed("%s: METADATA does not require numpy" % name)
        if lib[:4] != b"\x7fELF":
            raise Failed("%s: heatvox/%s is not an ELF file" % (name, SONAME))
        print("    %s, %d files" % (name, len(names)))

    def the_wheel_should_be_at_most_20_mb(self):
        self.need_wheel()
        size = os.path.getsize(self.wheel)
        print("    %s: %.2f MB" % (os.path.basename(self.wheel), size / 1e6))
        if size > MAX_WHEEL:
            raise Failed("%s is %d bytes, over %d" % (self.wheel, size, MAX_WHEEL))

    def the_installed_wheel_should_give_the_analytic_distance_of_a_cube_from_another_directory(self):
        self.need_wheel()
        run([PYTHON, "-m", "venv", "--system-site-packages", self.venv], self.tmp, clean_env(), 300, "python3 -m venv")
        vpy = os.path.join(self.venv, "bin", "python")
        run([vpy, "-m", "pip", "install", "--no-index", self.wheel], self.elsewhere, clean_env(), 300,
            "pip install of the wheel")
        self.check_distance(self.probe())
        self.check_docs()

    def check_docs(self):
        """The man pages and the completion under the environment's prefix,
        where man finds the pages from its bin/ on PATH."""
        for rel in ("share/man/man1/heatvox.1", "share/man/man1/heatvox-sdf.1",
                    "share/bash-completion/completions/heatvox"):
            if not os.path.isfile(os.path.join(self.venv, rel)):
                raise Failed("pip install put no %s in the environment" % rel)
        man = shutil.which("man")
        if man:
            path = os.path.join(self.venv, "bin") + os.pathsep + os.environ.get("PATH", "")
            got = run([man, "-w", "heatvox-sdf"], self.elsewhere, clean_env(PATH=path, MANPATH=""), 60, "man -w")
            want = os.path.join(os.path.realpath(self.venv), "share", "man", "man1", "heatvox-sdf.1")
            if os.path.realpath(got.strip()) != want:
                raise Failed("man -w heatvox-sdf gives %s, not %s" % (got.strip(), want))
            print("    man heatvox-sdf: %s" % got.strip())

    def check_distance(self, r):
        h = r["voxel_size"]
        print("    heatvox %s from %s: cube at voxel size %.4f, max |error| %.3g within 2 voxels of the surface, "
              "%.3g over the grid" % (r["version"], r["library"], h, r["near_max_error"], r["max_error"]))
        if self.version and r["version"] != self.version:
            raise Failed("heatvox.__version__ %s, the wheel's %s" % (r["version"], self.version))
        if r["sign_wrong"]:
            raise Failed("%d cells more than a voxel from the cube have the wrong sign" % r["sign_wrong"])
        if not r["near_max_error"] <= 1e-4:
            raise Failed("max |error| %g within 2 voxels of the cube's surface (exact there)" % r["near_max_error"])
        if not r["max_error"] <= 0.5 * h:
            raise Failed("max |error| %g over the grid, over half a voxel (%g)" % (r["max_error"], 0.5 * h))

    def pip_uninstall_of_the_wheel_should_leave_nothing_of_heatvox(self):
        self.need_venv()
        self.uninstall()

    def pip_install_from_the_source_tree_should_load_its_bundled_library(self):
        self.need_venv()
        vpy = os.path.join(self.venv, "bin", "python")
        run([vpy, "-m", "pip", "install", "--no-build-isolation", "--no-index", ROOT], ROOT, self.env, 600,
            "pip install .")
        self.check_distance(self.probe())
        self.check_docs()

    def pip_uninstall_after_a_source_install_should_leave_nothing_of_heatvox(self):
        self.need_venv()
        self.uninstall()

    def need_wheel(self):
        if not self.wheel:
            raise Failed("no wheel (see the first check)")

    def need_venv(self):
        if not os.path.exists(os.path.join(self.venv, "bin", "python")):
            raise Failed("no virtual environment (see the checks above)")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    build = os.path.join(ROOT, sys.argv[1])
    t0 = time.time()
    skip = why_skip(build)
    failed = 0
    if skip:
        for name in CHECKS:
            print("SKIP: %s: %s" % (name, skip))
    else:
        tmp = tempfile.mkdtemp(prefix="hv_pip_")
        r = Run(sys.argv[1], tmp)
        for name in CHECKS:
            print("  %s" % name, flush=True)
            try:
                getattr(r, name)()
                print("    ok")
            except Failed as e:
                failed += 1
                print("    FAILED: %s" % e)
            sys.stdout.flush()
        if failed:
            print("check_pip: work directory %s kept" % tmp)
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    n = len(CHECKS)
    print("%d%%: Checks: %d, Failures: %d, Errors: 0" % (100 * (n - failed) // n, n, failed))
    print("check_pip: %d checks in %.1f s" % (n, time.time() - t0))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
