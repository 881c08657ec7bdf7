"""Object transforms checked before any work: a world matrix that is not finite (NaN or infinity from a driver) or
that has no inverse (a scale of 0 on an axis, a parent flattening its child) cannot place a field.

``check_operands`` runs on the operands ``bridge`` read, before a voxel size is chosen or a field built: a matrix
that is not finite, or that squashes its object onto a line or a point, is refused with a sentence naming the object
and saying what to do. A matrix that flattens its object onto a plane is refused the same way unless the operand has
a thickness: then its evaluated geometry is moved to world space (a flat sheet, the identity its matrix) and goes the
way a plane does, given a wall that thick. ``check_target`` refuses a result object that could not receive a mesh.
"""

from dataclasses import replace

import numpy as np

from . import runtime

AXES = "XYZ"
# A singular value below this fraction of the largest counts as zero: a scale of 1e-7 flattens as a scale of 0 does.
FLAT_RATIO = 1e-6


def invertible(matrix) -> bool:
    """Whether a (4, 4) matrix is finite and its 3x3 part keeps all three dimensions (``FLAT_RATIO``)."""
    matrix = np.asarray(matrix, dtype=np.float64)
    if not np.all(np.isfinite(matrix)):
        return False
    values = np.linalg.svd(matrix[:3, :3], compute_uv=False)
    return bool(values[0] > 0.0 and values[2] > FLAT_RATIO * values[0])


def problem(name: str, matrix) -> tuple[str, bool] | None:
    """What is wrong with an object's world matrix, as ``(sentence, a thickness would fix it)``; None when nothing."""
    matrix = np.asarray(matrix, dtype=np.float64)
    if not np.all(np.isfinite(matrix)):
        return (
            f"'{name}' has a transform that is not a number (NaN or infinite, from a driver or a parent): "
            "give it a finite location, rotation and scale",
            False,
        )
    if invertible(matrix):
        return None
    linear = matrix[:3, :3]
    values = np.linalg.svd(linear, compute_uv=False)
    rank = int(np.sum(values > FLAT_RATIO * max(values[0], 1e-300)))
    lengths = np.linalg.norm(linear, axis=0)  # the scale along each local axis, parents included
    zero = [AXES[j] for j in range(3) if not lengths[j] > FLAT_RATIO * max(lengths.max(), 1e-300)]
    if zero:
        cause = f"its scale is 0 along {' and '.join(zero) if len(zero) < 3 else 'X, Y and Z'}"
    else:
        cause = "its transform (with its parents') squashes it"
    if rank == 2:
        return f"'{name}' is flat: {cause}; give it a thickness or a non-zero scale", True
    return f"'{name}' has no volume and no area: {cause}; give it a non-zero scale", False


def check_operands(operands, thickness) -> list:
    """The operands with their transforms checked: those flattened onto a plane that have a thickness moved to world
    space (vertices in world space, the identity as matrix), the others as they are.

    Args:
        operands: ``bridge.Operand`` list, as read.
        thickness: One wall thickness per operand (0: none).
    Returns:
        A list of operands, the same objects unless moved to world space (the read ones are not changed).
    Raises:
        AasdfError: Naming each object whose transform cannot be used, and what to do.
    """
    checked, refused = [], []
    for operand, wall in zip(operands, thickness, strict=True):
        found = problem(operand.name, operand.matrix)
        if found is None:
            checked.append(operand)
        elif found[1] and wall > 0.0:
            checked.append(flattened(operand))
        else:
            refused.append(found[0])
    if refused:
        raise runtime.engine().AasdfError("; ".join(refused))
    return checked


def flattened(operand):
    """A copy of ``operand`` whose vertices are in world space and whose matrix is the identity."""
    verts, tris = operand.world()
    return replace(operand, verts=verts, tris=tris, matrix=np.eye(4))


def check_target(obj) -> None:
    """Refuse an existing result object whose transform cannot take world-space vertices back to its own space.

    Raises:
        AasdfError: Naming the object and what to do.
    """
    if obj is None:
        return
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    if not invertible(matrix):
        sentence = problem(obj.name, matrix)[0].split(";")[0].split(": give")[0]
        raise runtime.engine().AasdfError(
            f"{sentence}: it receives the result, give it a finite, non-zero scale or choose another result name"
        )
