"""How a boolean reads an operand at the result's nodes (Warp functions for :mod:`.boolean`'s kernels).

An operand aligned with the result's lattice gives its own node values (:func:`lookup`, :func:`lookup_node`); elsewhere
it is sampled trilinearly in its finest band (:func:`finest_sample`), by moving least squares elsewhere
(:func:`sample_operand`, :func:`coarse_sample` reusing a leaf's gathered neighbours), extrapolated along its gradient on
coarse levels (:func:`extrapolate`), or only bracketed from its containing leaf, the field being 1-Lipschitz
(:func:`estimate`, :func:`bracket`, :func:`node_bracket`), so the boolean pays for interpolation only where an operand
can decide the result. Outside its domain an operand is the bound that grows with the distance to the domain. A placed
operand (``AdaptiveField.transformed``) is read in its own frame and its distances scaled back; it is never aligned, so
only the sampled paths meet it.
"""

from __future__ import annotations

import warp as wp
import warp.geometry

from . import octree
from .geometry import mesh_closest_face
from .octree import morton_encode, node_center
from .sampling import (
    LEAF_TOLERANCE,
    FieldArg,
    clamp_to_domain,
    closest_sample,
    coarse_mls,
    inside_domain,
    leaf_neighbours,
    level_spacing,
    locate_below,
    locate_leaf,
    locate_node,
    node_coords,
    sample_mls,
    stored_proj,
    to_frame,
    to_world_sample,
    trilinear_weights,
    unit_gradient,
    vec27i,
)

# A coarse leaf's value may exceed its distance by this share (the field type's LEAF_TOLERANCE):
# the brackets below widen by it, so they hold the exact value.
LEAF_SLACK = wp.constant(LEAF_TOLERANCE)


@wp.func
def _node_of(f: FieldArg, j: int, x: wp.vec3):
    """(1, phi, grad, j) of an operand's finest node ``j`` seen from ``x`` (its position)."""
    g = -wp.vec3(f.proj[j])  # from its closest point to the node (in voxels)
    ln = wp.length(g)
    phi = f.values[j]
    if ln > 0.0:
        g = g / ln
    if phi < 0.0:
        g = -g
    return 1, phi, g, j


@wp.func
def lookup(f: FieldArg, aligned: int, offset: wp.vec3i, c: wp.vec3i, x: wp.vec3):
    """An operand's own finest node at result node ``c`` when the lattices are aligned: (found, phi, grad, index)."""
    if aligned == 1:
        oc = c + offset
        if oc[0] >= 0 and oc[1] >= 0 and oc[2] >= 0:
            j = octree.find_key(f.codes, 0, f.fine_count, morton_encode(oc))
            if j >= 0:
                return _node_of(f, j, x)
    return 0, 0.0, wp.vec3(0.0), -1


