"""Test harness: the repository root is loaded as the package ``aasdf``, as Blender loads an extension.

``aasdf.operators``, ``aasdf.ui`` and ``aasdf.aasdf_addon`` are tested through their real relative imports. The
root is also put on ``sys.path`` so engine tests ``import engine`` (and ``from tests.support import ...``) without
Blender. Nothing here imports ``bpy``: that happens in ``tests/blender/conftest.py`` only. Warp's kernel cache goes to
``.warp-cache/`` in the repository (git-ignored) unless ``WARP_CACHE_PATH`` is already set, e.g. by CI.
"""

import importlib.util
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ADDON_PACKAGE = "aasdf"

os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp-cache"))


def _pinned_blas_kernels() -> None:
    """numpy's OpenBLAS picks its kernels by the CPU (SkylakeX where AVX-512 is, Haswell where only AVX2 is), and
    their sums round differently: the golden fingerprints (tests/engine/test_golden.py) of fields built on two
    x86-64 machines differed in every level. The tests take the Haswell kernels on every x86-64 CPU with AVX2 (set
    before numpy loads; the test processes inherit it)."""
    try:
        flags = Path("/proc/cpuinfo").read_text().split()
    except OSError:
        return
    if "avx2" in flags and "fma" in flags:
        os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")


_pinned_blas_kernels()

if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def load_addon_package(name: str = ADDON_PACKAGE):
    """Import the repository root as package ``name`` (its ``__init__.py`` imports nothing)."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


load_addon_package()


def pytest_configure(config):
    """Before a parallel run (``-n``, pytest-xdist) starts its workers, compile the kernels once for all of them
    (``tests/warm_kernels.py``)."""
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    import subprocess

    subprocess.run([sys.executable, str(ROOT / "tests" / "warm_kernels.py")], check=True)
