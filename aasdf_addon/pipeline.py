"""The one path from mesh objects to a result object, shared by ``aasdf.boolean``, ``aasdf.debug_volume`` and the CSG
tree: read → key → cache → build → combine → extract → write, in that order and only that way.

1. read: ``operands.read_operands`` gives each object's evaluated local geometry (a mesh, text, curve, surface or
   metaball, its instances realized) and world matrix; ``transforms.check_operands`` refuses a matrix that cannot place
   a field, or moves a flat operand that has a thickness to world space;
2. key: ``cache.geometry_key`` per operand (geometry in its own frame, field settings, device), refined by
   ``placement.field_key`` for an object no field of its geometry can reach by a similarity (its scale's ladder step,
   or its whole matrix under an uneven scale or a shear); a run into a named object (``Output.reuse``) keys its whole
   result first (``unchanged.inputs_key``) and stops there when the object still shows that result as written;
3. cache: ``cache.find`` returns the fields it has;
4. build: the missing ones are built together (``engine.build_fields``, checked together first) and ``cache.store``d;
   each field is relabelled with its operand's index (``field_id`` = position in the plan's operand list);
5. combine: a plan (``aasdf_addon.plan``: booleans, offsets, shells over the operands' fields) evaluated; the last
   result is reused when nothing changed (``cache.find_result``);
6. extract: the result's zero surface (creases kept sharp unless asked otherwise), each face carrying over its source
   face's material, shading, UV maps and colours (``transfer``) and every other attribute (``generic_attributes``);
7. write: a new object, or new mesh data for an existing one, plus debug objects and hidden inputs when asked.

``run`` does all of it, owns the progress bar and the status text, and returns the numbers of the run, also kept in
``last_run`` for the sidebar and for scripts. Nothing here loops over vertices or triangles in Python.
"""

import hashlib
import time
from contextlib import contextmanager
from dataclasses import dataclass

import bpy
import numpy as np

from . import (
    bridge,
    cache,
    custom_normals,
    generic_attributes,
    placement,
    plan,
    polygons,
    quad_faces,
    regions,
    runtime,
    transfer,
    transforms,
    unchanged,
)
from .fields import operand_fields
from .operands import read_operands

# Numbers of the last successful run (``aasdf.boolean`` or a CSG tree): read by the sidebar and by scripts.
last_run: dict = {}

STAGES = ("read", "key", "fields", "booleans", "surface", "attributes", "write")

# Callables ``listener(text)`` told each step of a run (the batch script prints them).
progress_listeners: list = []


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
    sharp: bool = True  # creases kept sharp (dual contouring) or rounded (marching cubes)
    keep_faces: bool = False  # the operands' own faces kept away from the seams (``AdaptiveField.kept_surface``)
    reuse: bool = False  # nothing done when ``target`` still shows the result of the same inputs (``unchanged``)
    adaptivity: float = 0.0  # 0 to 1: cells merged where the remeshed surface is flat (``AdaptiveField.to_mesh``)


class Progress:
    """The window manager's progress bar and the workspace's status text over the steps of a run (both harmless
    no-ops headless), and the ``progress_listeners``."""

    def __init__(self, context, steps: int):
        self.context, self.done, self.total = context, 0, max(1, steps)
        self.wm = context.window_manager
        self.wm.progress_begin(0, self.total)

    def step(self, text: str):
        self.done += 1
        self.wm.progress_update(self.done)
        if self.context.workspace is not None:
            self.context.workspace.status_text_set(f"SDF boolean: {text}")
        for listener in progress_listeners:
            listener(text)

    def compiling(self, done: int, count: int, name: str):
        """A step per kernel module compiled on a first run (``runtime.prepare_kernels``), drawn at once: each takes
        seconds, and the status bar is not redrawn while an operator runs."""
        if done == 0:
            self.total += count
            self.wm.progress_begin(0, self.total)
        text = f"compiling the engine's kernels for this machine (first run only): {done} of {count} done"
        self.step(f"{text}, {name}" if name else text)
        if not bpy.app.background and self.context.window is not None:
            bpy.ops.wm.redraw_timer(type="DRAW_WIN_SWAP", iterations=1)

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


# Voxel sizes derived from a resolution are snapped to this ladder (steps of 2^(1/4), about 19 %), and a run keeps
# the step the previous run on the same objects took while the raw size stays within VOXEL_HOLD of it: dragging an
# operand changes the combined bounding box a little, which must not change the voxel size of every field.
VOXEL_STEPS_PER_OCTAVE = placement.VOXEL_STEPS_PER_OCTAVE
VOXEL_HOLD_STEPS = 0.75
_voxel_steps: dict = {}  # frozenset of object uids -> the ladder step their last run took


