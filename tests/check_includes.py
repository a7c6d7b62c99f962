#!/usr/bin/env python3
"""The include map of src/README.md, checked: every #include "..." of src/,
include/heatvox/ and tools/ (the command includes public headers and its
own only) against the layers and interfaces that the two
tables of src/README.md give. A folder may hold folders of its own
(src/solve/mg/): each is a folder of the map, named by its path under src/,
and an include names a header by the path of its folder. Prints one line per broken include and a
closing line in the test framework's format.

Usage: tests/check_includes.py [ROOT]   (default: the project root)
"""
import glob
import os
import re
import sys

ROOT = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)
ROW = re.compile(r"^\|\s*`([^`]+)`\s*\|\s*(\d+)\s*\|(.*)$")


def read_map():
    """Folders: name -> (layer, interface headers); public headers: name -> layer."""
    folders, public = {}, {}
    with open(os.path.join(ROOT, "src", "README.md")) as f:
        for line in f:
            m = ROW.match(line.strip())
            if not m:
                continue
            name, layer, rest = m.group(1), int(m.group(2)), m.group(3)
            if name.endswith("/"):
                cells = rest.split("|")
                iface = set(re.findall(r"`([^`]+\.h)`", cells[1] if len(cells) > 1 else ""))
                folders[name[:-1]] = (layer, iface)
            else:
                public[name] = layer
    return folders, public


def includes(path):
    with open(path, encoding="utf-8", errors="replace") as f:
        return INCLUDE.findall(f.read())


def main():
    folders, public = read_map()
    bad, checked = [], 0
    # five checks: the folders listed, the public headers listed, and the
    # includes of src/, of include/heatvox/ and of tools/
    failed = set()
    kind = ["listed"]

    def fail(path, name, why):
        failed.add(kind[0])
        bad.append("%s: #include \"%s\": %s" % (os.path.relpath(path, ROOT), name, why))

    if not folders or not public:
        print("check_includes: no tables in src/README.md")
        return 1
    src = os.path.join(ROOT, "src")
    dirs = glob.glob(os.path.join(src, "*", "")) + glob.glob(os.path.join(src, "*", "*", ""))
    for d in sorted(dirs):
        name = os.path.relpath(d, src)
        if name not in folders:
            failed.add("folders")
            bad.append("src/%s: a folder src/README.md does not list" % name)
    for h in sorted(glob.glob(os.path.join(ROOT, "include", "heatvox", "*.h"))):
        if os.path.basename(h) not in public:
            failed.add("headers")
            bad.append("include/heatvox/%s: a header src/README.md does not list" % os.path.basename(h))
    kind[0] = "src"
    files = [f for d in ("*", os.path.join("*", "*")) for e in ("c", "h", "cpp")
             for f in glob.glob(os.path.join(src, d, "*." + e))]
    for path in sorted(files):
        folder = os.path.relpath(os.path.dirname(path), src)
        if folder not in folders:
            continue
        layer = folders[folder][0]
        for name in includes(path):
            checked += 1
            if "/" not in name:
                if not os.path.exists(os.path.join(os.path.dirname(path), name)):
                    fail(path, name, "not in this folder (name its folder)")
                continue
            # The folder an include names: the longest listed path before its file.
            top, base = name.split("/", 1)
            if name.rsplit("/", 1)[0] in folders:
                top, base = name.rsplit("/", 1)
            if top == "heatvox":
                if base not in public:
                    fail(path, name, "no such public header")
                elif public[base] > layer:
                    fail(path, name, "public header of layer %d above this folder's %d"
                         % (public[base], layer))
            elif top == folder:
                fail(path, name, "a header of this folder: include it without the folder")
            elif top in folders:
                if folders[top][0] >= layer:
                    fail(path, name, "%s/ (layer %d) is not below %s/ (layer %d)"
                         % (top, folders[top][0], folder, layer))
                elif base not in folders[top][1]:
                    fail(path, name, "private to %s/ (its interface: %s)"
                         % (top, ", ".join(sorted(folders[top][1])) or "none"))
    kind[0] = "public"
    for path in sorted(glob.glob(os.path.join(ROOT, "include", "heatvox", "*.h"))):
        me = os.path.basename(path)
        for name in includes(path):
            checked += 1
            base = name[len("heatvox/"):] if name.startswith("heatvox/") else name
            if base not in public:
                fail(path, name, "no such public header")
            elif public[base] > public.get(me, -1):
                fail(path, name, "layer %d above this header's %d" % (public[base], public.get(me, -1)))
    kind[0] = "tools"
    tools = [f for d in ("*", os.path.join("*", "*")) for e in ("c", "h", "cpp")
             for f in glob.glob(os.path.join(ROOT, "tools", d + "." + e))]
    top = os.path.realpath(os.path.join(ROOT, "tools"))
    for path in sorted(tools):
        for name in includes(path):
            checked += 1
            if name.startswith("heatvox/"):
                continue
            where = os.path.realpath(os.path.join(os.path.dirname(path), name))
            if not where.startswith(top + os.sep) or not os.path.exists(where):
                fail(path, name, "the command uses the public headers and its own only")
    for line in bad:
        print(line)
    print("%d%%: Checks: 5, Failures: %d, Errors: 0" % (100 * (5 - len(failed)) // 5, len(failed)))
    print("check_includes: %d includes of src/, include/heatvox/ and tools/ against src/README.md"
          % checked)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
