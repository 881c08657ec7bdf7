"""What a result's faces carry over from the operands they came from: material, shading, UV maps, colours.

Every result face has a source: the operand whose value decides there, the triangle of that operand's mesh closest to
the face's centre and, for each of the face's three corners, its barycentric coordinates on that same triangle
(``AdaptiveField.closest_sources`` / ``source_barycentrics``). A corner reads the source triangle of its face, never
another one, so the source's seams (UV islands, colour borders) stay seams. Arrays only: ``bridge`` reads the
operands' attributes from Blender and writes the result's.
"""

import numpy as np

from . import runtime

# The integer face attribute naming the operand each result face came from (its index among the operands).
OPERAND_ATTRIBUTE = "aasdf_operand"


def merged_materials(operands) -> tuple[list, list]:
    """The result's material slots: every operand's slots' materials once, in order (``None`` for an empty slot,
    and one empty slot when some operand has no material while others do). Returns the slots and, per operand, the
    (S,) int32 result slot of each of its own slots."""
    materials = []
    for operand in operands:
        for material in operand.materials:
            if material is not None and material not in materials:
                materials.append(material)
    if materials and any(not operand.materials or None in operand.materials for operand in operands):
        materials.append(None)
    slot_maps = []
    for operand in operands:
        own = operand.materials or [None]
        slot_maps.append(np.array([materials.index(m) if m in materials else 0 for m in own], dtype=np.int32))
    return materials, slot_maps


def face_attributes(operands, field_ids, triangle_ids, corner_bary) -> dict:
    """The attributes of F result faces from their sources.

    Args:
        operands: ``bridge.Operand`` per field id (field id k is ``operands[k]``).
        field_ids: (F,) int the operand of each face.
        triangle_ids: (F,) int its source triangle among that operand's ``tris`` (-1: none found).
        corner_bary: (F, 3, 3) float barycentric coordinates of each face's corners on that triangle.
    Returns:
        ``{"materials": slots, "material_index": (F,) int32, "smooth": (F,) bool, "operand": (F,) int32,
        "uv_maps": {name: (3F, 2) float32 per corner}, "colors": {name: (data type, (3F, 4) float32 per corner)},
        "shown": the base operand's rendered and active UV map and colour names (``bridge.Operand.shown``)}``.
        An operand without a UV map or colour attribute some other has gives zeros there.
    """
    field_ids = np.asarray(field_ids, dtype=np.int64)
    triangle_ids = np.asarray(triangle_ids, dtype=np.int64)
    corner_bary = np.ascontiguousarray(corner_bary, dtype=np.float32).reshape(-1, 3, 3)
    count = len(field_ids)
    materials, slot_maps = merged_materials(operands)
    out = {
        "materials": materials,
        "material_index": np.zeros(count, dtype=np.int32),
        "smooth": np.zeros(count, dtype=bool),
        "operand": field_ids.astype(np.int32),
        "uv_maps": {},
        "colors": {},
    }
    # the operands' triangles stacked one after the other: each face reads its source in one gather, whichever
    # operand it came from (no rows selected and scattered back per operand)
    first = np.cumsum([0] + [len(operand.tris) for operand in operands])
    has = (field_ids >= 0) & (field_ids < len(operands)) & (triangle_ids >= 0)
    # in the operands' own order, the base's first (its first map the one Blender shows first); which are rendered
    # and active, as the first operand with such a map has them (name order made the render map another)
    uv_names = list(dict.fromkeys(name for operand in operands for name in operand.uv_maps))
    color_names = list(dict.fromkeys(name for operand in operands for name in operand.colors))
    out["shown"] = next((op.shown for op in operands if op.uv_maps or op.colors), {})
    if has.any():
        stacked = np.where(has, first[np.where(has, field_ids, 0)] + triangle_ids, 0)
        weights = corner_bary if has.all() else np.where(has[:, None, None], corner_bary, np.float32(0.0))
        slot = np.concatenate(
            [
                slots[np.clip(operand.face_material[operand.faces], 0, len(slots) - 1)]
                for operand, slots in zip(operands, slot_maps, strict=True)
            ]
        )
        smooth = np.concatenate([operand.face_smooth[operand.faces] for operand in operands])
        out["material_index"] = np.where(has, slot[stacked], 0).astype(np.int32)
        out["smooth"] = np.where(has, smooth[stacked], False)

    def interpolated(parts, width, held=False):
        if not has.any():  # no face has a source (nor, maybe, any operand a triangle to gather from)
            return np.zeros((3 * count, width), dtype=np.float32)
        return _interpolate(parts, width, stacked, weights, held)

    for name in uv_names:  # (extrapolated past the source triangle's corners: a UV layout goes on linearly)
        out["uv_maps"][name] = interpolated([(operand.corners, operand.uv_maps.get(name)) for operand in operands], 2)
    for name in color_names:
        parts = []
        for operand in operands:
            domain, _kind, values = operand.colors.get(name, ("CORNER", None, None))
            parts.append((operand.corners if domain == "CORNER" else operand.tris, values))
        out["colors"][name] = (_color_kind(operands, name), interpolated(parts, 4, held=True))
    return out


def within_sources(found, values) -> np.ndarray:
    """(3F, W) ``found`` corner values held within the range of the operands' ``values`` (N, W): a new face's corner
    outside its source triangle reads them extrapolated (weights from -1.1 to 2 measured), which follows a smooth
    field beyond the triangle but can pass what the sources hold (a colour painted in [-2, 5] read 7.4, a crease
    weight in [0, 1] -0.42). (Held within each source triangle's own corners instead, a ball's colours read off its
    closest points 0.0086 apart at the 95th percentile, against 1/255.)"""
    if not len(values):
        return found
    low, high = values.min(axis=0), values.max(axis=0)
    return np.clip(found.reshape(len(found), -1), low, high).reshape(found.shape)


def stacked_parts(parts, width: int, dtype=np.float32) -> tuple[np.ndarray, np.ndarray]:
    """``(values (N, width), rows (T, 3) int64)``: per operand ``(corners, values)`` (its triangles' indices into its
    values, or values None: one zero row, which all its triangles' corners read) stacked as the kernel reads them."""
    values, index, offset = [], [], 0
    for corners, own in parts:
        if own is None:
            own, corners = np.zeros((1, width), dtype), np.zeros_like(corners)
        values.append(np.asarray(own, dtype=dtype).reshape(-1, width))
        index.append(np.asarray(corners, dtype=np.int64) + offset)
        offset += len(values[-1])
    return np.concatenate(values), np.concatenate(index)


def _color_kind(operands, name) -> str:
    """The result's data type of colour attribute ``name``: float when any operand's is."""
    kinds = {operand.colors[name][1] for operand in operands if name in operand.colors}
    return "FLOAT_COLOR" if "FLOAT_COLOR" in kinds else "BYTE_COLOR"


def _interpolate(parts, width, stacked, weights, held: bool = False) -> np.ndarray:
    """One attribute at the result's corners: ``parts`` per operand (:func:`stacked_parts`), stacked as the
    triangles are; each face's corners weighted by (F, 3, 3) ``weights`` on its stacked source triangle ``stacked``:
    (3F, ``width``) float32, from the engine's kernel; ``held`` within the operands' range (:func:`within_sources`)."""
    values, index = stacked_parts(parts, width)
    found = runtime.engine().interpolate_corners(values, index.astype(np.int32), stacked, weights)
    return within_sources(found, values) if held else found
