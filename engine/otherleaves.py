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
# bounding box (:class:`NearRows`).
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


class NearRows:
    """The rows of a judge's samples each other leaf must be read at: all, but for a closed clean mesh's leaf (no
    jumps) only those within a pad of its mesh's bounding box. Farther out its surface is farther than the pad and its
    field outside it (positive), whatever it reads there: a row of coplanar cubes' judge reads each cube's samples in
    its neighbours' fields alone, a plate's judge each of 36 bores' fields about the bore alone. The samples are
    sorted along x once a set (:meth:`index`), and each box finds its rows in that order by two binary searches."""

    def __init__(self, bvhs: list, jumps: list):
        self.bvhs, self.jumps, self.boxes = bvhs, jumps, {}

    @staticmethod
    def index(points: np.ndarray) -> dict:
        """``points`` to find rows of (sorted when first needed)."""
        return {"points": points}

    def rows(self, j: int, indexed: dict, pad: float) -> np.ndarray:
        """The rows of the :meth:`index`-ed points leaf ``j`` must be read at (sorted)."""
        points = indexed["points"]
        if self.bvhs[j] is None or self.jumps[j] is not None:
            return np.arange(len(points))
        if j not in self.boxes:
            corners = self.bvhs[j].points.numpy()
            self.boxes[j] = (corners.min(axis=0), corners.max(axis=0))
        if "order" not in indexed:
            indexed["order"] = np.argsort(points[:, 0], kind="stable")
            indexed["x"] = points[indexed["order"], 0]
        lo, hi = self.boxes[j]
        start = np.searchsorted(indexed["x"], lo[0] - pad, side="left")
        end = np.searchsorted(indexed["x"], hi[0] + pad, side="right")
        rows = indexed["order"][start:end]
        yz = points[rows, 1:]
        return np.sort(rows[((yz >= lo[1:] - pad) & (yz <= hi[1:] + pad)).all(axis=1)])
