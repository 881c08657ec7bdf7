"""Booleans between adaptive fields (Ren et al., Sec. 5), closed: the result is a field of the same kind.

The result's finest level is the union of both operands' finest levels on the result lattice (origin = the lower
corner of both domains, Eq. 11, snapped to the shared world origin). An operand with the result's spacing is
node-aligned and contributes its exact node values; an operand with another spacing has its finest level rebuilt
at the result's spacing from its own cells (the paper's "cells as primitives"), its values sampled by MLS. Each finest
node then takes ``op(phi_a, phi_b)`` (Eq. 8 with negative inside: union = min, intersection = max, difference =
max(a, -b)), or a round or chamfer blend of it when ``blend > 0`` (:mod:`.blends`). The intermediate and top levels are
rebuilt bottom-up with the construction's own structure code (parents + siblings, dense top), their values sampled from
the operands.
"""

from __future__ import annotations

import math
import threading
import time
from functools import partial
from typing import TYPE_CHECKING

import numpy as np
import warp as wp
import warp.geometry

from . import octree, parallel
from .blends import BLEND_MODES, chamfer_needs, lipschitz, sdf_combine
from .blendzone import blend_octets
from .closure import closed, needs_closure
from .earlyjudge import start_judge
from .errors import AasdfError
from .expression import OP_DIFFERENCE, OP_INTERSECTION, OP_UNION, combined
from .layout import level_layout
from .octree import MAX_CELLS_PER_AXIS, code_bits, morton_decode, node_center
from .ondemand import along_seams_only, for_boolean, seam_octets
from .operands import (
    blend_sample,
    estimate,
    extrapolate,
    finest_bracket,
    finest_sample,
    leaf_estimate,
    lookup_node,
    mesh_sample,
    octet_leaf,
)
from .plan import byte_grid_fits, check_budget, check_resolvable, check_voxel_size, plan_domain
from .prune import KEEP_BAND, offset_to, operand_octets, prune_octets
from .sampling import FieldArg, clamp_to_domain, locate_leaf, node_source, to_frame, vec27i

if TYPE_CHECKING:  # the field type imports this module for its operators
    from .field import AdaptiveField

# Consecutive nodes per thread of the combination (an octet on the sparse levels).
COMBINE_GROUP = 8
# Rounds of octets added about a surface read off a blended boolean (:mod:`.closure`): one or two are met.
CLOSURE_ROUNDS = 4


