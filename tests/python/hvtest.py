"""Helpers shared by the Python tests: the command of the build under test,
the generated scenes, temporary directories.

The build under test is the one whose library heatvox loaded
($HEATVOX_LIBRARY, set by tests/check_python.c to its own build): the command
is $HEATVOX_BIN, else the heatvox beside that library.
"""

import atexit
import os
import shutil
import subprocess
import tempfile
import unittest

import heatvox

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))

_scenes = None
_bin = None


def heatvox_bin():
    global _bin
    if _bin is None:
        cands = [os.environ.get("HEATVOX_BIN", "")]
        libdir = os.path.dirname(os.path.realpath(heatvox.library_path))
        cands += [os.path.join(libdir, "heatvox"), os.path.join(libdir, "..", "bin", "heatvox")]
        for c in cands:
            if c and os.access(c, os.X_OK):
                _bin = os.path.abspath(c)
                break
        else:
            raise AssertionError("no heatvox command beside %s; set HEATVOX_BIN" % heatvox.library_path)
    return _bin


def run(*args, cwd=None, expect=0):
    """Runs the command; returns its stdout. Fails the test on another exit code."""
    p = subprocess.run([heatvox_bin()] + [str(a) for a in args], cwd=cwd, capture_output=True, text=True)
    if p.returncode != expect:
        raise AssertionError(
            "heatvox %s: exit %d (expected %d)\nstderr: %s" % (" ".join(map(str, args)), p.returncode, expect, p.stderr)
        )
    return p.stdout


def tmpdir():
    """A temporary directory removed when the process exits."""
    d = tempfile.mkdtemp(prefix="hv_py_")
    atexit.register(shutil.rmtree, d, True)
    return d


def scenes():
    """`heatvox make-scenes` output, made once per process."""
    global _scenes
    if _scenes is None:
        d = tmpdir()
        run("make-scenes", os.path.join(d, "scenes"), "-q")
        _scenes = os.path.join(d, "scenes")
    return _scenes


def scene(rel):
    return os.path.join(scenes(), rel)


def need_pyopenvdb():
    try:
        import pyopenvdb  # noqa: F401
    except ImportError as e:
        raise unittest.SkipTest("pyopenvdb is not installed (%s)" % e)
    return pyopenvdb


def bits_equal(a, b):
    """Arrays equal bit for bit (NaN and -0 included)."""
    import numpy as np

    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def assert_bits_equal(tc, a, b, what=""):
    """Fails test case `tc` unless a and b are equal bit for bit."""
    import numpy as np

    if bits_equal(a, b):
        return
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        tc.fail("%s: %s %s against %s %s" % (what, a.shape, a.dtype, b.shape, b.dtype))
    with np.errstate(invalid="ignore"):
        d = np.abs(a.astype(np.float64) - b.astype(np.float64))
    tc.fail("%s: %d values differ, max |diff| %g" % (what, int((a != b).sum()), np.nanmax(d)))


def child_env():
    """This process's environment for a Python child run elsewhere: the
    heatvox package and library it loaded, by absolute paths."""
    env = dict(os.environ)
    pkg = os.path.dirname(os.path.dirname(os.path.abspath(heatvox.__file__)))
    env["PYTHONPATH"] = os.pathsep.join([pkg] + [os.path.abspath(p) for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env["HEATVOX_LIBRARY"] = os.path.realpath(heatvox.library_path)
    return env
