"""Add-on preferences: the compute device and the field cache's memory limit.

``ADDON_ID`` is the add-on's package name: ``bl_ext.<repo>.aasdf`` when installed as an extension, ``aasdf`` when the
repository is loaded as a plain package (tests). Warp is not imported here: the device list is static and
``aasdf_addon.runtime`` resolves it to an available Warp device when the engine is first used.
"""

import bpy
from bpy.props import EnumProperty, IntProperty

ADDON_ID = __package__.rpartition(".")[0]

DEVICES = (
    ("CPU", "CPU", "Run the engine's Warp kernels on the CPU"),
    ("CUDA", "CUDA", "Run the engine's Warp kernels on the first CUDA GPU (falls back to the CPU when there is none)"),
)


class AASDF_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    device: EnumProperty(
        name="Device",
        description="Where the engine runs",
        items=DEVICES,
        default="CPU",
    )
    cache_limit_mb: IntProperty(
        name="Cache Memory Limit",
        description="Memory the cache of input fields may use, in MB; 0 turns the cache off",
        default=1024,
        min=0,
        soft_max=16384,
    )

    def draw(self, context):
        layout = self.layout
        layout.use_property_split, layout.use_property_decorate = True, False
        layout.prop(self, "device")
        layout.prop(self, "cache_limit_mb")


def get(context=None):
    """The add-on's preferences, or ``None`` when the add-on has no entry in the preferences (a plain package)."""
    context = context or bpy.context
    addon = context.preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else None