@wp.kernel(enable_backward=False)
def _combine_nodes_kernel(
    a: FieldArg,
    b: FieldArg,
    a_aligned: int,
    b_aligned: int,
    a_offset: wp.vec3i,
    b_offset: wp.vec3i,
    codes: wp.array[wp.int64],
    first: int,
    end: int,
    group: int,
    sparse: int,
    origin: wp.vec3,
    spacing: float,
    op: int,
    blend: float,
    mode: int,
    walk: wp.vec2i,
    precise: int,
    proj: wp.array[wp.vec3h],
    source: wp.array[wp.int32],
    values: wp.array[wp.float32],
    tri: wp.array[wp.int32],
    a_octets: int,
    b_octets: int,
    a_first: wp.array[wp.int32],
    b_first: wp.array[wp.int32],
):
    """Value of the boolean at nodes [first, end) of one level, ``group`` consecutive nodes per thread (an octet on
    the sparse levels): both operands looked up or sampled, then combined. The operand whose value the
    combination follows gives the projection point and the source id. On the finest level, ``a_first``/``b_first``
    give each result octet's first node in an operand whose octets coincide with the result's
    (``a_octets``/``b_octets``), found by the bracket pass. The
    nodes of a group mostly share an operand's coarse leaf, whose neighbours an MLS sample reads: they are gathered
    once per leaf."""
    i0 = first + group * wp.tid()
    i1 = wp.min(i0 + group, end)
    cached_a = int(-1)
    count_a = int(0)
    ids_a = vec27i()
    levels_a = vec27i()
    cached_b = int(-1)
    count_b = int(0)
    ids_b = vec27i()
    levels_b = vec27i()
    foot_a = wp.vec3(0.0)  # the last exact closest point on each operand's mesh (``mesh_sample``)
    foot_b = wp.vec3(0.0)
    has_a = int(0)
    has_b = int(0)
    # a group of 8 on a sparse level is one octet (its first node's code decoded, its siblings offset from it)
    c0 = morton_decode(codes[i0])
    octet = sparse == 1 and group == 8 and i1 - i0 == 8
    for i in range(i0, i1):
        c = c0
        if octet:
            k = i - i0
            c = c0 + wp.vec3i(k & 1, (k >> 1) & 1, (k >> 2) & 1)
        else:
            c = morton_decode(codes[i])
        x = node_center(origin, spacing, c)
        # Exact node values where the lattices align; elsewhere a cheap bracket from the containing coarse leaf, and
        # the MLS sample only when that operand can decide the result (its bracket overlaps the other's within
        # blend).
        fa, va, ga, ja = lookup_node(a, a_aligned, a_offset, c, x, a_octets, a_first, i)
        fb, vb, gb, jb = lookup_node(b, b_aligned, b_offset, c, x, b_octets, b_first, i)
        # each operand's node the value came from, where a look-up below finds one (for the source id): on coarse
        # levels the operand's node of that level at x (or its coarser leaf), on the finest its leaf containing x
        leaf_a = wp.vec2i(-1, 0)
        leaf_b = wp.vec2i(-1, 0)
        if precise == 0:
            # coarse levels: each operand's containing leaf, extrapolated along its gradient
            if fa == 0:
                r, node_a = extrapolate(a, x, spacing)
                leaf_a = wp.vec2i(node_a, 0)
                va = r[0]
                ga = wp.vec3(r[1], r[2], r[3])
            if fb == 0:
                r, node_b = extrapolate(b, x, spacing)
                leaf_b = wp.vec2i(node_b, 0)
                vb = r[0]
                gb = wp.vec3(r[1], r[2], r[3])
        else:
            rad_a = float(0.0)
            rad_b = float(0.0)
            if fa == 0:
                known = octet_leaf(a_octets, a_first, i)
                if known[0] >= 0:
                    va, rad_a, leaf_a = leaf_estimate(a, x, known)
                else:
                    va, rad_a, leaf_a = estimate(a, x)
            if fb == 0:
                known = octet_leaf(b_octets, b_first, i)
                if known[0] >= 0:
                    vb, rad_b, leaf_b = leaf_estimate(b, x, known)
                else:
                    vb, rad_b, leaf_b = estimate(b, x)
            # in an operand's finest band: its finest node's bracket first, the trilinear sample only where needed
            fine_a = int(0)
            fine_b = int(0)
            if rad_a < 0.0:
                va, rad_a = finest_bracket(a, x, leaf_a[0])
                fine_a = 1
            if rad_b < 0.0:
                vb, rad_b = finest_bracket(b, x, leaf_b[0])
                fine_b = 1
            # bracket of the second argument as the operation sees it (difference uses -b)
            tb = vb
            if op == 2:
                tb = -vb
            need_a = int(1)
            need_b = int(1)
            if mode == 1:
                needs = chamfer_needs(op, va, rad_a, tb, rad_b, blend)
                need_a = needs[0]
                need_b = needs[1]
            elif op == 0:
                if tb - rad_b >= va + rad_a + blend:
                    need_b = 0
                elif va - rad_a >= tb + rad_b + blend:
                    need_a = 0
            else:
                if tb + rad_b <= va - rad_a - blend:
                    need_b = 0
                elif va + rad_a <= tb - rad_b - blend:
                    need_a = 0
            if need_a == 1 and (fine_a == 1 or rad_a > 0.0):
                found = int(0)
                # a mesh's own distance where the node's sign holds at x (a coarse leaf's always does)
                if a.mesh != wp.uint64(0) and (fine_a == 0 or wp.abs(va) > rad_a):
                    found, r, foot_a = mesh_sample(a, x, leaf_a, foot_a, has_a)
                    has_a = wp.max(has_a, found)
                if found == 0 and fine_a == 1:
                    r = finest_sample(a, x)
                elif found == 0:
                    r, cached_a, count_a, ids_a, levels_a = blend_sample(
                        a, walk[0], x, leaf_a, cached_a, count_a, ids_a, levels_a
                    )
                va = r[0]
                ga = wp.vec3(r[1], r[2], r[3])
            if need_b == 1 and (fine_b == 1 or rad_b > 0.0):
                found = int(0)
                # a mesh's own distance where the node's sign holds at x (a coarse leaf's always does)
                if b.mesh != wp.uint64(0) and (fine_b == 0 or wp.abs(vb) > rad_b):
                    found, r, foot_b = mesh_sample(b, x, leaf_b, foot_b, has_b)
                    has_b = wp.max(has_b, found)
                if found == 0 and fine_b == 1:
                    r = finest_sample(b, x)
                elif found == 0:
                    r, cached_b, count_b, ids_b, levels_b = blend_sample(
                        b, walk[1], x, leaf_b, cached_b, count_b, ids_b, levels_b
                    )
                vb = r[0]
                gb = wp.vec3(r[1], r[2], r[3])
        ra = wp.vec4(va, ga[0], ga[1], ga[2])
        rb = wp.vec4(vb, gb[0], gb[1], gb[2])
        phi = sdf_combine(op, ra[0], rb[0], blend, mode)
        b_term = rb[0]
        if op == 2:
            b_term = -rb[0]
        use_a = wp.abs(phi - ra[0]) <= wp.abs(phi - b_term)
        r = rb
        follow = b
        node = jb
        leaf = leaf_b[0]
        if use_a:
            r = ra
            follow = a
            node = ja
            leaf = leaf_a[0]
        g = wp.vec3(r[1], r[2], r[3])
        proj[i] = wp.vec3h(-r[0] * g / spacing)  # the closest point x - phi g, as an offset from x in spacings
        values[i] = phi
        if precise == 0:  # a coarse node: signed zero is positive (no surface to take a side of)
            values[i] = wp.where(phi < 0.0, -1.0, 1.0) * wp.abs(phi)
        if node < 0:
            node = leaf
        if node < 0:
            node = locate_leaf(follow, clamp_to_domain(follow, to_frame(follow, x)))[0]
        source[i] = node_source(follow, node)
        if precise == 1:  # a finest node: the closest triangle of the operand's node the value came from
            tri[i] = -1
            if node < follow.fine_count and follow.tri.shape[0] > 0:
                tri[i] = follow.tri[node]


