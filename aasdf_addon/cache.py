"""Per-object cache of input fields, so re-running a boolean on unchanged objects builds no field.

An entry belongs to one object (``obj.session_uid``) and is valid for one key: a hash of the object's evaluated
local geometry (vertex and triangle bytes), its world matrix and the field settings (voxel size, levels, padding,
device). A changed key rebuilds that object's field only. Entries are kept in least-recently-used order within the
memory limit of the add-on preferences (``cache_limit_mb``; 0 turns the cache off). A ``depsgraph_update_post``
handler drops the entries of objects whose geometry changed, ``load_pre`` empties the cache, and ``unregister()``
removes the handlers and empties it too.

Undo and redo re-evaluate every object as if its geometry had changed. The update that follows ``undo_post`` or
``redo_post`` is therefore not taken as an edit, so the redo panel re-runs an operator on cached fields (the key,
not the handler, is what keeps entries correct: a field is only ever reused for the same geometry hash).
"""

import copy
import hashlib
from collections import OrderedDict

import bpy
import numpy as np

from . import bridge, preferences, runtime

_entries: OrderedDict = OrderedDict()  # session_uid -> (key, field, nbytes), least recently used first
_stats = {"hits": 0, "builds": 0, "evictions": 0, "invalidations": 0}
_skip_next_update = False  # set by undo/redo: their re-evaluation is not an edit
_bytes = 0  # sum of the entries' nbytes, kept up to date so the sidebar reads it without summing

DEFAULT_LIMIT_MB = 1024

_FIELD_ARRAYS = ("codes", "coords", "values", "proj", "child", "source")


def field_nbytes(field) -> int:
    """Bytes held by a field's arrays."""
    return int(sum(getattr(getattr(field, name, None), "capacity", 0) or 0 for name in _FIELD_ARRAYS))


def limit_bytes(context=None) -> int:
    """The cache's memory limit in bytes, from the add-on preferences (1 GiB without preferences)."""
    prefs = preferences.get(context)
    mb = prefs.cache_limit_mb if prefs is not None else DEFAULT_LIMIT_MB
    return int(mb) * 2**20


def geometry_key(verts, tris, matrix, *, voxel_size, levels, padding, device) -> str:
    """Hash of local geometry, world matrix and field settings: equal keys give equal fields."""
    digest = hashlib.blake2b(digest_size=20)
    for array in (verts, tris, np.asarray(matrix, dtype=np.float64)):
        array = np.ascontiguousarray(array)
        digest.update(str(array.shape).encode())
        digest.update(array.tobytes())
    digest.update(repr((float(voxel_size), int(levels), int(padding), str(device))).encode())
    return digest.hexdigest()


def with_field_id(field, field_id: int):
    """The field with every node's source id set to ``field_id`` (a shallow copy; the field itself when equal)."""
    if tuple(field.field_ids) == (int(field_id),):
        return field
    import warp as wp

    relabelled = copy.copy(field)
    relabelled.source = wp.full(field.source.shape[0], int(field_id), dtype=wp.int32, device=field.source.device)
    relabelled.field_ids = (int(field_id),)
    return relabelled


def uncached_meshes(objects, depsgraph, *, voxel_size, levels, padding, device=None, context=None) -> list:
    """(object, (verts, tris) in world space, cache key) for each object whose field is not cached for these
    settings, to check and build them together (``build_together``)."""
    device = device or runtime.device(context)
    meshes = []
    for obj in objects:
        verts, tris = bridge.evaluated_local_mesh(obj, depsgraph)
        matrix = bridge.world_matrix(obj, depsgraph)
        key = geometry_key(verts, tris, matrix, voxel_size=voxel_size, levels=levels, padding=padding, device=device)
        entry = _entries.get(obj.original.session_uid)
        if entry is None or entry[0] != key:
            meshes.append((obj, bridge.to_world(verts, tris, matrix), key))
    return meshes


