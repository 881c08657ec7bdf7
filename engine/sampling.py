"""Point queries on an adaptive field: leaf location, moving-least-squares and linear interpolation.

A query descends from the dense top level to the leaf containing the point (children of a node are 8 consecutive
entries in Morton order, so each step is index arithmetic). Its interpolation neighbourhood is the set of leaves
containing the 27 lattice positions around that leaf's centre — the cross-level neighbour relation of Ren et al.
Fig. 4 (a same-level neighbour that is refined resolves to the adjacent finer leaf, a missing one to the coarser leaf
that covers it). Moving least squares fits ``phi = a + g . (x_i - x)`` with cubic-spline weights (Eq. 9-10).
"""

from __future__ import annotations

import warp as wp

from .octree import morton_decode, node_center

vec27i = wp.types.vector(length=27, dtype=wp.int32)

# A coarse leaf's value may exceed its distance by this share. A built field's dense top level takes a point of the
# mesh within this much of its closest: far from the surface proving the closest point is the bulk of a query's work
# (bunny /512: 0.32 s of thread time exact within 1 %, 0.15 s within 5 %), while the far field's error stays the
# interpolation's (p95 2.79 % exact, 2.85 % at 5 %). Whatever takes values as exact distances allows for it: the
# signs' empty balls stay within SIGN_SAFETY (a test checks), the booleans' brackets widen by it.
LEAF_TOLERANCE = 0.05


# A neighbour's prediction replaces the nearest so far only below this share of it: closest points kept in half
# floats (:func:`stored_proj`) differ by up to 2^-11 of their distance, so neighbours sharing one closest point (a
# vertex of the mesh) stay tied and the first keeps it, as with exact points.
TIE_SHARE = wp.constant(1.0 - 2.0**-9)

# Values of opposite signs at two nodes are distances to a surface between them only when they add up to no more than
# the nodes' distance (1-Lipschitz); the slack allows for rounding and smooth blends.
JUMP_SLACK = 1.5


@wp.struct
class FieldArg:
    """What a kernel needs to query a field."""

    origin: wp.vec3
    voxel_size: float
    levels: int
    top_dims: wp.vec3i
    top_offset: int
    domain_min: wp.vec3
    domain_max: wp.vec3
    child: wp.array[wp.int32]  # first child of each coarse node (node i at i - fine_count), -1: a leaf
    values: wp.array[wp.float32]
    proj: wp.array[wp.vec3h]  # each node's closest point as an offset from its centre, in its level's spacings
    source: wp.array[wp.int32]  # empty: every node's source id is single_source
    single_source: int
    codes: wp.array[wp.int64]
    fine_count: int
    tri: wp.array[wp.int32]  # per finest node, its closest point's triangle (empty: not known)
    exact: int  # 1: a re-distanced field (``stats["exact_distance"]``): every closest point on its surface
    inner_points: int  # 1: a boolean's result: a node's closest point is its operand's, which may lie inside another
    # (2: a chamfered boolean's, whose closest points are not its surface's: read trilinearly, :func:`coarse_mls`)
    lipschitz: float  # a bound on |grad phi|: 1 for a distance, more for a chamfer (:func:`.blends.lipschitz`)
    no_inside: int  # 1: no inside (a sheet's distance, a boolean made whole and empty): read as |phi| (to_world_sample)
    mesh: wp.uint64  # the BVH of the mesh whose signed distance the field is (``AdaptiveField.distance_mesh``); 0: none
    # world = scale * rotation @ frame + translation, when the field is placed (``moved`` 1)
    moved: int
    rotation: wp.mat33
    translation: wp.vec3
    scale: float


@wp.func
def node_coords(f: FieldArg, i: int) -> wp.vec3i:
    """Lattice coordinates of node ``i`` on its level, decoded from its Morton code (a field keeps no coordinates:
    12 bytes a node)."""
    return morton_decode(f.codes[i])


