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
# A mesh leaf's linear value this many of its voxels or more below its mesh's distance (up to a band and the least
# slack) is read again by MLS, for its sign (:func:`signed_again`).
SIGN_CHECK_VOXELS = 0.5


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


def leaf_values(field, bvh, points: np.ndarray, reach: float, device, distance=None, values=None, upto=None):
    """(N,) float32 how far the leaf's surface is from each point (up to ``reach``), negative inside it: from its
    mesh's ``bvh`` (:func:`leaf_bvh`) where it has one (or the unsigned ``distance`` given), else from its field (or
    its linear ``values`` given: :mod:`.leafreads`); with ``upto``, signs read again as :func:`signed_again` does."""
    if values is None:  # a tenth of MLS's time: signs, and distances within the slack
        values = field.sample(points, method="linear")
    if bvh is None:
        return np.clip(values, -reach, reach).astype(np.float32)
    distance = mesh_distances(bvh, points, reach, device) if distance is None else distance
    if upto is not None:
        values = signed_again(field, points, values, distance, upto)
    return np.copysign(distance, values).astype(np.float32)


def signed_again(field, points: np.ndarray, values: np.ndarray, distance: np.ndarray, upto: float) -> np.ndarray:
    """A mesh leaf's linear ``values`` at ``points`` with those more than SIGN_CHECK_VOXELS of its voxels below its
    mesh's ``distance`` there (up to ``upto``: a band and the least slack, within every reading's reach) read again by
    MLS, as the field's own queries read it. Past the finest band a coarse leaf's trilinear values can miss the
    distance by voxels about a crease, sign and all: the rocker arm united with its copy placed 2.56 voxels along x read
    +0.1 to +0.8 voxel 2.5 voxels inside the copy (MLS -2.5, the mesh's distance 2.54), and the judge kept pieces of
    faces inside it, which the join gave up without surface under them (the whole result made and joined again). A
    sign read wrong misses by the distance and the value together; the finest band's linear values, by tenths."""
    below = np.minimum(np.asarray(distance, np.float32), np.float32(upto)) - np.float32(sign_check(field))
    off = np.flatnonzero(np.abs(values) < below)
    if not len(off):
        return values
    values = np.array(values, dtype=np.float32)
    values[off] = field.sample(np.ascontiguousarray(points[off], dtype=np.float32))
    return values


def sign_check(field) -> float:
    """How far (world units) below its mesh's distance a leaf's linear value is read again (SIGN_CHECK_VOXELS)."""
    return SIGN_CHECK_VOXELS * float(field.world_voxel_size)


def leaf_jumps(field, device):
    """Where a leaf's field may jump (:mod:`.jumps`): None for a field that does not (a clean mesh's, a continuous
    one), else the spheres about its mesh's defect edges (a leaf without a mesh: anywhere)."""
    if field.stats.get("continuous", field.stats.get("clean_mesh", False)):
        return None
    if not mesh_leaf(field):
        return JumpSpheres(None, device)
    return JumpSpheres(jump_spheres(next(iter(field.world_sources().values()))), device)


def leaf_margin(
    field, bvh, jumps, points, band: float, reach: float, device, distance=None, values=None, upto=None
) -> tuple:
    """Per sample: how far the leaf's surface is (up to ``reach``; or ``distance``), and the leaf's sign there
    (``values``, ``upto``: :func:`leaf_values`'). A field with jumps (an open mesh's, across its holes;
    :func:`leaf_jumps`) counts as near (0) wherever its sign changes a band away along an axis, read near its defects,
    and where its value (read off its field) is below two bands."""
    values = leaf_values(field, bvh, points, reach, device, distance, values, upto)
    margin = np.abs(values)
    if jumps is not None:
        rows = np.flatnonzero(margin > band)  # (a value read off the field overstates a distance a little)
        rows = rows[((margin[rows] < 2.0 * band) & (bvh is None)) | jumps.near(points[rows], 2.0 * band)]
        around = (points[rows][:, None, :] + band * AXES[None]).reshape(-1, 3)
        signs = np.sign(field.sample(around, method="linear")).reshape(-1, 6)
        margin[rows[~(signs == np.sign(values[rows])[:, None]).all(axis=1)]] = 0.0
    return margin, np.sign(values).astype(np.int8)


def leaf_boxes(leaves: list) -> list:
    """Per leaf the bounding box of its mesh's triangles where placed (:meth:`.sources.SourceMesh.box`, the vertices
    its BVH holds: :func:`leaf_bvh`), ``(low, high)`` float32 (3,) each, or None for a leaf without one."""
    out = []
    for leaf in leaves:
        source = next(iter(leaf.world_sources().values())) if mesh_leaf(leaf) else None
        out.append(None if source is None or not len(source.verts) else source.box())
    return out


