"""AASDF: SDF booleans on Blender meshes, built on adaptive signed distance fields (numpy + NVIDIA Warp).

Blender loads this folder as the package ``bl_ext.<repo>.aasdf``. Importing it does nothing: ``register()`` imports
the add-on's modules, and the engine (with Warp) is imported only when an operator first needs it.
"""


def register():
    from .aasdf_addon import registration

    registration.register()


def unregister():
    from .aasdf_addon import registration

    registration.unregister()
