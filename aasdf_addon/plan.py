"""What a run computes from its operands' fields: a plan, and the combine stage that evaluates it.

A plan is nested tuples over the operands (operand ``k`` is field ``k``):

- ``("field", k)``: operand ``k``'s field;
- ``("boolean", operation, blend, blend_mode, [children])``: ``UNION`` / ``INTERSECT`` of all children, or
  ``DIFFERENCE``, the first minus the union of the others (that union is sharp; ``blend`` shapes the final cut), as
  balanced binary trees of the engine's booleans;
- ``("offset", distance, child)``: the child's surface moved by ``distance`` (outwards when positive);
- ``("shell", thickness, side, child)``: a wall ``thickness`` thick on ``side`` (``INSIDE``, ``OUTSIDE``,
  ``CENTER``) of the child's surface.

``aasdf.boolean`` and ``aasdf.offset`` / ``aasdf.shell`` make one-node plans; a CSG tree makes any plan
(``aasdf_addon.csg``). Plans are plain tuples, so equal plans over equal fields are the same result (the cache's).
"""

import math
from dataclasses import dataclass

import numpy as np

from . import runtime

OPERATIONS = ("UNION", "INTERSECT", "DIFFERENCE")
_ENGINE_OPS = {"UNION": "union", "INTERSECT": "intersection", "DIFFERENCE": "difference"}


@dataclass(frozen=True)
class Input:
    """One operand of a plan: a mesh object, and the thickness its surface is given (0: as it is)."""

    obj: object
    thickness: float = 0.0


def boolean_plan(operation: str, count: int, blend: float = 0.0, blend_mode: str = "ROUND") -> tuple:
    """The plan of ``aasdf.boolean`` over ``count`` operands."""
    if operation not in OPERATIONS:
        raise ValueError(f"Expected 'operation' in {OPERATIONS}, but got {operation!r}.")
    return ("boolean", operation, float(blend), blend_mode, [("field", k) for k in range(count)])


def check_numbers(plan: tuple) -> None:
    """Refuse, before any work, a plan whose numbers the engine would refuse halfway (a script can set a property to
    NaN or infinity, which Blender keeps as its largest float): blends of 0 or more, finite offsets, walls above 0.

    Raises:
        AasdfError: Naming the setting and its value.
    """
    kind = plan[0]
    if kind == "field":
        return
    value = float(plan[2] if kind == "boolean" else plan[1])
    name, fine, rule = {
        "offset": ("Distance", math.isfinite(value), "a finite number"),
        "shell": ("Wall", math.isfinite(value) and value > 0.0, "a finite number above 0"),
        "boolean": ("Blend", math.isfinite(value) and value >= 0.0, "a finite number of 0 or more"),
    }[kind]
    if not fine:
        raise runtime.engine().AasdfError(f"The {name} must be {rule}, not {value}")
    for child in plan[4] if kind == "boolean" else [plan[-1]]:
        check_numbers(child)


def check_reach(plan: tuple, lo, hi, voxel: float) -> None:
    """Refuse, before any field is read or built, a plan whose blends, offsets and walls grow the operands' box
    (``lo``, ``hi``) past the finest cells the octree addresses at ``voxel``, or whose box lies so far from the world
    origin that float32 positions cannot resolve the voxels (the engine refuses both too, but only once the fields
    are there). The growth counted is the least the engine's domains take, so nothing it accepts is refused.

    Walls thinner than two voxels are refused as well.

    Raises:
        AasdfError: Naming the setting that grows the box most, and its value; or how far the box lies; or a wall
            too thin and the least one.
    """
    for wall in _walls(plan):  # (named as the setting is: the engine's says "thickness")
        runtime.engine().plan.checked_wall("Wall", wall, voxel)
    grown, name, value = _growth(plan)
    span = (max(float(top - low) for low, top in zip(lo, hi, strict=True)) + 2.0 * grown) / voxel
    cells = runtime.engine().octree.MAX_CELLS_PER_AXIS - 1
    if grown > 0.0 and not span < cells:
        raise runtime.engine().AasdfError(
            f"The {name} of {value:g} needs a domain of {span:.4g} finest cells along an axis, more than the {cells} "
            f"the octree can address; use a smaller {name} or a larger voxel size"
        )
    lo, hi = np.asarray(lo, np.float64) - grown, np.asarray(hi, np.float64) + grown
    # where the same box about the origin would be resolved (else the voxel is too fine anywhere: the fields' memory
    # check says so, naming the object)
    engine = runtime.engine()
    if float(np.spacing(np.float32(np.max(hi - lo)))) * engine.plan.MIN_ULPS_PER_CELL <= voxel:
        engine.check_resolvable(lo, hi, voxel)


def result_box(plan: tuple, boxes: list):
    """(lo, hi) world box a plan's result lies in, from its operands' ``boxes`` ((lo, hi) each): a union's holds its
    children's, an intersection's is theirs in common, a difference's is its first child's; grown by what blends,
    offsets and walls may add (:func:`_growth`). None where an intersection's children share no box (an empty
    result)."""
    box = _box(plan, boxes)
    if box is None:
        return None
    grown = _growth(plan)[0]
    return np.asarray(box[0], np.float64) - grown, np.asarray(box[1], np.float64) + grown


