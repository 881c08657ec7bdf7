"""The Blender side of AASDF: registration, settings, preferences and the lazy gateway to the engine (``runtime``)."""
