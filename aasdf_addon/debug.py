"""Debug views of a field: a Volume object with the signed distances, and the octree's cells as points.

The volume is a real OpenVDB file written with the ``openvdb`` module Blender ships
(``bpy.utils.expose_bundled_modules()``, Blender 4.4 and later; where a Blender has none, ``openvdb_module`` refuses
with a sentence): one float grid named ``sdf`` (negative inside) whose transform puts voxel ``[i, j, k]`` at the world
position of dense sample ``[i, j, k]``. Files go to the extension's user folder
(``.../aasdf/debug``), or a temporary folder when the add-on is not installed as an extension. Both objects are
linked to a collection ``AASDF Debug``.
"""

import importlib
import os
import re
import tempfile
import uuid

import bpy
import numpy as np

from . import runtime
from .preferences import ADDON_ID

COLLECTION = "AASDF Debug"
# Dense samples of a debug volume at most; coarser spacings (powers of two of the voxel size) keep below it.
MAX_DENSE_SAMPLES = 2**22
# Bytes of .vdb files the debug folder keeps at most: each new file there removes the oldest that no volume of the open
# file reads (up to 16 MB each; a removed one is made again by asking for it).
DEBUG_FOLDER_BYTES = 1 << 30


def debug_dir() -> str:
    """Folder for debug files: the extension's user folder ``debug``, else ``<tempdir>/aasdf-debug``."""
    try:
        path = bpy.utils.extension_path_user(ADDON_ID, path="debug", create=True)
    except ValueError:  # "The package does not name an extension"
        path = ""
    if not path:
        path = os.path.join(tempfile.gettempdir(), "aasdf-debug")
        os.makedirs(path, exist_ok=True)
    return path


def dense_spacing(field, max_samples: int = MAX_DENSE_SAMPLES) -> float:
    """The voxel size of ``field`` doubled until its domain holds at most ``max_samples`` samples."""
    lo, hi = field.bounds
    spacing = field.voxel_size
    while np.prod(np.maximum(np.ceil((hi - lo) / spacing), 1)) > max_samples:
        spacing *= 2.0
    return spacing


def openvdb_module():
    """Blender's OpenVDB Python module: ``openvdb`` made importable by ``bpy.utils.expose_bundled_modules()`` (Blender
    4.4 and later), else an ``openvdb`` or ``pyopenvdb`` already on the path (older Blenders, some builds).

    Raises:
        AasdfError: When this Blender has none, saying so (the booleans themselves do not need it).
    """
    expose = getattr(bpy.utils, "expose_bundled_modules", None)
    if expose is not None:
        expose()
    for name in ("openvdb", "pyopenvdb"):
        try:
            return importlib.import_module(name)
        except ImportError:
            continue
    raise runtime.engine().AasdfError(
        f"Debug Volume needs OpenVDB's Python module, which Blender {bpy.app.version_string} does not provide "
        "(Blender 4.4 and later do): the booleans work without it"
    )


def write_vdb(field, filepath, *, spacing=None) -> str:
    """Write a field's dense signed distances as a float grid ``sdf`` to an OpenVDB file.

    Args:
        field: ``AdaptiveField``.
        filepath: Destination ``.vdb`` path.
        spacing: Sample spacing (default: ``dense_spacing(field)``).
    Returns:
        ``filepath``.
    Raises:
        AasdfError: If the dense block would not fit in memory, this Blender has no OpenVDB module, or the file cannot
            be written.
    """
    openvdb = openvdb_module()
    dense = field.to_dense(spacing=spacing or dense_spacing(field))
    values = np.ascontiguousarray(dense["values"], dtype=np.float32)
    step, origin = float(dense["spacing"]), [float(x) for x in dense["origin"]]
    grid = openvdb.FloatGrid(float(max(values.max(), step)))
    grid.copyFromArray(values, (0, 0, 0), 0.0)
    # OpenVDB multiplies row vectors: the translation is the last row. Voxel [0,0,0] sits at sample [0,0,0].
    matrix = [[step, 0.0, 0.0, 0.0], [0.0, step, 0.0, 0.0], [0.0, 0.0, step, 0.0], [*origin, 1.0]]
    grid.transform = openvdb.createLinearTransform(matrix)
    grid.gridClass = openvdb.GridClass.LEVEL_SET
    grid.name = "sdf"
    try:
        openvdb.write(str(filepath), grids=[grid])
    except OSError as err:  # (a folder that cannot be written: said, not a traceback after the result is written)
        raise runtime.engine().AasdfError(f"cannot write the debug volume: {err}") from None
    return str(filepath)


