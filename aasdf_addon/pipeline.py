"""The one path from mesh objects to a result object, shared by ``aasdf.boolean``, ``aasdf.debug_volume`` and the CSG
tree: read → key → cache → build → combine → extract → write, in that order and only that way.

1. read: ``bridge.read_operands`` gives each object's evaluated local geometry and world matrix;
2. key: ``cache.geometry_key`` per operand (geometry, transform, field settings, device);
3. cache: ``cache.find`` returns the fields it has;
4. build: the missing ones are built together (``engine.build_fields``, checked together first) and ``cache.store``d;
   each field is relabelled with its operand's index (``field_id`` = position in the plan's operand list);
5. combine: a plan (``("field", k)`` leaves, ``(operation, blend, [children])`` nodes) folded with the engine's
   booleans as balanced binary trees; the last result is reused when nothing changed (``cache.find_result``);
6. extract: the result's zero surface, each face carrying over its source face's material, shading, UV maps and
   colours (``transfer``);
7. write: a new object, or new mesh data for an existing one, plus debug objects and hidden inputs when asked.

``run`` does all of it, owns the progress bar and the status text, and returns the numbers of the run, also kept in
``last_run`` for the sidebar and for scripts. Nothing here loops over vertices or triangles in Python.
"""

import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from . import bridge, cache, runtime, transfer

# Numbers of the last successful run (``aasdf.boolean`` or a CSG tree): read by the sidebar and by scripts.
last_run: dict = {}

STAGES = ("read", "fields", "booleans", "surface", "attributes", "write")

# Callables ``listener(text)`` told each step of a run (the batch script prints them).
progress_listeners: list = []

_ENGINE_OPS = {"UNION": "union", "INTERSECT": "intersection", "DIFFERENCE": "difference"}


@dataclass(frozen=True)
class FieldSettings:
    """How operands become fields: ``voxel_size`` (0: the inputs' diagonal / ``resolution``), ``levels``,
    ``padding``."""

    voxel_size: float = 0.0
    resolution: int = 256
    levels: int = 4
    padding: int = 1

    @classmethod
    def of(cls, props) -> "FieldSettings":
        """The settings of anything that declares them (an operator, ``Scene.aasdf``, a CSG tree)."""
        return cls(float(props.voxel_size), int(props.resolution), int(props.levels), int(props.padding))


@dataclass
class Output:
    """Where and how a run writes its result: a new object ``name`` (in ``collection``, default the first
    operand's), or ``target``'s mesh data replaced in place."""

    name: str
    target: object = None
    collection: object = None
    select: bool = True
    hide_inputs: bool = False
    debug_volume: bool = False


def boolean_plan(operation: str, count: int, blend: float = 0.0) -> tuple:
    """The plan of ``aasdf.boolean`` over ``count`` operands: DIFFERENCE is the first minus all the others (their
    union is sharp; ``blend`` rounds the final cut only), UNION and INTERSECT take them all."""
    if operation not in _ENGINE_OPS:
        raise ValueError(f"Expected 'operation' in {tuple(_ENGINE_OPS)}, but got {operation!r}.")
    leaves = [("field", k) for k in range(count)]
    return (operation, float(blend), leaves)


class Progress:
    """The window manager's progress bar and the workspace's status text over the steps of a run (both harmless
    no-ops headless), and the ``progress_listeners``."""

    def __init__(self, context, steps: int):
        self.context, self.done = context, 0
        self.wm = context.window_manager
        self.wm.progress_begin(0, max(1, steps))

    def step(self, text: str):
        self.done += 1
        self.wm.progress_update(self.done)
        if self.context.workspace is not None:
            self.context.workspace.status_text_set(f"SDF boolean: {text}")
        for listener in progress_listeners:
            listener(text)

    def end(self):
        self.wm.progress_end()
        if self.context.workspace is not None:
            self.context.workspace.status_text_set(None)


class Timer:
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


# ---- the stages ----