def build_together(pending, *, voxel_size, levels, padding, device=None, context=None) -> dict:
    """Build the fields of ``uncached_meshes``' objects at the same time (``engine.build_fields``) and cache them
    (those the memory limit allows).

    Returns:
        ``{session_uid: field}`` (``field_id`` 0) for every object of ``pending``.
    Raises:
        AasdfError: From ``engine.build_fields`` ("Mesh <k>: ..." names the k-th of ``pending``).
    """
    if not pending:
        return {}
    engine = runtime.engine()
    device = device or runtime.device(context)
    fields = engine.build_fields(
        [mesh for _, mesh, _ in pending], voxel_size=voxel_size, levels=levels, padding=padding, device=device
    )
    limit = limit_bytes(context)
    built = {}
    for (obj, _, key), field in zip(pending, fields, strict=True):
        _stats["builds"] += 1
        _store(obj.original.session_uid, key, field, limit)
        built[obj.original.session_uid] = field
    return built


def field_for(obj, depsgraph, *, voxel_size, levels, padding, field_id=0, device=None, context=None):
    """The adaptive field of a mesh object's evaluated world-space geometry, from the cache or newly built.

    Args:
        obj: A mesh object (original).
        depsgraph: The evaluated depsgraph.
        voxel_size, levels, padding: Field settings, as for ``engine.build_field``.
        field_id: Source id of the returned field's nodes (cached fields are relabelled, not rebuilt).
        device: Warp device (``None``: the preferred device).
        context: For the preferences (memory limit, device).
    Returns:
        ``AdaptiveField``.
    Raises:
        AasdfError: From ``engine.build_field`` (empty or degenerate geometry, too fine for memory).
    """
    engine = runtime.engine()
    device = device or runtime.device(context)
    verts, tris = bridge.evaluated_local_mesh(obj, depsgraph)
    matrix = bridge.world_matrix(obj, depsgraph)
    key = geometry_key(verts, tris, matrix, voxel_size=voxel_size, levels=levels, padding=padding, device=device)
    uid = obj.original.session_uid
    entry = _entries.get(uid)
    if entry is not None and entry[0] == key:
        _entries.move_to_end(uid)
        _stats["hits"] += 1
        return with_field_id(entry[1], field_id)
    _pop(uid)
    world, world_tris = bridge.to_world(verts, tris, matrix)
    field = engine.build_field(
        world, world_tris, voxel_size=voxel_size, levels=levels, padding=padding, device=device, field_id=field_id
    )
    _stats["builds"] += 1
    _store(uid, key, field, limit_bytes(context))
    return field


def _store(uid, key, field, limit):
    global _bytes
    nbytes = field_nbytes(field)
    if nbytes > limit:
        return
    _pop(uid)
    _entries[uid] = (key, field, nbytes)
    _bytes += nbytes
    while _bytes > limit:
        _bytes -= _entries.popitem(last=False)[1][2]
        _stats["evictions"] += 1


def _pop(uid):
    """Remove one entry (if any) and return it."""
    global _bytes
    entry = _entries.pop(uid, None)
    if entry is not None:
        _bytes -= entry[2]
    return entry


def total_bytes() -> int:
    """Bytes held by all cached fields (a running sum: cheap enough for a panel's ``draw()``)."""
    return _bytes


def stats() -> dict:
    """Counters since the last ``reset_stats()``: hits, builds, evictions, invalidations; plus entries and bytes."""
    return {**_stats, "entries": len(_entries), "bytes": total_bytes()}


def reset_stats():
    for name in _stats:
        _stats[name] = 0


def invalidate(session_uid: int) -> bool:
    """Drop one object's entry; returns whether there was one."""
    if _pop(session_uid) is None:
        return False
    _stats["invalidations"] += 1
    return True


def clear():
    """Drop every cached field (and the last combined result, which holds fields)."""
    global _bytes
    _entries.clear()
    _bytes = 0
    bridge.clear_memo()


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
