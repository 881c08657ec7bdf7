"""The field cache: stores and finds fields; reads nothing from Blender.

A field is stored under a key: a hash of a mesh's evaluated geometry in its object's own frame and of the field
settings (``geometry_key``), with the world matrix it was built under. Objects with the same geometry (linked
duplicates, copies) find the same entry, and an object that moved, turned or was scaled finds its own: the pipeline
places the field where the object now is (``AdaptiveField.transformed``) instead of building it again. Entries are
kept in least-recently-used order within the memory limit of the add-on preferences (``cache_limit_mb``; 0 turns the
cache off); what the fields leave of it the engine may keep as resident pages for its next arrays (``spare_bytes``).
The last combined result is kept too (``find_result``), with its surface, so a run on unchanged inputs repeats neither
the booleans nor the extraction.

A ``depsgraph_update_post`` handler drops the entry of an object whose geometry changed (``note_object`` says which
entry an object uses), ``load_pre`` empties the cache, and ``unregister()`` removes the handlers and empties it too.
Undo and redo re-evaluate every object as if its geometry had changed: the update that follows ``undo_post`` or
``redo_post`` is not taken as an edit, so the redo panel re-runs an operator on cached fields (the key, not the
handler, is what keeps entries correct: a field is only ever reused for the same geometry).
"""

import hashlib
from collections import OrderedDict

import bpy
import numpy as np

from . import preferences, runtime

_entries: OrderedDict = OrderedDict()  # key -> (field, world matrix it was built under, nbytes), least recent first
_objects: dict = {}  # session_uid -> the key of the entry the object used last
_stats = {"hits": 0, "builds": 0, "evictions": 0, "invalidations": 0, "result_hits": 0}
_skip_next_update = False  # set by undo/redo: their re-evaluation is not an edit
_bytes = 0  # sum of the entries' nbytes, kept up to date so the sidebar reads it without summing
_result: dict = {}  # the last combined result: {"key", "fields", "field", "surface"}

DEFAULT_LIMIT_MB = 1024

_FIELD_ARRAYS = ("codes", "values", "proj", "child", "source", "tri")


def field_nbytes(field) -> int:
    """Bytes held by a field's arrays and the source meshes it keeps; for a field built on demand, by the most
    refined one its refiner keeps, and what it keeps to refine."""
    refiner = getattr(field, "refiner", None)
    latest = getattr(refiner, "latest", None)
    held = field if latest is None else latest
    arrays = sum(getattr(getattr(held, name, None), "capacity", 0) or 0 for name in _FIELD_ARRAYS)
    extra = 0 if latest is None else refiner.kept_bytes
    return int(arrays + extra + sum(source.nbytes for source in getattr(field, "sources", {}).values()))


def limit_bytes(context=None) -> int:
    """The cache's memory limit in bytes, from the add-on preferences (1 GiB without preferences)."""
    prefs = preferences.get(context)
    mb = prefs.cache_limit_mb if prefs is not None else DEFAULT_LIMIT_MB
    return int(mb) * 2**20


def geometry_key(verts, tris, *, voxel_size, levels, padding, device, thickness=0.0) -> str:
    """Hash of a mesh in its own frame and of the field settings: equal keys give the same field, up to where it is
    placed."""
    digest = hashlib.blake2b(digest_size=20)
    for array in (verts, tris):
        array = np.ascontiguousarray(array)
        digest.update(str(array.shape).encode())
        digest.update(array.tobytes())
    settings = (float(np.float32(voxel_size)), int(levels), int(padding), str(device), float(np.float32(thickness)))
    digest.update(repr(settings).encode())
    return digest.hexdigest()


def find(key: str):
    """``(field, world matrix it was built under)`` stored under ``key`` (counted as a hit), or None."""
    entry = _entries.get(key)
    if entry is None:
        return None
    _entries.move_to_end(key)
    _stats["hits"] += 1
    return entry[0], entry[1]


def store(key: str, field, matrix, limit: int) -> None:
    """Keep a newly built field (counted as a build) with the world matrix it was built under, within ``limit`` bytes,
    least recently used entries first out; a field larger than the whole limit is not kept."""
    global _bytes
    _stats["builds"] += 1
    nbytes = field_nbytes(field)
    if nbytes > limit:
        return
    _pop(key)
    _entries[key] = (field, np.asarray(matrix, dtype=np.float64), nbytes)
    _bytes += nbytes
    while _bytes > limit:
        _bytes -= _entries.popitem(last=False)[1][2]
        _stats["evictions"] += 1