def _box(plan: tuple, boxes: list):
    kind = plan[0]
    if kind == "field":
        return boxes[plan[1]]
    if kind != "boolean":
        return _box(plan[-1], boxes)
    found = [_box(child, boxes) for child in plan[4]]
    if plan[1] == "DIFFERENCE":
        return found[0]
    if plan[1] == "UNION":
        found = [box for box in found if box is not None]
        return (np.min([b[0] for b in found], axis=0), np.max([b[1] for b in found], axis=0)) if found else None
    if any(box is None for box in found):
        return None
    lo, hi = np.max([b[0] for b in found], axis=0), np.min([b[1] for b in found], axis=0)
    return (lo, hi) if (hi >= lo).all() else None


def _walls(plan: tuple) -> list:
    """The walls of a plan's shells."""
    if plan[0] == "field":
        return []
    below = [w for child in (plan[4] if plan[0] == "boolean" else [plan[-1]]) for w in _walls(child)]
    return below + ([float(plan[1])] if plan[0] == "shell" else [])


def _growth(plan: tuple) -> tuple[float, str, float]:
    """(how far a plan's result may reach past its operands, the setting that adds most, its value)."""
    kind = plan[0]
    if kind == "field":
        return 0.0, "", 0.0
    if kind == "boolean":
        below = max((_growth(child) for child in plan[4]), key=lambda found: found[0])
        own = plan[2] * (0.5 if plan[3] == "CHAMFER" else 0.25)  # (as the engine's boolean grows its domain)
        return below[0] + own, *(below[1:] if below[0] > own else ("Blend", plan[2]))
    below = _growth(plan[-1])
    if kind == "offset":
        own, name = max(plan[1], 0.0), "Distance"
    else:
        own, name = {"OUTSIDE": 1.0, "CENTER": 0.5}.get(plan[2], 0.0) * plan[1], "Wall"
    return below[0] + own, *(below[1:] if below[0] > own else (name, plan[1]))


def evaluate(plan: tuple, fields: list, progress=None, *, seams: bool = False):
    """The field of a plan over ``fields`` (the combine stage). ``seams``: its last boolean made along its seams
    (the engine's ``seams``: for kept faces; the booleans under it whole, as the last one reads them).

    Raises:
        AasdfError: From the engine (an offset past the octree's reach, a wall too thin for the voxels).
    """
    kind = plan[0]
    if kind == "field":
        return fields[plan[1]]
    engine = runtime.engine()
    if kind == "offset":
        result = engine.offset(evaluate(plan[2], fields, progress), plan[1])
        _step(progress, "offsetting")
        return result
    if kind == "shell":
        result = engine.shell(evaluate(plan[3], fields, progress), plan[1], side=plan[2].lower())
        _step(progress, "hollowing")
        return result
    _, operation, blend, mode, children = plan
    items = [evaluate(child, fields, progress) for child in children]
    # every field is built at the voxel size asked, one placed at another scale resampled at it (``spacing``): at a
    # placed one's finer spacing, every other would be resampled, losing its sharp edges by up to 0.3 voxel
    options = {"blend": blend, "blend_mode": mode.lower(), "spacing": "built"}
    if operation == "DIFFERENCE" and len(items) > 1:
        cutter = _fold(engine.union, items[1:], {"blend": 0.0, "spacing": "built"}, progress)
        result = engine.difference(items[0], cutter, **options, seams=seams)
        _step(progress, "combining fields")
        return result
    return _fold(getattr(engine, _ENGINE_OPS[operation]), items, options, progress, seams)


def read_whole(plan: tuple) -> set:
    """The operands (field indices) a plan's booleans read whole: every one but the operands its last boolean reads
    directly, which that boolean (made along its seams, for kept faces) reads only about them; a union of cutters, an
    offset or a shell reads its operands' whole surface (their fields are best built whole, not refined on demand)."""
    kind = plan[0]
    if kind == "field":
        return set()
    if kind != "boolean":
        return _fields(plan)
    children = plan[4]
    if plan[1] == "DIFFERENCE" and len(children) > 2:  # the first minus the cutters' union
        direct = [0]
    else:
        direct = list(range(len(children)))
        while len(direct) > 2:  # the pairs :func:`_fold` makes, level by level; an odd one out goes up a level
            direct = [None if i + 1 < len(direct) else direct[i] for i in range(0, len(direct), 2)]
    whole = set()
    for k, child in enumerate(children):
        whole |= _fields(child) if k not in direct or child[0] != "field" else set()
    return whole


def _fields(plan: tuple) -> set:
    """Every operand (field index) in ``plan``."""
    if plan[0] == "field":
        return {plan[1]}
    return set().union(*(_fields(child) for child in (plan[4] if plan[0] == "boolean" else [plan[-1]])))


def _fold(op, items, options, progress, seams: bool = False):
    """``items`` combined pairwise, level by level: a balanced binary tree of ``op`` (the last one with ``seams``)."""
    items = list(items)
    while len(items) > 1:
        paired = []
        for i in range(0, len(items) - 1, 2):
            last = len(items) == 2
            paired.append(op(items[i], items[i + 1], **options, seams=seams and last))
            _step(progress, "combining fields")
        if len(items) % 2:
            paired.append(items[-1])
        items = paired
    return items[0]


def _step(progress, text):
    if progress is not None:
        progress.step(text)