def continuous(f) -> bool:
    """Whether a field has no jumps: a closed, clean mesh's, a re-distanced one, a boolean of such fields (an open
    mesh's field jumps across its holes, where the winding number's sign flips)."""
    return bool(f.stats.get("continuous", f.stats.get("clean_mesh", False) or f.stats.get("exact_distance", False)))


def _check_operands(a, b, blend):
    for name, f in (("a", a), ("b", b)):
        if not callable(getattr(f, "arg", None)) or not hasattr(f, "level_offsets"):
            raise TypeError(f"Expected '{name}' to be an AdaptiveField, but got {type(f).__name__}.")
    blend = float(blend)
    if not math.isfinite(blend) or blend < 0.0:
        raise ValueError(f"Expected a non-negative 'blend', but got {blend}.")
    if a.device != b.device:
        raise ValueError(f"Both fields must live on the same device, but got {a.device} and {b.device}.")
    return blend


class BooleanRefiner:
    """What a boolean of fields built on demand keeps: its operands and options, to give the whole result (its
    finest octets wherever its surface may pass) where it was made along its seams alone (:mod:`.ondemand`)."""

    def __init__(self, a, b, op: int, options: dict):
        self.a, self.b, self.op, self.options = a, b, op, options
        self.whole = None
        self.lock = threading.Lock()

    def along_seams(self):
        """The result made along its seams again (its operands refined since: their octets there too)."""
        return combine(self.a, self.b, self.op, **self.options, seams=True)

    def asked(self, points, reach):
        """The whole result (whatever is asked of it: a boolean's seams hold no surface elsewhere)."""
        with self.lock:
            if self.whole is None:
                self.whole = combine(self.a, self.b, self.op, **self.options, seams=False)
            return self.whole


