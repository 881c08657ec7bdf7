"""Fields refined on demand: a mesh's field whose finest octets are a part of its band, more added when asked.

A mesh's field holds its finest level in octets about every triangle (:func:`.build.build_field`), and much of it
is never read: a boolean keeps its result's finest octets only within a few voxels of its surface, so where an
operand's surface lies inside the other operand (or outside it, for an intersection) its finest octets are built and
thrown away. Pavić, Campen and Kobbelt reach fine resolutions by confining the work to the cells near the
intersections; here a field built with ``refine="none"`` has every level above the finest as the full build has them
(the same nodes, values, closest points and signs: level 1 is placed as the parents of the whole band's finest
octets, :func:`.layout.level_layout`'s ``above``, and a level-1 node without children takes its exact closest point
directly, as a coarse leaf does) and no finest octet. :meth:`Refiner.refined` adds the band's finest octets a
consumer asks for, as a refinement round of the build does (the nodes found before keep their values, only new
octets are searched), so a refined place equals the full build's. The most refined field so far is kept with the
refiner (its cache): every copy of the field (placed, relabelled) asks it, and what one consumer refined the next
finds.

Asked of a partly refined field, the public queries answer as the full field does: :meth:`.field.AdaptiveField.sample`
refines about its points first, the surface, offsets and shells take the whole band; a boolean asks only where its
result's surface may pass (:func:`for_boolean`), or with ``seams`` only along them, for the kept faces
(:mod:`.seams`). ``refine="auto"`` builds on demand where a band is large for its mesh's triangles.

An open mesh's build has its band's octets about its holes' caps built first (its rounds across the holes then see
what the full build's see), and its bounds are not read there (its sign may jump across a hole).
"""

from __future__ import annotations

import copy
import threading
import weakref

import numpy as np
import warp as wp

from . import parallel
from .expression import OP_DIFFERENCE, OP_UNION, Operation
from .geometry import near_cap
from .meshsides import closed_sides
from .octree import code_bits, filled_notches, morton_decode_np, morton_encode_np, node_center, parent_octets
from .sampling import LEAF_TOLERANCE, FieldArg, clamp_to_domain, level_spacing, locate_leaf, node_coords, node_proj
from .signs import box_arrays
from .sources import mesh_distances
from .winding import WindingArg, inside_sign

# What a mesh's build found of it (:func:`.levels.finished`), carried to its refined fields.
FOUND = ("clean_mesh", "flat", "surface_points", "problem_faces", "mesh_distance", "hole_caps")

# A boolean's operand gets the finest octets of its band within this many voxels of where the result's surface may
# be: the boolean keeps its finest octets within KEEP_BAND (2.6) voxels of it, an octet's centre lies up to sqrt(3)
# voxels from its nodes, and an MLS sample reads nodes up to 1.5 voxels away (2.9 voxels to spare).
BOOLEAN_REACH_VOXELS = 2.6 + 1.75 + 1.5 + 2.9

# With ``seams``, the octets within this many voxels of the other operand's surface: the kept faces end about 2
# voxels from a seam (the judge's band and slack), and the voxel surface must reach under them (measured on the CAD
# pairs at /256: 5 joins every pair along its seams, 4 leaves the surface short on all but two; what falls short is
# joined on the whole result instead).
SEAM_REACH_VOXELS = 6.0
# The result's finest octets along the seams are those within SEAM_REACH_VOXELS of both operands' surfaces
# (:func:`seam_octets`); each operand is refined this much farther, so that what their nodes read of it (an octet's
# nodes up to sqrt(3) voxels from its centre, an MLS sample nodes up to 1.5 voxels away, a voxel for the bounds'
# tolerances) is built: their values are the full boolean's.
SEAM_READ_VOXELS = 1.75 + 1.5 + 1.0

# An open mesh built on demand has its band's octets this many octets (beside the rounds' own reach) about its caps
# built first: the band nodes beside the octets the rounds look at.
CAP_REACH_OCTETS = 2.0

# Finest octets within this many voxels (L-inf, about a point) are refined for a query there: an MLS sample reads the
# 27 nodes about the finest node nearest its point, within 1.5 voxels, and the leaf that holds it.
SAMPLE_REACH_VOXELS = 2.0


