#!/usr/bin/env python3
"""The OpenCL programs heatvox builds, read from the code: every hv_cl_module
description under src/ (src/cl/cl_core.h) with the kernel sources its
sources array names. Prints one line per module, NAME:SRC,SRC,...[:fp64]
(SRC a file of kernels/ without .cl; fp64 where the module is built only
with HV_FP64), for tests/check_kernels.sh. Exits 1 when a description or
its sources cannot be read.

Usage: tests/cl_programs.py [ROOT]   (default: the project root)
"""
import glob
import os
import re
import sys

ROOT = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
MODULE = re.compile(r'hv_cl_module\s+\w+\s*=\s*\{\s*"([^"]+)"\s*,\s*(\w+)\s*,\s*\w+\s*,\s*(\d+)')
ARRAY = r"\b%s\s*\[\s*\]\s*=\s*\{([^}]*)\}"


def main():
    found, bad = [], []
    for path in sorted(glob.glob(os.path.join(ROOT, "src", "**", "*.c"), recursive=True)):
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
        for name, arr, fp64 in MODULE.findall(text):
            m = re.search(ARRAY % re.escape(arr), text)
            srcs = re.findall(r"hv__kernel_(\w+)", m.group(1)) if m else []
            rel = os.path.relpath(path, ROOT)
            if not srcs:
                bad.append("%s: module \"%s\": no sources in %s[]" % (rel, name, arr))
                continue
            for s in srcs:
                if not os.path.exists(os.path.join(ROOT, "kernels", s + ".cl")):
                    bad.append("%s: module \"%s\": no kernels/%s.cl" % (rel, name, s))
            found.append("%s:%s%s" % (name.replace(" ", "_"), ",".join(srcs),
                                      ":fp64" if fp64 == "1" else ""))
    for line in bad:
        print("cl_programs: " + line, file=sys.stderr)
    if bad or not found:
        if not found:
            print("cl_programs: no hv_cl_module description under src/", file=sys.stderr)
        return 1
    print("\n".join(found))
    return 0


if __name__ == "__main__":
    sys.exit(main())