def debug_collection(context):
    """The ``AASDF Debug`` collection, created under the scene's collection when missing."""
    collection = bpy.data.collections.get(COLLECTION)
    if collection is None:
        collection = bpy.data.collections.new(COLLECTION)
    if collection.name not in context.scene.collection.children:
        context.scene.collection.children.link(collection)
    return collection


def add_volume_object(context, name, filepath):
    """A Volume object reading ``filepath``, in the debug collection; its grids are loaded."""
    volume = bpy.data.volumes.new(name)
    volume.filepath = filepath
    volume.grids.load()
    obj = bpy.data.objects.new(name, volume)
    debug_collection(context).objects.link(obj)
    return obj


def add_cells_object(context, name, field):
    """A mesh of loose vertices, one per stored octree node, with point attributes ``level``, ``sdf``, ``size`` and
    ``leaf`` (the leaves tile the domain)."""
    cells = field.debug_cells()
    centers = np.ascontiguousarray(cells["centers"], dtype=np.float32)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(centers))
    mesh.vertices.foreach_set("co", centers.ravel())
    kinds = (
        ("level", "INT", "levels"),
        ("sdf", "FLOAT", "sdf"),
        ("size", "FLOAT", "sizes"),
        ("leaf", "BOOLEAN", "leaf"),
    )
    for attr, kind, key in kinds:
        dtype = {"INT": np.int32, "FLOAT": np.float32, "BOOLEAN": bool}[kind]
        mesh.attributes.new(attr, kind, "POINT").data.foreach_set("value", np.ascontiguousarray(cells[key], dtype))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    debug_collection(context).objects.link(obj)
    return obj


def add_debug_objects(context, field, name, *, filepath=None):
    """Write ``field`` to a .vdb and add its Volume object and its octree-cells object.

    Args:
        context: Blender context (the scene receives the ``AASDF Debug`` collection).
        field: ``AdaptiveField``.
        name: Base name; the objects are ``<name>.sdf`` and ``<name>.cells``.
        filepath: Where to write the .vdb (default: a new file in ``debug_dir()``).
    Returns:
        (volume object, cells object).
    Raises:
        AasdfError: If the dense block would not fit in memory.
    """
    folder = None
    if filepath is None:
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
        folder = debug_dir()
        filepath = os.path.join(folder, f"{safe}-{uuid.uuid4().hex[:8]}.vdb")
    write_vdb(field, filepath)
    objects = add_volume_object(context, f"{name}.sdf", filepath), add_cells_object(context, f"{name}.cells", field)
    if folder is not None:
        pruned_debug_files(folder)
    return objects


def pruned_debug_files(folder: str, limit: int | None = None) -> list:
    """Remove the oldest ``.vdb`` files of ``folder`` that no Volume of the open file reads until its ``.vdb`` files
    take at most ``limit`` bytes (default ``DEBUG_FOLDER_BYTES``); a file that cannot be removed is left. Returns the
    paths removed."""
    limit = DEBUG_FOLDER_BYTES if limit is None else limit
    used = {_same_path(bpy.path.abspath(volume.filepath)) for volume in bpy.data.volumes if volume.filepath}
    files = []
    with os.scandir(folder) as entries:
        for entry in entries:
            if entry.name.endswith(".vdb") and entry.is_file():
                info = entry.stat()
                files.append((info.st_mtime, info.st_size, entry.path))
    total = sum(size for _, size, _ in files)
    removed = []
    for _, size, path in sorted(files):
        if total <= limit:
            break
        if _same_path(path) in used:
            continue
        try:
            os.remove(path)
        except OSError:
            continue
        total -= size
        removed.append(path)
    return removed


def _same_path(path: str) -> str:
    return os.path.normcase(os.path.realpath(path))