class Refiner:
    """What a field built on demand keeps to add finest octets later: the build's levels (:class:`.levels.LevelBuilder`:
    the mesh, its BVH and winding numbers, the plan), the whole band's finest octets, and the most refined field so
    far (unplaced, its own field id)."""

    def __init__(self, levels, band: np.ndarray, field):
        self.levels, self.band = levels, band
        self.latest = field
        self.built = np.isin(band, _finest_octets(field), assume_unique=True)  # (the band's octets built so far)
        self.centres = None  # the band's octets' centres (unplaced), found on first use
        self.box = (None, None)  # (the ``built`` it was found for, :meth:`unbuilt_box`)
        self.lock = threading.Lock()

    @property
    def kept_bytes(self) -> int:
        """Bytes kept to refine later beside the field's arrays and its source mesh (which keeps the mesh's BVH with
        its winding-number data): the band's octets, the plan's copy of the mesh."""
        plan = self.levels.plan
        return self.band.nbytes + plan["vertices"].nbytes + plan["triangles"].nbytes

    @property
    def share(self) -> float:
        """The part of the band's finest octets built so far."""
        return self.latest.level_counts[0] / max(8 * len(self.band), 1)

    def asked(self, points: np.ndarray | None, reach: float | None):
        """The field with the octets queries at unplaced ``points`` read built (None: all; ``reach``: instead those
        within it, L-inf, of them)."""
        if points is None:
            return self.refined(None)
        field, box = self.latest, self.unbuilt_box()
        if box is None:  # (every octet of the band built)
            return field
        if reach is None:
            return self.refined(_read_octets(field, points, box))
        return self.refined(octets_near(field, points[_touching(field, points, reach, box)], reach))

    def unbuilt_box(self) -> tuple | None:
        """The least and greatest octet coordinates (3,) of the band's octets not built yet (None: all are), found
        once for each state of the band. A query whose octets all lie outside the box asks for nothing new: sorting
        its octets is skipped (a row of cubes' judge reads each cube's samples in every other cube's field)."""
        built = self.built
        if self.box[0] is not built:
            codes = self.band[~built]
            coords = morton_decode_np(codes) if len(codes) else None
            self.box = (built, None if coords is None else (coords.min(axis=0), coords.max(axis=0)))
        return self.box[1]

    def refined(self, octets: np.ndarray | None):
        """The field with the band's finest octets among ``octets`` (sorted unique codes; None: all) added."""
        every = np.ones(len(self.band), dtype=bool)
        return self.refined_where(every if octets is None else np.isin(self.band, octets, assume_unique=True))

    def refined_where(self, wanted: np.ndarray):
        """The field with the band's finest octets where ``wanted`` ((K,) bool over the band) added."""
        with self.lock:
            built = self.built | wanted
            if np.array_equal(built, self.built):
                return self.latest
            octets_wp = wp.array(self.band[built], dtype=wp.int64, device=self.latest.device)
            field = self.levels.build(octets_wp, previous=self.latest, finest_only=True)
            # what the first build found of the mesh, and its source mesh (the same object: what is kept with it
            # stays)
            field.stats = {**field.stats, **{k: self.latest.stats[k] for k in FOUND if k in self.latest.stats}}
            field.sources, field.refiner = self.latest.sources, self
            self.latest, self.built = field, built
            field.stats["refined"] = self.share
            return field


def partial_build(levels, band: wp.array, finish, across_holes=None):
    """A mesh's field with every level above the finest as its full build has them and no finest octet, and its
    :class:`Refiner` (``levels``: the build's :class:`.levels.LevelBuilder`; ``band``: the whole band's finest octets,
    sorted; ``finish(field, octets)``: what the build does last to a field, :func:`.levels.finished`). An open mesh's
    (``across_holes(field, octets)``: the build's rounds across its holes, :func:`.levels.refined_across_holes`) has
    its band's octets near its holes' caps built first, so the rounds look at what the full build's do and add the
    same octets (the band takes them too)."""
    end_bit = 3 * code_bits(levels.plan["fine_dims"])
    levels.above = parent_octets(band, 1, end_bit=end_bit, presorted=True)
    codes, first = band.numpy(), np.zeros(0, dtype=np.int64)
    caps = levels.facts["caps"]
    if caps is not None:  # the rounds check the leaves and octets near the caps, and the band nodes beside them
        octet = 2.0 * levels.plan["voxel_size"]
        centres = levels.plan["origin"] + (morton_decode_np(codes) + 0.5) * octet
        reach = CAP_REACH_OCTETS * octet + _sign_check_reach(levels.plan)
        first = codes[_near_caps(caps, centres, reach, band.device)]
    field = levels.build(wp.array(first, dtype=wp.int64, device=band.device))
    if across_holes is not None:
        field = across_holes(field, wp.array(first, dtype=wp.int64, device=band.device))
        codes = np.union1d(codes, _finest_octets(field))
    field = finish(field, len(codes))
    field.refiner = Refiner(levels, codes, field)
    source = next(iter(field.sources.values()))
    source.adopt(levels.mesh)  # (with its winding numbers: :func:`own_sides`)
    source.refiner = field.refiner
    field.stats["refined"] = field.refiner.share
    return field


