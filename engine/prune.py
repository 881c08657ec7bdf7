"""The result's finest octets: those that cover the operands' finest levels, and those of them a boolean keeps.

An operand's finest level is covered octet by octet on the result lattice: an aligned operand's octets directly, a
resampled (or placed) one's cells as primitives (Ren et al., Sec. 5), each result octet within a voxel of one. Of
those, :func:`prune_octets` keeps only the octets the result's surface may pass near, deciding from the operands'
value brackets (:func:`.operands.node_bracket`) before any interpolation, so that only kept nodes pay for it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from . import octree, parallel
from .blends import result_bracket
from .blendzone import WIDE_BRACKET, centre_sample, sharper_bracket
from .octree import code_bits, morton_decode, morton_encode, node_center
from .operands import node_bracket, octet_source
from .plan import byte_grid_fits, check_budget
from .sampling import FieldArg, node_coords

if TYPE_CHECKING:
    from .field import AdaptiveField


# Finest octets are kept where some node is within this many voxels of the result's surface: more than the farthest
# the nearest node of an octet lies from a level-1 cube (2 voxels a side, its corners the octets) that the surface
# crosses, 1.5 x sqrt(3) = 2.598, so the level-1 surface of the high adaptivities (:mod:`.coarse`) finds every corner
# where the values change by at most the distance moved (2.5 left the rocker arm - cube's level-1 surface open along
# its seam: its missing corners added and the level contoured twice, 60 -> 40 ms at adaptivity 0.5).
KEEP_BAND = 2.6


@wp.func
def _codable(leaf: int, level: int) -> bool:
    """Whether a coarse leaf fits the code ``-2 - (16 x index + level)`` in an int32 (see :func:`prune_octets`)."""
    return leaf >= 0 and level < 16 and leaf < 134_000_000


@wp.kernel(enable_backward=False)
def _octet_bracket_kernel(
    first: int,
    a: FieldArg,
    b: FieldArg,
    a_aligned: int,
    b_aligned: int,
    a_octets: int,
    b_octets: int,
    a_offset: wp.vec3i,
    b_offset: wp.vec3i,
    octets: wp.array[wp.int64],
    origin: wp.vec3,
    spacing: float,
    op: int,
    blend: float,
    mode: int,
    band: float,
    near: wp.array[wp.int32],
    has_neg: wp.array[wp.int32],
    has_pos: wp.array[wp.int32],
    a_first_out: wp.array[wp.int32],
    b_first_out: wp.array[wp.int32],
):
    """Per finest octet of the result, from the operands' brackets alone (no interpolation): whether a node may lie
    within ``band`` of the result's surface, and which signs its nodes may have."""
    t = first + wp.tid()
    oc = octree.morton_decode(octets[t])
    a_first, a_leaf, a_level = octet_source(a, a_octets, a_offset, oc, origin, spacing)
    b_first, b_leaf, b_level = octet_source(b, b_octets, b_offset, oc, origin, spacing)
    n_near = int(0)
    neg = int(0)
    pos = int(0)
    centre = origin + 2.0 * spacing * wp.vec3(float(oc[0]) + 0.5, float(oc[1]) + 0.5, float(oc[2]) + 0.5)
    sampled_a = False
    sampled_b = False
    sample_a = wp.vec3(0.0)
    sample_b = wp.vec3(0.0)
    for k in range(8):
        c = wp.vec3i(2 * oc[0] + (k & 1), 2 * oc[1] + ((k >> 1) & 1), 2 * oc[2] + ((k >> 2) & 1))
        x = node_center(origin, spacing, c)
        va, ra = node_bracket(a, a_first, a_leaf, a_level, k, a_aligned, a_offset, c, x)
        # a hard boolean is surely beyond the band where a alone says so (a union inside a, an intersection or a
        # difference outside it): b's bracket, a descent into b per node, would change nothing
        if blend == 0.0 and mode == 0 and ra >= 0.0:
            if op == 0 and va + ra < -band:
                neg = 1
                continue
            if op != 0 and va - ra > band:
                pos = 1
                continue
        vb, rb = node_bracket(b, b_first, b_leaf, b_level, k, b_aligned, b_offset, c, x)
        if blend > 0.0 and ra >= 0.0 and rb >= 0.0:  # a blend's zone lies in both operands' coarse leaves
            if ra > WIDE_BRACKET * spacing:
                if not sampled_a:
                    sample_a = centre_sample(a, centre, spacing)
                    sampled_a = True
                va, ra = sharper_bracket(sample_a, centre, x, va, ra)
            if rb > WIDE_BRACKET * spacing:
                if not sampled_b:
                    sample_b = centre_sample(b, centre, spacing)
                    sampled_b = True
                vb, rb = sharper_bracket(sample_b, centre, x, vb, rb)
        if ra < 0.0 or rb < 0.0:
            n_near = 1
            neg = 1
            pos = 1
        else:
            tb = vb
            if op == 2:
                tb = -vb
            bounds = result_bracket(op, va, ra, tb, rb, blend, mode)
            lo = bounds[0]
            hi = bounds[1]
            if lo <= band and hi >= -band:
                n_near = 1
            # a node whose bracket contains zero may have either sign
            if hi < 0.0:
                neg = 1
            elif lo >= 0.0:
                pos = 1
            else:
                neg = 1
                pos = 1
    near[t] = n_near
    # an octet the operand lacks, inside one of its coarse leaves: that leaf, for the combination (no descent), where
    # its index and level fit the code (else -1: the combination descends)
    a_first_out[t] = wp.where(a_first < 0 and _codable(a_leaf, a_level), -2 - (16 * a_leaf + a_level), a_first)
    b_first_out[t] = wp.where(b_first < 0 and _codable(b_leaf, b_level), -2 - (16 * b_leaf + b_level), b_first)
    has_neg[t] = neg
    has_pos[t] = pos


