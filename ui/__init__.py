"""Panels and menus: ``draw()`` only reads settings and places operators. ``aasdf_addon.registration`` registers
everything in ``classes``, in order (a parent panel before its sub-panels)."""

from .panel import AASDF_PT_main, AASDF_PT_main_debug

classes = (AASDF_PT_main, AASDF_PT_main_debug)
