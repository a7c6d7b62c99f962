"""Blender data to and from the arrays heatvox takes: meshes with their
modifiers applied and in world coordinates, new mesh and volume objects."""

import numpy as np

import bpy


# The point attribute holding a cloud's normals (Houdini's name for them).
NORMAL_ATTR = "N"


class InputError(Exception):
    """An object the operator cannot take; the message names it."""


def _world(co, matrix):
    m = np.array(matrix, dtype=np.float64)
    return co @ m[:3, :3].T + m[:3, 3]


def triangles(context, objects):
    """(vertices, faces) of the objects' evaluated meshes (modifiers applied)
    in world coordinates, joined: float64 (n, 3) and int64 (m, 3)."""
    if not objects:
        raise InputError("select a mesh object")
    depsgraph = context.evaluated_depsgraph_get()
    verts, faces, base = [], [], 0
    for ob in objects:
        if ob.type != "MESH":
            raise InputError("%s is not a mesh (its type is %s)" % (ob.name, ob.type))
        ev = ob.evaluated_get(depsgraph)
        me = ev.to_mesh()
        try:
            me.calc_loop_triangles()
            n, m = len(me.vertices), len(me.loop_triangles)
            if m == 0:
                raise InputError("%s has no faces (%d vertices)" % (ob.name, n))
            co = np.empty(3 * n, dtype=np.float32)
            me.vertices.foreach_get("co", co)
            tri = np.empty(3 * m, dtype=np.int32)
            me.loop_triangles.foreach_get("vertices", tri)
            verts.append(_world(co.reshape(n, 3).astype(np.float64), ev.matrix_world))
            faces.append(tri.reshape(m, 3).astype(np.int64) + base)
            base += n
        finally:
            ev.to_mesh_clear()
    return np.concatenate(verts), np.concatenate(faces)


def points(context, ob):
    """(points, normals) of a vertex-only object in world coordinates: the
    normals from its point attribute NORMAL_ATTR (which import_points
    writes; Blender 3.4 reserves the name "normal"), None without one (a
    cloud whose orientation heatvox recovers)."""
    if ob is None:
        raise InputError("select a point cloud: a mesh object of vertices")
    if ob.type != "MESH":
        raise InputError("%s is not a mesh of points (its type is %s)" % (ob.name, ob.type))
    me = ob.data
    n = len(me.vertices)
    if n == 0:
        raise InputError("%s has no vertices" % ob.name)
    if len(me.polygons):
        raise InputError(
            "%s has %d faces: a point cloud is a mesh of vertices alone (SDF Volume and Remesh "
            "take meshes)" % (ob.name, len(me.polygons))
        )
    co = np.empty(3 * n, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    pts = _world(co.reshape(n, 3).astype(np.float64), ob.matrix_world)
    attr = me.attributes.get(NORMAL_ATTR)
    if attr is None:
        return pts, None
    if attr.domain != "POINT" or attr.data_type != "FLOAT_VECTOR":
        raise InputError(
            "%s: its attribute %s is not a vector per point, so it cannot be the points' normals "
            "(remove it and heatvox recovers them)" % (ob.name, NORMAL_ATTR)
        )
    nr = np.empty(3 * n, dtype=np.float32)
    attr.data.foreach_get("vector", nr)
    m = np.array(ob.matrix_world, dtype=np.float64)
    # Normals go with the inverse transpose; heatvox makes them unit length.
    nrm = nr.reshape(n, 3).astype(np.float64) @ np.linalg.inv(m[:3, :3])
    return pts, nrm


def new_mesh(name, vertices, faces):
    """A mesh datablock from (n, 3) vertices and (m, 3) triangles."""
    me = bpy.data.meshes.new(name)
    n, m = len(vertices), len(faces)
    me.vertices.add(n)
    me.vertices.foreach_set("co", np.asarray(vertices, dtype=np.float32).ravel())
    me.loops.add(3 * m)
    me.loops.foreach_set("vertex_index", np.asarray(faces, dtype=np.int32).ravel())
    me.polygons.add(m)
    me.polygons.foreach_set("loop_start", np.arange(0, 3 * m, 3, dtype=np.int32))
    me.polygons.foreach_set("loop_total", np.full(m, 3, dtype=np.int32))
    me.update(calc_edges=True)
    me.validate(verbose=False)
    return me


def new_points(name, pts, normals):
    """A vertex-only mesh with the normals (None: a cloud without them) as
    point attribute NORMAL_ATTR."""
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(pts))
    me.vertices.foreach_set("co", np.asarray(pts, dtype=np.float32).ravel())
    if normals is not None:
        attr = me.attributes.new(NORMAL_ATTR, "FLOAT_VECTOR", "POINT")
        attr.data.foreach_set("vector", np.asarray(normals, dtype=np.float32).ravel())
    me.update()
    return me


def link(context, ob):
    """Links a new object into the active collection, selected and active."""
    context.collection.objects.link(ob)
    for o in context.selected_objects:
        o.select_set(False)
    ob.select_set(True)
    context.view_layer.objects.active = ob


def fog_material():
    """A volume material shading the grid "density" (the inside): a
    Principled Volume, whose density attribute is "density" by default."""
    mat = bpy.data.materials.new("heatvox inside")
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()  # the default nodes are a surface's Principled BSDF
    out = nodes.new("ShaderNodeOutputMaterial")
    vol = nodes.new("ShaderNodeVolumePrincipled")
    vol.inputs["Color"].default_value = (0.8, 0.55, 0.3, 1.0)
    mat.node_tree.links.new(vol.outputs["Volume"], out.inputs["Volume"])
    return mat


def new_volume(context, name, path):
    """A Volume object reading the .vdb at path, with fog_material."""
    vol = bpy.data.volumes.new(name)
    # Relative to a saved .blend ("//NAME.vdb"), so that the two move together.
    vol.filepath = bpy.path.relpath(path) if bpy.data.filepath else path
    vol.materials.append(fog_material())
    ob = bpy.data.objects.new(name, vol)
    link(context, ob)
    return ob
