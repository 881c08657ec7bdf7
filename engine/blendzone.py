"""Where a blend needs finest octets: the zone in which both operands shape the blended surface.

A blend moves the result's surface off both operands' surfaces (up to ``blend / 4`` for a round one, ``blend / 2`` for
a chamfer), but only where the operands come within the blend radius of each other: everywhere else the result is one
operand alone, whose own finest octets already cover it. Growing every operand octet by the blend's reach instead
makes a shell around the whole surface whose size grows with the radius (and, for wide blends, more octets than
memory holds); this zone grows with the seam.

The zone is found top-down, as an octree is refined: from the result's dense top level, a cell is split into its 8
children while, over the cell (the operands' brackets at its centre widened by its half-diagonal; the fields are
1-Lipschitz), both operands can shape the result (:func:`.blends.blend_matters`) and the result may come within the
pruning band of zero (:func:`.blends.result_bracket`). Only cells along the blended part of the surface are visited,
so the work and memory grow with its area. The octets found are candidates like the operands' own; the pruning
(:func:`.prune.prune_octets`) decides which are kept.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import octree
from .blends import blend_matters, result_bracket
from .octree import count_then_emit, morton_decode, node_center
from .operands import bracket, mesh_sample, sample_operand
from .plan import check_budget
from .sampling import FieldArg, clamp_to_domain, locate_leaf, to_frame

# Half the diagonal of a unit cube: a cell's farthest point from its centre, in spacings.
HALF_DIAGONAL = 0.8660254037844386

# A coarse leaf's bracket wider than this many voxels is narrowed by a sample (:func:`sharper_bracket`).
WIDE_BRACKET = wp.constant(2.0)


@wp.func
def centre_sample(f: FieldArg, centre: wp.vec3, h: float) -> wp.vec3:
    """(value, growth, slack) of an operand at an octet's ``centre``, from which :func:`sharper_bracket` bounds its
    value at the octet's nodes: within ``growth`` x distance + ``slack`` of it. The distance to the operand's mesh
    where the field is one (what the combination then reads in a coarse leaf), else its MLS value (whose fit is
    off by a few per cent)."""
    if f.mesh != wp.uint64(0):
        leaf = locate_leaf(f, clamp_to_domain(f, to_frame(f, centre)))
        if leaf[1] > 0:  # a coarse leaf holds no triangle: its sign holds over it
            found, r, _foot = mesh_sample(f, centre, leaf, centre, 0)
            if found == 1:
                return wp.vec3(r[0], 1.001, 0.01 * h)
    v = sample_operand(f, centre)[0]
    if f.inner_points >= 1:  # a boolean's: read trilinearly where its fit is off, a cell's error (no narrowing)
        return wp.vec3(v, 1.1, 1.0e30)
    return wp.vec3(v, 1.1, 0.1 * wp.abs(v) + 0.1 * h)


@wp.func
def sharper_bracket(sample: wp.vec3, centre: wp.vec3, x: wp.vec3, phi: float, radius: float):
    """An operand's (phi, radius) at node ``x`` of an octet, narrowed by its :func:`centre_sample` where that is
    tighter. Inside a blend's zone the operands are coarse leaves whose brackets span their cells: without this the
    pruning keeps a slab of those cells' width."""
    widened = sample[1] * wp.length(x - centre) + sample[2]
    if widened < radius:
        return sample[0], widened
    return phi, radius


@wp.kernel(enable_backward=False)
def _zone_cells_kernel(
    first: int,
    a: FieldArg,
    b: FieldArg,
    cells: wp.array[wp.int64],
    origin: wp.vec3,
    spacing: float,
    op: int,
    blend: float,
    mode: int,
    band: float,
    split: int,
    offsets: wp.array[wp.int32],
    emit: int,
    counts: wp.array[wp.int32],
    codes: wp.array[wp.int64],
):
    """Cell ``first + tid`` of one level: kept when the blend can shape the result's surface in it; then its 8
    children's codes are written (``split``), or its own (the octet level). Counts first (``emit`` 0), then codes."""
    i = first + wp.tid()
    c = morton_decode(cells[i])
    x = node_center(origin, spacing, c)
    half = float(HALF_DIAGONAL) * spacing
    no_offset = wp.vec3i(0, 0, 0)
    va, ra = bracket(a, 0, no_offset, c, x)
    vb, rb = bracket(b, 0, no_offset, c, x)
    ra = wp.abs(ra) + half
    rb = wp.abs(rb) + half
    tb = vb
    if op == 2:
        tb = -vb
    n = int(0)
    if blend_matters(op, va, ra, tb, rb, blend, mode):
        bounds = result_bracket(op, va, ra, tb, rb, blend, mode)
        if bounds[0] <= band and bounds[1] >= -band:
            n = 1
            if split == 1:
                n = 8
    if emit == 0:
        counts[i] = n
        return
    start = offsets[i]
    if n == 1:
        codes[start] = cells[i]
    elif n == 8:
        base = cells[i] << wp.int64(3)
        for o in range(8):
            codes[start + int(o)] = base | wp.int64(o)


def blend_octets(a_arg, b_arg, origin, h: float, top_dims, levels: int, op: int, blend: float, mode: int, band: float):
    """(K,) int64 sorted unique codes of the result's finest octets (level 1 of the result's lattice: ``origin``,
    finest spacing ``h``, ``levels`` levels over a dense top level of ``top_dims`` cells) in which a blend can shape
    the result's surface within ``band``: see the module's docstring. ``a_arg``, ``b_arg``: the operands' FieldArgs
    (placed operands in world units); ``op`` as :mod:`.boolean`'s ``OP_*``; ``mode`` 0 round, 1 chamfer."""
    device = a_arg.values.device
    fine_dims = np.asarray(top_dims, dtype=np.int64) * 2 ** (levels - 1)
    cells = wp.empty(int(np.prod(top_dims)), dtype=wp.int64, device=device)
    octree.dense_level(top_dims, cells, wp.empty(0, dtype=wp.vec3i, device=device))
    origin_v = wp.vec3(*(float(v) for v in origin))
    for level in range(levels - 1, 0, -1):
        if cells.shape[0] == 0:
            break
        split = int(level > 1)
        cells = count_then_emit(
            _zone_cells_kernel,
            cells.shape[0],
            [a_arg, b_arg, cells, origin_v, float(h * 2**level), int(op), float(blend), int(mode), float(band), split],
            device,
            check=lambda total: check_budget(fine_dims, 0, 8 * total),
        )
    return octree.sort_unique(cells, end_bit=3 * octree.code_bits(fine_dims // 2))
