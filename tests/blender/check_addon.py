"""The Blender add-on's tests, inside Blender (make check-blender):

    blender -b --factory-startup --python-exit-code 1 -P tests/blender/check_addon.py -- ZIP OUT

installs ZIP (make blender-addon) as a user would (preferences.addon_install,
addon_enable), then runs every operator on meshes broken here (holes, flipped
faces, a duplicated sheet, under a world transform and a modifier) and on a
point cloud, checks the results (the Volume object's grid and transform, the
remesh's topology and volume, the surface through the points), the bad inputs
as reports, and renders with Cycles one frame of the add-on's volume and of
Blender's own Mesh to Volume of OUT/scenes/meshes/sphere_holes_flips.obj
(written by make-scenes), checking that the add-on's inside is filled where
Blender's is empty. The renders land in OUT as PNG files.

Prints a line per check, then "N%: Checks: C, Failures: F, Errors: 0" as the
other suites do; exits 1 when a check failed.
"""

import math
import os
import sys
import tempfile
import time
import traceback

import numpy as np

import bmesh
import bpy

ZIP, OUT = sys.argv[sys.argv.index("--") + 1:][:2]
OUT = os.path.abspath(OUT)


class Failed(Exception):
    pass


def expect(cond, msg):
    if not cond:
        raise Failed(msg)


# ---- scene helpers -----------------------------------------------------------


def reset():
    """An empty scene (the factory startup's cube, camera and light gone)."""
    bpy.ops.object.select_all(action="SELECT")
    bpy.ops.object.delete()
    for coll in (bpy.data.meshes, bpy.data.volumes, bpy.data.materials, bpy.data.cameras, bpy.data.lights):
        for block in list(coll):
            if block.users == 0:
                coll.remove(block)


def select(*objects):
    bpy.ops.object.select_all(action="DESELECT")
    for ob in objects:
        ob.select_set(True)
    bpy.context.view_layer.objects.active = objects[0] if objects else None


def tri_arrays(ob, world=True):
    """(vertices, faces) of an object's evaluated mesh, triangulated."""
    ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    me.calc_loop_triangles()
    co = np.array([v.co[:] for v in me.vertices], dtype=np.float64)
    tri = np.array([t.vertices[:] for t in me.loop_triangles], dtype=np.int64)
    m = np.array(ev.matrix_world)
    ev.to_mesh_clear()
    if world:
        co = co @ m[:3, :3].T + m[:3, 3]
    return co, tri