def recount(limit: int | None = None) -> None:
    """The entries' bytes counted again (fields built on demand grow as they are refined), least recently used
    entries out past ``limit`` (default: the preferences')."""
    global _bytes
    limit = limit_bytes() if limit is None else limit
    for key, (field, matrix, _nbytes) in list(_entries.items()):
        _entries[key] = (field, matrix, field_nbytes(field))
    _bytes = sum(entry[2] for entry in _entries.values())
    while _bytes > limit and _entries:
        _bytes -= _entries.popitem(last=False)[1][2]
        _stats["evictions"] += 1


def note_object(session_uid: int, key: str) -> None:
    """Object ``session_uid`` uses the entry under ``key`` (dropped when its geometry is edited)."""
    _objects[session_uid] = key


def entry_keys() -> list:
    """The keys of the stored fields, least recently used first."""
    return list(_entries)


def find_result(key):
    """``(field, surface)`` of the last combined result when it was combined under ``key`` (counted as a hit), else
    None. ``surface`` is the dict the pipeline keeps with it (filled as it goes)."""
    if _result and _result["key"] == key:
        _stats["result_hits"] += 1
        return _result["field"], _result["surface"]
    return None


def store_result(key, fields, field) -> dict:
    """Keep ``field``, combined under ``key`` from ``fields`` (held, so the ids in the key stay theirs); returns the
    empty surface dict kept with it."""
    _result.clear()
    _result.update(key=key, fields=list(fields), field=field, surface={})
    return _result["surface"]


def last_result() -> dict:
    """The last combined result as kept: ``{"key", "fields", "field", "surface"}``, or empty."""
    return dict(_result)


def _pop(key):
    """Remove one entry (if any) and return it."""
    global _bytes
    entry = _entries.pop(key, None)
    if entry is not None:
        _bytes -= entry[2]
    return entry


def total_bytes() -> int:
    """Bytes held by all cached fields (a running sum: cheap enough for a panel's ``draw()``)."""
    return _bytes


def stats() -> dict:
    """Counters since the last ``reset_stats()``: hits, builds, evictions, invalidations, result_hits; plus entries and
    bytes."""
    return {**_stats, "entries": len(_entries), "bytes": total_bytes()}


def reset_stats():
    for name in _stats:
        _stats[name] = 0


def invalidate(session_uid: int) -> bool:
    """Drop the entry an object used (its geometry changed); returns whether there was one."""
    if _pop(_objects.pop(session_uid, None)) is None:
        return False
    _stats["invalidations"] += 1
    return True


def clear():
    """Drop every cached field and the last combined result, and give the engine's pooled pages back."""
    global _bytes
    _entries.clear()
    _objects.clear()
    _bytes = 0
    _result.clear()
    runtime.release_memory()


def spare_bytes(context=None) -> int:
    """What the memory limit leaves beside the cached fields: the most the engine may keep pooled between runs."""
    return max(limit_bytes(context) - _bytes, 0)


# ---- handlers ----


@bpy.app.handlers.persistent
def _on_depsgraph_update(scene, depsgraph):
    global _skip_next_update
    if _skip_next_update:
        _skip_next_update = False
        return
    if not _entries:
        return
    for update in depsgraph.updates:
        if update.is_updated_geometry and isinstance(update.id, bpy.types.Object):
            invalidate(update.id.original.session_uid)


@bpy.app.handlers.persistent
def _on_load_pre(*_args):
    clear()


@bpy.app.handlers.persistent
def _on_undo_redo_post(*_args):
    global _skip_next_update
    _skip_next_update = True


_HANDLERS = (
    (bpy.app.handlers.depsgraph_update_post, _on_depsgraph_update),
    (bpy.app.handlers.load_pre, _on_load_pre),
    (bpy.app.handlers.undo_post, _on_undo_redo_post),
    (bpy.app.handlers.redo_post, _on_undo_redo_post),
)


def register():
    for handlers, handler in _HANDLERS:
        if handler not in handlers:
            handlers.append(handler)


def unregister():
    global _skip_next_update
    for handlers, handler in _HANDLERS:
        while handler in handlers:
            handlers.remove(handler)
    _skip_next_update = False
    clear()