@wp.func
def stored_proj(f: FieldArg, i: int, centre: wp.vec3, spacing: float) -> wp.vec3:
    """Node ``i``'s closest point (the field's frame) from its centre and its level's ``spacing``: a field keeps it as
    a half-float offset from the centre in spacings (6 bytes a node; within 2^-11 of the distance, a finest node's
    within 0.002 voxel)."""
    return centre + spacing * wp.vec3(f.proj[i])


@wp.func
def node_proj(f: FieldArg, i: int, level: int) -> wp.vec3:
    """Node ``i``'s closest point, its centre decoded from its code (``level``: its level)."""
    s = level_spacing(f, level)
    return stored_proj(f, i, node_center(f.origin, s, node_coords(f, i)), s)


@wp.func
def node_source(f: FieldArg, i: int) -> int:
    """Node ``i``'s source id (a field built from one mesh keeps one for all its nodes)."""
    if f.source.shape[0] == 0:
        return f.single_source
    return f.source[i]


@wp.func
def to_frame(f: FieldArg, x: wp.vec3) -> wp.vec3:
    """A world point in the field's own frame."""
    if f.moved == 0:
        return x
    return wp.transpose(f.rotation) @ (x - f.translation) / f.scale


@wp.func
def to_world_sample(f: FieldArg, r: wp.vec4) -> wp.vec4:
    """(phi, grad) read in the field's own frame, as seen in the world (distances scale, directions turn). A field
    with no inside (``no_inside``) is read as its absolute value: a fit or a tangent plane carried across a
    sheet's kinked distance would read below 0 on its far side, an inside the field does not have."""
    if f.no_inside == 1 and r[0] < 0.0:
        r = -r
    if f.moved == 0:
        return r
    g = f.rotation @ wp.vec3(r[1], r[2], r[3])
    return wp.vec4(r[0] * f.scale, g[0], g[1], g[2])


@wp.func
def level_spacing(f: FieldArg, level: int) -> float:
    return f.voxel_size * float(1 << level)


@wp.func
def clamp_to_domain(f: FieldArg, x: wp.vec3) -> wp.vec3:
    eps = f.voxel_size * 1.0e-4
    return wp.vec3(
        wp.clamp(x[0], f.domain_min[0] + eps, f.domain_max[0] - eps),
        wp.clamp(x[1], f.domain_min[1] + eps, f.domain_max[1] - eps),
        wp.clamp(x[2], f.domain_min[2] + eps, f.domain_max[2] - eps),
    )


@wp.func
def inside_domain(f: FieldArg, x: wp.vec3) -> bool:
    """Whether ``x`` lies strictly inside the field's domain box."""
    for a in range(3):
        if x[a] <= f.domain_min[a] or x[a] >= f.domain_max[a]:
            return False
    return True


@wp.func
def _top_cell_coords(f: FieldArg, x: wp.vec3) -> wp.vec3i:
    rel = (x - f.origin) / level_spacing(f, f.levels - 1)
    return wp.vec3i(
        wp.clamp(int(wp.floor(rel[0])), 0, f.top_dims[0] - 1),
        wp.clamp(int(wp.floor(rel[1])), 0, f.top_dims[1] - 1),
        wp.clamp(int(wp.floor(rel[2])), 0, f.top_dims[2] - 1),
    )


@wp.func
def top_cell(f: FieldArg, x: wp.vec3) -> int:
    """Index within the dense top level (x fastest) of the top cell containing ``x`` (clamped into the domain)."""
    c = _top_cell_coords(f, x)
    return c[0] + f.top_dims[0] * (c[1] + f.top_dims[1] * c[2])


@wp.func
def locate_node(f: FieldArg, x: wp.vec3, lowest: int) -> wp.vec2i:
    """(node index, level) of the node containing ``x`` (clamped into the domain) on level ``lowest``, or of the
    coarser leaf containing it: a descent from the dense top level through the child links."""
    level = f.levels - 1
    pc = _top_cell_coords(f, x)  # the node's coordinates, followed down (not decoded from its code)
    node = f.top_offset + pc[0] + f.top_dims[0] * (pc[1] + f.top_dims[1] * pc[2])
    return _descend(f, x, node, level, pc, lowest)