def volume_of(v, f):
    """The signed volume enclosed by triangles (positive when outward)."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def broken_sphere():
    """A UV sphere of radius 1 under a world transform, with an Array
    modifier (two copies), then broken: three holes, a quarter of its faces
    flipped, a sheet of faces duplicated. Returns (object, the volume of the
    intact solid in world units)."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=1.0)
    ob = bpy.context.active_object
    ob.name = "broken"
    ob.location = (0.4, -0.3, 0.2)
    ob.rotation_euler = (0.3, 0.2, 0.5)
    ob.scale = (1.2, 0.9, 1.0)
    arr = ob.modifiers.new("array", "ARRAY")
    arr.relative_offset_displace = (1.6, 0.0, 0.0)
    bpy.context.view_layer.update()
    intact = volume_of(*tri_arrays(ob))
    bm = bmesh.new()
    bm.from_mesh(ob.data)
    bm.faces.ensure_lookup_table()
    faces = list(bm.faces)
    rng = np.random.default_rng(7)
    # a sheet of faces duplicated in place (before the holes, away from them)
    bmesh.ops.duplicate(bm, geom=[faces[i] for i in range(300, 340)])
    bmesh.ops.reverse_faces(bm, faces=[faces[i] for i in rng.choice(len(faces), len(faces) // 4, replace=False)])
    bmesh.ops.delete(bm, geom=[faces[i] for i in (500, 700, 900)], context="FACES")
    bm.to_mesh(ob.data)
    bm.free()
    ob.data.update()
    return ob, intact


def edges_closed_oriented(f):
    """(closed, oriented): every edge in exactly two triangles; every edge
    run once each way."""
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    und = np.sort(d, axis=1)
    _, counts = np.unique(und, axis=0, return_counts=True)
    closed = bool(np.all(counts == 2))
    directed = np.unique(d, axis=0)
    return closed, closed and len(directed) == len(d)


def op_error(call):
    """The ERROR report of an operator call, which bpy.ops raises as
    RuntimeError; None when it did not fail."""
    try:
        call()
    except RuntimeError as e:
        return str(e)
    return None


def hv():
    """The heatvox package inside the installed add-on."""
    import heatvox_blender.library as lib
    import heatvox_blender.prefs as prefs

    return lib.load(prefs.get(bpy.context))


# ---- the checks ----------------------------------------------------------------


def install():
    before = set(m.__name__ for m in __import__("addon_utils").modules())
    expect("heatvox_blender" not in before, "heatvox_blender installed before the test")
    bpy.ops.preferences.addon_install(filepath=os.path.abspath(ZIP))
    bpy.ops.preferences.addon_enable(module="heatvox_blender")
    for name in ("sdf_volume", "remesh", "points_surface", "import_points"):
        expect(hasattr(bpy.ops.heatvox, name), "bpy.ops.heatvox.%s missing" % name)
    where = os.path.dirname(__import__("heatvox_blender").__file__)
    expect(where.startswith(os.environ["BLENDER_USER_SCRIPTS"]), "add-on loaded from %s" % where)
    h = hv()
    expect(h.library_path.startswith(where), "library %s, not the zip's" % h.library_path)
    print("    heatvox %s, library %s" % (h.__version__, h.library_path))


def sdf_volume():
    reset()
    ob, _ = broken_sphere()
    select(ob)
    v, f = tri_arrays(ob)
    directory = os.path.join(OUT, "vdb")
    n0 = len(bpy.data.objects)
    # The library's progress reaches the add-on's progress bar.
    import heatvox_blender.operators as ops

    seen, call = [], ops._Progress.__call__
    ops._Progress.__call__ = lambda self, f, stage: seen.append((f, stage)) or call(self, f, stage)
    try:
        r = bpy.ops.heatvox.sdf_volume(resolution=96, band=3.0, directory=directory)
    finally:
        ops._Progress.__call__ = call
    expect(r == {"FINISHED"}, "sdf_volume returned %s" % r)
    expect(len(seen) >= 3 and all(0 <= f <= 1 for f, _ in seen), "progress calls %s" % seen)
    print("    progress: %d calls, stages %s" % (len(seen), sorted(set(st for _, st in seen))))
    expect(len(bpy.data.objects) == n0 + 1, "objects %d -> %d" % (n0, len(bpy.data.objects)))
    vo = bpy.context.active_object
    expect(vo.type == "VOLUME" and vo.name == "broken_sdf", "new object %s %s" % (vo.name, vo.type))
    path = bpy.path.abspath(vo.data.filepath)
    expect(os.path.isfile(path) and os.path.dirname(path) == directory, "vdb at %s" % path)
    expect(not [x for x in os.listdir(directory) if not x.endswith(".vdb")], "leftovers in %s" % directory)
    vo.data.grids.load()
    names = sorted(g.name for g in vo.data.grids)
    expect(names == ["density", "sdf"], "grids %s" % names)
    g = vo.data.grids["sdf"]
    expect(g.data_type == "FLOAT", "grid type %s" % g.data_type)
    fog = vo.data.grids["density"]
    expect(np.allclose(np.array(fog.matrix_object), np.array(g.matrix_object)), "the grids are placed apart")
    # The same placement through the package: the grid's voxel size and its
    # voxel centres (index space to object space; the object sits at the world's origin).
    ref = hv().sdf(v, f, res=96, band_only=1.0)
    h, origin = ref.voxel_size, np.array(ref.origin)
    m = np.array(g.matrix_object)
    expect(np.allclose(m[:3, :3], np.eye(3) * h, rtol=1e-5, atol=1e-9), "grid matrix %s, h %g" % (m[:3, :3], h))
    k = (m[:3, 3] - (origin + 0.5 * h)) / h
    expect(np.allclose(k, np.round(k), atol=1e-4), "voxel centres off the lattice by %s voxel" % (k - np.round(k)))
    expect(np.allclose(np.array(vo.matrix_world), np.eye(4)), "volume object transform %s" % vo.matrix_world)
    # Its active voxels: the band around the mesh in world space, to the 8^3
    # leaves Blender's bounds go by.
    bpy.context.view_layer.update()
    bb = np.array([vo.matrix_world @ __import__("mathutils").Vector(c) for c in vo.bound_box])
    lo, hi = v.min(axis=0), v.max(axis=0)
    for side, out, want in (("min", lo - bb.min(axis=0), 3 * h), ("max", bb.max(axis=0) - hi, 3 * h)):
        expect(np.all((out >= want - 1.5 * h) & (out <= want + 8 * h)),
               "volume bounds %s beyond the mesh's by %s, the band %g" % (side, out, want))
    print("    grid sdf: h %.4g, bounds %s..%s (mesh %s..%s)" % (h, bb.min(axis=0).round(3), bb.max(axis=0).round(3),
                                                          lo.round(3), hi.round(3)))


def beside_the_blend():
    """A saved scene's volume lands beside its .blend, referred to relatively."""
    reset()
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.5)
    ob = bpy.context.active_object
    d = os.path.join(OUT, "saved")
    os.makedirs(d)
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(d, "scene.blend"))
    select(ob)
    r = bpy.ops.heatvox.sdf_volume(resolution=32)
    expect(r == {"FINISHED"}, "sdf_volume returned %s" % r)
    vol = bpy.context.active_object.data
    expect(vol.filepath == "//Icosphere_sdf.vdb", "filepath %r" % vol.filepath)
    expect(os.path.isfile(os.path.join(d, "Icosphere_sdf.vdb")), "no vdb beside the .blend")
    vol.grids.load()
    expect(sorted(g.name for g in vol.grids) == ["density", "sdf"], "grids of the saved scene's volume")
    bpy.ops.wm.read_homefile(use_empty=True)


def remesh():
    reset()
    ob, intact = broken_sphere()
    select(ob)
    r = bpy.ops.heatvox.remesh(resolution=128)
    expect(r == {"FINISHED"}, "remesh returned %s" % r)
    out = bpy.context.active_object
    expect(out.name == "broken_watertight" and out.type == "MESH", "new object %s" % out.name)
    v, f = tri_arrays(out)
    closed, oriented = edges_closed_oriented(f)
    expect(closed, "remesh not closed")
    expect(oriented, "remesh not consistently oriented")
    vol = volume_of(v, f)
    expect(abs(vol / intact - 1) <= 0.01, "remesh volume %.5f, intact solid %.5f" % (vol, intact))
    print("    %d triangles, closed, oriented; volume %.5f vs intact %.5f (%+.2f%%)" %
          (len(f), vol, intact, 100 * (vol / intact - 1)))
    # Replace: the same object gets the closed mesh in its own coordinates, the
    # modifier (applied in the result) gone.
    select(ob)
    r = bpy.ops.heatvox.remesh(resolution=128, replace=True, adaptivity=0.3)
    expect(r == {"FINISHED"}, "remesh replace returned %s" % r)
    expect(len(ob.modifiers) == 0, "modifiers left: %s" % list(ob.modifiers))
    v2, f2 = tri_arrays(ob)
    expect(edges_closed_oriented(f2) == (True, True), "replaced mesh not closed and oriented")
    expect(len(f2) < len(f), "adaptivity 0.3 kept %d of %d triangles" % (len(f2), len(f)))
    vol2 = volume_of(v2, f2)
    expect(abs(vol2 / intact - 1) <= 0.01, "replaced volume %.5f, intact %.5f" % (vol2, intact))


def fibonacci_sphere(n, r, centre):
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = i * math.pi * (3 - math.sqrt(5))
    s = np.sqrt(1 - z * z)
    nrm = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
    return centre + r * nrm, nrm


def points_surface():
    reset()
    pts, nrm = fibonacci_sphere(40000, 0.8, np.array([0.5, 0.2, -0.1]))
    nrm[::7] *= -1  # a seventh of the normals flipped: outvoted
    path = os.path.join(OUT, "cloud.xyz")
    np.savetxt(path, np.hstack([pts, nrm]), fmt="%.7f")
    r = bpy.ops.heatvox.import_points(filepath=path)
    expect(r == {"FINISHED"}, "import_points returned %s" % r)
    ob = bpy.context.active_object
    expect(ob.name == "cloud" and len(ob.data.vertices) == len(pts) and len(ob.data.polygons) == 0,
           "imported %s: %d vertices" % (ob.name, len(ob.data.vertices)))
    expect("N" in ob.data.attributes, "no normal attribute N")
    # A binary PLY of the same points: the normals kept, point for point.
    ply = os.path.join(OUT, "cloud_ply.ply")
    with open(ply, "wb") as fh:
        fh.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(pts)).encode())
        for c in ("x", "y", "z", "nx", "ny", "nz"):
            fh.write(("property float %s\n" % c).encode())
        fh.write(b"end_header\n")
        fh.write(np.hstack([pts, nrm]).astype("<f4").tobytes())
    r = bpy.ops.heatvox.import_points(filepath=ply)
    expect(r == {"FINISHED"}, "import_points of a PLY returned %s" % r)
    got = np.empty(3 * len(pts), dtype=np.float32)
    bpy.context.active_object.data.attributes["N"].data.foreach_get("vector", got)
    expect(np.allclose(got.reshape(-1, 3), nrm, atol=1e-6), "the PLY's normals did not arrive")
    bpy.data.objects.remove(bpy.context.active_object)
    select(ob)
    ob.location = (0.0, 0.0, 1.0)  # the surface must follow the object
    bpy.context.view_layer.update()
    r = bpy.ops.heatvox.points_surface(resolution=96)
    expect(r == {"FINISHED"}, "points_surface returned %s" % r)
    out = bpy.context.active_object
    v, f = tri_arrays(out)
    expect(edges_closed_oriented(f) == (True, True), "surface not closed and oriented")
    want = 4 / 3 * math.pi * 0.8**3
    vol = volume_of(v, f)
    expect(abs(vol / want - 1) <= 0.01, "surface volume %.5f, sphere %.5f" % (vol, want))
    c = v.mean(axis=0)
    expect(np.allclose(c, [0.5, 0.2, 0.9], atol=0.01), "surface centre %s" % c)
    print("    %d points -> %d triangles, volume %+.2f%% of the sphere's" % (len(pts), len(f), 100 * (vol / want - 1)))
    # The same points without their normals: imported bare, recovered.
    bare = os.path.join(OUT, "cloud_bare.xyz")
    np.savetxt(bare, pts, fmt="%.7f")
    r = bpy.ops.heatvox.import_points(filepath=bare)
    expect(r == {"FINISHED"}, "import_points of a bare cloud returned %s" % r)
    ob = bpy.context.active_object
    expect(len(ob.data.vertices) == len(pts) and "N" not in ob.data.attributes,
           "bare import: %d vertices, attributes %s" % (len(ob.data.vertices), list(ob.data.attributes.keys())))
    r = bpy.ops.heatvox.points_surface(resolution=96)
    expect(r == {"FINISHED"}, "points_surface of a bare cloud returned %s" % r)
    v, f = tri_arrays(bpy.context.active_object)
    expect(edges_closed_oriented(f) == (True, True), "recovered surface not closed and oriented")
    vol = volume_of(v, f)
    expect(abs(vol / want - 1) <= 0.01, "recovered surface volume %.5f, sphere %.5f" % (vol, want))
    expect(np.allclose(v.mean(axis=0), [0.5, 0.2, -0.1], atol=0.01), "recovered centre %s" % v.mean(axis=0))
    print("    the same points without normals -> %d triangles, volume %+.2f%%" % (len(f), 100 * (vol / want - 1)))