def voxel_size_for(read, settings: FieldSettings) -> float:
    """``settings.voxel_size`` when positive, else the diagonal of the read operands' combined world bounding box /
    ``settings.resolution``, snapped to a ladder of sizes (``VOXEL_STEPS_PER_OCTAVE`` a factor of 2, never coarser
    than asked) and held at the objects' previous step while the box changes little (``VOXEL_HOLD_STEPS``).

    Raises:
        AasdfError: When the objects have no extent and no voxel size is set, naming an object whose vertices are not
            all numbers (NaN or infinite: the build refuses them too).
    """
    if settings.voxel_size > 0.0:
        return float(np.float32(settings.voxel_size))
    lo, hi = world_bounds(read)
    raw = float(np.linalg.norm(hi - lo)) / int(settings.resolution)
    if not np.isfinite(raw):  # a vertex that is not a number, named as the build names it
        for operand in read:
            if bad := int(np.count_nonzero(~np.isfinite(operand.verts).all(axis=1))):
                raise runtime.engine().AasdfError(
                    f"{operand.name}: The mesh has {bad} vertices with NaN or infinite coordinates."
                )
    if not raw > 0.0:
        raise runtime.engine().AasdfError("The inputs have no extent: set a Voxel Size")
    step = int(np.floor(np.log2(raw) * VOXEL_STEPS_PER_OCTAVE))
    group = frozenset(operand.uid for operand in read)
    previous = _voxel_steps.get(group)
    position = np.log2(raw) * VOXEL_STEPS_PER_OCTAVE  # the step itself while in [step, step + 1)
    if previous is not None and previous - VOXEL_HOLD_STEPS <= position < previous + 1 + VOXEL_HOLD_STEPS:
        step = previous
    _voxel_steps[group] = step
    # single precision, as a Voxel Size setting holds it: the same size typed in finds the same fields
    return float(np.float32(2.0 ** (step / VOXEL_STEPS_PER_OCTAVE)))


def read_stage(context, inputs, steps, settings: FieldSettings, output: Output) -> tuple:
    """The read stage: the operands read and checked (:func:`read_checked`), the voxel size (:func:`voxel_size_for`),
    the plan's reach checked (``plan.check_reach``); and what the user is told of the voxel size
    (:func:`coarser_than_asked`). Returns ``(read, voxel_size, warnings)``."""
    read = read_checked(inputs, output, context.evaluated_depsgraph_get())
    voxel_size = voxel_size_for(read, settings)
    box = world_bounds(read)
    plan.check_reach(steps, *box, voxel_size)
    return read, voxel_size, coarser_than_asked(read, steps, settings, (voxel_size, box))


# A voxel size from a resolution that is this many times coarser than the resolution would give along the result's
# own box is told (a large box that halves a part: the part gets as many times fewer voxels).
COARSER_TOLD = 2.0


def coarser_than_asked(read, steps, settings: FieldSettings, taken: tuple) -> list:
    """A warning where **Resolution** (counted along all the inputs' box) gives voxels COARSER_TOLD times or more as
    coarse as it would along the box the result lies in (``plan.result_box``: a difference's first operand's, an
    intersection's common box), with the **Voxel Size** that would give the result its resolution; else none.
    ``taken``: the voxel size, and the inputs' box (:func:`world_bounds`)."""
    if settings.voxel_size > 0.0 or not read:
        return []
    box = plan.result_box(steps, [world_bounds([operand]) for operand in read])
    voxel_size, (lo, hi) = taken
    whole, own = float(np.linalg.norm(hi - lo)), 0.0 if box is None else float(np.linalg.norm(box[1] - box[0]))
    if not own > 0.0 or whole < COARSER_TOLD * own:
        return []
    return [
        f"Resolution counts voxels along all the inputs' box, {whole / own:.0f}x the result's: its voxels are "
        f"{voxel_size:.3g}. A Voxel Size of {own / settings.resolution:.3g} gives the result {settings.resolution} "
        "along its own box"
    ]


