"""The operators under bpy.ops.heatvox. Each one reads its input in world
coordinates, runs heatvox and adds the result as a new object; any failure
(a non-mesh object, an empty mesh, a directory that cannot be written, a
library error naming the file) is reported and cancels, with nothing added."""

import os
import tempfile
import time

import numpy as np

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import geometry, library, prefs


def _heatvox(context):
    """The heatvox module, with the preferences' thread count applied."""
    p = prefs.get(context)
    hv = library.load(p)
    hv.set_threads(p.threads)
    return hv


def _meshes(context):
    """The selected objects, or the active one when none is selected."""
    sel = list(context.selected_objects)
    if not sel and context.active_object is not None:
        sel = [context.active_object]
    return sel


def _unique(name):
    """name, or name.001, ...: one no object holds yet."""
    if name not in bpy.data.objects:
        return name
    k = 1
    while "%s.%03d" % (name, k) in bpy.data.objects:
        k += 1
    return "%s.%03d" % (name, k)


def _directory(path):
    """Where a .vdb goes: path if given, else the .blend's directory, else a
    temporary one; made if missing. Raises OSError naming it."""
    if path:
        d = bpy.path.abspath(path)
    elif bpy.data.filepath:
        d = os.path.dirname(bpy.data.filepath)
    else:
        d = os.path.join(tempfile.gettempdir(), "heatvox")
    d = os.path.normpath(d)
    try:
        os.makedirs(d, exist_ok=True)
    except OSError as e:
        raise OSError("cannot make the directory %s: %s" % (d, e.strerror)) from None
    if not os.access(d, os.W_OK | os.X_OK):
        raise OSError("cannot write into %s (read-only)" % d)
    return d


class _Progress:
    """heatvox's progress callback, shown in Blender's progress bar and status
    bar while the body of the with block runs."""

    def __init__(self, context, what):
        self.wm, self.ws, self.what = context.window_manager, context.workspace, what

    def __enter__(self):
        self.wm.progress_begin(0, 1000)
        self._status("")
        return self

    def __call__(self, fraction, stage):
        self.wm.progress_update(int(1000 * min(max(fraction, 0.0), 1.0)))
        self._status("%s %d%%" % (stage, 100 * fraction))
        return False

    def __exit__(self, *exc):
        self.wm.progress_end()
        if self.ws is not None:
            self.ws.status_text_set(None)

    def _status(self, text):
        if self.ws is not None:
            self.ws.status_text_set("heatvox: %s %s" % (self.what, text))


class _Placement:
    """The grid's size, by cells along the longest side or by voxel size."""

    size_mode: EnumProperty(
        name="Size",
        items=(
            ("RESOLUTION", "Resolution", "Cells along the longest side of the bounds"),
            ("VOXEL_SIZE", "Voxel Size", "The voxel size in scene units"),
        ),
        default="RESOLUTION",
    )
    resolution: IntProperty(name="Resolution", min=8, max=2048, default=128,
                            description="Cells along the longest side of the bounds, padding included")
    voxel_size: FloatProperty(name="Voxel Size", min=1e-6, default=0.05, subtype="DISTANCE",
                              precision=4, description="The voxel size in scene units")

    def placement(self):
        if self.size_mode == "VOXEL_SIZE":
            return {"voxel_size": self.voxel_size}
        return {"res": self.resolution}


class _Shape:
    """The surface moved, its gaps closed or its thin parts opened (scene units)."""

    offset: FloatProperty(name="Offset", default=0.0, subtype="DISTANCE",
                          description="Move the surface out (in when negative)")
    close: FloatProperty(name="Close", min=0.0, default=0.0, subtype="DISTANCE",
                         description="Fill gaps and cracks narrower than twice this")
    open: FloatProperty(name="Open", min=0.0, default=0.0, subtype="DISTANCE",
                        description="Remove parts thinner than twice this")

    def shape(self):
        """sdf()'s options for them; the exact values only near the surface
        unless the morphology needs them all."""
        more = {"offset": self.offset, "close": self.close, "open": self.open}
        if self.close == 0 and self.open == 0:
            more["band_only"] = 3.0
        return more


def _run(op, context, body):
    """body(hv) -> result, with every failure reported and cancelling."""
    t0 = time.time()
    try:
        msg = body(_heatvox(context))
    except (library.LoadError, geometry.InputError, OSError, ValueError, TypeError) as e:
        op.report({"ERROR"}, str(e))
        return {"CANCELLED"}
    except Exception as e:  # heatvox.Error (its message names the file) and the unforeseen
        op.report({"ERROR"}, str(e) if type(e).__name__ == "Error" else "%s: %s" % (type(e).__name__, e))
        return {"CANCELLED"}
    op.report({"INFO"}, "heatvox: %s (%.2f s)" % (msg, time.time() - t0))
    return {"FINISHED"}


class _ObjectOp:
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.mode == "OBJECT"


