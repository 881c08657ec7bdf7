"""Registers AASDF's classes and settings with Blender, and removes them again in reverse order.

To add a class, put it in the ``classes`` tuple of its package (``operators``, ``ui``) or of
``aasdf_addon.properties`` / ``aasdf_addon.nodes``; nothing here changes. A module that must hook into Blender beyond
classes (settings pointers, app handlers, timers, menu entries, caches to clear) gets ``register()``/``unregister()``
functions and a place in ``_modules()``.
"""

import bpy

from .. import operators, ui
from . import autoupdate, cache, nodes, preferences, properties, warmup


def _classes():
    """All classes in registration order: PropertyGroups first (pointers need them), node types, panels last."""
    return (
        *properties.classes,
        preferences.AASDF_AddonPreferences,
        *nodes.classes,
        *operators.classes,
        *ui.classes,
    )


def _modules():
    """Modules whose ``register()`` runs after the classes are registered, and ``unregister()`` before they go.

    Their ``unregister()`` must be harmless when ``register()`` did not run (it is also used to roll back).
    """
    return (properties, cache, autoupdate, ui, warmup)


def register():
    done = []
    try:
        nodes.classes_changing = True  # trees' updates wait until every node type is there
        try:
            for cls in _classes():
                bpy.utils.register_class(cls)
                done.append(cls)
        finally:
            nodes.classes_changing = False
        for module in _modules():
            module.register()
    except Exception:
        # Leave Blender as it was: a half-registered add-on cannot be enabled again.
        for module in reversed(_modules()):
            module.unregister()
        for cls in reversed(done):
            bpy.utils.unregister_class(cls)
        raise


def unregister():
    for module in reversed(_modules()):
        module.unregister()
    nodes.classes_changing = True  # no tree update reads nodes whose types are going
    try:
        for cls in reversed(_classes()):
            if cls.is_registered:
                bpy.utils.unregister_class(cls)
    finally:
        nodes.classes_changing = False