def box_arrays(boxes: list) -> tuple[np.ndarray, np.ndarray]:
    """(L, 3) float64 lows and highs of ``boxes`` (:func:`leaf_boxes`; None: everywhere), for :func:`boxes_meet`."""
    lows = np.array([(-np.inf,) * 3 if b is None else b[0] for b in boxes], dtype=np.float64).reshape(-1, 3)
    highs = np.array([(np.inf,) * 3 if b is None else b[1] for b in boxes], dtype=np.float64).reshape(-1, 3)
    return lows, highs


def boxes_meet(boxes, low: np.ndarray, high: np.ndarray, pad: float) -> np.ndarray:
    """(L,) bool the ``boxes`` (:func:`box_arrays`) that come within ``pad`` of the box ``low``-``high``, with a
    relative margin to spare: one test for all leaves before any is read row by row (a plate's judge with 100 bores
    read each bore's rows a round, every bore's judge each of the 100 others')."""
    lows, highs = boxes
    spare = float(pad) + 1e-5 * (float(np.abs(low).max(initial=0.0)) + float(np.abs(high).max(initial=0.0)) + pad)
    return ((lows - spare <= high) & (highs + spare >= low)).all(axis=1)


class NearRows:
    """The rows of a judge's samples each other leaf must be read at: all, but for a closed clean mesh's leaf (no
    jumps) only those within a pad of its mesh's bounding box. Farther out its surface is farther than the pad and its
    field outside it (positive), whatever it reads there: a row of coplanar cubes' judge reads each cube's samples in
    its neighbours' fields alone, a plate's judge each of 36 bores' fields about the bore alone. The samples are
    sorted along x once a set (:meth:`index`), and each box finds its rows in that order by two binary searches;
    :meth:`near` first finds the leaves whose box comes near the samples' at all (``boxes``: :func:`leaf_boxes`)."""

    def __init__(self, bvhs: list, jumps: list, boxes: list):
        self.bvhs, self.jumps = bvhs, jumps
        self.boxes = [None if j is not None else b for b, j in zip(boxes, jumps, strict=True)]
        self.arrays = box_arrays(self.boxes)

    @staticmethod
    def index(points: np.ndarray) -> dict:
        """``points`` to find rows of (sorted when first needed)."""
        return {"points": points}

    def near(self, indexed: dict, pad: float) -> np.ndarray:
        """(L,) bool the leaves that may have rows to read within ``pad`` (:meth:`rows` finds none for the others)."""
        bounds = self._bounds(indexed)
        if bounds is None:
            return np.zeros(len(self.boxes), dtype=bool)
        return boxes_meet(self.arrays, *bounds, pad)

    def read_together(self, reads, indexed: dict, leaves, pad: float, reach: float, distances: bool = True) -> dict:
        """{j: (rows, values, distance)}: each of ``leaves`` (indices) that ``reads`` (:class:`.leafreads.LeafReads`)
        reads together, at its :meth:`rows`, in one launch for all: its linear values and (with ``distances``) its
        mesh's distances (None, None where it has no row)."""
        rows = self.rows_of([j for j in leaves if reads.batched[j]], indexed, pad)
        together = [j for j, at in rows.items() if len(at)]
        points = indexed["points"]
        found = reads.read([(j, points[rows[j]]) for j in together], reach, distances)
        out = {j: (at, None, None) for j, at in rows.items()}
        out.update({j: (rows[j], *read) for j, read in zip(together, found, strict=True)})
        return out

    def rows_of(self, leaves, indexed: dict, pad: float) -> dict:
        """{j: :meth:`rows`} for each of ``leaves``, the boxed ones found together: the points binned once into
        squares in x and y about as wide as the boxes (their median padded width), each box's squares' points taken
        and filtered as :meth:`rows` filters them (a plate's judge read 100 bores' rows a round, each in its own
        slab of the points sorted along x)."""
        points = indexed["points"]
        out = {j: np.arange(len(points)) for j in leaves if self._holds_all(j, indexed, pad)}
        boxed = [j for j in leaves if j not in out]
        if not boxed or not len(points):
            out.update({j: np.zeros(0, np.int64) for j in boxed})
            return out
        lo, hi = np.stack([self.boxes[j][0] for j in boxed]), np.stack([self.boxes[j][1] for j in boxed])
        # the bounds as :meth:`rows` takes them: along x in float64 (its scalars), along y and z in float32
        x_lo, x_hi = lo[:, 0].astype(np.float64) - pad, hi[:, 0].astype(np.float64) + pad
        yz_lo, yz_hi = lo[:, 1:] - pad, hi[:, 1:] + pad
        least, most = self._bounds(indexed)  # (at most 4,096 squares a side: keys fit in an int64)
        spread = float(np.max(most[:2].astype(np.float64) - least[:2].astype(np.float64)))
        cell = max(float(np.median((hi - lo)[:, :2].max(axis=1))) + 2.0 * pad, spread / 4096.0, 1e-30)
        order, keys, origin, columns = self._binned(indexed, cell)
        first = np.maximum(self._square(x_lo, origin[0], cell, columns[0]), 0)
        last = np.minimum(self._square(x_hi, origin[0], cell, columns[0]), columns[0] - 1)
        y_first = np.maximum(self._square(yz_lo[:, 0].astype(np.float64), origin[1], cell, columns[1]), 0)
        y_last = np.minimum(self._square(yz_hi[:, 0].astype(np.float64), origin[1], cell, columns[1]), columns[1] - 1)
        spans = np.maximum(last - first + 1, 0)
        box = np.repeat(np.arange(len(boxed)), spans)  # one (box, column of squares) pair a row
        column = first[box] + np.arange(int(spans.sum())) - np.repeat(np.cumsum(spans) - spans, spans)
        start = np.searchsorted(keys, column * columns[1] + y_first[box], side="left")
        count = np.maximum(np.searchsorted(keys, column * columns[1] + y_last[box], side="right") - start, 0)
        box = np.repeat(box, count)
        rows = order[np.repeat(start - (np.cumsum(count) - count), count) + np.arange(int(count.sum()))]
        x, yz = points[rows, 0], points[rows, 1:]
        inside = (x >= x_lo[box]) & (x <= x_hi[box]) & ((yz >= yz_lo[box]) & (yz <= yz_hi[box])).all(axis=1)
        rows, box = rows[inside], box[inside]
        order = np.lexsort((rows, box))
        parts = np.split(rows[order], np.cumsum(np.bincount(box, minlength=len(boxed)))[:-1])
        out.update(zip(boxed, parts, strict=True))
        return out

    @staticmethod
    def _square(values: np.ndarray, origin: float, cell: float, count: int) -> np.ndarray:
        """The column (or row) of squares each float64 coordinate falls in, clipped to the ``count`` there are."""
        return np.clip(np.floor((values - origin) / cell), -1, count).astype(np.int64)

    def _binned(self, indexed: dict, cell: float) -> tuple:
        """The points binned into squares ``cell`` wide in x and y (found once a set and size): the rows in the order
        of their squares' keys (column x rows + row), the keys so sorted, the squares' origin and their counts."""
        found = indexed.get(("binned", cell))
        if found is None:
            points, (least, most) = indexed["points"], self._bounds(indexed)
            origin, top = least[:2].astype(np.float64), most[:2].astype(np.float64)
            columns = (np.floor((top - origin) / cell).astype(np.int64) + 1).tolist()
            square = [self._square(points[:, k].astype(np.float64), origin[k], cell, columns[k]) for k in range(2)]
            keys = square[0] * columns[1] + square[1]
            order = np.argsort(keys, kind="stable")
            found = indexed[("binned", cell)] = (order, keys[order], origin, columns)
        return found

    @staticmethod
    def _sorted(indexed: dict) -> np.ndarray:
        """The points' x in increasing order (``indexed["order"]`` the rows so sorted), found once a set."""
        if "order" not in indexed:
            points = indexed["points"]
            indexed["order"] = np.argsort(points[:, 0], kind="stable")
            indexed["x"] = points[indexed["order"], 0]
        return indexed["x"]

    @staticmethod
    def _bounds(indexed: dict) -> tuple:
        """The points' least and largest coordinates, found once a set."""
        if "bounds" not in indexed:
            points = indexed["points"]
            indexed["bounds"] = (points.min(axis=0), points.max(axis=0)) if len(points) else None
        return indexed["bounds"]

    def _holds_all(self, j: int, indexed: dict, pad: float) -> bool:
        """Whether leaf ``j``'s padded box holds every point, by :meth:`rows`' own tests (its rows are all of them:
        a copy of a part united with it reads every sample, 0.6 M of them sorted for nothing)."""
        bounds = self._bounds(indexed)
        if self.boxes[j] is None or bounds is None:
            return self.boxes[j] is None
        (lo, hi), (least, most) = self.boxes[j], bounds
        x = least[0] >= lo[0] - pad and most[0] <= hi[0] + pad
        return bool(x and (least[1:] >= lo[1:] - pad).all() and (most[1:] <= hi[1:] + pad).all())

    def rows(self, j: int, indexed: dict, pad: float) -> np.ndarray:
        """The rows of the :meth:`index`-ed points leaf ``j`` must be read at (sorted)."""
        points = indexed["points"]
        if self._holds_all(j, indexed, pad):
            return np.arange(len(points))
        self._sorted(indexed)
        lo, hi = self.boxes[j]
        start = np.searchsorted(indexed["x"], lo[0] - pad, side="left")
        end = np.searchsorted(indexed["x"], hi[0] + pad, side="right")
        rows = indexed["order"][start:end]
        yz = points[rows, 1:]
        return np.sort(rows[((yz >= lo[1:] - pad) & (yz <= hi[1:] + pad)).all(axis=1)])