def bad_input():
    reset()
    n0 = len(bpy.data.objects)
    empty_mesh = bpy.data.objects.new("nothing", bpy.data.meshes.new("nothing"))
    bpy.context.collection.objects.link(empty_mesh)
    lamp = bpy.data.objects.new("lamp", bpy.data.lights.new("lamp", "POINT"))
    bpy.context.collection.objects.link(lamp)
    n0 = len(bpy.data.objects)
    cases = [
        ("an empty mesh", empty_mesh, lambda: bpy.ops.heatvox.sdf_volume(), "nothing has no faces"),
        ("an empty mesh, remesh", empty_mesh, lambda: bpy.ops.heatvox.remesh(), "nothing has no faces"),
        ("a light", lamp, lambda: bpy.ops.heatvox.sdf_volume(), "lamp is not a mesh"),
        ("a light, points", lamp, lambda: bpy.ops.heatvox.points_surface(), "lamp is not a mesh of points"),
    ]
    bpy.ops.mesh.primitive_cube_add()
    cube = bpy.context.active_object
    cases.append(("a mesh, points", cube, lambda: bpy.ops.heatvox.points_surface(), "Cube has 6 faces"))
    # A directory nobody may write into, root included: one in /proc.
    ro = tempfile.mkdtemp(prefix="hv_ro_", dir=OUT)
    os.chmod(ro, 0o555)
    if os.access(ro, os.W_OK):
        ro = "/proc/self/fdinfo"
    cases.append(("a read-only directory", cube, lambda: bpy.ops.heatvox.sdf_volume(directory=ro, resolution=32), ro))
    bad = os.path.join(OUT, "bad.xyz")
    with open(bad, "w") as fh:
        fh.write("0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 nan 0 0 1\n")
    cases.append(("a cloud file with NaN", cube, lambda: bpy.ops.heatvox.import_points(filepath=bad), bad))
    bare = os.path.join(OUT, "bare.xyz")
    with open(bare, "w") as fh:
        fh.write("0 0 0\n1 0 0\n1 1 0\n0 1 1\n")
    expect(bpy.ops.heatvox.import_points(filepath=bare) == {"FINISHED"}, "a bare cloud was not imported")
    cloud = bpy.context.active_object
    expect("N" not in cloud.data.attributes, "a bare cloud came with normals")
    cases.append(("normals asked of a cloud without them", cloud,
                  lambda: bpy.ops.heatvox.points_surface(orient="given"), "bare has no normals"))
    n0 = len(bpy.data.objects)
    for what, ob, call, want in cases:
        select(ob)
        before = set(os.listdir(ro))
        err = op_error(call)
        expect(err is not None, "%s: no error" % what)
        expect(want in err, "%s: the report %r does not name %r" % (what, err, want))
        expect("Traceback" not in err, "%s: a traceback in the report" % what)
        expect(len(bpy.data.objects) == n0, "%s: an object was added" % what)
        expect(set(os.listdir(ro)) == before, "%s: files left in %s" % (what, ro))
        print("    %s: %s" % (what, err.strip().splitlines()[-1]))