def combine(
    a: AdaptiveField,
    b: AdaptiveField,
    op: int,
    *,
    blend: float = 0.0,
    spacing: str = "finer",
    blend_mode="round",
    seams: bool = False,
):
    """Boolean of two fields; ``op`` is OP_UNION, OP_INTERSECTION or OP_DIFFERENCE (a minus b).

    Args:
        a, b: Operands (any built field or boolean result).
        op: Which operation.
        blend: Size of the blend along the seam (world units); 0 = hard.
        blend_mode: ``"round"`` (a polynomial smooth minimum / maximum of radius ``blend``) or ``"chamfer"`` (a flat
            bevel meeting each face ``blend`` from the seam where the faces meet at a right angle).
        spacing: ``"finer"`` (default), ``"coarser"``, ``"a"`` or ``"b"``: whose finest spacing the result takes
            (where the operands are placed: ``world_voxel_size``); ``"built"``: the finer of the spacings they were
            built at, a placed one's unscaled (fields built at one voxel size and placed at scales about 1 give the
            result that size, each one in place keeping its nodes; the finer placed one's would resample them all).
        seams: Where an operand was built on demand (``build_field(refine=...)``), build the result's finest
            octets along its seams alone (:func:`.ondemand.for_boolean`), as kept faces read them; it keeps a
            :class:`BooleanRefiner` to give any other query the whole result.
    Returns:
        A new AdaptiveField whose node sources carry the operands' field ids.
    Raises:
        TypeError, ValueError: On wrong operands or options.
        AasdfError: If the combined domain would not fit in memory, or lies so far from the world origin that float32
            cannot resolve its voxels (:func:`.plan.check_resolvable`), or its voxels are below
            :data:`.plan.MIN_VOXEL_SIZE`.
    """
    blend, mode, h = _options(a, b, blend, blend_mode, spacing)
    # refused before any work (the kept faces' judge split pieces float32 cannot tell apart, round after round)
    check_voxel_size(h)
    check_resolvable(np.minimum(a.bounds[0], b.bounds[0]), np.maximum(a.bounds[1], b.bounds[1]), h)
    asked = (a, b, op, {"blend": blend, "spacing": spacing, "blend_mode": blend_mode})
    early = start_judge(combined(op, blend, a, b), h, a.device) if seams else None  # its kept faces' judge, beside
    expression = None
    try:  # built on demand: the octets it needs (:mod:`.ondemand`)
        a, b, seams = for_boolean(a, b, op, blend, seams=seams)
        if seams and early is not None and early.crossed_ahead():  # along all of such an operand's crossings too
            a, b, seams = for_boolean(*asked[:3], blend, seams=seams)
        # a sparse finest level under a dense top one, even when both operands are dense (one level)
        levels, timings = max(a.levels, b.levels, 2), {}
        origin, top_dims = _domain(a, b, h, levels, mode, blend)  # (a domain too large is refused: no judge)
        expression = combined(op, blend, a, b)
    finally:
        if early is not None:  # the judge goes on with the refined operands (or stops)
            early.proceed(expression if seams else None)
    aligned, args, grid = [_aligned(f, origin, h) for f in (a, b)], (a.arg(), b.arg()), (origin, top_dims, levels)
    finest, pruned = _finest(a, b, args, aligned, grid, h, (op, blend, mode), seams, timings)
    walk = wp.vec2i(*(int(mode == 1 and f.stats.get("surface_points", False)) for f in (a, b)))
    closure = pruned if needs_closure(a, b, blend) else None  # (octets the values need about the surface: added)
    layout, nodes = _laid_out(finest, closure, grid[1:], args, aligned, origin, h, (op, blend, mode, walk), timings)
    slope = lipschitz(mode, blend, *(f.stats.get("lipschitz", 1.0) for f in (a, b)))  # (more than 1: chamfers)
    result = type(a).from_layout(
        layout, voxel_size=h, origin=origin, **nodes, field_ids=a.field_ids + b.field_ids, timings=timings,
        sources={**a.world_sources(), **b.world_sources()},
        stats={"continuous": not finest["jumps"], "lipschitz": slope},
    )  # fmt: skip
    result.expression = expression  # what it was made of, for the faces it keeps (:mod:`.keep`)
    result.early_judge = early if seams else None
    result.refiner = BooleanRefiner(*asked) if seams else None  # (the whole result, asked anything else)
    return result


def _aligned(f, origin, h: float) -> bool:
    """Whether operand ``f``'s nodes lie on the result's lattice (a placed operand is resampled from its cells, never
    aligned)."""
    if f.placement is not None or not np.isclose(f.voxel_size, h, rtol=1e-6, atol=0.0):
        return False
    return bool(np.allclose((f.origin - origin) / h, np.rint((f.origin - origin) / h), atol=1e-3))


