#!/usr/bin/env python3
"""Zips the Blender add-on for Preferences > Add-ons > Install.

Usage: blender_zip.py OUT.zip ADDON_DIR PACKAGE_DIR LIBRARY

The zip holds ADDON_DIR as heatvox_blender/, the Python package PACKAGE_DIR
as heatvox_blender/heatvox/ and a stripped copy of LIBRARY inside it as
heatvox/libheatvox.so.0 (where the package looks first, as in the wheel), so
that the add-on needs nothing else installed. It is written through a
temporary name: a failed run leaves no zip.
"""

import os
import shutil
import subprocess
import sys
import tempfile
import zipfile

SONAME = "libheatvox.so.0"


def files(root):
    """The .py files under root, relative to it, sorted."""
    out = []
    for d, dirs, names in os.walk(root):
        dirs[:] = sorted(x for x in dirs if x != "__pycache__")
        out += [os.path.relpath(os.path.join(d, n), root) for n in sorted(names) if n.endswith(".py")]
    return out


def stripped(lib, tmp):
    """A copy of lib without its symbol table (the exports stay)."""
    dest = os.path.join(tmp, SONAME)
    strip = shutil.which("strip")
    if strip:
        subprocess.run([strip, "--strip-unneeded", "-o", dest, os.path.realpath(lib)], check=True)
    else:
        shutil.copyfile(os.path.realpath(lib), dest)
    return dest


def main(argv):
    if len(argv) != 5:
        sys.stderr.write("usage: blender_zip.py OUT.zip ADDON_DIR PACKAGE_DIR LIBRARY\n")
        return 2
    out, addon, package, lib = argv[1:]
    if "_install.py" in files(package):
        sys.stderr.write("blender_zip.py: %s holds _install.py (an installed copy?)\n" % package)
        return 1
    part = out + ".part"
    with tempfile.TemporaryDirectory() as tmp:
        so = stripped(lib, tmp)
        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as z:
            for f in files(addon):
                z.write(os.path.join(addon, f), os.path.join("heatvox_blender", f))
            for f in files(package):
                z.write(os.path.join(package, f), os.path.join("heatvox_blender", "heatvox", f))
            z.write(so, os.path.join("heatvox_blender", "heatvox", SONAME))
    os.replace(part, out)
    print("%s: %.1f MB" % (out, os.path.getsize(out) / 1e6))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
