#!/bin/sh
# make demo: generates the scenes, then runs the main jobs on them into out/:
# a batch of broken meshes to VDB level sets with previews, a scanned point
# cloud to a level set and a closed mesh, 2D signed distances
# from broken curves to EXR and PNG, slices, geodesic distance around walls and
# through a building, and a velocity extension. Usage: tools/demo.sh path/to/heatvox
set -e
hv=${1:-build/heatvox}
out=out
t0=$(date +%s)

echo "== scenes: broken meshes, a level set, distance sources and obstacles (heatvox make-scenes)"
"$hv" make-scenes scenes

echo
echo "== batch: signed distance volumes for scenes/batch/meshes.list"
# Two inputs of the manifest fail on purpose (exit code 1): the batch reports them and goes on.
rc=0
"$hv" batch scenes/batch/meshes.list -o "$out/batch" -j 2 --res 64 --preview \
    --report "$out/batch/report.jsonl" || rc=$?
[ "$rc" -le 1 ] || exit "$rc"

echo
echo "== a scanned torus: oriented points to a level set and a closed mesh"
mkdir -p "$out/points"
"$hv" sdf scenes/points/torus_scan.xyz -o "$out/points/torus_scan.vdb" \
    --mesh-out "$out/points/torus_scan.ply" --res 96

echo
echo "== 2D: signed distance from broken curves (heatvox sdf2d)"
mkdir -p "$out/2d"
for f in scenes/curves/*.txt scenes/curves/*.svg; do
    n=$(basename "$f")
    n=${n%.*}
    "$hv" sdf2d "$f" -o "$out/2d/$n.exr" --png "$out/2d/$n.png" --res 256
done

echo
echo "== slices of the volumes (heatvox slice)"
"$hv" slice "$out/batch/torus_holes.vdb" --axis z -o "$out/batch/torus_holes_z.png"
"$hv" slice "$out/batch/sphere_holes_flips.vdb" --axis x -o "$out/batch/sphere_holes_flips_x.exr"

echo
echo "== geodesic distance around obstacles (heatvox distance)"
mkdir -p "$out/distance"
"$hv" distance --sources scenes/distance/sources.txt --obstacles scenes/distance/walls.vdb \
    -o "$out/distance/walls.vdb"
"$hv" distance --sources scenes/distance/sources.txt --obstacle-mesh scenes/distance/building.obj \
    --res 64 -o "$out/distance/building.vdb"
"$hv" slice "$out/distance/walls.vdb" --grid distance --axis z -o "$out/distance/walls_z.png"

echo
echo "== extension of a velocity off a level set (heatvox extend)"
mkdir -p "$out/extend"
"$hv" extend scenes/levelset/sphere_velocity.vdb --levelset sdf --field v \
    -o "$out/extend/sphere_velocity_ext.vdb"

echo
echo "done in $(($(date +%s) - t0)) s; results:"
echo "  $out/batch/*.vdb          level sets (grid \"sdf\"), *.png previews (x, y, z middle slices)"
echo "  $out/batch/report.jsonl   one JSON line per input: status, errors, grid, seconds per stage"
echo "  $out/points/              the scanned torus's level set and closed mesh"
echo "  $out/2d/*.exr, *.png      2D signed distances from scenes/curves/"
echo "  $out/batch/*_z.png, *_x.exr   slices cut by heatvox slice"
echo "  $out/distance/*.vdb       geodesic distance (grid \"distance\"), walls_z.png a slice"
echo "  $out/extend/              extended velocity"