def _sign_check_reach(plan: dict) -> float:
    """How far from a cap :func:`.holes.sign_change_octets` looks (its ``reach``)."""
    top, h = plan["voxel_size"] * 2 ** (plan["levels"] - 1), plan["voxel_size"]
    return 1.05 * (0.866 * top + max(0.5 * top + 0.25 * h, 3.465 * h))


@wp.kernel(enable_backward=False)
def _near_caps_kernel(
    points: wp.array[wp.vec3],
    lo: wp.array[wp.vec3],
    hi: wp.array[wp.vec3],
    radius: wp.array[wp.float32],
    margin: float,
    out: wp.array[wp.uint8],
):
    i = wp.tid()
    out[i] = wp.uint8(wp.where(near_cap(points[i], lo, hi, radius, margin), 1, 0))


def _near_caps(caps, points: np.ndarray, margin: float, device) -> np.ndarray:
    """(N,) where the caps' cones may move the winding number by 1/4 or more within ``margin`` of each point
    (:func:`.geometry.near_cap`: sum of (radius_c / d_c)^2 at least 1, d_c the box's distance less the margin)."""
    n = len(points)
    out = wp.empty(n, dtype=wp.uint8, device=device)
    if n:
        pts = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
        boxes = box_arrays(caps, device)
        parallel.launch_split(
            _near_caps_kernel, n, lambda lo, k: [pts[lo : lo + k], *boxes, float(margin), out[lo : lo + k]], device
        )
    return out.numpy().astype(bool)


def refined(field, points=None, reach: float | None = None, *, view: bool = False):
    """``field`` with the finest octets of its band that queries at ``points`` (world, (N, 3); None: everywhere)
    read built, placed and labelled as ``field`` is (``reach``: instead, the octets within that many world units,
    L-inf, of them); ``field`` itself when it was built whole. ``view``: a copy without the refiner, which answers
    from the octets built (what a query reads after asking)."""
    refiner = getattr(field, "refiner", None)
    if refiner is None:
        return field
    if view:
        return as_built(refined(field, points, reach))
    pts = None if points is None else np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if pts is not None and field.placement is not None:
        pts = field.placement.to_local(pts)
        reach = None if reach is None else reach / field.placement.scale
    return _as(field, refiner.asked(pts, reach))


@wp.kernel(enable_backward=False)
def _leaf_cells_kernel(
    f: FieldArg,
    points: wp.array[wp.vec3],
    leaves: wp.array[wp.int32],
    centres: wp.array[wp.vec3],
    spacing: wp.array[float],
):
    """The leaf holding each point, its centre and its spacing."""
    i = wp.tid()
    leaf = locate_leaf(f, points[i])
    s = level_spacing(f, leaf[1])
    leaves[i] = leaf[0]
    centres[i] = node_center(f.origin, s, node_coords(f, leaf[0]))
    spacing[i] = s


def _read_octets(field, points: np.ndarray, box: tuple) -> np.ndarray:
    """Sorted codes of the finest octets an MLS sample at each unplaced point may read in the full field: those
    within SAMPLE_REACH_VOXELS of it (where its leaf is a finest node there), and those holding the centres of the
    27 cells about its leaf in ``field`` as it stands (the leaves a fit reads, :func:`.sampling.leaf_neighbours`,
    where its leaf is coarse there: each such leaf once; the levels above the finest are the full field's); those
    within the octets ``box`` (:meth:`Refiner.unbuilt_box`) alone: the rest are built, or not in the band."""
    n, device = len(points), field.device
    leaves = wp.empty(n, dtype=wp.int32, device=device)
    centres = wp.empty(n, dtype=wp.vec3, device=device)
    spacing = wp.empty(n, dtype=wp.float32, device=device)
    if n:
        pts = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
        wp.launch(_leaf_cells_kernel, dim=n, inputs=[field.arg(), pts, leaves, centres, spacing], device=device)
    coarse = np.flatnonzero(spacing.numpy() > 1.5 * field.voxel_size)
    coarse = coarse[np.unique(leaves.numpy()[coarse], return_index=True)[1]]
    steps = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    cells = centres.numpy()[coarse, None, :] + spacing.numpy()[coarse, None, None] * steps[None]
    reach, cells = SAMPLE_REACH_VOXELS * field.voxel_size, cells.reshape(-1, 3).astype(np.float64)
    near = octets_near(field, points[_touching(field, points, reach, box)], reach)
    return np.union1d(near, octets_near(field, cells[_touching(field, cells, 0.0, box)], 0.0))


