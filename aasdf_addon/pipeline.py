"""The one path from mesh objects to a boolean result, shared by ``aasdf.boolean`` and the CSG node tree.

``voxel_size_for`` picks the finest spacing, ``operand_fields`` asks ``cache`` for one field per operand (operand ``k``
gets ``field_id=k``), ``bridge.combine`` folds fields, ``surface`` extracts the result's triangles and gives each face
the material slot of the operand it came from, and ``write_result`` creates or updates the result object. ``Run``
times these stages; ``record`` keeps the numbers of the last successful run in ``last_run`` for the sidebar and for
scripts. Nothing here loops over vertices or triangles in Python.
"""

import time
from contextlib import contextmanager

import numpy as np

from . import bridge, cache, runtime

# Numbers of the last successful run (``aasdf.boolean`` or a CSG tree): read by the sidebar and by scripts.
last_run: dict = {}

STAGES = ("fields", "booleans", "surface", "write")


class Run:
    """Wall-clock seconds per stage of one run, and the cache counters at its start."""

    def __init__(self):
        self.start = time.perf_counter()
        self.stages = dict.fromkeys(STAGES, 0.0)
        self.cache_before = cache.stats()

    @contextmanager
    def stage(self, name):
        began = time.perf_counter()
        try:
            yield
        finally:
            self.stages[name] = self.stages.get(name, 0.0) + time.perf_counter() - began

    @property
    def seconds(self) -> float:
        return time.perf_counter() - self.start

    def cache_delta(self) -> tuple[int, int]:
        """(cache hits, fields built) since the run started."""
        after = cache.stats()
        return after["hits"] - self.cache_before["hits"], after["builds"] - self.cache_before["builds"]


def voxel_size_for(objects, depsgraph, voxel_size: float, resolution: int) -> float:
    """``voxel_size`` when positive, else the diagonal of the objects' combined world bounding box / ``resolution``.

    Returns 0.0 when the objects have no extent (the caller reports it).
    """
    if voxel_size > 0.0:
        return float(voxel_size)
    lo, hi = bridge.world_bounds(objects, depsgraph)
    return float(np.linalg.norm(hi - lo)) / int(resolution)


def operand_fields(context, objects, depsgraph, *, voxel_size, levels, padding, progress=None) -> list:
    """One field per object, from the cache or newly built; object ``k`` gets ``field_id=k``.

    Args:
        context: For the preferences (device, memory limit).
        objects: Mesh objects (originals).
        depsgraph: The evaluated depsgraph.
        voxel_size, levels, padding: Field settings.
        progress: Optional callable ``progress(k, obj)`` called before each object's field.
    Returns:
        List of ``AdaptiveField``.
    Raises:
        AasdfError: From the engine, its message prefixed with the object's name.
    """
    engine = runtime.engine()
    # Everything that must be built is checked together first: an impossible request builds nothing.
    pending = cache.uncached_meshes(
        objects, depsgraph, voxel_size=voxel_size, levels=levels, padding=padding, context=context
    )
    if pending and progress is not None:
        progress(list(objects).index(pending[0][0]), pending[0][0])
    try:
        # checked together (build_fields does) and built at the same time
        built = cache.build_together(pending, voxel_size=voxel_size, levels=levels, padding=padding, context=context)
    except engine.AasdfError as err:
        message = str(err)
        if message.startswith("Mesh "):  # "Mesh <k>: ..." counts the pending meshes: name the object instead
            head, _, rest = message.partition(": ")
            message = f"{pending[int(head.split()[1])][0].name}: {rest}"
        raise engine.AasdfError(message) from err
    fields = []
    for k, obj in enumerate(objects):
        if progress is not None:
            progress(k, obj)
        field = built.get(obj.original.session_uid)
        if field is not None:
            fields.append(cache.with_field_id(field, k))
            continue
        try:
            field = cache.field_for(
                obj, depsgraph, voxel_size=voxel_size, levels=levels, padding=padding, field_id=k, context=context
            )
        except engine.AasdfError as err:
            raise engine.AasdfError(f"{obj.name}: {err}") from err
        fields.append(field)
    return fields


def surface(field, operands) -> dict:
    """The zero surface of ``field`` with the operands' materials.

    Args:
        field: The combined ``AdaptiveField``; its source ids index ``operands``.
        operands: The mesh objects, in ``field_id`` order.
    Returns:
        ``{"verts": (V,3) float32, "tris": (F,3) int32, "materials": [...], "face_slots": (F,) int32 or None,
        "edges": the surface's edge cache (see ``bridge.result_mesh``)}``.
    """
    faces = getattr(field, "_faces", None)  # a reused result (see bridge.combine) keeps its surface
    if faces is None:
        field._faces = faces = {"verts_tris": field.to_mesh()}
    verts, tris = faces["verts_tris"]
    materials, slot_of = bridge.operand_materials(operands)
    face_slots = None
    if materials and len(tris):
        if "ids" not in faces:  # which operand each face came from: only needed for materials
            faces["ids"] = field.source_ids(verts[tris].mean(axis=1))
        face_slots = slot_of[faces["ids"].clip(0, len(operands) - 1)]
    edges = faces.setdefault("edges", {})  # filled by the first write, reused by the next ones
    return {"verts": verts, "tris": tris, "materials": materials, "face_slots": face_slots, "edges": edges}


def write_result(context, name, result: dict, *, smooth: bool, target=None, collection=None, select=True):
    """Write a ``surface()`` result: into ``target``'s new mesh data (in place), or as a new object ``name``.

    Args:
        context: The caller's context.
        name: Name of a new object (ignored when ``target`` is given).
        result: From ``surface()``.
        smooth: Smooth shading for all faces.
        target: An existing mesh object to update in place (same object, new mesh data), or ``None``.
        collection: Collection for a new object (default: the active object's, as ``aasdf.boolean`` does).
        select: Make a new object the active one and the only selection.
    Returns:
        The result object.
    """
    arrays = (result["verts"], result["tris"])
    options = {
        "materials": result["materials"],
        "face_material_index": result["face_slots"],
        "smooth": smooth,
        "edge_cache": result.get("edges"),
    }
    if target is not None:
        return bridge.update_result_object(target, *arrays, **options)
    return bridge.write_result_object(context, name, *arrays, collection=collection, select=select, **options)


def record(run: Run, field, result: dict, **numbers) -> dict:
    """Replace ``last_run`` with the numbers of a finished run and return it.

    Keys: ``seconds``, ``stages`` (seconds per stage), ``nodes``, ``level_counts`` (field nodes per level, finest
    first), ``vertices``, ``triangles``, ``cache_hits``, ``fields_built``, plus ``numbers`` (object, operation, ...).
    """
    hits, builds = run.cache_delta()
    last_run.clear()
    last_run.update(
        numbers,
        seconds=run.seconds,
        stages=dict(run.stages),
        nodes=field.node_count,
        level_counts=field.level_counts,
        vertices=len(result["verts"]),
        triangles=len(result["tris"]),
        cache_hits=hits,
        fields_built=builds,
    )
    return last_run
