"""Nothing changed, nothing done: the key of a run's inputs, kept on the object it wrote.

A run that writes into a named object (a CSG tree's Output node) keys everything its result depends on
(``inputs_key``): each operand's evaluated geometry in its own frame (``cache.geometry_key``, with the field settings
and the operand's thickness) and everything its faces carry over (materials by name, shading, UV maps, colours,
seams, sharp edges, creases: every array ``bridge.Operand`` holds), its world matrix, the plan, the voxel size as
resolved and the output's options. After the write the key is stored on the result object (``Object.aasdf``) with a
fingerprint of the object as written (``object_key``: every attribute of its mesh, its material slots, its world
matrix). A later run over the same inputs finds the same key and, when the object is still as it was written (not
edited, moved, emptied or unlinked by the user), nothing to do: it reads and keys its inputs, and builds, extracts and
writes nothing (``is_current``).

The key lives in the .blend: a file saved and opened again finds its results current without any field (the field
cache is in memory and emptied on load). It holds whether an object shows its inputs' result, never whether the cache
holds fields: any input changed (its mesh, modifiers, transform, materials, the settings) gives another key, so the
run is done. Keys hash the arrays the read stage got by ``foreach_get`` (SHA-1 over their bytes, a fingerprint and no
security measure: twice blake2b's speed here, with the processor's SHA instructions): about 5 ms for the 4.7 MB of a
70 k-triangle mesh, nothing read again from Blender item by item.
"""

import dataclasses
import hashlib

import numpy as np

from . import cache

# Changes when what a result is made of changes for the same inputs (an update that computes results otherwise).
KEY_VERSION = 1

# Operand fields hashed apart (the geometry key) or not at all (the object itself: what it carries is hashed).
_OWN_KEY = {"obj", "uid", "verts", "tris", "matrix"}

# foreach_get of an attribute's data by its data type: (property, dtype, values per item).
_ATTRIBUTE_ARRAYS = {
    "FLOAT": ("value", np.float32, 1),
    "INT": ("value", np.int32, 1),
    "BOOLEAN": ("value", bool, 1),
    "INT8": ("value", np.int32, 1),
    "FLOAT2": ("vector", np.float32, 2),
    "FLOAT_VECTOR": ("vector", np.float32, 3),
    "FLOAT_COLOR": ("color", np.float32, 4),
    "BYTE_COLOR": ("color", np.float32, 4),
    "INT32_2D": ("value", np.int32, 2),
    "INT16_2D": ("value", np.int32, 2),
    "QUATERNION": ("value", np.float32, 4),
    "FLOAT4X4": ("value", np.float32, 16),
}

# Attributes the user changes without editing the mesh (selection, hiding in Edit Mode): left out of the fingerprint.
_STATE_PREFIXES = (".select", ".uv_select", ".hide", ".uv_pin")


def _digest():
    return hashlib.sha1(usedforsecurity=False)


def _update(digest, value) -> None:
    """Feed ``value`` (arrays, dicts and sequences of them, materials, numbers, strings, None) to ``digest``."""
    if isinstance(value, np.ndarray):
        digest.update(f"{value.dtype}{value.shape}".encode())
        digest.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, dict):
        digest.update(b"{")
        for name in sorted(value):
            digest.update(repr(name).encode())
            _update(digest, value[name])
        digest.update(b"}")
    elif isinstance(value, list | tuple):
        digest.update(f"[{len(value)}".encode())
        for item in value:
            _update(digest, item)
    elif hasattr(value, "name_full"):  # an ID (a material): by name, as the result's slots take it
        digest.update(f"<{type(value).__name__} {value.name_full}>".encode())
    else:
        digest.update(repr(value).encode())


def inputs_key(read, thickness, steps, options: dict, *, sharp: bool, keep_faces: bool, adaptivity: float = 0.0) -> str:
    """The key of a run's result.

    Args:
        read: ``bridge.Operand`` per input, as read (``pipeline.read_checked``).
        thickness: The wall thickness asked of each operand (0: none).
        steps: The plan (``aasdf_addon.plan``), a nested tuple.
        options: Field settings as ``cache.geometry_key`` takes them: ``voxel_size`` (resolved), ``levels``,
            ``padding``, ``device``.
        sharp, keep_faces, adaptivity: The output's options.
    Returns:
        A hex digest.
    """
    digest = _digest()
    _update(digest, (KEY_VERSION, steps, sharp, keep_faces, float(adaptivity), len(read)))
    for operand, wall in zip(read, thickness, strict=True):
        digest.update(cache.geometry_key(operand.verts, operand.tris, **options, thickness=wall).encode())
        _update(digest, np.asarray(operand.matrix, dtype=np.float64))
        for item in dataclasses.fields(operand):
            if item.name not in _OWN_KEY:
                digest.update(item.name.encode())
                _update(digest, getattr(operand, item.name))
    return digest.hexdigest()


def object_key(obj) -> str:
    """A fingerprint of a mesh object as it is: every attribute of its mesh (but selection and hiding), its counts,
    its material slots' materials and its world matrix."""
    mesh = obj.data
    digest = _digest()
    counts = (len(mesh.vertices), len(mesh.edges), len(mesh.polygons), len(mesh.loops))
    _update(digest, (counts, [slot.material for slot in obj.material_slots]))
    _update(digest, np.array(obj.matrix_world, dtype=np.float64))
    for attribute in mesh.attributes:
        if attribute.name.startswith(_STATE_PREFIXES):
            continue
        digest.update(f"{attribute.name}:{attribute.domain}:{attribute.data_type}".encode())
        layout = _ATTRIBUTE_ARRAYS.get(attribute.data_type)
        if layout is None:  # strings: their count only
            digest.update(str(len(attribute.data)).encode())
            continue
        prop, dtype, width = layout
        values = np.empty(len(attribute.data) * width, dtype=dtype)
        attribute.data.foreach_get(prop, values)
        digest.update(values.tobytes())
    return digest.hexdigest()


def is_current(obj, key: str) -> bool:
    """Whether ``obj`` (a result object, or None) shows the result of inputs keyed ``key`` as it was written: in a
    collection, a mesh, with that key stored and not edited since."""
    if obj is None or obj.type != "MESH" or not obj.users_collection:
        return False
    stored = obj.aasdf.result_key
    if not stored.startswith(f"{key}/"):
        return False
    return stored == f"{key}/{object_key(obj)}"


def remember(obj, key: str) -> None:
    """Store ``key`` on ``obj`` just written, with its fingerprint as written."""
    obj.aasdf.result_key = f"{key}/{object_key(obj)}"


def forget(obj) -> None:
    """Drop what ``obj`` remembers (its result no longer answers its key)."""
    if obj is not None and obj.aasdf.result_key:
        obj.aasdf.result_key = ""
