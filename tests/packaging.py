"""What belongs in the extension zip, shared by tests/test_packaging.py and tests/test_install.py."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIRS = ("aasdf_addon", "engine", "operators", "ui", "batch")  # batch: aasdf_batch.py's, shipped with it


def package_files() -> set[str]:
    """Repository files the zip must carry: the root ``__init__.py`` and every module of the packages."""
    files = {"__init__.py"}
    for folder in PACKAGE_DIRS:
        files |= {p.relative_to(ROOT).as_posix() for p in (ROOT / folder).rglob("*.py") if "__pycache__" not in p.parts}
    return files


def unexpected_in_package(files) -> list[str]:
    """Files that have no business in the extension zip (tests, tools, caches, dot-files...), sorted."""
    allowed_top = {*PACKAGE_DIRS, "__init__.py", "blender_manifest.toml", "README.md", "LICENSE"}
    return sorted(
        f
        for f in files
        if "__pycache__" in f
        or f.endswith(".pyc")
        or not (
            f.split("/")[0] in allowed_top
            or ("/" not in f and f.endswith(".py"))
            or f.startswith("wheels/")
            or (f.startswith("kernels/wp_") and f.endswith((".o", ".ptx", ".meta")))
        )
    )