def world_bounds(read) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) float64 (3,) world corners of the read operands' boxes (their local boxes' corners placed)."""
    corners = [np.zeros((1, 3))]
    for operand in read:
        if len(operand.verts):
            lo, hi = operand.verts.min(axis=0), operand.verts.max(axis=0)
            box = np.array(np.meshgrid(*zip(lo, hi, strict=True), indexing="ij"), dtype=np.float64).reshape(3, -1).T
            corners.append(box @ operand.matrix[:3, :3].T + operand.matrix[:3, 3])
    points = np.concatenate(corners[1:] or corners)
    return points.min(axis=0), points.max(axis=0)


def read_checked(inputs, output: Output, depsgraph) -> list:
    """Read the inputs (``plan.Input``) as operands and check their transforms and the result object's, before any
    work (``operands.read_operands``, ``transforms.check_operands``, ``transforms.check_target``).

    Raises:
        AasdfError: Naming each object that has no geometry or a transform that cannot be used, and what to do.
    """
    read = read_operands([item.obj for item in inputs], depsgraph)
    read = transforms.check_operands(read, [item.thickness for item in inputs])
    transforms.check_target(output.target)
    return read


def _matrix_bytes(field) -> bytes:
    """Where a field is placed, as a key (empty when it is not)."""
    return b"" if field.placement is None else field.placement.matrix.tobytes()


def extract(
    field, surface: dict, *, sharp: bool = True, keep_faces: bool = False, adaptivity: float = 0.0, seams=None
) -> dict:
    """The zero surface of ``field``, computed once per result (``surface`` is the dict the cache keeps with it);
    with ``keep_faces`` the operands' own faces away from the seams (``AdaptiveField.kept_surface``, its face
    sources kept in ``surface["kept"]``; ``adaptivity``: its new faces merged where flat); else the remeshed
    surface's polygons (``adaptivity``: merged where flat)
    taken apart into triangles, its quads first (``quad_faces.fans``); merged only within the regions ``seams``
    (``regions.source_regions``: never across a material border or UV seam).

    Returns:
        ``{"verts": (V,3) float32, "tris": (F,3) int32, "creases": (E,2) int32 vertex pairs of the edges
        reconstructed as creases, "edges": the surface's edge cache (see ``bridge.result_mesh``), "quads": how many
        quads the first triangles pair into, "warnings": what the user is told (kept faces that could not be
        joined)}``.
    """
    if "verts" not in surface and keep_faces:
        kept = field.kept_surface(sharp=sharp, adaptivity=adaptivity if sharp else 0.0, regions=seams)
        surface["verts"], surface["tris"], surface["quads"] = kept["verts"], kept["tris"], kept.get("quads", 0)
        if kept["stats"].get("join_failed"):
            why = kept["stats"]["kept_fallback"]
            surface["warnings"] = [f"Keep Original Faces: the seams could not be joined to the kept faces ({why}); "
                                   "the whole result is remeshed"]  # fmt: skip
        elif kept["stats"]["kept_fallback"] == runtime.engine().littlekept.LITTLE_KEPT:
            surface["warnings"] = ["Keep Original Faces: the inputs' faces lie within a few voxels of each other "
                                   "almost everywhere; the whole result is remeshed (a smaller Voxel Size keeps "
                                   "more)"]  # fmt: skip
        surface["kept"] = kept
    elif "verts" not in surface:
        adaptivity = adaptivity if sharp else 0.0
        verts, faces, sizes, creases = field.to_mesh(
            sharp=sharp, return_creases=True, quads=True, adaptivity=adaptivity, regions=seams
        )
        surface["verts"], surface["creases"] = verts, creases
        surface["tris"], surface["quads"] = quad_faces.fans(faces, sizes)
    edges = surface.setdefault("edges", {})
    if "edge_verts" not in edges and len(surface["tris"]):
        # found in kernels (half the time Blender takes to derive them); an unusual surface's are left to the first
        # write to derive and keep
        found = runtime.engine().surface_edges(surface["tris"], len(surface["verts"]))
        if found is not None:
            edges["edge_verts"], edges["corner_edge"] = found[0].ravel(), found[1]
    if "creases" not in surface:  # kept faces: the edges where the surface folds, found on those edges
        found = (edges["edge_verts"], edges["corner_edge"]) if "edge_verts" in edges else None
        folds = runtime.engine().fold_edges(surface["verts"], surface["tris"], edges=found) if sharp and found else None
        surface["creases"] = np.zeros((0, 2), dtype=np.int32) if folds is None else folds
    result = {"verts": surface["verts"], "tris": surface["tris"], "creases": surface["creases"], "edges": edges}
    return {**result, "quads": surface.get("quads", 0), "warnings": list(surface.get("warnings", []))}


def carry_over(field, surface: dict, operands) -> dict:
    """What each face of the extracted ``surface`` carries over from its operand (``transfer.face_attributes``); each
    face's source is found once per result and kept in ``surface``."""
    tris = surface["tris"]
    if not len(tris):
        return {}
    if "sources" not in surface:  # every corner on its face's source triangle, so the source's seams stay seams
        surface["sources"] = _in_corner_order(field, operands, _face_sources(field, surface))
    attributes = transfer.face_attributes(operands, *surface["sources"])
    sources, n_verts = surface["sources"], len(surface["verts"])
    attributes["generic"] = generic_attributes.carried(operands, sources, tris, n_verts, surface.get("kept"))
    normals = custom_normals.kept_corner_normals(
        operands, surface["verts"], tris, surface.get("kept"), surface["sources"]
    )
    if normals is not None:
        attributes["custom_normals"] = normals
    return attributes