def voxel_size_for(objects, depsgraph, settings: FieldSettings) -> float:
    """``settings.voxel_size`` when positive, else the diagonal of the objects' combined world bounding box /
    ``settings.resolution``.

    Raises:
        AasdfError: When the objects have no extent and no voxel size is set.
    """
    if settings.voxel_size > 0.0:
        return float(settings.voxel_size)
    lo, hi = bridge.world_bounds(objects, depsgraph)
    voxel_size = float(np.linalg.norm(hi - lo)) / int(settings.resolution)
    if not voxel_size > 0.0:
        raise runtime.engine().AasdfError("The inputs have no extent: set a Voxel Size")
    return voxel_size


def operand_fields(context, operands, settings: FieldSettings, voxel_size: float, progress=None) -> list:
    """Key → cache → build for read operands (``bridge.read_operands``): one field per operand, operand ``k``'s
    with ``field_id`` k. What is missing is checked together first and built at the same time.

    Raises:
        AasdfError: From the engine, its message naming the object.
    """
    engine = runtime.engine()
    device = runtime.device(context)
    options = {"voxel_size": voxel_size, "levels": settings.levels, "padding": settings.padding}
    keys = [cache.geometry_key(op.verts, op.tris, op.matrix, **options, device=device) for op in operands]
    fields = [cache.find(op.uid, key) for op, key in zip(operands, keys, strict=True)]
    missing = [k for k, field in enumerate(fields) if field is None]
    if missing:
        if progress is not None:
            progress.step(f"building the fields of {', '.join(operands[k].name for k in missing)}")
        try:
            built = engine.build_fields([operands[k].world() for k in missing], **options, device=device)
        except engine.AasdfError as err:
            message = str(err)
            if message.startswith("Mesh "):  # "Mesh <j>: ..." counts the missing meshes: name the object instead
                head, _, rest = message.partition(": ")
                message = f"{operands[missing[int(head.split()[1])]].name}: {rest}"
            raise engine.AasdfError(message) from err
        limit = cache.limit_bytes(context)
        for k, field in zip(missing, built, strict=True):
            cache.store(operands[k].uid, keys[k], field, limit)
            fields[k] = field
    return [field.relabel(k) for k, field in enumerate(fields)]


def combine(plan: tuple, fields: list, progress=None):
    """The field of a plan: ``("field", k)`` is ``fields[k]``; ``(operation, blend, children)`` combines its
    children as a balanced binary tree (depth ``ceil(log2 n)``), DIFFERENCE as the first child minus the union of
    the others."""
    if plan[0] == "field":
        return fields[plan[1]]
    engine = runtime.engine()
    operation, blend, children = plan
    items = [combine(child, fields, progress) for child in children]
    if operation == "DIFFERENCE" and len(items) > 1:
        cutter = _fold(engine.union, items[1:], 0.0, progress)
        result = engine.difference(items[0], cutter, blend=blend)
        if progress is not None:
            progress.step("combining fields")
        return result
    return _fold(getattr(engine, _ENGINE_OPS[operation]), items, blend, progress)


def _fold(op, items, blend, progress):
    items = list(items)
    while len(items) > 1:
        paired = []
        for i in range(0, len(items) - 1, 2):
            paired.append(op(items[i], items[i + 1], blend=blend))
            if progress is not None:
                progress.step("combining fields")
        if len(items) % 2:
            paired.append(items[-1])
        items = paired
    return items[0]


def extract(field, surface: dict) -> dict:
    """The zero surface of ``field``, computed once per result (``surface`` is the dict the cache keeps with it).

    Returns:
        ``{"verts": (V,3) float32, "tris": (F,3) int32, "edges": the surface's edge cache (see
        ``bridge.result_mesh``)}``.
    """
    if "verts" not in surface:
        surface["verts"], surface["tris"] = field.to_mesh()
    edges = surface.setdefault("edges", {})  # filled by the first write, reused by the next ones
    return {"verts": surface["verts"], "tris": surface["tris"], "edges": edges}


def carry_over(field, surface: dict, operands) -> dict:
    """What each face of the extracted ``surface`` carries over from its operand (``transfer.face_attributes``); each
    face's source is found once per result and kept in ``surface``."""
    verts, tris = surface["verts"], surface["tris"]
    if not len(tris):
        return {}
    if "sources" not in surface:  # every corner on its face's source triangle, so the source's seams stay seams
        surface["sources"] = field.face_sources(verts, tris)
    return transfer.face_attributes(operands, *surface["sources"])


