"""Why an operand's field has no inside, in a sentence: it is smaller than two voxels (no node lies inside it), a
surface that encloses nothing, or closed but thinner than two voxels (as a whole, or in its walls)."""

import numpy as np

from . import runtime

FINER = "set a smaller Voxel Size or a higher Resolution"


def reason(operand, voxel_size: float) -> str:
    """The sentence refusing ``operand`` (a ``bridge.Operand`` whose field has no inside) at ``voxel_size``."""
    size = _extents(operand)
    if float(size.max()) < 2.0 * voxel_size:
        return (
            f"'{operand.name}' is smaller than two voxels ({float(size.max()):.3g} across, voxels of "
            f"{voxel_size:.3g}): no voxel lies inside it; {FINER}"
        )
    if runtime.engine().surface_edges(operand.tris, len(operand.verts)) is None:  # (not closed)
        return (
            f"'{operand.name}' encloses no volume: give it a thickness or close it (where its walls are thinner than "
            f"two voxels of {voxel_size:.3g}, {FINER})"
        )
    if float(size.min()) < 2.0 * voxel_size:
        return (
            f"'{operand.name}' is thinner than two voxels ({float(size.min()):.3g} thick, voxels of "
            f"{voxel_size:.3g}): no voxel lies inside it; {FINER}, or give it a Thickness"
        )
    return (
        f"'{operand.name}' is closed, but no voxel lies inside it: its walls are thinner than two voxels of "
        f"{voxel_size:.3g}; {FINER}"
    )


def _extents(operand) -> np.ndarray:
    """(3,) the operand's box in its own space, each side as long as its object's transform makes it."""
    if not len(operand.verts):
        return np.zeros(3)
    local = operand.verts.max(axis=0).astype(np.float64) - operand.verts.min(axis=0)
    return local * np.linalg.norm(np.asarray(operand.matrix, dtype=np.float64)[:3, :3], axis=0)
