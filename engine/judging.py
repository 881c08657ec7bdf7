"""Samples on an operand's triangles, and the judge's verdicts on them in two kernel launches a round.

:mod:`.keep` judges a leaf's triangles (and the pieces of the partly keepable ones) at samples about a voxel apart:
the corners, and rows of points parallel to the longest edge (:func:`.samples.triangle_samples`). Its general path
places every sample, reads the other leaves there with a launch per leaf and query, and reduces per triangle in numpy.

The fused path (:class:`FusedJudge`) writes no sample: one launch reads the pieces' corners (each vertex once per
judge, whatever the round), and a second, one thread a piece, walks the piece's rows of samples (placed as
:func:`.samples.triangle_samples` places them), reads them, and folds corners and rows into the piece's verdict. A
sample's reading is every other leaf's sign (its field, linear, as ``field.sample`` reads it; a field that jumps also
a band away along the axes) and how far the nearest of their surfaces and of the leaf's own defects is (their BVHs, or
the field where a leaf has none); on a shell that crosses itself, also the leaf's own side across the piece there.
What the expression makes of the other leaves' signs (whether it crosses with the leaf, and which way) is a table over
their sign patterns, three signs a leaf (-, 0, +), found once per judge by the general path's own evaluation.

The verdicts are the general path's: the same samples and float32 readings, the same comparisons in float64. Three
things differ and cannot change them: a piece's rows are read only while they can change its verdict (kept only ever
turns false, partly keepable only true); a sample's distances are read only as far as its piece's checks look (a
margin beyond passes them whatever it is), not as far as the round's largest piece needs; a corner's reading is kept
from the round that first read it. Where distances are recorded for the next boolean (:mod:`.verdicts`), a piece of
many samples a few voxels across records a bound read at its centre (Lipschitz's), a little below its samples' least
distance: a verdict reused from it is one its samples would give again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .jumps import JumpSpheres, near_sphere
from .otherleaves import sign_check
from .ownside import gap_side
from .parallel import host_view, launch_split
from .queries import mls_value
from .samples import row_grid, row_point, row_steps
from .sampling import FieldArg, clamp_to_domain, locate_leaf, node_proj, sample_linear

# The fused path takes expressions of at most this many leaves besides the judged one (a table of 3^n patterns).
MAX_TABLE_LEAVES = 10
# A reach exceeds the distance it must tell apart by this many least spacings of samples (float32 rounds far less).
READ_PAD = 0.01
# Where distances are recorded, a piece of more samples than this (besides its corners, about) has its centre read
# instead of each of them beyond what its verdict needs: a bound by Lipschitz's, its farthest corner's distance less.
CENTRE_SAMPLES = 8
# ... and whose corners lie within this many least spacings of its centre (the bound is that much looser, twice over:
# a large face's read whole keeps its verdict over moves of a few voxels)
CENTRE_SPREAD = 8.0
# A piece's slack counts as larger than the least (keep's ``_Judge.partly_slack``) by more than this many least
# spacings (float rounding of the same slack is far less).
PARTLY_TIE = 1e-9
# Verdict bits of :func:`judge_pieces`.
KEPT_BIT, PARTLY_BIT, FLIP_BIT = 1, 2, 4
# and, where distances are recorded: no sample where the expression crosses; a defect, or its own field crossing it
# nowhere
SIGNS_ONLY_BIT, OWN_ONLY_BIT = 8, 16

# ---- readings ----


@wp.struct
class LeafArg:
    """A leaf as the fused judge reads it: one of the other leaves, or the judged one (for its own side)."""

    field: FieldArg
    mesh: wp.uint64  # the BVH of its clean closed mesh (world), 0: its distances are its field's
    placed: int  # 1: world points are taken to the field's frame as ``Placement.to_local`` takes them
    rotation: wp.mat33d
    translation: wp.vec3d
    scale: wp.float64
    value_scale: float  # its values times this (the placement's scale), as ``field.sample`` gives them
    jumps: int  # 1: a field that jumps (an open mesh's, across its holes): read a band away along the axes too,
    # where its value is below two bands or near the spheres about its defects (:mod:`.jumps`; ``jumps_anywhere``)
    jump_bvh: wp.uint64
    jump_spheres: wp.array[wp.vec4]
    jumps_anywhere: int
    weight: int  # its sign's place in a sign pattern: 3^(its rank among the other leaves)
    sign_check: float  # a linear value this far below its mesh's distance is read again by MLS (:mod:`.otherleaves`)


@wp.struct
class JudgeArg:
    """What the fused judge needs besides the pieces (lengths in world units, float64 as the general path's)."""

    leaves: wp.array[LeafArg]
    defect_mesh: wp.uint64  # the leaf's own defects' mesh, 0: none
    table: wp.array[wp.int8]  # per sign pattern: 1 the expression crosses with the leaf, 2 and it flips
    band: wp.float64
    probe: float  # the band, float32: how far along the axes a field that jumps is read
    probe_reach: float  # a little over the band: how far a field that jumps is read at least (to know it is farther)
    spacing: wp.float64  # the least spacing of samples
    slack_share: wp.float64  # a piece's slack per unit of its samples' spacing
    sample_share: wp.float64  # and its samples' spacing per unit of its slack
    partly_at: wp.float64  # band + least slack: a piece is partly keepable with a margin (+ a large one's slack) above
    pad: wp.float64  # a reach exceeds the distance it must tell apart by this much (float32 rounding is far less)
    corner_reach: float  # how far corners are read: a piece of the least slack's reach (a larger piece reads on)
    # a shell that crosses itself (``crossing`` 1): its own field is read at every sample, pulled ``pull`` towards the
    # piece's centre, ``side_offset`` in front of and behind it (keep's ``_own_sides``); else each piece has its source
    # triangle's side
    crossing: int
    own: LeafArg
    pull: float
    side_offset: float
    side_clear: float  # a quarter of side_offset: both sides clearly inside: an internal face (outside: a thin part)
    thin_side: int  # the side of a part thinner than the field sees (:data:`.ownside.THIN`)
    tiny: float  # how far a ray for a gap in front of a face starts off it (:mod:`.ownside`)


@wp.func
def _in_frame(leaf: LeafArg, x: wp.vec3) -> wp.vec3:
    """World point ``x`` in the leaf's own frame, as ``Placement.to_local`` takes it."""
    p = x
    if leaf.placed != 0:
        d = wp.vec3d(wp.float64(x[0]), wp.float64(x[1]), wp.float64(x[2])) - leaf.translation
        q = (wp.transpose(leaf.rotation) @ d) / leaf.scale
        p = wp.vec3(wp.float32(q[0]), wp.float32(q[1]), wp.float32(q[2]))
    return p


@wp.func
def _mls_value(leaf: LeafArg, x: wp.vec3) -> float:
    """The leaf's field at world point ``x`` by MLS, as ``field.sample(x)`` reads it."""
    phi = mls_value(leaf.field, _in_frame(leaf, x))
    if leaf.placed != 0:
        phi = phi * leaf.value_scale
    return phi


@wp.func
def _field_value(leaf: LeafArg, x: wp.vec3) -> float:
    """The leaf's field at world point ``x``, linear, as ``field.sample(x, method="linear")`` reads it."""
    p = _in_frame(leaf, x)
    f = leaf.field
    xc = clamp_to_domain(f, p)
    out = wp.length(p - xc)
    phi = sample_linear(f, xc)
    if out > 0.0:
        through = wp.max(phi, 0.0) + out
        at = locate_leaf(f, xc)
        direct = wp.length(p - node_proj(f, at[0], at[1]))
        phi = wp.max(wp.min(through, direct), out)
    if leaf.placed != 0:
        phi = phi * leaf.value_scale
    return phi


@wp.func
def _mesh_distance(mesh: wp.uint64, x: wp.vec3, reach: float) -> float:
    """Unsigned distance from ``x`` to the mesh, ``reach`` where it is farther."""
    d = reach
    q = wp.mesh_query_point_no_sign(mesh, x, reach)
    if q.result:
        d = wp.length(x - wp.mesh_eval_position(mesh, q.face, q.u, q.v))
    return d


@wp.func
def _sign_digit(value: float) -> int:
    """0, 1, 2 for a negative, zero, positive value."""
    return wp.where(value < 0.0, 0, wp.where(value > 0.0, 2, 1))


@wp.func
def _jumps_near(judge: JudgeArg, leaf: LeafArg, x: wp.vec3, sign: int) -> bool:
    """Whether the leaf's sign a band away from ``x`` along any axis differs from ``sign`` (its digit at ``x``): a
    field that jumps (across an open mesh's holes) counts as near there."""
    jumped = False
    for axis in range(6):
        if not jumped:
            step = wp.vec3(0.0)
            step[axis // 2] = wp.where(axis % 2 == 0, judge.probe, -judge.probe)
            jumped = _sign_digit(_field_value(leaf, x + step)) != sign
    return jumped


@wp.func
def _may_jump(judge: JudgeArg, leaf: LeafArg, x: wp.vec3, near: float) -> bool:
    """Whether the leaf's sign may change within a band of ``x`` (``near`` from its surface) but across it: near its
    defects, or below two bands where read off its field (a value overstates a distance; its mesh's does not)."""
    reach = 2.0 * judge.probe
    read_off_field = near < reach and leaf.mesh == wp.uint64(0)
    return read_off_field or leaf.jumps_anywhere != 0 or near_sphere(leaf.jump_bvh, leaf.jump_spheres, x, reach)


@wp.func
def reading(judge: JudgeArg, x: wp.vec3, reach: float) -> wp.vec2:
    """(the other leaves' sign pattern, the nearest of their surfaces and the leaf's defects, up to ``reach``) at
    ``x``. A sign is 0 where the value is 0: on a leaf with a BVH, where its surface passes through ``x``. The signs
    do not depend on ``reach``: a field that jumps is read at least a little over the band (its axis probes)."""
    code = int(0)
    margin = reach
    for j in range(judge.leaves.shape[0]):
        leaf = judge.leaves[j]
        value = _field_value(leaf, x)
        far = wp.where(leaf.jumps != 0, wp.max(reach, judge.probe_reach), reach)
        near = far
        sign = int(1)
        if leaf.mesh != wp.uint64(0):
            near = _mesh_distance(leaf.mesh, x, far)
            if wp.abs(value) < wp.min(near, float(judge.partly_at)) - leaf.sign_check:  # (:func:`.signed_again`)
                value = _mls_value(leaf, x)
            sign = wp.where(near == 0.0, 1, wp.where(value < 0.0, 0, 2))
        else:
            near = wp.abs(wp.clamp(value, -far, far))
            sign = _sign_digit(value)
        if leaf.jumps != 0 and near > judge.probe and _may_jump(judge, leaf, x, near):
            if _jumps_near(judge, leaf, x, sign):
                near = 0.0
        margin = wp.min(margin, near)
        code += sign * leaf.weight
    if judge.defect_mesh != wp.uint64(0):
        margin = wp.min(margin, _mesh_distance(judge.defect_mesh, x, reach))
    return wp.vec2(float(code), margin)


@wp.kernel(enable_backward=False)
def _read_vertices_kernel(
    judge: JudgeArg,
    verts: wp.array[wp.vec3],
    used: wp.array[wp.int64],
    reach: float,
    again: int,
    offset: int,
    read: wp.array[wp.int8],
    codes: wp.array[wp.int32],
    margins: wp.array[wp.float32],
):
    """The reading (:func:`reading`, up to ``reach``) at each used vertex not read in an earlier round (``again``
    1: at every one)."""
    v = used[wp.tid() + offset]
    if read[v] != wp.int8(0) and again == 0:
        return
    r = reading(judge, verts[v], reach)
    codes[v] = int(r[0])
    margins[v] = r[1]
    read[v] = wp.int8(1)


@wp.func
def _fold(judge: JudgeArg, code: int, margin: float, bounds: wp.vec2) -> wp.vec2:
    """(least, most) over a piece's samples so far with one more: its margin where the expression crosses, else -1."""
    m = wp.where((int(judge.table[code]) & 1) != 0, margin, -1.0)
    return wp.vec2(wp.min(bounds[0], m), wp.max(bounds[1], m))


@wp.func
def _norm(v: wp.vec3) -> float:
    """The length of ``v`` as numpy's ``linalg.norm`` finds it (squares added in turn)."""
    x = v[0] * v[0]
    y = v[1] * v[1]
    z = v[2] * v[2]
    return wp.sqrt((x + y) + z)


@wp.func
def _unit_normal(p0: wp.vec3, p1: wp.vec3, p2: wp.vec3) -> wp.vec3:
    """The triangle's unit normal as :func:`.trimeasures.unit_normals` finds it (float32 cross, float64 normalised)."""
    e = p1 - p0
    f = p2 - p0
    n = wp.vec3d(
        wp.float64(e[1] * f[2] - e[2] * f[1]),
        wp.float64(e[2] * f[0] - e[0] * f[2]),
        wp.float64(e[0] * f[1] - e[1] * f[0]),
    )
    x = n[0] * n[0]
    y = n[1] * n[1]
    z = n[2] * n[2]
    size = wp.max(wp.sqrt((x + y) + z), wp.float64(1.0e-30))
    return wp.vec3(wp.float32(n[0] / size), wp.float32(n[1] / size), wp.float32(n[2] / size))


@wp.func
def _side_of(judge: JudgeArg, x: wp.vec3, n: wp.vec3) -> int:
    """The leaf's own side across ``x`` along ``n`` (:func:`.ownside.side_at`): 1 growing, -1 falling, 0 internal."""
    step = judge.side_offset * n
    front = _field_value(judge.own, x + step)
    back = _field_value(judge.own, x - step)
    if wp.min(front, back) > judge.side_clear:  # a part thinner than the field sees
        return judge.thin_side
    internal = wp.max(front, back) < -judge.side_clear
    if internal:  # or the wall of a gap narrower than the field sees (:mod:`.ownside`)
        return gap_side(judge.own.mesh, x, n, front, back, judge.side_offset, judge.tiny, judge.thin_side)
    return wp.where(front >= back, 1, -1)


@wp.func
def _fold_side(judge: JudgeArg, sides: int, x: wp.vec3, centre: wp.vec3, n: wp.vec3, side: int) -> int:
    """``sides`` (1: some sample's side differs from the centre's ``side``, 2: some sample's is not 0) with the
    sample at ``x``, read pulled a voxel towards the centre (not read within a voxel of it)."""
    towards = centre - x
    length = _norm(towards)
    if length <= judge.pull:
        return sides
    at = _side_of(judge, x + towards * (judge.pull / length), n)
    return sides | wp.where(at != side, 1, 0) | wp.where(at != 0, 2, 0)


@wp.func
def _keeps(judge: JudgeArg, same: bool, bounds: wp.vec2, slack: wp.float64, side: int, sides: int) -> bool:
    """Whether a piece may still be kept: the same signs at every sample so far, a margin above its band where the
    expression crosses, its own field crossing it (its centre's side, not 0, everywhere). Only ever turns false."""
    return same and wp.float64(bounds[0]) > judge.band + slack and side != 0 and (sides & 1) == 0


@wp.func
def _partly(judge: JudgeArg, bounds: wp.vec2, slack: wp.float64, side: int, sides: int) -> bool:
    """Whether a piece is partly keepable (a margin above the partly keepable one, its own field crossing it
    somewhere): only ever turns true."""
    return wp.float64(bounds[1]) + _partly_slack(judge, slack) > judge.partly_at and (side != 0 or (sides & 2) != 0)


@wp.func
def _partly_slack(judge: JudgeArg, slack: wp.float64) -> wp.float64:
    """What a piece's largest margin is raised by before it is compared with ``partly_at`` (keep's
    ``_Judge.partly_slack``): its slack where larger than the least, else 0."""
    return wp.where(
        slack > judge.partly_at - judge.band + wp.float64(PARTLY_TIE) * judge.spacing, slack, wp.float64(0.0)
    )


@wp.kernel(enable_backward=False)
def _judge_pieces_kernel(
    judge: JudgeArg,
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int64],
    turn: wp.array[wp.int64],
    longest: wp.array[wp.float64],
    parent: wp.array[wp.int64],
    codes: wp.array[wp.int32],
    margins: wp.array[wp.float32],
    defects: wp.array[wp.int8],
    side: wp.array[wp.int8],
    full_reach: float,
    offset: int,
    verdicts: wp.array[wp.int8],
    nearest: wp.array[wp.float32],
):
    """A piece's verdict bits (:class:`FusedJudge`) from its corners' readings and its rows' (read here, while they
    can change the verdict). A sample is read as far as the piece's checks look: a margin beyond them passes them
    whatever it is (a piece that may be kept: over its band and slack, one that may not: over the partly keepable
    margin). With a ``full_reach`` (above 0), distances are recorded (``nearest``, and the bits SIGNS_ONLY_BIT,
    OWN_ONLY_BIT, set only where every sample was read): the corners and a piece of few samples have each read that
    far; a piece of many, a few voxels across, its centre that far and its farthest corner's distance, a bound of
    its samples' (Lipschitz's: a few voxels looser, where reading each would cost most)."""
    t = wp.tid() + offset
    slack = wp.max(longest[t] / wp.float64(8.0), judge.spacing) * judge.slack_share
    keep_reach = wp.float32(judge.band + slack + judge.pad)
    partly_reach = wp.float32(wp.max(judge.partly_at - _partly_slack(judge, slack), wp.float64(0.0)) + judge.pad)
    full = full_reach > 0.0
    least = float(1.0e30)  # the least margin of the samples read as far as recorded
    first = codes[tris[t, 0]]
    same = True
    bounds = wp.vec2(1.0e30, -1.0e30)
    p0 = verts[tris[t, 0]]
    p1 = verts[tris[t, 1]]
    p2 = verts[tris[t, 2]]
    n = _unit_normal(p0, p1, p2)
    centre = ((p0 + p1) + p2) / 3.0
    own = int(side[parent[t]])
    if judge.crossing != 0:
        own = _side_of(judge, centre, n)
    sides = int(0)
    for corner in range(3):
        v = tris[t, corner]
        margin = margins[v]
        if not full and margin >= judge.corner_reach and keep_reach > judge.corner_reach:  # a large piece's: read on
            margin = reading(judge, verts[v], keep_reach)[1]
        least = wp.min(least, margin)
        same = same and codes[v] == first
        bounds = _fold(judge, codes[v], margin, bounds)
        if judge.crossing != 0:
            sides = _fold_side(judge, sides, verts[v], centre, n, own)
    keeps = _keeps(judge, same, bounds, slack, own, sides)
    # a shell that crosses itself may be crossed by its own field at a later sample
    may_cross = own != 0 or judge.crossing != 0
    live = defects[parent[t]] == wp.int8(0) and (keeps or (may_cross and not _partly(judge, bounds, slack, own, sides)))
    k = int(turn[t])
    a = verts[tris[t, k]]
    b = verts[tris[t, (k + 1) % 3]]
    c = verts[tris[t, (k + 2) % 3]]
    step = wp.float32(slack * judge.sample_share)
    grid = row_grid(a, b, c, step)
    rows = int(grid[1])
    first_steps = row_steps(0.0, grid[0], step)
    inner = rows > 1 or first_steps > 1  # samples besides the corners
    # distances recorded (``full``): a piece of few samples has each read that far; one of many, its centre
    spread = wp.max(wp.max(wp.length(p0 - centre), wp.length(p1 - centre)), wp.length(p2 - centre))
    small = wp.float64(spread) <= wp.float64(CENTRE_SPREAD) * judge.spacing
    dense = full and rows * (first_steps + 2) > 2 * CENTRE_SAMPLES and small
    if full and not dense:
        keep_reach = full_reach
        partly_reach = full_reach
        live = True
    complete = live or not inner  # every sample read (or the piece was given up with rows unread)
    r = int(0)
    while live and r < rows:
        s = float(r) / float(rows)
        steps = row_steps(s, grid[0], step)
        i = int(0)
        while live and i <= steps:
            if r > 0 or (i > 0 and i < steps):
                x = row_point(a, b, c, s, i, steps)
                got = reading(judge, x, wp.where(keeps, keep_reach, partly_reach))
                same = same and int(got[0]) == first
                bounds = _fold(judge, int(got[0]), got[1], bounds)
                if not dense:
                    least = wp.min(least, got[1])
                if judge.crossing != 0:
                    sides = _fold_side(judge, sides, x, centre, n, own)
                keeps = _keeps(judge, same, bounds, slack, own, sides)
                live = (full and not dense) or keeps or not _partly(judge, bounds, slack, own, sides)
            i += 1
        r += 1
    bits = int(0)
    if keeps and defects[parent[t]] == wp.int8(0):
        bits = KEPT_BIT
    if _partly(judge, bounds, slack, own, sides) and defects[parent[t]] == wp.int8(0):
        bits = bits | PARTLY_BIT
    if ((int(judge.table[first]) & 2) != 0) != (own < 0):
        bits = bits | FLIP_BIT
    if bounds[1] < 0.0 and complete:
        bits = bits | SIGNS_ONLY_BIT
    if defects[parent[t]] != wp.int8(0) or (complete and not (own != 0 or (sides & 2) != 0)):
        bits = bits | OWN_ONLY_BIT
    verdicts[t] = wp.int8(bits)
    if dense:  # its samples lie within the farthest corner's distance of the centre
        least = wp.min(least, reading(judge, centre, full_reach + spread)[1] - spread)
    nearest[t] = least


# ---- the fused judge ----
def leaf_arg(field, bvh, rank: int, jumps=None) -> LeafArg:
    """A :class:`LeafArg` of an other leaf ``field`` (its ``bvh`` or None, where its field jumps: ``jumps``, a
    :class:`.jumps.JumpSpheres` or None), the ``rank``-th of the other leaves."""
    arg = LeafArg()
    arg.field = field.arg()
    arg.mesh = wp.uint64(bvh.id if bvh is not None else 0)
    placed = field.placement
    arg.placed = int(placed is not None)
    arg.rotation = wp.mat33d(*(placed.rotation.ravel() if placed is not None else np.eye(3).ravel()))
    arg.translation = wp.vec3d(*(placed.translation if placed is not None else np.zeros(3)))
    arg.scale = wp.float64(placed.scale if placed is not None else 1.0)
    arg.value_scale = float(np.float32(placed.scale)) if placed is not None else 1.0
    arg.jumps = int(jumps is not None)
    spheres = jumps if jumps is not None else JumpSpheres(np.zeros((0, 4), np.float32), field.device)
    arg.jump_bvh, arg.jump_spheres, arg.jumps_anywhere = spheres.bvh_id, spheres.spheres, int(spheres.anywhere)
    arg.weight = 3**rank
    arg.sign_check = sign_check(field)
    return arg


def sign_patterns(n: int) -> np.ndarray:
    """(3^n, n) int8 every pattern of ``n`` signs (-1, 0, 1), pattern ``sum((sign + 1) * 3^k)`` at that row."""
    return ((np.arange(3**n)[:, None] // 3 ** np.arange(n)[None, :]) % 3 - 1).astype(np.int8)


@dataclass
class FusedJudge:
    """The fused path of a leaf's judge (module docstring): the other leaves (``(field, bvh, jumps)``), the table of
    what the expression makes of their signs (:func:`sign_patterns`' rows: 1 it crosses with the leaf, 2 and the
    result's inside is on the leaf's outside), the leaf's own defects' mesh (or None), the band, the least spacing
    of samples, its slack and the slack per unit of spacing, and per source triangle whether it is a defect and its
    side."""

    others: list
    table: np.ndarray
    defect_mesh: object
    band: float
    spacing: float
    slack: float
    slack_share: float
    sample_share: float
    defects: np.ndarray  # (T,) bool
    side: np.ndarray  # (T,) int8
    own: object  # the judged leaf's field
    crossing: bool  # its shell crosses itself: its side read at every sample, ``side_offset`` off
    side_offset: float
    thin_side: int
    device: object
    own_rays: object = None  # the BVH of the judged leaf's own mesh (gaps narrower than its field sees), or None
    ray_start: float = 0.0  # how far a ray for such a gap starts off a face

    def __post_init__(self):
        self.leaf_args = [leaf_arg(*other[:2], k, other[2]) for k, other in enumerate(self.others)]  # kept alive
        arg = JudgeArg()
        arg.leaves = wp.array(self.leaf_args, dtype=LeafArg, device=self.device)
        arg.defect_mesh = wp.uint64(self.defect_mesh.id if self.defect_mesh is not None else 0)
        arg.table = wp.array(self.table.astype(np.int8), dtype=wp.int8, device=self.device)
        arg.band, arg.spacing, arg.slack_share = self.band, self.spacing, self.slack_share
        arg.sample_share = self.sample_share
        arg.partly_at, arg.pad = self.band + self.slack, READ_PAD * self.spacing
        arg.probe, arg.probe_reach = self.band, self.band + arg.pad
        arg.corner_reach = self.band + self.slack + arg.pad
        arg.crossing, arg.own = int(self.crossing), leaf_arg(self.own, self.own_rays, 0)
        arg.pull, arg.side_offset, arg.side_clear = self.spacing, self.side_offset, 0.25 * self.side_offset
        arg.thin_side, arg.tiny = self.thin_side, self.ray_start
        self.arg = arg
        self.defects_wp = wp.array(self.defects.astype(np.int8), dtype=wp.int8, device=self.device)
        self.side_wp = wp.array(self.side.astype(np.int8), dtype=wp.int8, device=self.device)
        self.read = wp.zeros(0, dtype=wp.int8, device=self.device)
        self.codes = wp.zeros(0, dtype=wp.int32, device=self.device)
        self.margins = wp.zeros(0, dtype=wp.float32, device=self.device)

    def __call__(self, verts, tris, parent, longest, turn, beyond: float | None = None):
        """Per piece (``tris`` (T, 3) int64 of ``verts`` (V, 3) float32, in source triangles ``parent``, ``longest``
        and ``turn`` their :func:`edge_turns`): ``(kept, partly, flip, found)``, as keep's general path finds them.
        With ``beyond``, distances up to ``beyond`` farther than the round's largest piece needs are recorded, and
        ``found`` is what keep's general path records (``margin``, ``signs_only``, ``own_only``; else None), with
        ``margin`` a bound of its samples' least distance (:func:`_judge_pieces_kernel`: a piece of many samples
        has its centre read), and the bits set only where they hold for certain.
        Successive calls pass the vertices of one mesh that only grows (vertices appended): a vertex is read once
        (again where distances are recorded)."""
        device = self.device
        if not len(tris):
            empty = np.zeros(0, dtype=bool)
            return empty, empty, empty, self._found(np.zeros(0, np.int8), np.zeros(0, np.float32), beyond)
        full_reach = 0.0
        if beyond is not None:
            slack = np.maximum(longest / 8.0, self.spacing) * self.slack_share
            full_reach = self.band + float(slack.max()) + self.spacing + beyond
        verts_wp = host_view(np.ascontiguousarray(verts, dtype=np.float32), wp.vec3, device)
        self._read_corners(verts_wp, tris, full_reach)
        pieces = [host_view(np.ascontiguousarray(a, dtype=np.int64), wp.int64, device) for a in (tris, turn)]
        pieces += [host_view(np.ascontiguousarray(longest, dtype=np.float64), wp.float64, device)]
        pieces += [host_view(np.ascontiguousarray(parent, dtype=np.int64), wp.int64, device)]
        verdicts = wp.empty(len(tris), dtype=wp.int8, device=device)
        nearest = wp.empty(len(tris), dtype=wp.float32, device=device)
        arrays = [self.codes, self.margins, self.defects_wp, self.side_wp]
        launch_split(
            _judge_pieces_kernel,
            len(tris),
            lambda lo, _n: [self.arg, verts_wp, *pieces, *arrays, full_reach, lo, verdicts, nearest],
            device,
        )
        bits = verdicts.numpy()
        found = self._found(bits, nearest.numpy(), beyond)
        return (bits & KEPT_BIT) != 0, (bits & PARTLY_BIT) != 0, (bits & FLIP_BIT) != 0, found

    @staticmethod
    def _found(bits, nearest, beyond) -> dict | None:
        if beyond is None:
            return None
        return {
            "margin": nearest.astype(np.float64),
            "signs_only": (bits & SIGNS_ONLY_BIT) != 0,
            "own_only": (bits & OWN_ONLY_BIT) != 0,
        }

    def _read_corners(self, verts_wp, tris, full_reach: float) -> None:
        """Read the vertices ``tris`` use that no earlier call read (the per-vertex arrays grown to ``verts_wp``); with
        a ``full_reach`` (above 0) every one, that far."""
        n = verts_wp.shape[0]
        if n > self.read.shape[0]:
            size = max(n, 2 * self.read.shape[0])
            for name, dtype in (("read", wp.int8), ("codes", wp.int32), ("margins", wp.float32)):
                old, grown = getattr(self, name), wp.zeros(size, dtype=dtype, device=self.device)
                wp.copy(grown, old, count=old.shape[0])
                setattr(self, name, grown)
        used = np.zeros(n, dtype=bool)
        used[tris] = True
        used_wp = host_view(np.flatnonzero(used), wp.int64, self.device)
        reach, again = (full_reach, 1) if full_reach > 0.0 else (self.arg.corner_reach, 0)
        launch_split(
            _read_vertices_kernel,
            used_wp.shape[0],
            lambda lo, _n: [self.arg, verts_wp, used_wp, reach, again, lo, self.read, self.codes, self.margins],
            self.device,
        )
