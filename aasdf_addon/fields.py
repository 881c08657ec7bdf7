"""The fields of a run's operands (the key, cache and build stages): each operand's field from the cache, placed where
its object is, or built, the missing ones at the same time."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from . import bridge, cache, novolume, placement, runtime

if TYPE_CHECKING:
    from .pipeline import FieldSettings


def operand_fields(
    context, operands, settings: FieldSettings, voxel_size: float, progress=None, thickness=None, refine="all"
) -> list:
    """Key → cache → build for read operands (``bridge.read_operands``): one field per operand, operand ``k``'s
    with ``field_id`` k, placed where its object is. A cached field of the same geometry and settings (the object's
    own, or a duplicate's) is placed by the rigid motion and uniform scale from where it was built; what is missing
    is checked together first and built at the same time, one field per distinct geometry. ``thickness`` (one per
    operand, default 0) gives an operand whose surface encloses no volume (a plane, a sheet) a wall that thick,
    centred on it; operands that enclose a volume stay as they are. ``refine`` (one value, or one per operand):
    ``"auto"`` builds a new field's finest level where a boolean reads it where that saves time
    (``engine.build_field``'s; a cached field serves either way).

    Raises:
        AasdfError: From the engine, its message naming the object; or naming an operand that encloses no volume.
    """
    wanted = [0.0] * len(operands) if thickness is None else [float(t) for t in thickness]
    refine = [refine] * len(operands) if isinstance(refine, str) else list(refine)
    placed = _placed_fields(context, operands, settings, voxel_size, progress, [0.0] * len(operands), refine)
    flat = [k for k, field in enumerate(placed) if not field.encloses_volume and wanted[k] > 0.0]
    if flat:  # a second field, with the wall, for each surface that encloses nothing
        walls = [wanted[k] for k in flat]
        asked = [refine[k] for k in flat]
        thick = _placed_fields(context, [operands[k] for k in flat], settings, voxel_size, progress, walls, asked)
        for k, field in zip(flat, thick, strict=True):
            placed[k] = field
    for k, field in enumerate(placed):
        if not field.encloses_volume:
            raise runtime.engine().AasdfError(novolume.reason(operands[k], voxel_size))
    return [field.relabel(k) for k, field in enumerate(placed)]


def _placed_fields(context, operands, settings: FieldSettings, voxel_size: float, progress, thickness, refine) -> list:
    """One field per operand, each with the wall ``thickness[k]`` (0: none), from the cache or built (as
    ``refine[k]`` asks); placed."""
    device = runtime.device(context)
    options = {"voxel_size": voxel_size, "levels": settings.levels, "padding": settings.padding}
    placed = [None] * len(operands)
    missing = {}  # key -> (the matrix to build it under, the operands that need it)
    for k, operand in enumerate(operands):
        key = cache.geometry_key(operand.verts, operand.tris, **options, thickness=thickness[k], device=device)
        key, build, found = placement.field_key(key, operand.matrix, missing)
        cache.note_object(operand.uid, key)
        if found is None:
            missing.setdefault(key, (build, []))[1].append(k)
        else:
            placed[k] = found[0].transformed(placement.placement(operand.matrix, found[1]))
    if missing:
        runtime.prepare_kernels(device, progress.compiling if progress is not None else None)
        if progress is not None:
            names = ", ".join(operands[ks[0]].name for _build, ks in missing.values())
            progress.step(f"building the fields of {names}")
        built = _build(operands, list(missing.values()), options, (thickness, refine), device)
        limit = cache.limit_bytes(context)
        for (key, (build, ks)), field in zip(missing.items(), built, strict=True):
            cache.store(key, field, build, limit)
            for k in ks:
                same = np.array_equal(operands[k].matrix, build)
                placed[k] = field if same else field.transformed(placement.placement(operands[k].matrix, build))
    return placed


def _build(operands, wanted, options, asked, device) -> list:
    """Build one field per ``(matrix, operand indices)`` of ``wanted``: the first operand's geometry placed by that
    matrix, checked and built together, a group per thickness (``asked``: per operand its thickness and how it is
    refined; whole where one of the operands sharing the field asks for it whole).

    Raises:
        AasdfError: From the engine, naming the object instead of the engine's "Mesh <j>".
    """
    engine = runtime.engine()
    thickness, refine = asked
    built = [None] * len(wanted)
    by_thickness = {}
    for j, (_matrix, ks) in enumerate(wanted):
        by_thickness.setdefault(thickness[ks[0]], []).append(j)
    try:
        for wall, js in by_thickness.items():
            meshes = [
                bridge.to_world(operands[wanted[j][1][0]].verts, operands[wanted[j][1][0]].tris, wanted[j][0])
                for j in js
            ]
            extra = {"thickness": wall} if wall > 0.0 else {}
            extra["refine"] = ["all" if any(refine[k] == "all" for k in wanted[j][1]) else "auto" for j in js]
            for j, field in zip(js, engine.build_fields(meshes, **options, **extra, device=device), strict=True):
                built[j] = field
    except engine.AasdfError as err:
        message = str(err)
        if message.startswith("Mesh "):  # "Mesh <i>: ..." counts the meshes of a group: name the object instead
            head, _, rest = message.partition(": ")
            message = f"{operands[wanted[js[int(head.split()[1])]][1][0]].name}: {rest}"
        raise engine.AasdfError(message) from err
    return built