def whole_faces_back(result: dict, surface: dict, operands, output: Output) -> dict:
    """``result`` with the operands' faces kept whole given back as themselves (``polygons``): not into an object
    whose transform mirrors (its faces would need their corners turned)."""
    if surface.get("kept") is None or output.target is not None and np.linalg.det(output.target.matrix_world) < 0:
        return result
    result["attributes"]["kept_edges"] = (surface["kept"], operands)  # their seams, sharp edges, creases
    whole = polygons.whole_faces(surface["kept"], result["tris"], operands)
    return result if whole is None else polygons.as_polygons(result, whole, operands)


def _seams(operands, output: Output):
    """The operands' regions an adaptive surface merges within (``regions.source_regions``), else None."""
    if output.adaptivity <= 0.0 or not output.sharp:
        return None
    return regions.source_regions(operands)


def _seams_key(seams) -> bytes:
    """The regions as a key: a surface merged within other materials or UV islands is another surface."""
    if seams is None:
        return b""
    return hashlib.blake2b(b"".join(np.ascontiguousarray(v).tobytes() for v in seams.values())).digest()


def quads_back(result: dict, output: Output) -> dict:
    """``result`` with its quads whose halves agree written as quads (``quad_faces.quads_back``): not into an object
    whose transform mirrors (their corners would need turning)."""
    if output.target is not None and np.linalg.det(output.target.matrix_world) < 0:
        return result
    return quad_faces.quads_back(result, result["quads"])


def _in_corner_order(field, operands, sources) -> tuple:
    """``sources`` with each face's corner weights in its operand's own corner order: a field built under a mirroring
    matrix holds its triangles turned (``bridge.to_world``) and the weights follow them (a mirrored operand's split and
    new faces took their UVs, colours and normals from the wrong corners: custom normals 15 degrees off)."""
    ids, tri_ids, bary = sources
    turned = [k for k, operand in enumerate(operands) if _turned(field.sources.get(k), operand)]
    if not turned:
        return sources
    rows = np.isin(ids, turned)
    bary = bary.copy()
    bary[rows] = bary[rows][:, :, ::-1]
    return ids, tri_ids, bary


def _turned(source, operand) -> bool:
    """Whether a field's ``source`` triangles run against its operand's own (one compared: all are, or none)."""
    if source is None or not len(source.tris):
        return False
    own = np.asarray(operand.tris)[source.triangle_ids[0]]
    return bool(np.array_equal(source.tris[0], own[::-1]) and not np.array_equal(source.tris[0], own))


def _face_sources(field, surface: dict) -> tuple:
    """Each face's (field id, source triangle, corner weights): a kept face's are its own, a new face's found by the
    field (``AdaptiveField.face_sources``)."""
    verts, tris, kept = surface["verts"], surface["tris"], surface.get("kept")
    if kept is None or not kept["kept"].any() and "new_sources" not in kept:
        return field.face_sources(verts, tris)
    ids, tri_ids, bary = kept["field_id"].copy(), kept["triangle_id"].copy(), kept["corner_bary"].copy()
    if "new_sources" in kept:  # found where a boolean made along its seams made them
        new, *found = kept["new_sources"]
        ids[new], tri_ids[new], bary[new] = found
        return ids, tri_ids, bary
    new = np.flatnonzero(~kept["kept"])
    if len(new):
        ids[new], tri_ids[new], bary[new] = field.face_sources(verts, tris[new])
    return ids, tri_ids, bary


