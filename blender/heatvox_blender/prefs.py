"""The add-on's preferences: where libheatvox is, and the threads it uses."""

import bpy

from . import library


class HeatvoxPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    library: bpy.props.StringProperty(
        name="Library",
        description=(
            "libheatvox.so to load; empty: the copy inside the add-on, else the heatvox "
            "package that make install or pip install made (read when the add-on first "
            "runs: restart Blender after changing it)"
        ),
        subtype="FILE_PATH",
        default="",
    )
    threads: bpy.props.IntProperty(
        name="Threads",
        description="Worker threads of heatvox's kernels; 0: every core",
        min=0,
        max=1024,
        default=0,
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "library")
        layout.prop(self, "threads")
        layout.label(text=library.describe())


def get(context):
    """The add-on's preferences."""
    return context.preferences.addons[__package__].preferences
