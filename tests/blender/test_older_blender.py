"""What an older Blender lacks, done another way or switched off with a sentence: ``bpy.utils.expose_bundled_modules``
(Blender 4.4 and later) is taken away here, as Blender 4.2 LTS has it missing."""

import sys

import bpy
import pytest

from aasdf.aasdf_addon import pipeline
from tests.blender.scene import add_mesh_object, select
from tests.support import uv_sphere


@pytest.fixture
def blender_4_2(monkeypatch):
    """``bpy.utils`` without ``expose_bundled_modules``."""
    monkeypatch.delattr(bpy.utils, "expose_bundled_modules")
    return monkeypatch


def test_debug_volume_uses_an_openvdb_module_already_importable(blender_4_2):
    assert not hasattr(bpy.utils, "expose_bundled_modules")
    if "openvdb" not in sys.modules:  # as a Blender that ships it on its path
        blender_4_2.undo()
        bpy.utils.expose_bundled_modules()
        __import__("openvdb")
        blender_4_2.delattr(bpy.utils, "expose_bundled_modules")
    ball = add_mesh_object("Ball", *uv_sphere(1.0, rings=16, segments=32))
    select(ball)
    assert bpy.ops.aasdf.debug_volume(resolution=32) == {"FINISHED"}
    volume = bpy.data.objects["Ball.sdf"].data
    assert volume.grids.load() and "sdf" in volume.grids


def test_debug_volume_without_openvdb_is_refused_with_a_sentence(blender_4_2):
    blender_4_2.setitem(sys.modules, "openvdb", None)  # import fails, as where Blender ships no module
    blender_4_2.setitem(sys.modules, "pyopenvdb", None)
    ball = add_mesh_object("Ball", *uv_sphere(1.0, rings=16, segments=32))
    other = add_mesh_object("Other", *uv_sphere(1.0, rings=16, segments=32), location=(0.5, 0.0, 0.0))
    select(ball)
    objects = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match="Debug Volume needs OpenVDB's Python module, which Blender .* does not"):
        bpy.ops.aasdf.debug_volume(resolution=32)
    assert len(bpy.data.objects) == objects and "AASDF Debug" not in bpy.data.collections
    # a boolean asked for a debug volume too: the result is written, the volume is not, with a warning
    select(ball, other)
    assert bpy.ops.aasdf.boolean(operation="UNION", resolution=32, debug_volume=True) == {"FINISHED"}
    assert "Ball.aasdf" in bpy.data.objects and "Ball.aasdf.sdf" not in bpy.data.objects
    assert pipeline.last_run["warnings"] == [
        f"No debug volume: Debug Volume needs OpenVDB's Python module, which Blender {bpy.app.version_string} does "
        "not provide (Blender 4.4 and later do): the booleans work without it"
    ]