# ---- renders: the add-on's volume beside Blender's Mesh to Volume ---------------


def slab_material(name):
    """A volume material showing a slab |z| < 0.08 of the grid "density"
    (the inside: heatvox's fog grid, Blender's Mesh to Volume)."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nodes, links = nt.nodes, nt.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    vol = nodes.new("ShaderNodeVolumePrincipled")
    vol.inputs["Color"].default_value = (0.9, 0.6, 0.3, 1)
    vol.inputs["Emission Color"].default_value = (0.9, 0.6, 0.3, 1)
    vol.inputs["Emission Strength"].default_value = 0.6
    def math(op, a, b):
        """A Math node op(a, b) of sockets or numbers."""
        m = nodes.new("ShaderNodeMath")
        m.operation = op
        for i, x in enumerate((a, b)):
            if isinstance(x, float):
                m.inputs[i].default_value = x
            else:
                links.new(x, m.inputs[i])
        return m.outputs[0]

    coords = nodes.new("ShaderNodeTexCoord")
    xyz = nodes.new("ShaderNodeSeparateXYZ")
    links.new(coords.outputs["Object"], xyz.inputs["Vector"])
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "density"
    slab = math("LESS_THAN", math("ABSOLUTE", xyz.outputs["Z"], 0.0), 0.08)
    dens = math("MULTIPLY", math("MULTIPLY", slab, attr.outputs["Fac"]), 60.0)
    links.new(dens, vol.inputs["Density"])
    links.new(dens, vol.inputs["Emission Strength"])
    links.new(vol.outputs["Volume"], out.inputs["Volume"])
    return mat


def render(ob, path):
    """One Cycles CPU frame of ob alone from above at a slant (orthographic,
    transparent film); returns the alpha channel, (rows, cols), row 0 at the
    bottom."""
    scene = bpy.context.scene
    for o in scene.objects:
        o.hide_render = o is not ob and o.type != "CAMERA"
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.cycles.volume_step_rate = 2.0
    scene.cycles.use_denoising = False
    scene.render.film_transparent = True
    scene.render.resolution_x = scene.render.resolution_y = 200
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    px = np.array(img.pixels[:], dtype=np.float32).reshape(img.size[1], img.size[0], 4)
    bpy.data.images.remove(img)
    return px[:, :, 3]


def camera():
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    bpy.context.collection.objects.link(cam)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 2.6
    tilt = math.radians(35)
    cam.location = (0.0, -6 * math.sin(tilt), 6 * math.cos(tilt))
    cam.rotation_euler = (tilt, 0.0, 0.0)
    bpy.context.scene.camera = cam


def renders():
    reset()
    path = os.path.join(OUT, "scenes", "meshes", "sphere_holes_flips.obj")
    bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
    mesh = bpy.context.selected_objects[0]
    camera()
    select(mesh)
    r = bpy.ops.heatvox.sdf_volume(resolution=96, directory=os.path.join(OUT, "vdb"))
    expect(r == {"FINISHED"}, "sdf_volume returned %s" % r)
    ours = bpy.context.active_object
    h = hv().sdf(*tri_arrays(mesh), res=96, band_only=1.0).voxel_size
    ours.data.materials.clear()
    ours.data.materials.append(slab_material("heatvox slab"))
    # Blender's own: a Volume object with the Mesh to Volume modifier, interior fill on.
    bpy.ops.object.volume_add()
    theirs = bpy.context.active_object
    mod = theirs.modifiers.new("mesh to volume", "MESH_TO_VOLUME")
    mod.object = mesh
    mod.resolution_mode = "VOXEL_SIZE"
    mod.voxel_size = h
    mod.use_fill_volume = True
    theirs.data.materials.append(slab_material("blender slab"))
    t0 = time.time()
    a = render(ours, os.path.join(OUT, "heatvox_sdf_volume.png"))
    b = render(theirs, os.path.join(OUT, "blender_mesh_to_volume.png"))
    rows, cols = a.shape
    centre = (slice(rows // 2 - 3, rows // 2 + 4), slice(cols // 2 - 3, cols // 2 + 4))
    ca, cb = float(a[centre].mean()), float(b[centre].mean())
    # Both show the wall: along the slab's rim, left and right of the centre.
    rim = int(cols / 2.6 * 0.97)
    wa = float(a[rows // 2, cols // 2 - rim:cols // 2 + rim].max())
    wb = float(b[rows // 2, cols // 2 - rim:cols // 2 + rim].max())
    print("    centre alpha: heatvox %.2f, Mesh to Volume %.2f; wall %.2f, %.2f (%.1f s)" %
          (ca, cb, wa, wb, time.time() - t0))
    expect(wa > 0.5 and wb > 0.5, "the wall does not show in both renders")
    expect(ca > 0.9, "heatvox's inside is not filled (alpha %.2f)" % ca)
    expect(cb < 0.1, "Mesh to Volume's inside is filled here (alpha %.2f): the comparison shows nothing" % cb)


def readme_example():
    """README.md's Blender example, as written, in a Blender of its own: from
    a directory laid out like the repository root (build/ with the zip,
    scenes/ from make-scenes), the add-on installed into a scripts directory
    of its own, the unsaved scene's .vdb under $TMPDIR/heatvox."""
    import re
    import subprocess

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with open(os.path.join(root, "README.md")) as fh:
        text = fh.read()
    part = text.split("\n## Blender\n", 1)
    expect(len(part) == 2, "README.md has no '## Blender' section")
    m = re.search(r"\n```python\n(.*?)\n```\n", part[1].split("\n## ", 1)[0], re.S)
    expect(m is not None, "the Blender section of README.md has no ```python block")
    d = tempfile.mkdtemp(prefix="hv_readme_", dir=OUT)
    os.mkdir(os.path.join(d, "build"))
    os.symlink(os.path.abspath(ZIP), os.path.join(d, "build", "heatvox_blender.zip"))
    os.symlink(os.path.join(OUT, "scenes"), os.path.join(d, "scenes"))
    code = m.group(1) + "\nbpy.ops.wm.save_as_mainfile(filepath=%r)\n" % os.path.join(d, "result.blend")
    with open(os.path.join(d, "example.py"), "w") as fh:
        fh.write(code)
    env = dict(os.environ, PWD=d, TMPDIR=d, BLENDER_USER_SCRIPTS=os.path.join(d, "scripts"))
    p = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1",
                        "-P", "example.py"], cwd=d, env=env, capture_output=True, text=True, timeout=300)
    expect(p.returncode == 0, "README example failed (exit %d):\n%s%s" % (p.returncode, p.stdout[-3000:], p.stderr[-2000:]))
    vdb = os.path.join(d, "heatvox", "sphere_holes_flips_sdf.vdb")
    expect(os.path.isfile(vdb), "no %s" % vdb)
    for line in p.stdout.splitlines():
        if line.startswith("Info: heatvox"):
            print("    " + line)
    # The saved scene holds both results.
    bpy.ops.wm.open_mainfile(filepath=os.path.join(d, "result.blend"))
    names = sorted(o.name for o in bpy.data.objects)
    expect("sphere_holes_flips_sdf" in names and "sphere_holes_flips_watertight" in names, "objects %s" % names)
    v, f = tri_arrays(bpy.data.objects["sphere_holes_flips_watertight"])
    expect(edges_closed_oriented(f) == (True, True), "README remesh not closed and oriented")