def _touching(field, points: np.ndarray, reach: float, box: tuple) -> np.ndarray:
    """(N,) bool the unplaced ``points`` whose octets within ``reach`` (as :func:`octets_near` finds them) reach into
    the octets ``box`` (least and greatest coordinates)."""
    octet = 2.0 * field.voxel_size
    dims = np.asarray(field.fine_dims, dtype=np.int64) // 2
    lo = np.clip(np.floor((points - field.origin - reach) / octet).astype(np.int64), 0, dims - 1)
    hi = np.clip(np.floor((points - field.origin + reach) / octet).astype(np.int64), 0, dims - 1)
    return (hi >= box[0]).all(axis=1) & (lo <= box[1]).all(axis=1)


def _as(field, out):
    """``out`` (the refiner's unplaced field) placed and labelled as ``field``."""
    if out.field_ids != field.field_ids:
        out = out.relabel(field.field_ids[0])
    if field.placement is None:
        return out
    placed = copy.copy(out)
    placed.placement = field.placement
    return placed


def octets_near(field, points: np.ndarray, reach: float) -> np.ndarray:
    """Sorted unique codes of the finest octets (of ``field``'s lattice) within ``reach`` (L-inf) of the unplaced
    ``points``. The points' lowest octets are told apart by one integer each (a sort of N keys, where rows of three
    sort several times slower), and only the distinct ones are grown by the span."""
    octet = 2.0 * field.voxel_size
    dims = np.asarray(field.fine_dims, dtype=np.int64) // 2
    lo = np.floor((points - field.origin - reach) / octet).astype(np.int64)
    hi = np.floor((points - field.origin + reach) / octet).astype(np.int64)
    lo, hi = np.clip(lo, 0, dims - 1), np.clip(hi, 0, dims - 1)
    span = int((hi - lo).max(initial=0)) + 1
    key = np.unique((lo[:, 0] * dims[1] + lo[:, 1]) * dims[2] + lo[:, 2])
    corner = np.stack([key // (dims[1] * dims[2]), (key // dims[2]) % dims[1], key % dims[2]], axis=1)
    steps = np.stack(np.meshgrid(*[np.arange(span)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    cells = np.minimum(corner[:, None, :] + steps[None], dims - 1).reshape(-1, 3)
    return np.unique(morton_encode_np(cells))


@wp.kernel(enable_backward=False)
def _value_bounds_kernel(f: FieldArg, points: wp.array[wp.vec3], low: wp.array[wp.float32], high: wp.array[wp.float32]):
    """Bounds of the field's value at each point from the leaf holding it: its node's value (an exact distance,
    within LEAF_TOLERANCE on the top level) and the distance to its centre (the field is 1-Lipschitz); outside the
    domain, no nearer than the domain (a mesh's surface lies inside its field's domain)."""
    i = wp.tid()
    x = points[i]
    leaf = locate_leaf(f, x)
    v = f.values[leaf[0]]
    r = f.lipschitz * wp.length(x - node_center(f.origin, level_spacing(f, leaf[1]), node_coords(f, leaf[0])))
    slack = r + LEAF_TOLERANCE * wp.abs(v)
    out = wp.length(x - clamp_to_domain(f, x))  # outside the domain: at least that far from its surface
    low[i] = wp.where(out > 0.0, wp.max(v - slack, out), v - slack)
    high[i] = v + slack


def value_bounds(field, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) lower and upper bounds of ``field``'s value at world ``points``, read from its nodes as they stand
    (nothing refined; :func:`_value_bounds_kernel`). A field that may jump (an open mesh's, across its holes) is
    bounded only away from where it may (:func:`_may_jump`), one that may anywhere nowhere (-inf to inf)."""
    if not (field.stats.get("clean_mesh") or field.stats.get("continuous") or "hole_caps" in field.stats):
        return np.full(len(points), -np.inf, np.float32), np.full(len(points), np.inf, np.float32)
    pts = np.asarray(points, dtype=np.float64)
    scale = 1.0
    if field.placement is not None:
        pts, scale = field.placement.to_local(pts), field.placement.scale
    n, device = len(pts), field.device
    low, high = wp.empty(n, dtype=wp.float32, device=device), wp.empty(n, dtype=wp.float32, device=device)
    if n:
        arg = field.in_frame().arg()
        pts_wp = wp.array(np.ascontiguousarray(pts, dtype=np.float32), dtype=wp.vec3, device=device)
        args = lambda lo, k: [arg, pts_wp[lo : lo + k], low[lo : lo + k], high[lo : lo + k]]  # noqa: E731
        parallel.launch_split(_value_bounds_kernel, n, args, device, min_dim=parallel.EMIT_SPLIT_MIN_DIM)
    low, high = low.numpy() * np.float32(scale), high.numpy() * np.float32(scale)
    jumps = _may_jump(field, pts)
    low[jumps], high[jumps] = -np.inf, np.inf
    return low, high


def _may_jump(field, local: np.ndarray) -> np.ndarray:
    """(N,) where an open mesh's field may change sign away from its triangles near the unplaced ``local`` points:
    near its caps (:func:`_near_caps`) within a top leaf's diagonal (a bound reads a node up to that far away)."""
    caps = field.stats.get("hole_caps")
    if caps is None:
        return np.zeros(len(local), dtype=bool)
    return _near_caps(caps, local, 2.0 * np.sqrt(3.0) * field.top_spacing, field.device)


def for_boolean(a, b, op: int, blend: float, *, seams: bool = False) -> tuple:
    """Operands ``a`` and ``b`` of a boolean (``op``: :mod:`.expression`'s, a minus b for a difference), each built on
    demand refined where the result's surface may pass: where the other's value bounds (:func:`value_bounds`, at
    the centres of its band's octets) leave room for it within BOOLEAN_REACH_VOXELS (and the blend) of the octet.
    A union's operand's surface is the result's only where the other's value is not below that reach (outside the
    other, or near its surface); an intersection's where it is not above it; a difference's first operand as a
    union's, its second (turned inside out) as an intersection's. What the boolean reads of an operand (its finest
    nodes and their MLS samples, the pruning's brackets) lies within that reach of the result's surface. ``seams``:
    only where the other's surface may be within that reach (the seams, where a boolean that keeps the operands'
    faces makes new surface). An operand that is a boolean built on demand is taken whole. Returns the operands, and
    whether the result is made along its seams (asked, and an operand built on demand or one whose octets it builds
    along them alone: :func:`along_seams_only`)."""
    seams = seams and any(
        isinstance(getattr(x, "refiner", None), Refiner) or along_seams_only(x, y) for x, y in ((a, b), (b, a))
    )
    out = [a, b]

    def refine(k, x, y):
        refiner = getattr(x, "refiner", None)
        if not isinstance(refiner, Refiner):  # a boolean's (:class:`.boolean.BooleanRefiner`): whole
            out[k] = refined(x)
            return
        centres = band_centres(x)
        world = centres if x.placement is None else x.placement.to_world(centres)
        if seams:  # where the other's surface is near (its mesh where a coarse leaf's bound is loose by its size)
            near, todo = refiner.built.copy(), ~refiner.built  # (what is built stays)
            reach = (SEAM_REACH_VOXELS + SEAM_READ_VOXELS) * x.world_voxel_size + blend
            near[todo] = surface_within(y, world[todo], reach)
        else:
            low, high = value_bounds(y, world)
            reach = BOOLEAN_REACH_VOXELS * x.world_voxel_size + float(blend)
            below = op == OP_UNION or (op == OP_DIFFERENCE and k == 0)  # the other's inside buries it
            near = high >= -reach if below else low <= reach
        out[k] = _as(x, refiner.refined_where(near))

    # side by side (one Python thread each on the CPU; one field used twice is refined once at a time: its lock)
    asked = [(k, x, y) for k, (x, y) in enumerate(((a, b), (b, a))) if getattr(x, "refiner", None) is not None]
    parallel.run_tasks([lambda task=task: refine(*task) for task in asked], a.device)
    return out[0], out[1], seams


def seam_octets(octets: wp.array, x, other, origin, h: float, blend: float) -> wp.array:
    """Of the result's finest ``octets`` that cover a boolean's operand ``x`` (:func:`along_seams_only`: built on
    demand, or a mesh's built whole; codes on the result's lattice: ``origin``, voxel ``h``), those the result keeps
    along its seams: within SEAM_REACH_VOXELS (and the ``blend``) of the ``other`` operand's surface
    (:func:`surface_within`), or about ``x``'s holes' caps (built first, :func:`partial_build`: the result's surface
    there is its own), or about where a mesh of either that passes through itself may give its faces up
    (:func:`crosses_itself`), pinholes and notches closed (:func:`.octree.filled_notches`). Elsewhere ``x`` may have
    octets built for another boolean (its refiner keeps them), at whose edges it is read off coarser nodes; along the
    seams it is built SEAM_READ_VOXELS farther (:func:`for_boolean`): the values there are the full boolean's."""
    codes = octets.numpy()
    if not len(codes):
        return octets
    centres = np.asarray(origin, dtype=np.float64) + (morton_decode_np(codes) + 0.5) * (2.0 * h)
    keep = surface_within(other, centres, SEAM_REACH_VOXELS * h + float(blend))
    for f in (x, other):  # about where a mesh that passes through itself may give its faces up
        near = _near_region(f, centres, SEAM_REACH_VOXELS * h + float(blend), h)
        if near is None:
            return octets
        keep |= near
    caps = x.stats.get("hole_caps")
    if caps is not None:
        plan = {"voxel_size": x.voxel_size, "levels": x.levels}
        local = centres if x.placement is None else x.placement.to_local(centres)
        reach = CAP_REACH_OCTETS * 2.0 * plan["voxel_size"] + _sign_check_reach(plan)
        keep |= _near_caps(caps, local, reach, octets.device)
    return wp.array(codes[filled_notches(codes, keep, octets.device)], dtype=wp.int64, device=octets.device)


# The source meshes a kept-faces judge found passing through themselves, or with defects other than holes
# (:func:`.ownpart.gives_own_faces_up`): a boolean along its seams builds every finest octet of such an operand, whose
# faces are given up about the crossings and defects (only the voxel surface is there, away from the seams), unless it
# knows where they may be given up (``_REGIONS``).
_CROSSING: weakref.WeakSet = weakref.WeakSet()
# Per such source mesh: where its faces may be given up whatever the other operand is (:func:`.ownpart.own_region`: its
# defects, crossings included, and its faces that read internal), as ``(voxel, BVH)`` in its own frame, at the voxel
# size it was judged at. A boolean along its seams at that voxel size keeps the finest octets about it too, of both
# operands (:func:`seam_octets`), instead of all of them: the voxel surface reaches under every face given up there.
_REGIONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def crosses_itself(field, region: tuple | None = None, voxel: float | None = None) -> None:
    """Mark ``field``'s mesh as passing through itself: booleans along their seams build all of its octets, or with
    ``region`` (``(points, tris)`` in the field's own frame, judged at the world ``voxel``) only those about it."""
    if region is not None:  # (marked last: a boolean on another thread sees a region, or no crossing yet)
        points, tris = region
        scale, device = 1.0 if field.placement is None else field.placement.scale, field.device
        mesh = None
        if len(tris):
            mesh = wp.Mesh(
                points=wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device),
                indices=wp.array(np.ascontiguousarray(tris, dtype=np.int32).reshape(-1), dtype=wp.int32, device=device),
            )
        for source in field.sources.values():
            _REGIONS[source] = (float(voxel) / scale, mesh)
    _CROSSING.update(field.sources.values())


def along_seams_only(field, beside) -> bool:
    """Whether a boolean along its seams builds an operand's finest octets only along them and about its holes' caps
    (``beside``: the other operand): one built on demand, or a mesh's built whole that is closed or whose only defects
    are holes (its kept faces are the rest of its surface on the result's), but not a mesh marked as passing through
    itself (:func:`crosses_itself`), nor a mesh's built whole beside one (whose join gives up kept faces about its
    crossings, the other's too, farther from the seams than their voxel surface would reach), unless each such mesh's
    region is known (its octets there kept too, :func:`seam_octets`)."""
    if _crossing(field) and not _regioned(field):
        return False
    if built_on_demand(field):
        return True
    stats = field.stats
    plain = stats.get("thickness") is None and not stats.get("flat", False) and len(field.sources) == 1
    holes_only = stats.get("clean_mesh", False) or "hole_caps" in stats or _regioned(field)
    beside_ok = not _crossing(beside) or _regioned(beside)
    return bool(holes_only) and plain and getattr(field, "expression", None) is None and beside_ok


def _regioned(field) -> bool:
    return len(field.sources) == 1 and next(iter(field.sources.values())) in _REGIONS


def _near_region(field, centres: np.ndarray, reach: float, h: float) -> np.ndarray | None:
    """(N,) bool the world ``centres`` within ``reach`` of ``field``'s region (:data:`_REGIONS`), all False where its
    mesh crosses itself nowhere; None where it does and its region is unknown at the voxel ``h`` (every octet kept)."""
    if not _crossing(field):
        return np.zeros(len(centres), dtype=bool)
    scale = 1.0 if field.placement is None else field.placement.scale
    found = _REGIONS.get(next(iter(field.sources.values()))) if len(field.sources) == 1 else None
    if found is None or not np.isclose(found[0], h / scale, rtol=1e-6):
        return None
    if found[1] is None:
        return np.zeros(len(centres), dtype=bool)
    local = centres if field.placement is None else field.placement.to_local(centres)
    return mesh_distances(found[1], local, reach / scale, field.device) < reach / scale


def _crossing(field) -> bool:
    return any(source in _CROSSING for source in field.sources.values())


def surface_within(field, points: np.ndarray, reach: float) -> np.ndarray:
    """(N,) bool: whether ``field``'s surface may lie within ``reach`` (with the leaves' tolerance to spare) of each
    world point. Its value bounds (:func:`value_bounds`) decide where they put the value surely beyond the reach
    (False: the field changes by at most the distance) or surely within it (True); elsewhere (a coarse leaf's bound
    is loose by its size) a field built from a mesh (no thickness, no expression), whose values' size is at most the
    distance to its triangles and whose surface lies on them but for an open mesh's caps (where its winding number
    may move by 1/4: within the reach of that, :func:`_near_caps`, it may), is answered by the distance to the mesh
    (its BVH, unplaced, kept with its source mesh); any other field may have it there (True)."""
    far = (1.0 + 2.0 * LEAF_TOLERANCE) * reach
    low, high = value_bounds(field, points)
    may = (low <= far) & (high >= -far)
    unsure = np.flatnonzero(may & ((low < -far) | (high > far)))
    source = next(iter(field.sources.values()), None) if len(field.sources) == 1 else None
    plain = "clean_mesh" in field.stats and field.stats.get("thickness") is None and not field.stats.get("flat")
    if source is None or not plain or getattr(field, "expression", None) is not None or not len(unsure):
        return may
    local, scale = np.asarray(points, dtype=np.float64)[unsure], 1.0
    if field.placement is not None:
        local, scale = field.placement.to_local(local), field.placement.scale
    caps = field.stats.get("hole_caps")  # (its sign jumps only where the caps move its winding number by 1/4)
    ask = np.ones(len(local), dtype=bool) if caps is None else ~_near_caps(caps, local, far / scale, field.device)
    ask[ask] = _leaf_point_distances(field, local[ask]) >= far / scale  # (a point of the mesh within reach)
    distance = mesh_distances(source.bvh(field.device), local[ask], far / scale, field.device)
    may[unsure[ask]] = distance < far / scale
    return may


@wp.kernel(enable_backward=False)
def _leaf_point_kernel(f: FieldArg, points: wp.array[wp.vec3], out: wp.array[wp.float32]):
    i = wp.tid()
    leaf = locate_leaf(f, points[i])
    out[i] = wp.length(points[i] - node_proj(f, leaf[0], leaf[1]))


def _leaf_point_distances(field, local: np.ndarray) -> np.ndarray:
    """(N,) the distance from each unplaced point to the closest point its leaf's node holds (a point of the mesh:
    the distance to the mesh is at most that)."""
    n, device = len(local), field.device
    out = wp.empty(n, dtype=wp.float32, device=device)
    if n:
        arg = field.in_frame().arg()
        pts = wp.array(np.ascontiguousarray(local, dtype=np.float32), dtype=wp.vec3, device=device)
        args = lambda lo, k: [arg, pts[lo : lo + k], out[lo : lo + k]]  # noqa: E731
        parallel.launch_split(_leaf_point_kernel, n, args, device, min_dim=parallel.EMIT_SPLIT_MIN_DIM)
    return out.numpy()


def as_built(field):
    """A copy of ``field`` without its refiner: it answers from what is built (nothing is refined on its
    queries); ``built_by`` names the refiner."""
    out = copy.copy(field)
    out.refiner, out.built_by = None, field.refiner or field.built_by
    return out


@wp.kernel(enable_backward=False)
def _mesh_sides_kernel(f: WindingArg, front: wp.array[wp.vec3], back: wp.array[wp.vec3], out: wp.array[wp.int8]):
    """A face's side from the mesh's winding number at its point in ``front`` and the one ``back``: +1 outside ahead
    and inside behind, -1 the other way round, 0 where both are on one side (which a field's values may read
    otherwise: near a crease, in a groove narrower than the offset, at an internal face)."""
    i = wp.tid()
    ahead = inside_sign(f, front[i])
    behind = inside_sign(f, back[i])
    out[i] = wp.int8(wp.where(ahead == behind, 0, wp.where(ahead > behind, 1, -1)))


def own_sides(field, points: np.ndarray, normals: np.ndarray, offset: float, read, tris=None) -> np.ndarray:
    """(N,) int8 the side of each (world) point's face on a mesh's field built on demand, as ``read(field, points,
    normals, offset)`` (:mod:`.keep`'s reading of its values) gives it on the full field: where the mesh's winding
    number (its BVH, kept with its source mesh) puts the points ``offset`` ahead and behind on either side, from it
    (the field's values there, within a tenth of a voxel of the distance, have those signs: the side it reads);
    elsewhere (a narrow groove, an internal face) by ``read`` on the field with the octets there built. ``tris``:
    the faces' corners (one face a point), for a closed mesh's winding numbers carried between neighbours
    (:func:`.meshsides.closed_sides`)."""
    source = next(iter(field.sources.values()))
    ends = [np.asarray(points, np.float64) + sign * offset * np.asarray(normals, np.float64) for sign in (1.0, -1.0)]
    local = ends if field.placement is None else [field.placement.to_local(end) for end in ends]
    f = source.refiner.levels.winding  # the build's (an open mesh's: exact near its holes)
    side = None if tris is None else closed_sides(f, tris, *local, field.device)
    if side is None:
        side = winding_sides(f, local, field.device)
    unsure = np.flatnonzero(side == 0)
    if len(unsure):
        asked = np.concatenate([local[0][unsure], local[1][unsure]])
        near = as_built(_as(field, source.refiner.asked(asked, None)))
        side[unsure] = read(near, points[unsure], normals[unsure], offset)
    return side


def winding_sides(f, local: list, device) -> np.ndarray:
    """:func:`_mesh_sides_kernel` at the points ``local`` (front, back) in the mesh's frame."""
    front, back = (wp.array(end.astype(np.float32), dtype=wp.vec3, device=device) for end in local)
    out = wp.empty(len(front), dtype=wp.int8, device=device)
    if len(front):
        args = lambda lo, k: [f, front[lo : lo + k], back[lo : lo + k], out[lo : lo + k]]  # noqa: E731
        parallel.launch_split(_mesh_sides_kernel, len(front), args, device, min_dim=parallel.EMIT_SPLIT_MIN_DIM)
    return out.numpy()


def built_on_demand(field) -> bool:
    """Whether ``field`` (or the field a view of it was made from) has a part of its finest level built."""
    return field.stats.get("refined", 1.0) < 1.0


def built_leaves(expression):
    """``expression`` (:mod:`.expression`) with its leaves built on demand read as built (:func:`as_built`: each the
    same arrays): the kept faces' judge reads an operand away from the seams only for its sign and whether it is
    farther than the band, which its levels above the finest tell (for a mesh without defects, whose distances the
    judge reads off the mesh itself). Each leaf is its refiner's most refined so far."""
    if isinstance(expression, Operation):
        a, b = built_leaves(expression.a), built_leaves(expression.b)
        if a is expression.a and b is expression.b:
            return expression
        return Operation(expression.op, expression.blend, a, b)
    refiner = getattr(expression, "refiner", None)
    return as_built(_as(expression, refiner.latest)) if isinstance(refiner, Refiner) else expression


def _finest_octets(field) -> np.ndarray:
    """Sorted codes of ``field``'s finest octets (each octet's 8 nodes lie together, in octant order)."""
    n0 = field.level_counts[0]
    return (field.codes[:n0].numpy()[::8] >> 3).astype(np.int64) if n0 else np.zeros(0, np.int64)


def band_centres(field) -> np.ndarray:
    """The centres (unplaced) of a field's whole band of finest octets (its refiner's, in its order), found once."""
    refiner = field.refiner
    if refiner.centres is None:
        octet = 2.0 * field.voxel_size
        refiner.centres = field.origin + (morton_decode_np(refiner.band) + 0.5) * octet
    return refiner.centres
