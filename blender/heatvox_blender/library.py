"""Finds and loads the heatvox Python package, once per Blender run.

In order: the library named in the preferences (through HEATVOX_LIBRARY,
which the package honours alone), the package zipped into the add-on by
``make blender-addon`` (heatvox/ beside this file, with libheatvox inside),
else ``import heatvox``: the package that ``make install`` put in
/usr/local/lib/python3/dist-packages or ``pip install`` in Blender's Python.
"""

import importlib
import os


class LoadError(Exception):
    """heatvox cannot be loaded; the message says what was tried."""


_module = None


def load(prefs):
    """The heatvox module; raises LoadError."""
    global _module
    if _module is not None:
        return _module
    lib = prefs.library.strip()
    if lib:
        import bpy

        lib = bpy.path.abspath(lib)
        if not os.path.isfile(lib):
            raise LoadError("heatvox: the library in the add-on's preferences, %s, is not a file" % lib)
        os.environ["HEATVOX_LIBRARY"] = lib
    here = os.path.dirname(os.path.abspath(__file__))
    name = __package__ + ".heatvox" if os.path.isdir(os.path.join(here, "heatvox")) else "heatvox"
    try:
        _module = importlib.import_module(name)
    except ImportError as e:
        raise LoadError(
            "heatvox: %s (install the add-on's zip from make blender-addon, or make install, or "
            "set the library in the add-on's preferences)" % e
        ) from None
    return _module


def describe():
    """One line on the loaded library, for the preferences."""
    if _module is None:
        return "heatvox is loaded when an operator first runs"
    return "heatvox %s from %s" % (_module.__version__, _module.library_path)