@wp.func
def lookup_node(
    f: FieldArg,
    aligned: int,
    offset: wp.vec3i,
    c: wp.vec3i,
    x: wp.vec3,
    octet_mode: int,
    octet_first: wp.array[wp.int32],
    i: int,
):
    """:func:`lookup` for result finest node ``i`` (child ``i % 8`` of octet ``i // 8``), through the octet's first
    node in the operand when the octets coincide (``octet_mode``; -1 there: the operand lacks the octet)."""
    if octet_mode == 1:
        j0 = octet_first[i // 8]
        if j0 >= 0:
            return _node_of(f, j0 + i % 8, x)
        return 0, 0.0, wp.vec3(0.0), -1
    return lookup(f, aligned, offset, c, x)


@wp.func
def _beyond_domain(r: wp.vec4, x: wp.vec3, xc: wp.vec3) -> wp.vec4:
    """(phi, grad) ``r`` sampled at ``xc``, ``x`` clamped into the domain, as seen from ``x``: the bound that grows
    with the distance to the domain."""
    out = wp.length(x - xc)
    if out > 0.0:
        gd = (x - xc) / out
        return wp.vec4(wp.max(r[0], 0.0) + out, gd[0], gd[1], gd[2])
    return r


@wp.func
def sample_operand(f: FieldArg, x: wp.vec3) -> wp.vec4:
    """(phi, grad) by MLS at world point ``x``; outside the domain, the bound that grows with the distance to the
    domain."""
    xf = to_frame(f, x)
    xc = clamp_to_domain(f, xf)
    return to_world_sample(f, _beyond_domain(sample_mls(f, xc), xf, xc))


@wp.func
def finest_sample(f: FieldArg, x: wp.vec3) -> wp.vec4:
    """:func:`sample_operand` at ``x`` in the operand's finest band: trilinear between the 8 finest nodes around it
    (8 descents instead of the MLS fit's 28 and no 4x4 solve; as accurate on exact distances a voxel from the
    surface). Where a corner is no finest node, or two corners differ by more than their distance (the field jumps
    there: a hole's surface), the MLS fit, which keeps to one side of a jump."""
    xf = to_frame(f, x)
    if not inside_domain(f, xf):
        return sample_operand(f, x)
    s = f.voxel_size
    rel = (xf - f.origin) / s - wp.vec3(0.5)
    base = wp.vec3(wp.floor(rel[0]), wp.floor(rel[1]), wp.floor(rel[2]))
    t = rel - base
    v = wp.vec4(0.0)  # the value, then its derivatives along x, y, z (in lattice units)
    lo = float(1.0e30)
    hi = float(-1.0e30)
    for o in range(8):
        ox = o & 1
        oy = (o >> 1) & 1
        oz = (o >> 2) & 1
        q = f.origin + s * (base + wp.vec3(float(ox) + 0.5, float(oy) + 0.5, float(oz) + 0.5))
        if not inside_domain(f, q):
            return sample_operand(f, x)
        nb = locate_leaf(f, q)
        if nb[1] != 0:
            return sample_operand(f, x)
        phi = f.values[nb[0]]
        lo = wp.min(lo, phi)
        hi = wp.max(hi, phi)
        v += phi * trilinear_weights(o, t)
    if hi - lo > 1.75 * s * (f.lipschitz + LEAF_SLACK):  # farther apart than the cell's diagonal allows: a jump
        return sample_operand(f, x)
    return to_world_sample(f, unit_gradient(v))


@wp.func
def coarse_sample(f: FieldArg, x: wp.vec3, leaf: wp.vec2i, cached: int, count: int, ids: vec27i, levels: vec27i):
    """:func:`sample_operand` where ``x`` (clamped into the domain) lies in coarse leaf ``leaf`` (index, level), with
    the neighbours (:func:`leaf_neighbours`) of leaf ``cached`` at hand: gathered again only for another leaf. Returns
    the sample and the neighbours now at hand (cached leaf, count, indices, levels)."""
    if leaf[0] != cached:
        count, ids, levels = leaf_neighbours(f, leaf[0], leaf[1])
    xf = to_frame(f, x)
    xc = clamp_to_domain(f, xf)
    r = coarse_mls(f, count, ids, levels, xc, level_spacing(f, leaf[1]), f.values[leaf[0]])
    return to_world_sample(f, _beyond_domain(r, xf, xc)), leaf[0], count, ids, levels


@wp.func
def mesh_sample(f: FieldArg, x: wp.vec3, leaf: wp.vec2i, hint: wp.vec3, has_hint: int):
    """(found, (phi, grad), closest point in the field's frame) at world point ``x`` in node ``leaf`` (index, level;
    ``x`` clamped into the domain) of a field that is the signed distance to its mesh (``f.mesh``): the exact distance
    to that mesh, with the node's sign, which must hold at ``x``: a coarse leaf holds no triangle, so the winding
    number is constant over it; in a finest node's cell the caller's bracket must exclude zero (outside the domain is
    outside). One closest-point query, within the distance to the nearer of two points of the mesh: the node's own
    closest point (kept within 2^-11 of its distance per axis) and ``hint`` (with ``has_hint``: the caller's previous
    sample's, a voxel away). Cheaper than the MLS fit it replaces in a coarse leaf (27 neighbours, a 4x4 solve) on
    meshes of a few thousand triangles, about as cheap on larger ones, cheaper than a trilinear sample's 8 descents in
    the finest band, and exact where the fit reads a few voxels off a flat face up to a tenth too far and the
    trilinear sample beside an edge a tenth of a voxel off. Not found (rounding at the bound): the caller's own."""
    xf = to_frame(f, x)
    s = level_spacing(f, leaf[1])
    v = f.values[leaf[0]]
    foot = stored_proj(f, leaf[0], node_center(f.origin, s, node_coords(f, leaf[0])), s)
    bound = wp.length(xf - foot) + 0.002 * wp.abs(v)
    if has_hint == 1:
        bound = wp.min(bound, wp.length(xf - hint))
    p, face = mesh_closest_face(f.mesh, xf, bound + 0.001 * f.voxel_size)
    if face < 0:
        return 0, wp.vec4(0.0), hint
    sign = wp.where(v < 0.0, -1.0, 1.0)
    if not inside_domain(f, xf):
        sign = 1.0
    d = wp.length(xf - p)
    g = wp.vec3(0.0)
    if d > 0.0:
        g = (sign / d) * (xf - p)
    return 1, to_world_sample(f, wp.vec4(sign * d, g[0], g[1], g[2])), p


@wp.func
def blend_sample(
    f: FieldArg, walk: int, x: wp.vec3, leaf: wp.vec2i, cached: int, count: int, ids: vec27i, levels: vec27i
):
    """An operand's value in its coarse leaf ``leaf``: :func:`coarse_sample`, or with ``walk`` the distance to the
    operand's nearest stored closest point (:func:`.sampling.closest_sample`): exact where the MLS estimate of a
    coarse leaf is not (a few voxels off a flat face it reads up to a tenth too far), for blends that reach that far
    and operands whose closest points lie on their surface. (A field of a mesh reads the mesh: :func:`mesh_sample`.)"""
    if walk == 1:
        return to_world_sample(f, closest_sample(f, to_frame(f, x), leaf)), cached, count, ids, levels
    return coarse_sample(f, x, leaf, cached, count, ids, levels)


@wp.func
def _tangent_plane(f: FieldArg, xc: wp.vec3, node: wp.vec2i):
    """(phi, grad, sure) at ``xc`` (the field's frame, in its domain) from node ``node`` (index, level): its value
    carried along its exact gradient (the direction from its closest point), i.e. the distance to its tangent plane,
    and whether that keeps the node's side: it does where the node's value is farther from zero than ``xc`` is from
    the node (the field is 1-Lipschitz). Nearer, the plane can cross to the other side (beside an edge of a box, the
    plane of a node off the edge runs into the outside along the face). A coarse leaf holds no surface, so it is sure
    of its side all over: where its plane crosses, the distance to its closest point (the edge's, there)."""
    s = level_spacing(f, node[1])
    centre = node_center(f.origin, s, node_coords(f, node[0]))
    phi = f.values[node[0]]
    side = wp.where(phi < 0.0, -1.0, 1.0)
    n = -wp.vec3(f.proj[node[0]])  # from its closest point to the node
    ln = wp.length(n)
    g = wp.vec3(0.0)
    if ln > 0.0:
        g = side * n / ln
    plane = phi + wp.dot(g, xc - centre)
    if wp.abs(phi) >= f.lipschitz * wp.length(xc - centre) + LEAF_SLACK * wp.abs(phi):
        return plane, g, True
    if node[1] == 0 or plane * side > 0.0:
        return plane, g, node[1] > 0 and f.child[node[0] - f.fine_count] < 0
    if f.child[node[0] - f.fine_count] >= 0:
        return plane, g, False
    d = xc - stored_proj(f, node[0], centre, s)
    ld = wp.length(d)
    if ld > 0.0:
        g = side * d / ld
    return side * ld, g, True


@wp.func
def extrapolate(f: FieldArg, x: wp.vec3, spacing: float):
    """(phi, grad) from the operand's node containing ``x`` with the given spacing, or the coarser leaf containing it:
    the distance to its tangent plane (:func:`_tangent_plane`), exactly its own value where a node of the operand sits
    at ``x``. Cheap; used for the coarse levels of a result (``spacing``: theirs). Where that plane may read the wrong
    side, the plane of the leaf containing ``x``: a finest node's is off by less than its distance to ``x`` (within a
    voxel's half-diagonal). Also returns the node."""
    xf = to_frame(f, x)
    xc = clamp_to_domain(f, xf)
    node = locate_node(f, xc, wp.max(int(wp.round(wp.log2(spacing / (f.voxel_size * f.scale)))), 0))
    phi, g, sure = _tangent_plane(f, xc, node)
    if not sure:
        leaf = locate_below(f, xc, node, 0)
        if leaf[0] != node[0]:
            phi, g, sure = _tangent_plane(f, xc, leaf)
    out = wp.length(xf - xc)
    if out > 0.0:
        g = (xf - xc) / out
        phi = wp.max(phi, 0.0) + out
    return to_world_sample(f, wp.vec4(phi, g[0], g[1], g[2])), node[0]


@wp.func
def leaf_estimate(f: FieldArg, x: wp.vec3, leaf: wp.vec2i):
    """:func:`estimate` at ``x`` in the operand's leaf ``leaf`` (index, level), known to hold ``x`` (clamped into the
    domain)."""
    xf = to_frame(f, x)
    xc = clamp_to_domain(f, xf)
    if leaf[1] == 0:
        return 0.0, -1.0, leaf
    s = level_spacing(f, leaf[1])
    centre = node_center(f.origin, s, node_coords(f, leaf[0]))
    phi = f.values[leaf[0]]
    out = wp.length(xf - xc)
    if out > 0.0:
        phi = wp.max(phi, 0.0) + out
    radius = f.lipschitz * wp.length(xc - centre) + LEAF_SLACK * wp.abs(f.values[leaf[0]])
    return phi * f.scale, radius * f.scale, leaf


@wp.func
def estimate(f: FieldArg, x: wp.vec3):
    """A cheap bracket of an operand's value: (phi, radius) from the coarse leaf containing ``x`` (the field is
    1-Lipschitz, so the value at ``x`` lies within ``radius`` of the leaf's, widened by ``LEAF_SLACK``); radius -1 in
    the finest band. Also returns that leaf (index, level; ``x`` clamped into the domain). World units for a placed
    field."""
    return leaf_estimate(f, x, locate_leaf(f, clamp_to_domain(f, to_frame(f, x))))


@wp.func
def octet_leaf(octet_mode: int, octet_first: wp.array[wp.int32], i: int) -> wp.vec2i:
    """The coarse leaf (index, level) covering result finest node ``i``'s octet in an operand whose octets coincide
    with the result's (``octet_mode``), as the pruning found it (:func:`.prune.prune_octets`); (-1, 0): none known."""
    if octet_mode == 1:
        j0 = octet_first[i // 8]
        if j0 <= -2:
            code = -2 - j0
            return wp.vec2i(code // 16, code % 16)
    return wp.vec2i(-1, 0)


@wp.func
def finest_bracket(f: FieldArg, x: wp.vec3, node: int):
    """(phi, radius): an operand's value at world point ``x`` lies within ``radius`` of ``phi``, from its finest node
    ``node`` whose cell holds ``x`` (the field is 1-Lipschitz; world units for a placed field)."""
    xc = clamp_to_domain(f, to_frame(f, x))
    centre = node_center(f.origin, f.voxel_size, node_coords(f, node))
    v = f.values[node]
    return v * f.scale, (f.lipschitz * wp.length(xc - centre) + LEAF_SLACK * wp.abs(v)) * f.scale


@wp.func
def bracket(f: FieldArg, aligned: int, offset: wp.vec3i, c: wp.vec3i, x: wp.vec3):
    """(phi, radius): an operand's value at result node ``c`` lies within ``radius`` of ``phi`` — exact (radius 0)
    where the lattices align, the containing coarse leaf's bracket elsewhere; radius -1 in a non-aligned finest band."""
    found, phi, g, j = lookup(f, aligned, offset, c, x)
    if found == 1:
        return phi, 0.0
    phi, radius, leaf = estimate(f, x)
    if radius < 0.0:  # in the finest band: the finest node whose cell holds x (the field is 1-Lipschitz there too)
        return finest_bracket(f, x, leaf[0])
    return phi, radius


@wp.func
def octet_source(f: FieldArg, octet_mode: int, offset: wp.vec3i, oc: wp.vec3i, origin: wp.vec3, spacing: float):
    """Where an operand holds result octet ``oc`` when its lattice is aligned at octet granularity: (index of the
    octet's first child in its finest level, or -1; else the coarse leaf covering the whole octet, or -1; its level,
    -1 when the octet lies outside the operand's domain).
    The octet is a level-1 cell of the operand: a descent from its dense top level finds the node of that cell, whose
    8 children are the octet when it has any (an operand's finest level is octet-complete and every octet has its
    parent), or the coarser leaf that covers it."""
    if octet_mode == 1:
        x = origin + 2.0 * spacing * wp.vec3(float(oc[0]) + 0.5, float(oc[1]) + 0.5, float(oc[2]) + 0.5)
        if not inside_domain(f, x):
            return -1, -1, -1  # outside the operand's domain, so none of its octets
        if f.levels == 1:  # the dense top level is the finest: the octet's first child by its code
            c0 = wp.vec3i(2 * oc[0], 2 * oc[1], 2 * oc[2]) + offset
            return octree.find_key(f.codes, 0, f.fine_count, morton_encode(c0)), -1, 0
        leaf = locate_node(f, x, 1)
        if leaf[1] == 1 and f.child[leaf[0] - f.fine_count] >= 0:
            return f.child[leaf[0] - f.fine_count], -1, 0
        return -1, leaf[0], leaf[1]
    return -1, -1, 0


@wp.func
def node_bracket(
    f: FieldArg, first: int, leaf: int, level: int, k: int, aligned: int, offset: wp.vec3i, c: wp.vec3i, x: wp.vec3
):
    """(phi, radius) of an operand at child ``k`` of an octet located by :func:`octet_source`."""
    if first >= 0:
        return f.values[first + k], 0.0
    if leaf >= 0:
        centre = node_center(f.origin, level_spacing(f, level), node_coords(f, leaf))
        phi = f.values[leaf]
        return phi, f.lipschitz * wp.length(x - centre) + LEAF_SLACK * wp.abs(phi)
    if level < 0:  # the octet lies outside the operand's domain: no node of it to look up
        phi, radius, _leaf = estimate(f, x)
        return phi, radius
    return bracket(f, aligned, offset, c, x)