def write(context, result: dict, output: Output):
    """Write an ``extract`` result: into ``output.target``'s new mesh data (in place), or as a new object."""
    arrays = (result["verts"], result["tris"], result["attributes"])
    if output.target is not None:
        if not output.target.users_collection:  # an orphan: show it again
            (output.collection or context.scene.collection).objects.link(output.target)
        return bridge.update_result_object(output.target, *arrays, edge_cache=result["edges"])
    return bridge.write_result_object(
        context, output.name, *arrays, collection=output.collection, select=output.select, edge_cache=result["edges"]
    )


# ---- a whole run ----


def run(context, objects, plan, settings: FieldSettings, output: Output, *, source: str, operation: str) -> dict:
    """Evaluate ``plan`` over ``objects`` (``("field", k)`` is ``objects[k]``) and write the result.

    Returns:
        The numbers of the run (also in ``last_run`` unless the result is empty): ``seconds``, ``stages``, ``nodes``,
        ``level_counts``, ``vertices``, ``triangles``, ``cache_hits``, ``fields_built``, ``voxel_size``, ``object``,
        ``source``, ``operation``, ``operands``, ``warnings`` (list of messages); ``{"object": name, "empty": True}``
        when the result has no surface (nothing is written).
    Raises:
        AasdfError: Bad input or too fine for memory, the object named; nothing is written.
    """
    engine = runtime.engine()
    timer = Timer()
    progress = Progress(context, len(objects) + 5)
    warnings = []
    try:
        with timer.stage("read"):
            progress.step(f"reading {len(objects)} objects")
            depsgraph = context.evaluated_depsgraph_get()
            voxel_size = voxel_size_for(objects, depsgraph, settings)
            operands = bridge.read_operands(objects, depsgraph)
        with timer.stage("fields"):
            fields = operand_fields(context, operands, settings, voxel_size, progress)
        with timer.stage("booleans"):
            key = (plan, tuple((id(f.codes), f.field_ids) for f in fields))
            found = cache.find_result(key)
            if found is None:
                field = combine(plan, fields, progress)
                surface = cache.store_result(key, fields, field)
            else:
                field, surface = found
        with timer.stage("surface"):
            progress.step("extracting the surface")
            result = extract(field, surface)
        if len(result["tris"]) == 0:
            return {"object": output.target.name if output.target is not None else output.name, "empty": True}
        with timer.stage("attributes"):
            result["attributes"] = carry_over(field, surface, operands)
        with timer.stage("write"):
            progress.step("writing the result")
            obj = write(context, result, output)
            if output.debug_volume:
                from . import debug

                progress.step("writing the debug volume")
                try:
                    debug.add_debug_objects(context, field, obj.name)
                except engine.AasdfError as err:  # too large for memory: the result stays
                    warnings.append(f"No debug volume: {err}")
                if output.select:
                    context.view_layer.objects.active = obj
            if output.hide_inputs:
                for operand in objects:
                    operand.hide_set(True)
    finally:
        progress.end()
    hits, builds = timer.cache_delta()
    last_run.clear()
    last_run.update(
        seconds=timer.seconds,
        stages=dict(timer.stages),
        nodes=field.node_count,
        level_counts=field.level_counts,
        vertices=len(result["verts"]),
        triangles=len(result["tris"]),
        cache_hits=hits,
        fields_built=builds,
        voxel_size=voxel_size,
        object=obj.name,
        source=source,
        operation=operation,
        operands=len(objects),
        warnings=warnings,
    )
    return dict(last_run)


def object_field(context, obj, settings: FieldSettings):
    """One object's field (read → key → cache → build), for views of a single field (``aasdf.debug_volume``).

    Raises:
        AasdfError: As ``operand_fields``.
    """
    depsgraph = context.evaluated_depsgraph_get()
    voxel_size = voxel_size_for([obj], depsgraph, settings)
    return operand_fields(context, bridge.read_operands([obj], depsgraph), settings, voxel_size)[0]
