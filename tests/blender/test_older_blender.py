"""What an older Blender lacks, done another way or switched off with a sentence: ``bpy.utils.expose_bundled_modules``
(Blender 4.4 and later) is taken away here, as Blender 4.2 LTS has it missing. ``make test`` also runs these on 4.2
itself, where nothing is taken away and the debug volume is refused for real; and the ``bpy`` module of 4.2 and 4.5,
which cannot end its process once the add-on was registered, has the batch script end it."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import bpy
import pytest

from aasdf.aasdf_addon import pipeline
from batch import shutdown
from tests.blender.scene import NO_OPENVDB, SHIPS_OPENVDB, add_mesh_object, select
from tests.support import uv_sphere


@pytest.fixture
def blender_4_2(monkeypatch):
    """``bpy.utils`` without ``expose_bundled_modules``."""
    monkeypatch.delattr(bpy.utils, "expose_bundled_modules", raising=SHIPS_OPENVDB)
    return monkeypatch


def test_debug_volume_uses_an_openvdb_module_already_importable(blender_4_2):
    assert not hasattr(bpy.utils, "expose_bundled_modules")
    ball = add_mesh_object("Ball", *uv_sphere(1.0, rings=16, segments=32))
    select(ball)
    if not SHIPS_OPENVDB:  # Blender 4.2 itself: no OpenVDB module on its path either, so it is refused
        assert importlib.util.find_spec("openvdb") is None and importlib.util.find_spec("pyopenvdb") is None
        with pytest.raises(RuntimeError, match=f"{NO_OPENVDB} \\(Blender 4.4 and later do\\)"):
            bpy.ops.aasdf.debug_volume(resolution=32)
        assert set(bpy.data.objects.keys()) == {"Ball"}
        return
    if "openvdb" not in sys.modules:  # as a Blender that ships it on its path
        blender_4_2.undo()
        bpy.utils.expose_bundled_modules()
        __import__("openvdb")
        blender_4_2.delattr(bpy.utils, "expose_bundled_modules")
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


ROOT = Path(__file__).resolve().parents[2]
# A process as a batch run leaves it, the add-on registered, then ended with a status or a fault of ours.
ENDED_BY_THE_BATCH_SCRIPT = """
import sys
sys.path.insert(0, ".")
import bpy
from batch import scene, shutdown
scene.ensure_addon()

def main():
    if sys.argv[1] == "fault":
        raise ValueError("a fault of ours")
    return int(sys.argv[1])

sys.exit(shutdown.run_main(main))
"""


def test_the_bpy_module_is_told_from_blender_and_ended_by_the_batch_script_where_it_cannot_end_itself():
    assert shutdown.bpy_module() is bpy  # 4.2 has no bpy.app.module: its empty binary path says so
    assert shutdown.needs_hard_exit() == (bpy.app.version < (5, 0, 0))
    for arg, status in (("3", 3), ("fault", 1)):  # 4.2 crashed with SIGSEGV here and 4.5 hung before batch/shutdown.py
        done = subprocess.run(
            [sys.executable, "-c", ENDED_BY_THE_BATCH_SCRIPT, arg],
            cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
        assert done.returncode == status, done.stderr[-3000:]
        assert ("ValueError: a fault of ours" in done.stderr) == (arg == "fault"), done.stderr[-3000:]
