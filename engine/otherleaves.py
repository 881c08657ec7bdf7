"""What the other operands of a boolean say at the kept faces' judge's samples (:mod:`.keep`): whether an operand is a
mesh with faces to keep, its BVH (its distances read off its mesh, exactly), where its field may jump (an open
mesh's, across its holes: :mod:`.jumps`), and per sample how far its surface is and its sign there.
"""

from __future__ import annotations

import numpy as np

from .defects import AXES
from .jumps import JumpSpheres, jump_spheres
from .sources import mesh_distances

# A closed clean mesh's leaf is read only at samples within the judge's reach and this many voxels more of its mesh's
# bounding box (:func:`near_rows`).
NEAR_BOX_VOXELS = 2.0


def mesh_leaf(field) -> bool:
    """Whether a leaf field's surface is its source mesh's triangles (a field built from a mesh that encloses a
    volume, without a thickness): only such leaves have faces to keep."""
    stats = field.stats
    return (
        "clean_mesh" in stats
        and stats.get("thickness") is None
        and not stats.get("flat", False)
        and len(field.sources) == 1
    )


def leaf_bvh(field, device):
    """The BVH of a mesh leaf's triangles where the leaf is placed (None for any other leaf): its distances are read
    off its mesh, exactly (its field's values are those distances, interpolated; an open mesh's sign may also jump
    away from them, where :func:`leaf_jumps` says)."""
    if not mesh_leaf(field):
        return None
    return next(iter(field.world_sources().values())).bvh(device)


def leaf_values(field, bvh, points: np.ndarray, reach: float, device, distance=None) -> np.ndarray:
    """(N,) float32 how far the leaf's surface is from each point (up to ``reach``), negative inside it: from its
    mesh's ``bvh`` (:func:`leaf_bvh`) where it has one (or the unsigned ``distance`` given), else from its field."""
    values = field.sample(points, method="linear")  # a tenth of MLS's time: signs, and distances within the slack
    if bvh is None:
        return np.clip(values, -reach, reach).astype(np.float32)
    distance = mesh_distances(bvh, points, reach, device) if distance is None else distance
    return np.copysign(distance, values).astype(np.float32)


def leaf_jumps(field, device):
    """Where a leaf's field may jump (:mod:`.jumps`): None for a field that does not (a clean mesh's, a continuous
    one), else the spheres about its mesh's defect edges (a leaf without a mesh: anywhere)."""
    if field.stats.get("continuous", field.stats.get("clean_mesh", False)):
        return None
    if not mesh_leaf(field):
        return JumpSpheres(None, device)
    return JumpSpheres(jump_spheres(next(iter(field.world_sources().values()))), device)


def leaf_margin(field, bvh, jumps, points, band: float, reach: float, device, distance=None) -> tuple:
    """Per sample: how far the leaf's surface is (up to ``reach``; or ``distance``), and the leaf's sign there. A
    field with jumps (an open mesh's, across its holes; :func:`leaf_jumps`) counts as near (0) wherever its sign
    changes a band away along an axis, read near its defects, and where its value (read off its field) is below two
    bands."""
    values = leaf_values(field, bvh, points, reach, device, distance)
    margin = np.abs(values)
    if jumps is not None:
        rows = np.flatnonzero(margin > band)  # (a value read off the field overstates a distance a little)
        rows = rows[((margin[rows] < 2.0 * band) & (bvh is None)) | jumps.near(points[rows], 2.0 * band)]
        around = (points[rows][:, None, :] + band * AXES[None]).reshape(-1, 3)
        signs = np.sign(field.sample(around, method="linear")).reshape(-1, 6)
        margin[rows[~(signs == np.sign(values[rows])[:, None]).all(axis=1)]] = 0.0
    return margin, np.sign(values).astype(np.int8)


def near_rows(bvh, jumps, points: np.ndarray, pad: float, boxes: dict, key) -> np.ndarray:
    """The rows of ``points`` a leaf (its :func:`leaf_bvh` and :func:`leaf_jumps`) must be read at: all, but for a
    closed clean mesh's leaf only those within ``pad`` of its mesh's bounding box (kept in ``boxes`` under ``key``).
    Farther out its surface is farther than the pad and its field outside it (positive), whatever it reads there: a
    row of coplanar cubes' judge reads each cube's samples in its neighbours' fields alone, not in every cube's."""
    if bvh is None or jumps is not None:
        return np.arange(len(points))
    if key not in boxes:
        corners = bvh.points.numpy()
        boxes[key] = (corners.min(axis=0), corners.max(axis=0))
    lo, hi = boxes[key]
    return np.flatnonzero(((points >= lo - pad) & (points <= hi + pad)).all(axis=1))