def _options(a, b, blend, blend_mode, spacing) -> tuple:
    """(blend, mode, finest spacing) of a boolean, checked."""
    blend = _check_operands(a, b, blend)
    if blend_mode not in BLEND_MODES:
        raise ValueError(f"Expected 'blend_mode' to be one of {sorted(BLEND_MODES)}, but got {blend_mode!r}.")
    mode = BLEND_MODES[blend_mode] if blend > 0.0 else 0  # no blend: the hard min / max either way
    choices = {
        "finer": min(a.world_voxel_size, b.world_voxel_size),
        "built": min(a.voxel_size, b.voxel_size),
        "coarser": max(a.world_voxel_size, b.world_voxel_size),
        "a": a.world_voxel_size,
        "b": b.world_voxel_size,
    }
    if spacing not in choices:
        raise ValueError(f"Expected 'spacing' to be one of {sorted(choices)}, but got {spacing!r}.")
    return blend, mode, choices[spacing]


def _domain(a, b, h: float, levels: int, mode: int, blend: float) -> tuple:
    """(origin, top dims) of the result's domain: both operands' boxes, grown by where a blend may fill outside them
    (up to blend / 4 for a round one, blend / 2 for a chamfer's plane); refused when it would not fit."""
    (a_lo, a_hi), (b_lo, b_hi) = a.bounds, b.bounds
    lo, hi = np.minimum(a_lo, b_lo), np.maximum(a_hi, b_hi)
    reach = (0.5 if mode == 1 else 0.25) * blend
    span = float(np.max(hi - lo) + 2.0 * reach) / h
    if blend > 0.0 and not span < MAX_CELLS_PER_AXIS - 1:  # (Blender's largest float as a blend: no plan at all)
        raise AasdfError(
            f"A blend of {blend:g} needs a domain of {span:.4g} finest cells along an axis, more than the "
            f"{MAX_CELLS_PER_AXIS - 1} the octree can address; use a smaller blend or a larger voxel size."
        )
    origin, top_dims = plan_domain(lo, hi, h, levels, reach / h + 1.0 if blend > 0.0 else 0.0)
    check_budget(top_dims * 2 ** (levels - 1), int(np.prod(top_dims)), 8 * (a.level_counts[0] + b.level_counts[0]))
    return origin, top_dims