def write(context, result: dict, output: Output):
    """Write an ``extract`` result: into ``output.target``'s new mesh data (in place), or as a new object."""
    arrays = (result["verts"], result["tris"], {**result["attributes"], "creases": result["creases"]})
    if output.target is not None:
        if not output.target.users_collection:  # an orphan: show it again
            (output.collection or context.scene.collection).objects.link(output.target)
        return bridge.update_result_object(output.target, *arrays, edge_cache=result["edges"])
    return bridge.write_result_object(
        context, output.name, *arrays, collection=output.collection, select=output.select, edge_cache=result["edges"]
    )


# ---- a whole run ----


def run(context, inputs, steps, settings: FieldSettings, output: Output, *, source: str, operation: str) -> dict:
    """Evaluate the plan ``steps`` over ``inputs`` (``plan.Input``, or mesh objects taken as they are;
    ``("field", k)`` is ``inputs[k]``) and write the result.

    Returns:
        The numbers of the run (also in ``last_run`` unless the result is empty): ``seconds``, ``stages``, ``nodes``,
        ``level_counts``, ``vertices``, ``triangles``, ``cache_hits``, ``fields_built``, ``voxel_size``, ``object``,
        ``source``, ``operation``, ``operands``, ``warnings`` (list of messages), ``unchanged`` (True when
        ``output.target`` already showed this result: nothing built, combined, extracted or written);
        ``{"object": name, "empty": True}`` when the result has no surface (nothing is written).
    Raises:
        AasdfError: Bad input or too fine for memory, the object named; nothing is written.
    """
    runtime.engine()  # imported first (Warp configured before anything loads it)
    inputs = [item if isinstance(item, plan.Input) else plan.Input(item) for item in inputs]
    objects = [item.obj for item in inputs]
    plan.check_numbers(steps)
    timer = Timer()
    progress = Progress(context, len(objects) + 5)
    try:
        with timer.stage("read"):
            progress.step(f"reading {len(objects)} objects")
            read, voxel_size, notes = read_stage(context, inputs, steps, settings, output)
        with timer.stage("key"):
            keyed = result_key(context, read, inputs, steps, settings, voxel_size, output)
            current = keyed is not None and unchanged.is_current(output.target, keyed)
        if current:  # the result object shows this result as it was written: nothing to build, extract or write
            _hide_inputs(objects, output)
            return _record(timer, output.target, voxel_size, source, operation, len(objects))
        with timer.stage("fields"):
            walls, refine = [item.thickness for item in inputs], _refined(steps, len(inputs), output)
            fields = operand_fields(context, read, settings, voxel_size, progress, thickness=walls, refine=refine)
        with timer.stage("booleans"):
            seams = _seams(read, output)
            field, surface = combined(steps, fields, output, seams, progress)
        with timer.stage("surface"):
            progress.step("extracting the surface")
            result = _extracted(field, surface, output, seams)
        if len(result["tris"]) == 0:
            return {"object": output.target.name if output.target is not None else output.name, "empty": True}
        with timer.stage("attributes"):
            result["attributes"] = carry_over(field, surface, read)
            triangles = len(result["tris"])  # as many as Blender's triangulation of what is written
            result = quads_back(whole_faces_back(result, surface, read, output), output)
        with timer.stage("write"):
            obj = _written(context, result, output, keyed, field, progress)
            warnings = notes + result["warnings"] + _written_notes(context, field, obj, output)
            _hide_inputs(objects, output)
    finally:
        progress.end()
        # the engine's freed arrays stay resident for the next run's (a drag's moves), within the cache's limit
        runtime.release_memory(cache.spare_bytes(context))
    faces = len(result["tris"]) + len(result["attributes"].get("polygons", ((),))[0])
    counts, delta = (len(result["verts"]), triangles, faces), timer.cache_delta()
    numbers = {"field": field, "warnings": warnings, "counts": counts, "cache_delta": delta}
    return _record(timer, obj, voxel_size, source, operation, len(objects), **numbers)


def _extracted(field, surface: dict, output: Output, seams) -> dict:
    """The surface stage: :func:`extract` with the output's settings."""
    options = {"sharp": output.sharp, "keep_faces": output.keep_faces, "adaptivity": output.adaptivity}
    return extract(field, surface, seams=seams, **options)


def _written_notes(context, field, obj, output: Output) -> list:
    """What the write stage tells the user: the debug volume's warnings where one is asked, and a device fallen back
    from (no usable GPU)."""
    notes = debug_volume(context, field, obj, output) if output.debug_volume else []
    return notes + ([found] if (found := runtime.device_fallback(context)) else [])


