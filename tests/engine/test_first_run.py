"""A first run in a checkout: the engine's modules whose kernels Warp's cache lacks are found before any compiles, and
compiled one after the other with a report before each (what the add-on shows as progress)."""

import warp as wp

import engine
from engine.kernels import ENGINE_MODULES


def test_the_modules_to_compile_are_those_the_kernel_cache_lacks(tmp_path, monkeypatch):
    wp.init()  # Warp sets its kernel cache folder when it starts: the folder is replaced after that
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path))
    missing = engine.kernels.modules_to_compile("engine", "cpu")
    assert [module.__name__ for module in missing] == [f"engine.{name}" for name in ENGINE_MODULES]
    # a module compiled for the CPU: its folder holds an object file
    folder = tmp_path / wp.get_module("engine.octree").get_module_identifier(1)
    folder.mkdir()
    (folder / f"{folder.name}.o").write_bytes(b"")
    missing = engine.kernels.modules_to_compile("engine", "cpu")
    assert len(missing) == len(ENGINE_MODULES) - 1 and engine.octree not in missing


def test_modules_are_compiled_with_a_report_as_each_is_done(monkeypatch):
    loaded, reports = [], []
    monkeypatch.setattr(engine.parallel, "load_modules", lambda modules, device: loaded.append((modules, device)))
    engine.kernels.compile_modules([engine.octree, engine.distance], "cpu", lambda *args: reports.append(args))
    assert reports[0] == (0, 2, "") and sorted(name for _done, _count, name in reports[1:]) == ["distance", "octree"]
    assert [done for done, _count, _name in reports] == [0, 1, 2]
    assert sorted(loaded, key=str) == [([engine.distance], "cpu"), ([engine.octree], "cpu")]