def installed_package():
    """The add-on alone (blender/heatvox_blender, no package inside) finds the
    heatvox that make install put on Blender's path (the staged install of
    make check; /usr/local/lib/python3.X/dist-packages with PREFIX=/usr/local,
    which Debian's Blender searches), in a Blender of its own."""
    import shutil
    import subprocess

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    stage = os.path.join(os.path.dirname(os.path.abspath(ZIP)), "stage", "lib")
    site = [os.path.join(stage, p, "dist-packages") for p in os.listdir(stage) if p.startswith("python3")]
    expect(len(site) == 1, "no staged Python package under %s" % stage)
    d = tempfile.mkdtemp(prefix="hv_installed_", dir=OUT)
    addons = os.path.join(d, "scripts", "addons")
    shutil.copytree(os.path.join(root, "blender", "heatvox_blender"), os.path.join(addons, "heatvox_blender"))
    code = """
import sys
sys.path.insert(0, %r)
import bpy, addon_utils
bpy.ops.preferences.addon_enable(module="heatvox_blender")
bpy.ops.mesh.primitive_ico_sphere_add(radius=0.5)
assert bpy.ops.heatvox.remesh(resolution=32) == {"FINISHED"}
import heatvox_blender.library as lib
print("LOADED", lib.describe())
""" % site[0]
    with open(os.path.join(d, "probe.py"), "w") as fh:
        fh.write(code)
    env = dict(os.environ, BLENDER_USER_SCRIPTS=os.path.join(d, "scripts"))
    p = subprocess.run([bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1",
                        "-P", os.path.join(d, "probe.py")], cwd=d, env=env, capture_output=True, text=True,
                       timeout=300)
    expect(p.returncode == 0, "exit %d:\n%s%s" % (p.returncode, p.stdout[-2000:], p.stderr[-2000:]))
    line = [x for x in p.stdout.splitlines() if x.startswith("LOADED")]
    expect(line and os.path.join(stage, "libheatvox.so") in line[0], "loaded %s" % line)
    print("    " + line[0])


CHECKS = [install, sdf_volume, beside_the_blend, remesh, points_surface, bad_input, renders, readme_example, installed_package]


def main():
    t0 = time.time()
    failed = 0
    for check in CHECKS:
        print("  %s" % check.__name__, flush=True)
        try:
            check()
            print("    ok", flush=True)
        except Failed as e:
            failed += 1
            print("    FAILED: %s" % e, flush=True)
        except Exception:
            failed += 1
            print("    ERROR:\n" + traceback.format_exc(), flush=True)
    n = len(CHECKS)
    print("%d%%: Checks: %d, Failures: %d, Errors: 0" % (100 * (n - failed) // n, n, failed))
    print("check_addon: %d checks in %.1f s" % (n, time.time() - t0))
    sys.stdout.flush()
    if failed:
        sys.exit(1)


main()