def _refined(steps, count: int, output: Output) -> list:
    """Per operand how its field is built if missing: on demand (``"auto"``) where only a boolean along its seams
    reads it (kept faces), else whole (a union of cutters reads all of theirs: refined on demand, every bore of a
    plate minus 100 bores cost 0.2 s more in the unions than built whole)."""
    whole = plan.read_whole(steps) if output.keep_faces else set(range(count))
    return ["all" if k in whole else "auto" for k in range(count)]


def combined(steps, fields, output: Output, seams, progress):
    """``(field, surface)``: the plan ``steps`` evaluated over ``fields``, or the result cache's entry of the same
    steps over the same fields (placements included) with the same surface settings."""
    fingerprint = tuple((id(f.codes), f.field_ids, _matrix_bytes(f)) for f in fields)
    key = (steps, fingerprint, output.sharp, output.keep_faces, output.adaptivity, _seams_key(seams))
    found = cache.find_result(key)
    if found is not None:
        return found
    field = plan.evaluate(steps, fields, progress, seams=output.keep_faces)
    cache.recount()  # fields built on demand grow as booleans refine them
    return field, cache.store_result(key, fields, field)


def debug_volume(context, field, obj, output: Output) -> list:
    """Add ``field``'s debug volume beside the result ``obj``: the warnings (a volume too large for memory is left
    out; the result stays)."""
    from . import debug

    warnings = []
    try:
        debug.add_debug_objects(context, field, obj.name)
    except runtime.engine().AasdfError as err:
        warnings.append(f"No debug volume: {err}")
    if output.select:
        context.view_layer.objects.active = obj
    return warnings


def _hide_inputs(objects, output: Output) -> None:
    if output.hide_inputs:
        for operand in objects:
            operand.hide_set(True)


def result_key(context, read, inputs, steps, settings: FieldSettings, voxel_size: float, output: Output):
    """The key of everything the run's result depends on (``unchanged.inputs_key``) when the output reuses results,
    else None."""
    if not output.reuse or output.debug_volume:
        return None
    options = {"voxel_size": voxel_size, "levels": settings.levels, "padding": settings.padding}
    options["device"] = runtime.device(context)
    thickness = [item.thickness for item in inputs]
    return unchanged.inputs_key(
        read, thickness, steps, options, sharp=output.sharp, keep_faces=output.keep_faces, adaptivity=output.adaptivity
    )


def _written(context, result: dict, output: Output, keyed, field, progress):
    """The result object written (remembered as showing ``keyed`` inputs), with the debug volume's step told."""
    progress.step("writing the result")
    obj = write(context, result, output)
    if keyed is not None:
        unchanged.remember(obj, keyed)
    if output.debug_volume:
        progress.step("writing the debug volume")
    return obj


def _record(
    timer, obj, voxel_size, source, operation, count, *, field=None, warnings=(), counts=None, cache_delta=None
):
    """The numbers of a run, kept in ``last_run``; with no ``field``, those of a run that found ``obj`` current
    (``"unchanged": True``: nothing built, combined, extracted or written; its counts are the object's)."""
    if counts is None:
        mesh = obj.data  # triangles: as many as Blender's triangulation of its faces
        counts = (len(mesh.vertices), len(mesh.loops) - 2 * len(mesh.polygons), len(mesh.polygons))
    hits, builds = cache_delta or (0, 0)
    last_run.clear()
    last_run.update(
        seconds=timer.seconds,
        stages=dict(timer.stages),
        nodes=field.node_count if field is not None else 0,
        level_counts=field.level_counts if field is not None else [],
        vertices=counts[0],
        triangles=counts[1],
        faces=counts[2],
        cache_hits=hits,
        fields_built=builds,
        voxel_size=voxel_size,
        object=obj.name,
        source=source,
        operation=operation,
        operands=count,
        warnings=list(warnings),
        unchanged=field is None,
    )
    return dict(last_run)


def object_field(context, obj, settings: FieldSettings):
    """One object's field (read → key → cache → build), for views of a single field (``aasdf.debug_volume``).

    Raises:
        AasdfError: As ``operand_fields``.
    """
    read = read_checked([plan.Input(obj)], Output(obj.name), context.evaluated_depsgraph_get())
    return operand_fields(context, read, settings, voxel_size_for(read, settings))[0]
