"""Operators: one per user action (``aasdf.<verb>``), each reading its settings, calling bridge → engine → bridge,
and reporting. ``aasdf_addon.registration`` registers everything in ``classes``, in order."""

from .boolean import AASDF_OT_boolean, AASDF_OT_clear_cache, AASDF_OT_debug_volume

classes = (AASDF_OT_boolean, AASDF_OT_debug_volume, AASDF_OT_clear_cache)