@wp.func
def locate_below(f: FieldArg, x: wp.vec3, node: wp.vec2i, lowest: int) -> wp.vec2i:
    """:func:`locate_node` continued from node ``node`` (index, level), known to contain ``x``."""
    if node[1] <= lowest:
        return node
    return _descend(f, x, node[0], node[1], node_coords(f, node[0]), lowest)


@wp.func
def _descend(f: FieldArg, x: wp.vec3, node: int, level: int, pc: wp.vec3i, lowest: int) -> wp.vec2i:
    """The descent of :func:`locate_node` from node ``node`` on level ``level`` at coordinates ``pc``."""
    s = level_spacing(f, level)
    while level > lowest and f.child[node - f.fine_count] >= 0:
        level = level - 1
        s = s * 0.5
        rel = (x - f.origin) / s
        cx = wp.clamp(int(wp.floor(rel[0])) - 2 * pc[0], 0, 1)
        cy = wp.clamp(int(wp.floor(rel[1])) - 2 * pc[1], 0, 1)
        cz = wp.clamp(int(wp.floor(rel[2])) - 2 * pc[2], 0, 1)
        node = f.child[node - f.fine_count] + cx + 2 * cy + 4 * cz
        pc = wp.vec3i(2 * pc[0] + cx, 2 * pc[1] + cy, 2 * pc[2] + cz)
    return wp.vec2i(node, level)


@wp.func
def locate_leaf(f: FieldArg, x: wp.vec3) -> wp.vec2i:
    """(node index, level) of the leaf containing ``x`` (clamped into the domain)."""
    return locate_node(f, x, 0)


@wp.func
def cubic_spline(q: float) -> float:
    """Cubic B-spline kernel with support [0, 2)."""
    if q < 1.0:
        return 2.0 / 3.0 - q * q + 0.5 * q * q * q
    if q < 2.0:
        t = 2.0 - q
        return t * t * t / 6.0
    return 0.0


