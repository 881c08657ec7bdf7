"""Layering: the engine never touches Blender, and registering the add-on does not import Warp (or the engine).

The import checks run in fresh subprocesses, so modules other tests imported cannot hide a violation.
"""

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BLENDER_MODULES = {"bpy", "bmesh", "mathutils", "bpy_extras", "gpu", "addon_utils"}
ADDON_MODULES = {"aasdf", "aasdf_addon", "operators", "ui", "tests"}


def run_python(code: str, *args: str) -> dict:
    """Run ``code`` in a fresh interpreter with the repository root as its working directory; return its JSON."""
    done = subprocess.run(
        [sys.executable, "-c", code, *args], cwd=ROOT, capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr[-4000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


IMPORT_ENGINE = """
import json, sys
sys.path.insert(0, ".")
import engine
print(json.dumps({"file": engine.__file__, "loaded": sorted(m for m in sys.argv[1:] if m in sys.modules)}))
"""

REGISTER_ADDON = """
import importlib.util, json, sys
spec = importlib.util.spec_from_file_location("aasdf", "__init__.py", submodule_search_locations=["."])
aasdf = importlib.util.module_from_spec(spec)
sys.modules["aasdf"] = aasdf
spec.loader.exec_module(aasdf)
after_import = sorted(m for m in sys.modules if m == "bpy" or m.startswith("aasdf."))
aasdf.register()
import bpy
state = {
    "after_import": after_import,
    "registered": hasattr(bpy.types.Scene, "aasdf"),
    "warp": sorted(m for m in sys.modules if m == "warp" or m.startswith("warp.")),
    "engine": sorted(m for m in sys.modules if m == "aasdf.engine" or m.startswith("aasdf.engine.")),
}
aasdf.unregister()
print(json.dumps(state))
"""


def test_import_engine_loads_no_blender_module():
    result = run_python(IMPORT_ENGINE, *sorted(BLENDER_MODULES))
    assert Path(result["file"]).resolve() == ROOT / "engine" / "__init__.py"
    assert result["loaded"] == []


def test_register_loads_neither_warp_nor_the_engine():
    result = run_python(REGISTER_ADDON)
    assert result["after_import"] == []  # importing the root package imports nothing
    assert result["registered"] is True
    assert result["warp"] == []
    assert result["engine"] == []


def engine_imports():
    """(file, line, level, module) for every import statement in engine/*.py."""
    found = []
    for path in sorted((ROOT / "engine").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.Import):
                found += [(path.name, node.lineno, 0, alias.name) for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                found.append((path.name, node.lineno, node.level, node.module or ""))
    return found


def test_engine_source_imports_nothing_from_blender_or_above_itself():
    imports = engine_imports()
    assert imports, "engine/ has no imports at all: the scan found no source"
    parents = [imp for imp in imports if imp[2] > 1]
    blender = [imp for imp in imports if imp[3].split(".")[0] in BLENDER_MODULES]
    addon = [imp for imp in imports if imp[2] == 0 and imp[3].split(".")[0] in ADDON_MODULES | {"engine"}]
    assert parents == [], "engine/ must not reach out with '..'"
    assert blender == [], "engine/ must not import Blender modules"
    assert addon == [], "engine/ must import its own modules relatively and nothing of the add-on"


# ---- the engine's files: one stage each ----

MAX_LINES = 620  # "about 600": a stage that outgrows it is split


def _modules(folder: str) -> dict:
    """{module name: parsed tree} of the .py files of a package folder."""
    return {p.stem: ast.parse(p.read_text(encoding="utf-8")) for p in sorted((ROOT / folder).glob("*.py"))}


def _runtime_imports(tree) -> list:
    """(level, module, names) of the imports that run: at module level or in a function, not under TYPE_CHECKING."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING":
            skip |= {id(n) for child in node.body for n in ast.walk(child)}
    found = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom):
            found.append((node.level, node.module or "", [alias.name for alias in node.names]))
    return found


def test_engine_files_stay_small():
    sizes = {p.name: len(p.read_text(encoding="utf-8").splitlines()) for p in (ROOT / "engine").glob("*.py")}
    assert {name: n for name, n in sizes.items() if n > MAX_LINES} == {}


@pytest.mark.parametrize("folder", ["engine", "aasdf_addon", "operators", "ui", "batch"])
def test_no_private_name_is_imported_from_another_file(folder):
    private = []
    for name, tree in _modules(folder).items():
        for level, module, names in _runtime_imports(tree):
            if level >= 1:  # the project's own files (another library's internals are its business)
                private += [f"{name}: from {'.' * level}{module} import {n}" for n in names if n.startswith("_")]
        imported = set()  # modules bound by `from . import x`, whose private attributes are off limits too
        for level, module, names in _runtime_imports(tree):
            if level >= 1 and module in ("", "engine"):
                imported |= set(names)
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in imported:
                if node.attr.startswith("_") and not node.attr.startswith("__"):
                    private.append(f"{name}: {node.value.id}.{node.attr}")
    assert private == []


def test_engine_modules_import_each_other_without_a_cycle():
    modules = _modules("engine")
    graph = {
        name: {
            m.split(".")[0]
            for level, module, names in _runtime_imports(tree)
            if level == 1
            for m in ([module] if module else names)
        }
        & set(modules)
        for name, tree in modules.items()
    }
    state = {}

    def visit(node, path):
        if state.get(node) == "done":
            return
        assert state.get(node) != "open", f"import cycle: {' -> '.join([*path, node])}"
        state[node] = "open"
        for nxt in sorted(graph[node]):
            visit(nxt, [*path, node])
        state[node] = "done"

    for name in sorted(graph):
        visit(name, [])


# Kernels with atomics launched in parallel parts (``parallel.launch_split``), each only ever raising a "changed" flag
# a lost update cannot bring back to 0 (Warp's CPU atomics are not atomic across two threads' launches)
FLAG_ONLY_ATOMICS = {"fim_sweep_kernel", "_propagate_sign_octet_kernel", "_propagate_sign_kernel"}


def _atomic_kernels(tree: ast.Module) -> set:
    """The names of the functions of ``tree`` that call ``wp.atomic_*``."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef):
            calls = [c for c in ast.walk(node) if isinstance(c, ast.Call) and isinstance(c.func, ast.Attribute)]
            if any(c.func.attr.startswith("atomic_") for c in calls):
                found.add(node.name)
    return found


def test_no_kernel_with_atomics_runs_in_parallel_parts_but_a_flag():
    # a counter or a sum added atomically from launch_split's parts loses one part's additions (measured: an int32
    # sum of 479,910 read 239,497 in one of three runs), so such kernels run whole (wp.launch) or per part
    trees = {path: ast.parse(path.read_text()) for path in (ROOT / "engine").glob("*.py")}
    atomic = set().union(*(_atomic_kernels(tree) for tree in trees.values()))
    split = set()
    for tree in trees.values():
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Call)
                and getattr(node.func, "attr", getattr(node.func, "id", "")) == "launch_split"
            ):
                if node.args and isinstance(node.args[0], ast.Name):
                    split.add(node.args[0].id)
    assert atomic and split, "nothing found: the scan is broken"
    assert (atomic & split) <= FLAG_ONLY_ATOMICS, sorted((atomic & split) - FLAG_ONLY_ATOMICS)


def test_every_engine_module_with_kernels_is_prebuilt():
    # the zip carries the kernels of ENGINE_MODULES (engine/kernels.py): a module left out compiles on a user's first
    # boolean (seconds), as engine/ownside.py and engine/samples.py did until this test
    from engine.kernels import ENGINE_MODULES

    with_kernels = {path.stem for path in (ROOT / "engine").glob("*.py") if "@wp.kernel" in path.read_text()}
    assert with_kernels - set(ENGINE_MODULES) == set()