@wp.kernel(enable_backward=False)
def _keep_octets_kernel(
    first: int,
    octets: wp.array[wp.int64],
    near: wp.array[wp.int32],
    has_neg: wp.array[wp.int32],
    has_pos: wp.array[wp.int32],
    dims: wp.vec3i,
    jumps: int,
    signs: wp.array[wp.uint8],
    keep: wp.array[wp.int32],
):
    """Keep an octet near the surface, or with a sign change inside it or (where the operands may ``jumps``) towards
    one of its 26 neighbours. The neighbours' possible signs come from ``signs`` (the octet grid, x-fastest, see
    ``_octet_signs_kernel``) or, when it is empty, by binary search among ``octets``."""
    t = first + wp.tid()
    keep[t] = 0
    if near[t] == 1 or (has_neg[t] == 1 and has_pos[t] == 1):
        keep[t] = 1
        return
    if jumps == 0:
        return
    c = octree.morton_decode(octets[t])
    n = octets.shape[0]
    # the sign a neighbour must be able to have: bit 0 negative, bit 1 positive
    other = wp.where(has_pos[t] == 1, 1, 0) + wp.where(has_neg[t] == 1, 2, 0)
    for o in range(27):
        q = c + wp.vec3i(o % 3 - 1, (o // 3) % 3 - 1, o // 9 - 1)
        if o != 13 and octree.in_grid(q, dims):
            if signs.shape[0] > 0:
                if (int(signs[q[0] + dims[0] * (q[1] + dims[1] * q[2])]) & other) != 0:
                    keep[t] = 1
                    return
            else:
                j = octree.find_key(octets, 0, n, morton_encode(q))
                if j >= 0:
                    if (has_neg[j] == 1 and has_pos[t] == 1) or (has_pos[j] == 1 and has_neg[t] == 1):
                        keep[t] = 1
                        return


@wp.kernel(enable_backward=False)
def _octet_signs_kernel(
    first: int,
    octets: wp.array[wp.int64],
    has_neg: wp.array[wp.int32],
    has_pos: wp.array[wp.int32],
    dims: wp.vec3i,
    signs: wp.array[wp.uint8],
):
    """The signs octet ``first + tid`` may have (bit 0 negative, bit 1 positive) at its place in the octet grid."""
    t = first + wp.tid()
    c = octree.morton_decode(octets[t])
    signs[c[0] + dims[0] * (c[1] + dims[1] * c[2])] = wp.uint8(has_neg[t] + 2 * has_pos[t])


@wp.kernel(enable_backward=False)
def _aligned_octets_kernel(
    node_codes: wp.array[wp.int64],
    offset: wp.vec3i,
    step: int,
    dims: wp.vec3i,
    mask: wp.array[wp.uint8],
    codes: wp.array[wp.int64],
):
    """Octet, on the result lattice, of every ``step``-th finest node of an aligned operand: marked in ``mask`` (the
    octet grid, x-fastest) when it is not empty, else its code written to ``codes``."""
    i = wp.tid()
    c = morton_decode(node_codes[step * i]) + offset
    o = wp.vec3i(c[0] >> 1, c[1] >> 1, c[2] >> 1)
    if mask.shape[0] > 0:
        mask[o[0] + dims[0] * (o[1] + dims[1] * o[2])] = wp.uint8(1)
    else:
        codes[i] = morton_encode(o)


@wp.kernel(enable_backward=False)
def _octets_of_cells_kernel(
    first: int,
    f: FieldArg,
    origin: wp.vec3,
    octet_size: float,
    pad: float,
    dims: wp.vec3i,
    per_cell: int,
    mask: wp.array[wp.uint8],
    offsets: wp.array[wp.int32],
    emit: int,
    counts: wp.array[wp.int32],
    codes: wp.array[wp.int64],
):
    """Result octets within ``pad`` of each finest octet of an operand (its cells as primitives, 8 at a time, or one
    at a time for a dense single level: ``per_cell``; those of a placed operand where it is placed, a turned box),
    counted (``emit`` 0), written (1) or marked in ``mask`` (2, see ``octree.mark_then_compact``)."""
    t = first + wp.tid()
    c = node_center(f.origin, f.voxel_size, node_coords(f, t))
    size = f.voxel_size  # the primitive's half width: a cell's half, or an octet's
    if per_cell == 0:
        c = node_center(f.origin, f.voxel_size, node_coords(f, 8 * t)) + wp.vec3(0.5 * f.voxel_size)
        size = 2.0 * f.voxel_size
    half = wp.vec3(0.5 * size + pad)
    if f.moved == 1:
        c = f.scale * (f.rotation @ c) + f.translation
        for k in range(3):
            reach = wp.abs(f.rotation[k, 0]) + wp.abs(f.rotation[k, 1]) + wp.abs(f.rotation[k, 2])
            half[k] = 0.5 * size * f.scale * reach + pad
    i0 = wp.vec3i(0)
    i1 = wp.vec3i(0)
    for k in range(3):
        i0[k] = wp.clamp(int(wp.floor((c[k] - half[k] - origin[k]) / octet_size)), 0, dims[k] - 1)
        i1[k] = wp.clamp(int(wp.floor((c[k] + half[k] - origin[k]) / octet_size)), 0, dims[k] - 1)
    n = int(0)
    base = int(0)
    if emit == 1:
        base = offsets[t]
    for z in range(i0[2], i1[2] + 1):
        for y in range(i0[1], i1[1] + 1):
            for xx in range(i0[0], i1[0] + 1):
                if emit == 2:
                    mask[xx + dims[0] * (y + dims[1] * z)] = wp.uint8(1)
                elif emit == 1:
                    codes[base + n] = morton_encode(wp.vec3i(xx, y, z))
                n += 1
    if emit == 0:
        counts[t] = n


def offset_to(f: AdaptiveField, origin: np.ndarray, spacing: float) -> np.ndarray:
    """An aligned operand's finest lattice offset (in its own nodes) from a result lattice at ``origin``."""
    return np.rint((f.origin - origin) / spacing).astype(np.int64)


def operand_octets(f: AdaptiveField, origin, spacing, oct_dims, aligned, device, mask=None):
    """Octet codes (result lattice) that cover an operand's finest level; with ``mask`` (a byte per octet of the
    grid, x-fastest), those octets marked there instead (returns None)."""
    n0 = int(f.level_offsets[1])
    dims_v = wp.vec3i(*(int(d) for d in oct_dims))
    if aligned:
        offset_np = offset_to(f, origin, spacing)
        # with even offsets the operand's octets are result octets: one code per octet (its first node) will do
        step = 8 if f.levels > 1 and not (offset_np % 2).any() else 1
        codes = wp.empty(0 if mask is not None else n0 // step, dtype=wp.int64, device=device)
        offset = wp.vec3i(*(int(v) for v in offset_np))
        no_mask = wp.empty(0, dtype=wp.uint8, device=device)
        parallel.load_modules([_aligned_octets_kernel.module], device)
        wp.launch(
            _aligned_octets_kernel,
            dim=n0 // step,
            inputs=[f.codes, offset, step, dims_v, mask if mask is not None else no_mask],
            outputs=[codes],
            device=device,
        )
        return None if mask is not None else codes
    per_cell = int(f.levels == 1)  # a dense single level is not stored in octets
    # the result octets that overlap the operand's finest cells cover its band; an operand finer than the result
    # (its band narrower than a result voxel) gets a voxel more
    pad = spacing if f.world_voxel_size < spacing * (1.0 - 1e-6) else 0.0
    args = [f.arg(), wp.vec3(*origin), 2.0 * spacing, pad, dims_v, per_cell]
    n_octets = n0 if per_cell else n0 // 8
    if mask is not None:
        octree.mark_octets(_octets_of_cells_kernel, n_octets, args, mask, device)
        return None
    if byte_grid_fits(oct_dims):  # each result octet marked once in a byte per octet, no (cell, octet) pairs sorted
        return octree.mark_then_compact(
            _octets_of_cells_kernel,
            n_octets,
            args,
            oct_dims,
            device,
            end_bit=3 * code_bits(oct_dims),
            check=lambda total: check_budget(oct_dims * 2, 0, 8 * total),
        )
    return octree.count_then_emit(
        _octets_of_cells_kernel,
        n_octets,
        [*args, wp.empty(0, dtype=wp.uint8, device=device)],
        device,
        check=lambda total: check_budget(oct_dims * 2, 0, 0, pairs=total),
    )


def prune_octets(
    octets, args, aligned, octet_flags, offsets, origin, h, op, blend, mode, oct_dims, *, jumps=True, band=KEEP_BAND
):
    """The octets of ``octets`` (sorted Morton codes on the result lattice) that may change the result's surface,
    and for each its first node in either operand (``octet_source``; -1 where not octet-aligned).

    Keep the result adaptive: drop octets the result's surface is far from (an operand's band buried inside the
    other operand, say), deciding from the operands' brackets before any interpolation, so only kept nodes pay
    for MLS. A marching cube with a corner farther than its diagonal from the surface cannot contain it, so
    octets whose nodes are all beyond ``band`` voxels change no surface — unless the field jumps there (the
    surface an open operand gets across a hole): octets with both signs, or next to one of the other sign, stay. Where
    neither operand jumps (``jumps`` False: the combination is continuous and changes by at most sqrt(2) times the
    distance moved, a chamfer's most, so every corner of a cube the surface crosses lies within sqrt(6) < KEEP_BAND
    voxels of it) the band alone decides: the neighbours' signs kept an octet more on either side of the surface.
    (A chamfer over a chamfered boolean changes faster, and a blended boolean read off its coarse leaves strays from
    its brackets: there the boolean adds what its values show lacking, :mod:`.closure`.)

    Args:
        octets: (M,) int64 Warp array of octet codes.
        args: The operands' ``FieldArg`` structs (a, b).
        aligned: Per operand, 1 where its finest nodes are the result's (see ``combine``).
        octet_flags: Per operand, 1 where its octets are also the result's (even lattice offsets).
        offsets: Per operand, its lattice offset from the result's (``wp.vec3i``; zero when not aligned).
        origin, h: The result lattice's origin and finest spacing.
        op, blend, mode: The boolean (``OP_*``), its blend size and blend mode (0 round / none, 1 chamfer).
        oct_dims: The octet grid's dimensions.
        jumps: Whether an operand's field may jump (an open mesh's, across its holes).
    Returns:
        (octets, a_first, b_first) Warp arrays of the kept octets: an operand's first node of each, -1 where none is
        known, or -2 - (16 x index + level) of its coarse leaf covering the octet (:func:`.operands.octet_leaf`).
    """
    device = octets.device
    a_arg, b_arg = args
    flags = [int(v) for v in aligned]
    offs = list(offsets)
    origin_v = wp.vec3(*origin)
    n_oct = octets.shape[0]
    near, has_neg, has_pos, keep_wp, a_first, b_first = (
        wp.empty(n_oct, dtype=wp.int32, device=device) for _ in range(6)
    )
    parallel.launch_split(
        _octet_bracket_kernel,
        n_oct,
        lambda start, n: [
            start,
            a_arg,
            b_arg,
            *flags,
            *octet_flags,
            offs[0],
            offs[1],
            octets,
            origin_v,
            float(h),
            int(op),
            blend,
            mode,
            band * h,
            near,
            has_neg,
            has_pos,
            a_first,
            b_first,
        ],
        device,
        balance=True,
    )
    if band == np.inf:  # every octet kept: what the combination reads of them
        return octets, a_first, b_first
    dims_v = wp.vec3i(*(int(d) for d in oct_dims))
    if jumps and byte_grid_fits(oct_dims):
        # a byte per octet of the grid: the 26 neighbours are found by index rather than by binary search
        signs = wp.zeros(int(np.prod(oct_dims)), dtype=wp.uint8, device=device)
        parallel.launch_split(
            _octet_signs_kernel, n_oct, lambda start, n: [start, octets, has_neg, has_pos, dims_v, signs], device
        )
    else:
        signs = wp.empty(0, dtype=wp.uint8, device=device)
    parallel.launch_split(
        _keep_octets_kernel,
        n_oct,
        lambda start, n: [start, octets, near, has_neg, has_pos, dims_v, int(jumps), signs, keep_wp],
        device,
    )
    keep = keep_wp.numpy().astype(bool)
    if not keep.all():
        octets, a_first, b_first = (
            wp.array(arr.numpy()[keep], dtype=arr.dtype, device=device) for arr in (octets, a_first, b_first)
        )
    return octets, a_first, b_first
