"""Operators: one per user action (``aasdf.<verb>``), each reading its settings, calling bridge → engine → bridge,
and reporting. ``aasdf_addon.registration`` registers everything in ``classes``, in order."""

from .boolean import AASDF_OT_boolean, AASDF_OT_clear_cache, AASDF_OT_debug_volume, AASDF_OT_offset, AASDF_OT_shell
from .tree import AASDF_OT_evaluate_tree, AASDF_OT_tree_from_selection

classes = (
    AASDF_OT_boolean,
    AASDF_OT_offset,
    AASDF_OT_shell,
    AASDF_OT_debug_volume,
    AASDF_OT_clear_cache,
    AASDF_OT_evaluate_tree,
    AASDF_OT_tree_from_selection,
)
