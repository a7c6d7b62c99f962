"""heatvox for Blender: signed distance volumes, watertight remeshes and
surfaces through point clouds, from broken meshes and scans.

Blender's own Mesh to Volume fills the inside only of closed meshes; a mesh
with holes, flipped faces or duplicated sheets gives a shell. heatvox's signed
heat method gives such a mesh a solid inside. The operators (bpy.ops.heatvox):

- ``sdf_volume``: the selected meshes -> a Volume object holding the ``sdf``
  grid (negative inside), written as a .vdb beside the .blend;
- ``remesh``: the selected meshes -> one closed, consistently oriented mesh;
- ``points_surface``: a vertex-only object, with a normal per point or
  without (recovered from the points) -> a closed mesh through the points;
- ``import_points``: a point cloud file (.ply, .xyz, .pts, .xyzn) -> a
  vertex-only object keeping the file's normals where it has them (point
  attribute "N").

Everything runs in world coordinates, so results line up with their inputs.
The work is done by the heatvox Python package (heatvox/ in this add-on when
it was zipped by ``make blender-addon``, else the one ``make install`` or
``pip install`` put where Blender's Python finds it).
"""

bl_info = {
    "name": "heatvox",
    "author": "heatvox",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Object > heatvox; File > Import > Point cloud (heatvox)",
    "description": "Signed distance volumes and watertight meshes from broken meshes and point clouds",
    "category": "Object",
}

if "bpy" in locals():  # F8 / script reload: take the edited modules
    import importlib

    importlib.reload(prefs)
    importlib.reload(operators)
else:
    from . import operators, prefs

import bpy


class VIEW3D_MT_heatvox(bpy.types.Menu):
    bl_idname = "VIEW3D_MT_heatvox"
    bl_label = "heatvox"

    def draw(self, context):
        layout = self.layout
        layout.operator(operators.HEATVOX_OT_sdf_volume.bl_idname, icon="VOLUME_DATA")
        layout.operator(operators.HEATVOX_OT_remesh.bl_idname, icon="MOD_REMESH")
        layout.operator(operators.HEATVOX_OT_points_surface.bl_idname, icon="OUTLINER_OB_POINTCLOUD")


def _object_menu(self, context):
    self.layout.menu(VIEW3D_MT_heatvox.bl_idname)


def _import_menu(self, context):
    self.layout.operator(operators.HEATVOX_OT_import_points.bl_idname, text="Point cloud (heatvox)")


CLASSES = (
    prefs.HeatvoxPreferences,
    operators.HEATVOX_OT_sdf_volume,
    operators.HEATVOX_OT_remesh,
    operators.HEATVOX_OT_points_surface,
    operators.HEATVOX_OT_import_points,
    VIEW3D_MT_heatvox,
)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.VIEW3D_MT_object.append(_object_menu)
    bpy.types.TOPBAR_MT_file_import.append(_import_menu)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(_import_menu)
    bpy.types.VIEW3D_MT_object.remove(_object_menu)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
