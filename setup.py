"""The wheel of the Python package: python/heatvox with libheatvox inside it.

pip runs this through pyproject.toml (`pip install --no-build-isolation
--no-index .`, `pip wheel ...`). build_py runs the project's own make for
the shared library, which reuses the build directory when it is up to date
(build/, or make's BUILD in $HEATVOX_BUILD), and puts a stripped copy of
the library in the package as heatvox/libheatvox.so.0, which heatvox/_lib.py
loads before the make-install and development-tree copies. The man pages and
the bash completion go in as data files (doc_files). setuptools' own files (build/lib,
bdist, egg-info) go under BUILD/python, beside make's.

The wheel holds no Python extension (the package loads the library through
ctypes), so it suits any Python 3, but only this platform and a system with
the runtime libraries libheatvox links (Debian 12's OpenVDB, TBB, assimp,
FFTW, OpenCL loader, and PETSc where the build found it): it is tagged
py3-none-<platform>, never pure.
"""

import glob
import os
import re
import shutil
import subprocess

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py
from wheel.bdist_wheel import bdist_wheel

ROOT = os.path.dirname(os.path.abspath(__file__))
# make's BUILD as make knows it (relative to the root, as on its command line).
BUILD_ARG = os.environ.get("HEATVOX_BUILD") or "build"
BUILD = os.path.join(ROOT, BUILD_ARG)
SONAME = "libheatvox.so.0"


def version():
    with open(os.path.join(ROOT, "include", "heatvox", "core.h")) as f:
        m = re.search(r'^#define HV_VERSION_STRING "([^"]+)"', f.read(), re.M)
    if not m:
        raise RuntimeError("include/heatvox/core.h: no HV_VERSION_STRING")
    return m.group(1)


def make(*targets):
    """Runs make for targets under BUILD (paths relative to it)."""
    cmd = [os.environ.get("MAKE") or "make", "-C", ROOT]
    if os.environ.get("HEATVOX_BUILD"):
        cmd.append("BUILD=" + BUILD_ARG)
    cmd += [BUILD_ARG.rstrip("/") + "/" + t for t in targets]
    print("heatvox: " + " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)


def make_library():
    """Runs make for BUILD/libheatvox.so; returns the file it links to."""
    make("libheatvox.so")
    return os.path.realpath(os.path.join(ROOT, BUILD, "libheatvox.so"))


def doc_files():
    """The wheel's data files, where a prefix keeps them: the man pages in
    share/man/man1 (a venv's man finds them from its bin/ on PATH) and the
    bash completion in share/bash-completion/completions. make writes both
    (with the command they are generated from) when they are not up to date."""
    make("man/.generated", "completion/heatvox")
    pages = sorted(glob.glob(os.path.join(BUILD, "man", "*.1")))
    if not pages:
        raise RuntimeError("make wrote no man pages under %s/man" % BUILD)
    rel = lambda p: os.path.relpath(p, ROOT)  # setuptools wants them relative
    return [
        ("share/man/man1", [rel(p) for p in pages]),
        ("share/bash-completion/completions", [rel(os.path.join(BUILD, "completion", "heatvox"))]),
    ]


class build_py_with_library(build_py):
    """build_py, then the shared library into the package."""

    def run(self):
        # A module removed from python/heatvox must not stay in the wheel.
        shutil.rmtree(os.path.join(self.build_lib, "heatvox"), ignore_errors=True)
        super().run()
        lib = make_library()
        dest = os.path.join(self.build_lib, "heatvox", SONAME)
        os.makedirs(os.path.dirname(dest), exist_ok=True)
        if os.path.exists(dest):
            os.remove(dest)
        # The symbol table is not needed to load it (the exports are in the
        # dynamic one): stripped, the library is a quarter smaller.
        strip = shutil.which("strip")
        if strip:
            subprocess.run([strip, "--strip-unneeded", "-o", dest, lib], check=True)
        else:
            shutil.copyfile(lib, dest)
        os.chmod(dest, 0o755)

    def get_outputs(self, include_bytecode=1):
        return super().get_outputs(include_bytecode) + [os.path.join(self.build_lib, "heatvox", SONAME)]


class BinaryDistribution(Distribution):
    """Says it has extension modules, for the shared library: install puts
    the package in platlib, and the wheel is not pure."""

    def has_ext_modules(self):
        return True


class bdist_wheel_platform(bdist_wheel):
    """A wheel for this platform (it holds a shared library) for any Python 3:
    no extension module ties it to one interpreter (ctypes loads the
    library)."""

    def get_tag(self):
        return ("py3", "none", super().get_tag()[2])


# setuptools' build/lib, bdist and egg-info under BUILD/python, apart from
# the sources and from make's files.
SETUP_BUILD = os.path.join(BUILD, "python")
os.makedirs(SETUP_BUILD, exist_ok=True)

setup(
    version=version(),
    package_dir={"": "python"},
    packages=["heatvox"],
    data_files=doc_files(),
    distclass=BinaryDistribution,
    cmdclass={"build_py": build_py_with_library, "bdist_wheel": bdist_wheel_platform},
    options={"build": {"build_base": SETUP_BUILD}, "egg_info": {"egg_base": SETUP_BUILD}},
)