class HEATVOX_OT_sdf_volume(_ObjectOp, _Placement, _Shape, bpy.types.Operator):
    """Signed distance volume of the selected meshes (holes, flipped faces and
    duplicated sheets welcome): a Volume object with the level set "sdf"
    (negative inside) and its inside as the fog grid "density"
    """

    bl_idname = "heatvox.sdf_volume"
    bl_label = "Signed Distance Volume"

    band: FloatProperty(name="Band", min=1.0, max=64.0, default=3.0,
                        description="Half width of the narrow band, in voxels")
    shell: FloatProperty(name="Shell", min=0.0, default=0.0, subtype="DISTANCE",
                         description="> 0: only a wall of this thickness inside the surface")
    directory: StringProperty(name="Directory", subtype="DIR_PATH", default="",
                              description="Where the .vdb goes; empty: beside the .blend, or a temporary directory")

    def execute(self, context):
        return _run(self, context, lambda hv: self._volume(hv, context))

    def _volume(self, hv, context):
        objects = _meshes(context)
        v, f = geometry.triangles(context, objects)
        name = _unique(objects[0].name + "_sdf")
        path = os.path.join(_directory(self.directory), name + ".vdb")
        more = dict(self.shape(), shell=self.shell)
        if "band_only" in more:
            more["band_only"] = self.band  # exact values across the band written
        with _Progress(context, "signed distance") as progress:
            g = hv.sdf(v, f, band=self.band, progress=progress, **more, **self.placement())
            g.write_vdb(path, fog="density")
        h, n = g.voxel_size, g.shape[::-1]
        geometry.new_volume(context, name, path)
        return "%s: %d x %d x %d voxels of %.4g" % (path, n[0], n[1], n[2], h)


class HEATVOX_OT_remesh(_ObjectOp, _Placement, _Shape, bpy.types.Operator):
    """Watertight remesh of the selected meshes: one closed, consistently
    oriented mesh around their inside, for printing and booleans"""

    bl_idname = "heatvox.remesh"
    bl_label = "Watertight Remesh"

    adaptivity: FloatProperty(name="Adaptivity", min=0.0, max=1.0, default=0.0,
                              description="0: a vertex per crossed voxel; more merges flat parts")
    replace: BoolProperty(name="Replace", default=False,
                          description="Replace the active object's mesh (and its modifiers, "
                          "which the result holds) instead of adding an object")

    def execute(self, context):
        return _run(self, context, lambda hv: self._remesh(hv, context))

    def _remesh(self, hv, context):
        objects = _meshes(context)
        if self.replace and len(objects) != 1:
            raise geometry.InputError("Replace takes one object; %d are selected" % len(objects))
        v, f = geometry.triangles(context, objects)
        with _Progress(context, "remesh") as progress:
            g = hv.sdf(v, f, progress=progress, **self.shape(), **self.placement())
            verts, faces = g.to_mesh(self.adaptivity)
        if self.replace:
            ob = objects[0]
            m = np.linalg.inv(np.array(ob.matrix_world, dtype=np.float64))
            local = verts @ m[:3, :3].T + m[:3, 3]
            old = ob.data
            ob.data = geometry.new_mesh(old.name, local, faces)
            ob.modifiers.clear()
            if old.users == 0:
                bpy.data.meshes.remove(old)
        else:
            name = _unique(objects[0].name + "_watertight")
            ob = bpy.data.objects.new(name, geometry.new_mesh(name, verts, faces))
            geometry.link(context, ob)
        return "%s: %d vertices, %d triangles, closed" % (ob.name, len(verts), len(faces))


class HEATVOX_OT_points_surface(_ObjectOp, _Placement, bpy.types.Operator):
    """Closed surface through the active point cloud (a mesh of vertices, with a
    normal per point or without): flipped normals on part of it are outvoted,
    missing ones recovered from the points"""

    bl_idname = "heatvox.points_surface"
    bl_label = "Points to Surface"

    orient: EnumProperty(
        name="Normals",
        items=(
            ("auto", "Auto", "The cloud's normals (point attribute N), recovered where it has none"),
            ("given", "Given", "The cloud's normals; a cloud without them is an error"),
            ("recover", "Recover", "Recovered from the points alone, the cloud's own ignored"),
        ),
        default="auto",
    )

    def execute(self, context):
        return _run(self, context, lambda hv: self._surface(hv, context))

    def _surface(self, hv, context):
        ob = context.active_object
        pts, nrm = geometry.points(context, ob)
        if nrm is None and self.orient == "given":
            raise geometry.InputError(
                "%s has no normals (no vector point attribute %s): set Normals to Auto or Recover"
                % (ob.name, geometry.NORMAL_ATTR))
        verts, faces, rep = hv.points_surface(pts, nrm, orient=self.orient, **self.placement())
        name = _unique(ob.name + "_surface")
        out = bpy.data.objects.new(name, geometry.new_mesh(name, verts, faces))
        geometry.link(context, out)
        if rep["recovered"]:
            return "%s: %d points, %d triangles, normals recovered (%d components, %.2f s)" % (
                name, len(pts), len(faces), rep["orient_components"], rep["t_orient"])
        return "%s: %d points, %d triangles, %d normals against the rest" % (
            name, len(pts), len(faces), rep["normals_against"])


class HEATVOX_OT_import_points(bpy.types.Operator, ImportHelper):
    """A point cloud file (PLY vertices, x y z or x y z nx ny nz text) as a mesh
    of vertices that keeps the normals where it has them (point attribute "N")"""

    bl_idname = "heatvox.import_points"
    bl_label = "Import Point Cloud"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default="*.ply;*.xyz;*.pts;*.xyzn", options={"HIDDEN"})

    def execute(self, context):
        return _run(self, context, lambda hv: self._import(hv, context))

    def _import(self, hv, context):
        pts, nrm = hv.read_points(self.filepath)
        name = _unique(os.path.splitext(os.path.basename(self.filepath))[0])
        ob = bpy.data.objects.new(name, geometry.new_points(name, pts, nrm))
        geometry.link(context, ob)
        if nrm is None:
            return "%s: %d points without normals (Points to Surface recovers them)" % (name, len(pts))
        return "%s: %d points with normals" % (name, len(pts))