def _finest(a, b, args, aligned, grid, h: float, how: tuple, seams: bool, timings: dict) -> tuple:
    """The result's finest octets (:func:`_pruned`'s dict): the candidates (:func:`_candidate_octets`, and where a blend
    shapes the surface, away from both operands' own octets) pruned, keeping the result adaptive: the octets its
    surface is far from dropped before any interpolation. Also the pruning of other octets (``pruned(codes, band)``).
    ``grid``: origin, top dims and levels; ``how``: op, blend, mode."""
    (origin, top_dims, levels), (op, blend, mode) = grid, how
    t0 = time.perf_counter()
    octets = _candidate_octets(
        (a, b), aligned, origin, h, top_dims * 2 ** (levels - 1), a.device, seams=seams, blend=blend
    )
    if blend > 0.0:
        zone = blend_octets(*args, origin, h, top_dims, levels, op, blend, mode, KEEP_BAND * h)
        octets = octree.merge_unique(octets, zone, end_bit=3 * code_bits(top_dims * 2 ** (levels - 2)))
    timings["finest_cells"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    oct_dims = top_dims * 2 ** (levels - 2)
    pruned = partial(_pruned, fields=(a, b), args=args, aligned=aligned, origin=origin, h=h, oct_dims=oct_dims, how=how)
    finest = pruned(octets)
    timings["finest_prune"] = time.perf_counter() - t0
    return finest, pruned


def _pruned(octets, fields, args, aligned, origin, h: float, oct_dims, how: tuple, band=None) -> dict:
    """The candidate ``octets`` the result's surface may pass near (:func:`.prune.prune_octets`; ``how``: op, blend,
    mode; ``band`` in voxels, default KEEP_BAND), with what the combination needs of the operands there: ``octets``,
    ``a_first``/``b_first``, ``octet_flags``, ``offsets`` and ``jumps``."""
    offs = [
        wp.vec3i(*(int(v) for v in (-offset_to(f, origin, h) if al else (0, 0, 0))))
        for f, al in zip(fields, aligned, strict=False)
    ]
    flags = [int(al and not (offset_to(f, origin, h) % 2).any()) for f, al in zip(fields, aligned, strict=False)]
    jumps = not all(continuous(f) for f in fields)
    op, blend, mode = how
    octets, a_first, b_first = prune_octets(
        octets, args, [int(al) for al in aligned], flags, offs, origin, h, op, blend, mode, oct_dims, jumps=jumps,
        band=KEEP_BAND if band is None else band,
    )  # fmt: skip
    return {"octets": octets, "a_first": a_first, "b_first": b_first, "octet_flags": flags, "offsets": offs,
            "jumps": jumps}  # fmt: skip


def _laid_out(finest: dict, closure, grid, args, aligned, origin, h: float, how, timings: dict) -> tuple:
    """(layout, node values) of the result's finest ``finest`` octets (:func:`_pruned`'s; ``grid``: top dims and
    levels): every node's place first, so the finest values are computed where they are kept. With ``closure`` (the
    pruning, :func:`.closure.needs_closure`) the finest values come first, and the octets they show lacking about
    the surface are added with theirs (:func:`.closure.closed`)."""
    (top_dims, levels), device, done = grid, finest["octets"].device, None
    if closure is not None:
        t0 = time.perf_counter()
        values_of = partial(_finest_values, args=args, aligned=aligned, origin=origin, h=h, levels=levels, how=how)
        finest, done = closed(finest, closure, values_of, top_dims * 2 ** (levels - 2), CLOSURE_ROUNDS)
        timings["finest_closed"] = time.perf_counter() - t0
    layout = level_layout(finest.pop("octets"), top_dims, levels, device, timings, lean=True)
    return layout, _node_values(layout, finest, args, aligned, origin, h, levels, how, timings, done=done)


def _node_values(layout, finest: dict, args, aligned, origin, h: float, levels: int, how, timings: dict, done=None):
    """Every node's value, closest point, source and (finest) triangle, level by level: the finest from the operands'
    nodes or MLS samples (or ``done``: :func:`_finest_values` of them), the coarser levels from the operands' own
    nodes there or their leaves extrapolated (Eq. 8 per node: a result is a field like any other). ``how``: (op,
    blend, mode, walk). The pruning's arrays in ``finest`` are let go after the finest level."""
    device, offsets = layout["codes"].device, layout["offsets"]
    out = _node_arrays(int(offsets[-1]), int(offsets[1]), device)
    tk = time.perf_counter()
    if done is None:
        _level_values(0, layout["codes"], (0, int(offsets[1])), out, finest, args, aligned, origin, h, levels, how)
    else:
        for key, array in done.items():
            wp.copy(out[key], array, count=array.shape[0])
    timings["finest_values"] = time.perf_counter() - tk
    finest["a_first"] = finest["b_first"] = None  # not needed above the finest level
    for k in range(1, levels):
        tk = time.perf_counter()
        span = (int(offsets[k]), int(offsets[k + 1]))
        _level_values(k, layout["codes"], span, out, finest, args, aligned, origin, h, levels, how)
        timings["top_level" if k == levels - 1 else f"level_{k}"] = time.perf_counter() - tk
    return out


def _finest_values(finest: dict, *, args, aligned, origin, h: float, levels: int, how) -> dict:
    """:func:`_node_values`' finest level alone, of ``finest``'s octets (their children, in order)."""
    codes, _coords = octree.expand_octets(finest["octets"])
    out = _node_arrays(codes.shape[0], codes.shape[0], codes.device)
    _level_values(0, codes, (0, codes.shape[0]), out, finest, args, aligned, origin, h, levels, how)
    return out


def _node_arrays(n: int, n_finest: int, device) -> dict:
    """What the combination writes per node (``n``) and per finest node (``n_finest``), unset."""
    return {
        "proj": wp.empty(n, dtype=wp.vec3h, device=device),
        "source": wp.empty(n, dtype=wp.int32, device=device),
        "values": wp.empty(n, dtype=wp.float32, device=device),
        "triangles": wp.empty(n_finest, dtype=wp.int32, device=device),
    }


def _level_values(k: int, codes, span, out: dict, finest: dict, args, aligned, origin, h, levels: int, how) -> None:
    """The combination of level ``k``'s nodes ``codes[span[0]:span[1]]`` into ``out``'s rows alike."""
    op, blend, mode, walk = how
    (lo, hi), spacing, at_finest, group = span, h * 2**k, k == 0, COMBINE_GROUP
    flags = [int(aligned[0] and at_finest), int(aligned[1] and at_finest)]
    no_octets = wp.empty(0, dtype=wp.int32, device=codes.device)
    octet_args = [
        finest["octet_flags"][0] if at_finest else 0,
        finest["octet_flags"][1] if at_finest else 0,
        finest["a_first"] if at_finest else no_octets,
        finest["b_first"] if at_finest else no_octets,
    ]
    offs = finest["offsets"]
    parallel.launch_split(
        _combine_nodes_kernel,
        (hi - lo + group - 1) // group,
        lambda start, count: [
            *args,
            *flags,
            offs[0],
            offs[1],
            codes,
            lo + group * start,
            min(hi, lo + group * (start + count)),
            group,
            int(k < levels - 1),
            wp.vec3(*origin),
            float(spacing),
            int(op),
            blend,
            mode,
            walk,
            int(k == 0),
            out["proj"],
            out["source"],
            out["values"],
            out["triangles"],
            *octet_args,
        ],  # fmt: skip
        codes.device,
        balance=True,  # MLS samples bunch where the operands meet
    )


def _seam_candidates(operands, aligned, origin, h: float, fine_dims, device, blend: float) -> wp.array:
    """The candidate octets of a boolean made along its seams: an operand built on demand's, or a mesh's built whole
    that is closed or open only at holes, only where the result keeps them (:func:`.ondemand.along_seams_only`,
    :func:`.ondemand.seam_octets`: what else is built of it was built for other booleans, or is covered by its kept
    faces); any other has them all, as without seams."""
    oct_dims = fine_dims // 2
    parts = []
    for f, other, al in zip(operands, operands[::-1], aligned, strict=True):
        codes = operand_octets(f, origin, h, oct_dims, al, device)
        parts.append(seam_octets(codes, f, other, origin, h, blend) if along_seams_only(f, other) else codes)
    return octree.merge_unique(*parts, end_bit=3 * code_bits(oct_dims))


def _candidate_octets(operands, aligned, origin, h: float, fine_dims, device, *, seams=False, blend=0.0) -> wp.array:
    """(K,) int64 sorted Morton codes of the result's finest octets before pruning: every octet either operand has
    there (a resampled operand's cells marked on a byte grid when it fits, else the codes merged); ``seams``: along
    the seams alone (:func:`_seam_candidates`)."""
    if seams:
        return _seam_candidates(operands, aligned, origin, h, fine_dims, device, blend)
    oct_dims = fine_dims // 2
    end_bit = 3 * code_bits(oct_dims)
    if not all(aligned) and byte_grid_fits(oct_dims):
        # a resampled operand's cells mark a byte per octet: the other's octets marked there too, one compaction and
        # one sort (two aligned operands' codes are merged without a grid to scan)
        mask = wp.zeros(int(np.prod(oct_dims)), dtype=wp.uint8, device=device)
        for f, al in zip(operands, aligned, strict=False):
            operand_octets(f, origin, h, oct_dims, al, device, mask=mask)
        return octree.compact_mask(mask, oct_dims, device, end_bit, lambda total: check_budget(fine_dims, 0, 8 * total))
    parts = [operand_octets(f, origin, h, oct_dims, al, device) for f, al in zip(operands, aligned, strict=False)]
    return octree.merge_unique(*parts, end_bit=end_bit)


def union(
    a: AdaptiveField,
    b: AdaptiveField,
    *,
    blend: float = 0.0,
    spacing: str = "finer",
    blend_mode: str = "round",
    seams: bool = False,
) -> AdaptiveField:
    """``a`` or ``b`` (min); blended when ``blend > 0`` (round or chamfer). See :func:`combine`."""
    return combine(a, b, OP_UNION, blend=blend, spacing=spacing, blend_mode=blend_mode, seams=seams)


def intersection(
    a: AdaptiveField,
    b: AdaptiveField,
    *,
    blend: float = 0.0,
    spacing: str = "finer",
    blend_mode: str = "round",
    seams: bool = False,
) -> AdaptiveField:
    """``a`` and ``b`` (max); blended when ``blend > 0`` (round or chamfer). See :func:`combine`."""
    return combine(a, b, OP_INTERSECTION, blend=blend, spacing=spacing, blend_mode=blend_mode, seams=seams)


def difference(
    a: AdaptiveField,
    b: AdaptiveField,
    *,
    blend: float = 0.0,
    spacing: str = "finer",
    blend_mode: str = "round",
    seams: bool = False,
) -> AdaptiveField:
    """``a`` minus ``b`` (max(a, -b)); blended when ``blend > 0`` (round or chamfer). See :func:`combine`."""
    return combine(a, b, OP_DIFFERENCE, blend=blend, spacing=spacing, blend_mode=blend_mode, seams=seams)