@wp.func
def leaf_neighbours(f: FieldArg, leaf: int, level: int):
    """The distinct leaves at the centres of leaf ``leaf`` (on ``level``) and its 26 neighbour cells, in the order
    the MLS fits read them: (count, their indices (27,), their levels (27,)). The same for every point of the leaf,
    so callers with many points in one leaf find them once."""
    s = level_spacing(f, level)
    c = node_center(f.origin, s, node_coords(f, leaf))
    ids = vec27i()
    levels = vec27i()
    count = int(0)
    for o in range(27):
        off = wp.vec3(float(o % 3 - 1), float((o // 3) % 3 - 1), float(o // 9 - 1))
        q = c + s * off
        if inside_domain(f, q):
            nb = locate_leaf(f, q)
            dup = int(0)
            for t in range(count):
                if ids[t] == nb[0]:
                    dup = int(1)
            if dup == 0:
                ids[count] = nb[0]
                levels[count] = nb[1]
                count += 1
    return count, ids, levels


@wp.func
def _neighbour_weight(f: FieldArg, node: int, level: int, x: wp.vec3, s: float):
    """(centre, MLS weight at ``x``) of neighbour ``node`` on ``level`` of a leaf of spacing ``s``: the cubic spline
    over twice the larger of the two spacings."""
    sn = level_spacing(f, level)
    xn = node_center(f.origin, sn, node_coords(f, node))
    return xn, _spline_weight(xn, sn, x, s)


@wp.func
def _spline_weight(xn: wp.vec3, sn: float, x: wp.vec3, s: float) -> float:
    """MLS weight at ``x`` of a neighbour at ``xn`` with spacing ``sn``, for a leaf of spacing ``s``."""
    return cubic_spline(2.0 * wp.length(xn - x) / (2.0 * wp.max(s, sn)))


@wp.func
def trilinear_weights(o: int, t: wp.vec3) -> wp.vec4:
    """Corner ``o``'s (bits x, y, z) trilinear weight at ``t`` in the cell (0 to 1 per axis) and its derivatives along
    x, y and z (in the cell's units)."""
    wx = wp.where((o & 1) == 1, t[0], 1.0 - t[0])
    wy = wp.where(((o >> 1) & 1) == 1, t[1], 1.0 - t[1])
    wz = wp.where(((o >> 2) & 1) == 1, t[2], 1.0 - t[2])
    sx = wp.where((o & 1) == 1, 1.0, -1.0)
    sy = wp.where(((o >> 1) & 1) == 1, 1.0, -1.0)
    sz = wp.where(((o >> 2) & 1) == 1, 1.0, -1.0)
    return wp.vec4(wx * wy * wz, sx * wy * wz, wx * sy * wz, wx * wy * sz)


@wp.func
def unit_gradient(v: wp.vec4) -> wp.vec4:
    """(value, gradient) with the gradient made a unit vector (left as it is where it is zero)."""
    g = wp.vec3(v[1], v[2], v[3])
    ln = wp.length(g)
    if ln > 0.0:
        g = g / ln
    return wp.vec4(v[0], g[0], g[1], g[2])


@wp.func
def coarse_linear(f: FieldArg, x: wp.vec3, s: float) -> wp.vec4:
    """(phi, unit gradient) at ``x`` by trilinear interpolation between the 8 lattice centres of spacing ``s`` around
    it, each the value of the leaf that contains it (as :func:`sample_linear`), the gradient the interpolant's."""
    rel = (x - f.origin) / s - wp.vec3(0.5, 0.5, 0.5)
    base = wp.vec3(wp.floor(rel[0]), wp.floor(rel[1]), wp.floor(rel[2]))
    t = rel - base
    v = wp.vec4(0.0)
    for o in range(8):
        ox = o & 1
        oy = (o >> 1) & 1
        oz = (o >> 2) & 1
        q = f.origin + s * (base + wp.vec3(float(ox) + 0.5, float(oy) + 0.5, float(oz) + 0.5))
        v += f.values[locate_leaf(f, clamp_to_domain(f, q))[0]] * trilinear_weights(o, t)
    return unit_gradient(v)


@wp.func
def coarse_mls(
    f: FieldArg, count: int, ids: vec27i, levels: vec27i, x: wp.vec3, s: float, leaf_value: float
) -> wp.vec4:
    """:func:`sample_mls` at ``x`` in a coarse leaf of spacing ``s`` and value ``leaf_value``, from its neighbours
    (:func:`leaf_neighbours`). A coarser leaf holds no surface, so the whole cell has the leaf's sign; each
    neighbour predicts the distance from ``x`` to its own exact closest point, and the MLS fit is of constant order
    over those predictions: second-order accurate where the linear fit would smooth over curvature and medial axes.
    A boolean's result (``f.inner_points``) is read trilinearly (:func:`coarse_linear`) where that prediction breaks
    the field's 1-Lipschitz bound from the leaves around ``x``: its nodes' closest points are its operands', and one
    inside another operand (an operand's surface buried in the other, as a union's is) predicts a distance to no
    surface of the result (the union of two balls, read 8 voxels inside one where the other's buried surface is
    near: -9.8 voxels for -18.5). A chamfered boolean (``f.inner_points`` 2: its chamfer's surface is no operand's) is
    read trilinearly throughout (its MLS reads were up to 5.2 voxels off 2-12 voxels from its surface, the trilinear
    2.1), and such a read is held within its leaf's Lipschitz bracket."""
    if f.inner_points == 2:
        return _on_leaf_side(f, x, s, leaf_value, _within_leaf(f, x, s, leaf_value, coarse_linear(f, x, s)))
    r = _nearest_prediction(f, count, ids, levels, x, s, leaf_value)
    if f.inner_points == 1 and not _lipschitz_consistent(f, x, s, r[0]):
        r = _within_leaf(f, x, s, leaf_value, coarse_linear(f, x, s))
    return _on_leaf_side(f, x, s, leaf_value, r) if f.inner_points > 0 else r


@wp.func
def _cell_centre(f: FieldArg, x: wp.vec3, s: float) -> wp.vec3:
    """The centre of the cell of spacing ``s`` holding ``x`` (where a leaf of that spacing has its node)."""
    rel = (x - f.origin) / s
    return f.origin + s * wp.vec3(wp.floor(rel[0]) + 0.5, wp.floor(rel[1]) + 0.5, wp.floor(rel[2]) + 0.5)


@wp.func
def _on_leaf_side(f: FieldArg, x: wp.vec3, s: float, leaf_value: float, r: wp.vec4) -> wp.vec4:
    """``r`` with its value on its coarse leaf's side of the surface, at least as far as the Lipschitz bound from the
    leaf's value keeps it (a thousandth of a spacing where that bound reaches the surface): a boolean keeps every
    octet its surface crosses, so no surface lies in a coarser leaf. Its neighbours read past one (a trilinear read
    across a buried operand's surface) could put a value on the other side: an intersection of two boxes read 1.9
    voxels inside gave +0.48 voxel, and a union over it a sheet of faces inside the solid."""
    centre = _cell_centre(f, x, s)
    side = wp.where(leaf_value < 0.0, -1.0, 1.0)
    least = wp.max(wp.abs(leaf_value) - f.lipschitz * wp.length(x - centre), 1.0e-3 * s)
    return wp.vec4(side * wp.max(side * r[0], least), r[1], r[2], r[3])


@wp.func
def _within_leaf(f: FieldArg, x: wp.vec3, s: float, leaf_value: float, r: wp.vec4) -> wp.vec4:
    """``r`` with its value held within what the field's Lipschitz bound allows from the value of the leaf of spacing
    ``s`` holding ``x`` (the bracket a boolean prunes with, :func:`.operands.node_bracket`)."""
    centre = _cell_centre(f, x, s)
    reach = f.lipschitz * wp.length(x - centre)
    return wp.vec4(wp.clamp(r[0], leaf_value - reach, leaf_value + reach), r[1], r[2], r[3])


@wp.func
def _lipschitz_consistent(f: FieldArg, x: wp.vec3, s: float, phi: float) -> bool:
    """Whether ``phi`` at ``x`` is within what a 1-Lipschitz field allows from the 8 leaves around it (each leaf's
    value within its centre's distance), with a tenth of a spacing to spare."""
    rel = (x - f.origin) / s - wp.vec3(0.5, 0.5, 0.5)
    base = wp.vec3(wp.floor(rel[0]), wp.floor(rel[1]), wp.floor(rel[2]))
    for o in range(8):
        q = f.origin + s * (base + wp.vec3(float(o & 1) + 0.5, float((o >> 1) & 1) + 0.5, float((o >> 2) & 1) + 0.5))
        leaf = locate_leaf(f, clamp_to_domain(f, q))
        centre = node_center(f.origin, level_spacing(f, leaf[1]), node_coords(f, leaf[0]))
        if wp.abs(phi - f.values[leaf[0]]) > f.lipschitz * wp.length(x - centre) + 0.1 * s:
            return False
    return True


@wp.func
def _nearest_prediction(
    f: FieldArg, count: int, ids: vec27i, levels: vec27i, x: wp.vec3, s: float, leaf_value: float
) -> wp.vec4:
    """:func:`coarse_mls`'s prediction from the neighbours' closest points."""
    leaf_sign = wp.where(leaf_value < 0.0, -1.0, 1.0)
    gsum = wp.vec3(0.0)
    best = float(1.0e30)
    plane = float(1.0e30)
    for t in range(count):
        # the nearest prediction of the neighbours the weight reaches (its closest point from its centre, decoded; the
        # spline only where the prediction would be the nearest so far, by more than the stored points' rounding:
        # neighbours sharing a closest point keep the first)
        sn = level_spacing(f, levels[t])
        xn = node_center(f.origin, sn, node_coords(f, ids[t]))
        p = stored_proj(f, ids[t], xn, sn)
        r = x - p
        dist = wp.length(r)
        if dist < best * TIE_SHARE:
            w = _spline_weight(xn, sn, x, s)
            if w > 0.0:
                best = dist
                # the neighbour's surface normal: from its closest point towards the node
                nrm = xn - p
                ln = wp.length(nrm)
                gsum = r / wp.max(dist, 1.0e-20)
                if ln > 0.0:
                    gsum = nrm / ln
                    plane = wp.abs(wp.dot(r, gsum))
    if best >= 1.0e30:  # no neighbour within reach
        return wp.vec4(leaf_value, 0.0, 0.0, 0.0)
    g = leaf_sign * gsum
    # The tangent plane of the nearest closest point corrects the point distance when x's foot on that plane is
    # within a cell of it (a locally flat patch); beyond that the plane may run past the surface's edge.
    est = float(best)
    if plane < best:
        tangential = wp.sqrt(wp.max(best * best - plane * plane, 0.0))
        if tangential <= 0.5 * s:
            est = plane
    return wp.vec4(leaf_sign * est, g[0], g[1], g[2])


@wp.func
def sample_mls(f: FieldArg, x: wp.vec3) -> wp.vec4:
    """(phi, dphi/dx, dphi/dy, dphi/dz) at ``x`` inside the domain by moving least squares.

    In a finest leaf (the narrow band around the surface) this is the paper's linear MLS fit of the neighbours'
    values (Eq. 9-10); in a coarser leaf :func:`coarse_mls`. A neighbour of the other sign than the leaf whose value
    and the leaf's cannot both be distances to a surface between them (their sum beyond ``JUMP_SLACK`` times the
    distance between the nodes: where an open mesh's inside ends across a hole, away from every triangle, the values
    jump) is left out: the fit keeps the leaf's side instead of smearing the jump over two cells.
    """
    leaf = locate_leaf(f, x)
    s = level_spacing(f, leaf[1])
    count, ids, levels = leaf_neighbours(f, leaf[0], leaf[1])
    leaf_value = f.values[leaf[0]]
    if leaf[1] > 0:
        return coarse_mls(f, count, ids, levels, x, s, leaf_value)
    x_leaf = node_center(f.origin, s, node_coords(f, leaf[0]))
    ata = wp.mat44(0.0)
    atb = wp.vec4(0.0)
    wsum = float(0.0)
    vsum = float(0.0)
    for t in range(count):
        xn, w = _neighbour_weight(f, ids[t], levels[t], x, s)
        phi = f.values[ids[t]]
        if (phi < 0.0) != (leaf_value < 0.0):
            if wp.abs(phi) + wp.abs(leaf_value) > JUMP_SLACK * wp.length(xn - x_leaf):
                w = 0.0
        if w > 0.0:
            d = (xn - x) / s
            b = wp.vec4(1.0, d[0], d[1], d[2])
            ata += w * wp.outer(b, b)
            atb += (w * phi) * b
            vsum += w * phi
            wsum += w
    if wsum <= 0.0:
        return wp.vec4(leaf_value, 0.0, 0.0, 0.0)
    # A small ridge on the gradient keeps one-sided neighbourhoods well posed.
    ridge = 1.0e-4 * wsum
    ata[1, 1] += ridge
    ata[2, 2] += ridge
    ata[3, 3] += ridge
    if wp.abs(wp.determinant(ata)) < 1.0e-12 * wsum * wsum * wsum * wsum:
        return wp.vec4(vsum / wsum, 0.0, 0.0, 0.0)
    coef = wp.inverse(ata) * atb
    return wp.vec4(coef[0], coef[1] / s, coef[2] / s, coef[3] / s)


@wp.func
def sample_linear(f: FieldArg, x: wp.vec3) -> float:
    """Trilinear interpolation between the 8 lattice centres of the containing leaf's level around ``x``; each
    corner takes the value of the leaf that contains it (so level boundaries show the paper's Fig. 8 jaggedness)."""
    leaf = locate_leaf(f, x)
    s = level_spacing(f, leaf[1])
    rel = (x - f.origin) / s - wp.vec3(0.5, 0.5, 0.5)
    base = wp.vec3(wp.floor(rel[0]), wp.floor(rel[1]), wp.floor(rel[2]))
    t = rel - base
    acc = float(0.0)
    for o in range(8):
        ox = float(o & 1)
        oy = float((o >> 1) & 1)
        oz = float((o >> 2) & 1)
        q = f.origin + s * (base + wp.vec3(ox, oy, oz) + wp.vec3(0.5, 0.5, 0.5))
        nb = locate_leaf(f, clamp_to_domain(f, q))
        w = wp.where(ox > 0.5, t[0], 1.0 - t[0]) * wp.where(oy > 0.5, t[1], 1.0 - t[1])
        w = w * wp.where(oz > 0.5, t[2], 1.0 - t[2])
        acc += w * f.values[nb[0]]
    return acc


# ---- the nearest stored closest point ----

# Steps of the walk to a point's nearest stored closest point (each moves to the nodes around a nearer one).
MAX_WALK_STEPS = 16


@wp.func
def _nearer(f: FieldArg, x: wp.vec3, q: wp.vec3, level: int, best: float, best_p: wp.vec3, best_n: wp.vec3):
    """The nearest to ``x`` of (``best``, ``best_p``) and the closest point of the node holding ``q`` on ``level`` (or
    the coarser leaf holding it), with that node's surface normal line (``best_n``, from its closest point to it)."""
    if inside_domain(f, q):
        node = locate_node(f, q, level)
        s = level_spacing(f, node[1])
        centre = node_center(f.origin, s, node_coords(f, node[0]))
        p = stored_proj(f, node[0], centre, s)
        d = wp.length(x - p)
        if d < best:
            best = d
            best_p = p
            best_n = centre - p
    return best, best_p, best_n


@wp.func
def _walk(f: FieldArg, x: wp.vec3, best: float, best_p: wp.vec3, best_n: wp.vec3):
    """From (``best``, ``best_p``, ``best_n``) on through the finest band: while a nearer closest point turns up, the 8
    finest nodes around ``x``'s foot on the tangent plane at the nearest point so far (a flat surface's exact foot:
    one step), or else the 27 around that point (an edge, where the tangent plane misleads; these confirm the end: a
    foot a voxel from a face's nearest point may lie past its edge)."""
    h = f.voxel_size
    # loop bounds held in variables keep Warp from unrolling the searches (compile time)
    block = int(27)
    octet = int(8)
    steps = int(MAX_WALK_STEPS)
    for _step in range(steps):
        before = best
        ln = wp.length(best_n)
        if ln > 0.0:
            nrm = best_n / ln
            rel = (x - nrm * wp.dot(x - best_p, nrm) - f.origin) / h - wp.vec3(0.5)
            base = wp.vec3(wp.floor(rel[0]), wp.floor(rel[1]), wp.floor(rel[2]))
            for o in range(octet):
                q = wp.vec3(float(o & 1) + 0.5, float((o >> 1) & 1) + 0.5, float(o >> 2) + 0.5)
                best, best_p, best_n = _nearer(f, x, f.origin + h * (base + q), 0, best, best_p, best_n)
        if best >= before:
            rel = (best_p - f.origin) / h
            base = wp.vec3(wp.floor(rel[0]), wp.floor(rel[1]), wp.floor(rel[2]))
            for o in range(block):
                q = wp.vec3(float(o % 3 - 1) + 0.5, float((o // 3) % 3 - 1) + 0.5, float(o // 9 - 1) + 0.5)
                best, best_p, best_n = _nearer(f, x, f.origin + h * (base + q), 0, best, best_p, best_n)
            if best >= before:
                break
    return best, best_p


mat43 = wp.types.matrix(shape=(4, 3), dtype=wp.float32)


@wp.func
def closest_stored_point(f: FieldArg, x: wp.vec3):
    """(distance, point) of the nearest of the field's stored closest points to ``x``: the nodes of the 27 cells
    around the leaf holding ``x`` (clamped into the domain) give starts, from which walks (:func:`_walk`) go on
    through the finest band. Those nodes' closest points overestimate ``x``'s distance by up to about s^2 / 2S (s
    their spacing; on a build's top level they are within 5 % of the closest), so near a medial axis the nearest of
    them may lie in the wrong basin: the nearest start in each of up to 4 basins (starts more than two cells apart)
    walks when it is within two cells of the nearest end so far, and the nearest end wins. The finest band's closest
    points sample the surface a voxel apart: for a field whose closest points lie on its surface, the distance is
    exact but for that sampling (an upper bound within about h^2 / 4S)."""
    xc = clamp_to_domain(f, x)
    leaf = locate_leaf(f, xc)
    s = level_spacing(f, leaf[1])
    c = node_center(f.origin, s, node_coords(f, leaf[0]))
    # the nearest start of each basin found: distances, points, normal lines (slots past ``count`` unused)
    dists = wp.vec4(1.0e30)
    points = mat43()
    normals = mat43()
    count = int(0)
    # outside the domain x's foot may lie as far aside as x lies out: the block of cells around the clamped point
    # widens with that distance (2 cells either side at most)
    r = wp.min(2, 1 + int(wp.ceil(wp.length(x - xc) / s)))
    w = 2 * r + 1
    for o in range(w * w * w):
        q = c + s * wp.vec3(float(o % w - r), float((o // w) % w - r), float(o // (w * w) - r))
        d, p, n = _nearer(f, x, q, leaf[1], float(1.0e30), x, wp.vec3(0.0))
        if d < 1.0e30:
            slot = int(-1)
            for b in range(count):
                if wp.length(p - points[b]) <= 2.0 * s:
                    slot = b
            if slot < 0:
                if count < 4:
                    slot = count
                    count += 1
                else:  # a fifth basin: it replaces the farthest one if nearer
                    far = int(0)
                    for b in range(4):
                        if dists[b] > dists[far]:
                            far = b
                    slot = far
            if d < dists[slot]:
                dists[slot] = d
                points[slot] = p
                normals[slot] = n
    best = float(1.0e30)
    best_p = x
    # nearest start first, then the others that may end nearer
    order = int(0)
    for b in range(count):
        if dists[b] < dists[order]:
            order = b
    best, best_p = _walk(f, x, dists[order], points[order], normals[order])
    for b in range(count):
        if b != order and dists[b] < best + 2.0 * s:
            d2, p2 = _walk(f, x, dists[b], points[b], normals[b])
            if d2 < best:
                best = d2
                best_p = p2
    return best, best_p


@wp.func
def closest_sample(f: FieldArg, x: wp.vec3, leaf: wp.vec2i) -> wp.vec4:
    """(phi, grad) at ``x`` in coarse leaf ``leaf`` (or outside the domain) of a field whose closest points lie on its
    surface: the distance to the nearest of them (:func:`closest_stored_point`), with the leaf's sign (a coarse leaf
    holds no surface; outside the domain is outside)."""
    d, p = closest_stored_point(f, x)
    sign = wp.where(f.values[leaf[0]] < 0.0, -1.0, 1.0)
    if not inside_domain(f, x):
        sign = 1.0
    g = wp.vec3(0.0)
    if d > 0.0:
        g = (sign / d) * (x - p)
    return wp.vec4(sign * d, g[0], g[1], g[2])
