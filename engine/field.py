"""The algebraic adaptive signed distance field of a triangle mesh (Ren et al., Sec. 4), built bottom-up in Warp.

Pipeline of :func:`build_field`:

1. finest level: one thread per triangle lists the octets (parents of finest cells) that a triangle-box test says
   lie within ``padding`` cells of it (Eq. 4-5: whole octets, so every parent gets exactly 8 children), marked in a
   byte per octet (or, for very large grids, all (triangle, octet) pairs radix-sorted), gathered, radix-sorted into
   Morton order, expanded to cells; exact closest points octet by octet (one BVH query at the octet centre bounds the
   candidate triangles, one box query lists them), per cell from Warp's mesh BVH for meshes finer than the cells;
2. intermediate levels: grandparents of the level below expanded to their 8 children (Eq. 6: parents plus the
   parents' siblings), de-duplicated; internal nodes take the nearest of their children's projection points, leaves
   are solved by a fast iterative method over same-level neighbours found by axis-wise key sorting (Eq. 7);
3. top level: a dense grid over the domain, initialised from its children and solved the same way;
4. signs, top-down: inside means generalised winding number >= 0.5. A node inherits its parent's sign when their
   empty balls cover the segment between them; only undecided nodes pay the winding number (the dense top level
   and the coarse nodes within about half a cell of the surface). Signs also spread between same-level neighbours
   (on an open mesh only away from the caps over its holes, see :func:`hole_caps`).

Sign convention: negative inside, positive outside (Blender/OpenVDB); the paper uses the opposite.
"""

from __future__ import annotations

import itertools
import math
import os
import threading
import time

import numpy as np
import warp as wp

from . import octree
from .errors import AasdfError
from .octree import (
    MAX_CELLS_PER_AXIS,
    UNSET_DISTANCE,
    mesh_closest_face,
    mesh_closest_point,
    morton_encode,
    node_center,
)
from .sampling import FieldArg, _sample_field_kernel, _source_ids_kernel, inside_domain, locate_leaf, top_cell

# Bytes a finest node costs while building (codes, coords, distances, projections, links, sort buffers).
BUILD_BYTES_PER_NODE = 160
SIGN_SAFETY = 0.9
# Fast winding number accuracy (Barill et al.'s beta): 1 is 3x faster than Warp's default 2 near the surface and
# agreed with it on 99.996 % of points around the Stanford bunny.
WINDING_ACCURACY = 1.0
# Rounds of refining coarse leaves the zero set crosses (open meshes: the surface across a hole).
MAX_SIGN_REFINEMENTS = 4
# Octets around the caps of an open mesh's holes whose centres' winding numbers locate the surface across the holes
# before the first build, and the most such octets per band octet that is worth (beyond it, a hole about as large
# as the mesh, the refinement rounds find that surface from the coarse signs instead).
CAP_LATTICE_MARGIN = 1
CAP_LATTICE_MAX_RATIO = 1.0
# ... and the least part of a box's octets that surface must cross, as seen from cells twice their size, for the box
# to be sampled (Suzanne's eyes: 0.2 %, holes of the bunny and the teapot: 10-30 %)
CAP_LATTICE_MIN_SHEET = 0.02
# Relative error allowed to the closest points of the top level's leaves (0: exact). Far from the surface it is the
# bulk of a query's work (bunny /512: 0.32 s of thread time at 1 %, 0.15 s at 5 %), while the far field's error stays
# the interpolation's (p95 2.79 % exact, 2.85 % at 5 %). A value up to this share above the distance must keep the
# empty balls of the signs within SIGN_SAFETY (a test checks) and widens the booleans' brackets (``LEAF_SLACK``).
TOP_LEVEL_TOLERANCE = 0.05
# Sweeps of same-level sign propagation, and the stride along each axis of the oracle's seeds on the dense top level
# (a lattice through the whole volume, so every region larger than a few top cells, inside or out, holds one).
MAX_SIGN_SWEEPS = 64
TOP_SEED_STRIDE = 4
# A sweep of the empty-ball phase that signs fewer than this share of a level's nodes ends it (another sweep over the
# whole level would sign a handful; the next phase takes them).
SIGN_SWEEP_SETTLED = 1e-3
# Finest octets search their candidate triangles in a box (instead of 8 BVH queries) when the mean triangle area is
# at least this many cell faces (measured break-even about 0.15 on this CPU: the bunny's finest distances take 0.075 s
# node by node against 0.083 s by boxes at 0.10 cell faces per triangle, 0.19 s against 0.145 s at 0.41).
OCTET_SEARCH_MIN_AREA = 0.15


# ---- finest level: octets overlapping triangles ----


@wp.func
def _axis_test(axis: wp.vec3, v0: wp.vec3, v1: wp.vec3, v2: wp.vec3, half: wp.vec3) -> bool:
    """True when ``axis`` separates the triangle (box-centred) from the box."""
    if wp.length_sq(axis) < 1.0e-30:
        return False
    p0 = wp.dot(v0, axis)
    p1 = wp.dot(v1, axis)
    p2 = wp.dot(v2, axis)
    r = half[0] * wp.abs(axis[0]) + half[1] * wp.abs(axis[1]) + half[2] * wp.abs(axis[2])
    return wp.min(p0, wp.min(p1, p2)) > r or wp.max(p0, wp.max(p1, p2)) < -r


@wp.func
def tri_box_overlap(center: wp.vec3, half: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> bool:
    """Separating-axis triangle/box overlap test (Akenine-Moller); the triangle's AABB is tested by the caller."""
    v0 = a - center
    v1 = b - center
    v2 = c - center
    e0 = v1 - v0
    e1 = v2 - v1
    e2 = v0 - v2
    # the triangle's plane first: it rejects most boxes near a triangle
    if _axis_test(wp.cross(e0, e1), v0, v1, v2, half):
        return False
    for k in range(3):
        unit = wp.vec3(0.0)
        unit[k] = 1.0
        if _axis_test(wp.cross(unit, e0), v0, v1, v2, half):
            return False
        if _axis_test(wp.cross(unit, e1), v0, v1, v2, half):
            return False
        if _axis_test(wp.cross(unit, e2), v0, v1, v2, half):
            return False
    return True


@wp.kernel(enable_backward=False)
def _octets_per_triangle_kernel(
    first: int,
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    origin: wp.vec3,
    octet_size: float,
    pad: float,
    dims: wp.vec3i,
    mask: wp.array[wp.uint8],
    offsets: wp.array[wp.int32],
    emit: int,
    counts: wp.array[wp.int32],
    codes: wp.array[wp.int64],
):
    """Count (emit=0), write (emit=1) or mark in ``mask`` (emit=2, see ``octree.mark_then_compact``) the octets
    within ``pad`` of triangle ``t``."""
    t = first + wp.tid()
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    lo = wp.min(a, wp.min(b, c)) - wp.vec3(pad)
    hi = wp.max(a, wp.max(b, c)) + wp.vec3(pad)
    i0 = wp.vec3i(0)
    i1 = wp.vec3i(0)
    for k in range(3):
        i0[k] = wp.clamp(int(wp.floor((lo[k] - origin[k]) / octet_size)), 0, dims[k] - 1)
        i1[k] = wp.clamp(int(wp.floor((hi[k] - origin[k]) / octet_size)), 0, dims[k] - 1)
    half = wp.vec3(0.5 * octet_size + pad)
    n = int(0)
    base = int(0)
    if emit == 1:
        base = offsets[t]
    for z in range(i0[2], i1[2] + 1):
        for y in range(i0[1], i1[1] + 1):
            for x in range(i0[0], i1[0] + 1):
                cell = wp.vec3i(x, y, z)
                center = origin + octet_size * wp.vec3(float(x) + 0.5, float(y) + 0.5, float(z) + 0.5)
                if emit == 2:
                    # an octet a neighbouring triangle marked already needs no test (races only write 1 twice)
                    m = x + dims[0] * (y + dims[1] * z)
                    if mask[m] == wp.uint8(0):
                        if tri_box_overlap(center, half, a, b, c):
                            mask[m] = wp.uint8(1)
                elif tri_box_overlap(center, half, a, b, c):
                    if emit == 1:
                        codes[base + n] = morton_encode(cell)
                    n += 1
    if emit == 0:
        counts[t] = n


@wp.func
def _closest_on_segment(p: wp.vec3, a: wp.vec3, b: wp.vec3) -> wp.vec3:
    ab = b - a
    t = wp.dot(p - a, ab) / wp.max(wp.dot(ab, ab), 1.0e-30)
    return a + ab * wp.clamp(t, 0.0, 1.0)


@wp.func
def _closest_on_edges(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> wp.vec3:
    """The nearest point to ``p`` on the three edges of triangle (a, b, c)."""
    q = _closest_on_segment(p, a, b)
    r = _closest_on_segment(p, b, c)
    if wp.length_sq(p - r) < wp.length_sq(p - q):
        q = r
    r = _closest_on_segment(p, c, a)
    if wp.length_sq(p - r) < wp.length_sq(p - q):
        q = r
    return q


@wp.func
def triangle_edges(a: wp.vec3, b: wp.vec3, c: wp.vec3):
    """(ab, ac, ab.ab, ab.ac, ac.ac): what ``closest_on_triangle`` needs of a triangle, once for many points."""
    ab = b - a
    ac = c - a
    return ab, ac, wp.dot(ab, ab), wp.dot(ab, ac), wp.dot(ac, ac)


@wp.func
def closest_on_triangle(
    p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3, ab: wp.vec3, ac: wp.vec3, d00: float, d01: float, d11: float
) -> wp.vec3:
    """Closest point to ``p`` on triangle (a, b, c) by Voronoi regions (Ericson, Real-Time Collision Detection
    5.1.5), with the triangle's edges ``ab`` = b - a, ``ac`` = c - a and their products (``d00`` = ab.ab, ``d01`` =
    ab.ac, ``d11`` = ac.ac) computed once for the many points tested against it: the six dot products of the regions
    follow from two (ab.ap, ac.ap). A degenerate triangle (or one within float rounding of it) falls back to its
    nearest edge."""
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return a
    d3 = d1 - d00  # ab.(p - b)
    d4 = d2 - d01  # ac.(p - b)
    if d3 >= 0.0 and d4 <= d3:
        return b
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        return a + ab * (d1 / (d1 - d3))
    d5 = d1 - d01  # ab.(p - c)
    d6 = d2 - d11  # ac.(p - c)
    if d6 >= 0.0 and d5 <= d6:
        return c
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        return a + ac * (d2 / (d2 - d6))
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))
    total = va + vb + vc  # |ab x ac|^2, up to rounding
    if total > 1.0e-6 * d00 * d11:
        return a + ab * (vb / total) + ac * (vc / total)
    # degenerate, or so nearly (its two edges' angle under 1e-3) that float rounding would decide the point
    return _closest_on_edges(p, a, b, c)


@wp.func
def _node_closest_point(mesh: wp.uint64, x: wp.vec3, max_dist: float, far_dist: float):
    """(found, closest point) of one node by the mesh BVH: within ``max_dist``, else within ``far_dist``."""
    found, p = mesh_closest_point(mesh, x, max_dist)
    if not found:
        # a node added where an open mesh's surface crosses a hole can be far from every triangle
        found, p = mesh_closest_point(mesh, x, far_dist)
    return wp.where(found, 1, 0), p


@wp.kernel(enable_backward=False)
def _finest_octet_distance_kernel(
    first: int,
    mesh: wp.uint64,
    coords: wp.array[wp.vec3i],
    octet_nodes: wp.array[wp.int32],
    origin: wp.vec3,
    spacing: float,
    max_dist: float,
    far_dist: float,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    octet_dist: wp.array[wp.float32],
    octet_proj: wp.array[wp.vec3],
    box_search: int,
):
    """Exact closest points of the 8 nodes of one finest octet (first node ``octet_nodes[first + tid]``, children in
    Morton order). One BVH query at the octet's centre gives its closest triangle; each node's distance to that
    triangle bounds its own (tighter than its distance to the centre's closest point: a smaller box, and fewer
    triangles pass the tests below), so the triangles whose boxes meet the box around those balls are all the
    candidates, and every node is tested against them directly — one BVH query per octet instead of eight. Octets
    far from the mesh (no triangle within ``max_dist`` of the centre) query per node, each bounded by the centre's
    closest point, and every octet does when ``box_search`` is 0 (a mesh whose triangles are much smaller than a cell
    would put hundreds in each box). The centre's closest point (the octet's parent node's) goes to
    ``octet_dist``/``octet_proj`` (UNSET_DISTANCE when not found)."""
    t = first + wp.tid()
    base = octet_nodes[t]
    c = node_center(origin, spacing, coords[base]) + wp.vec3(0.5 * spacing)
    centre_foot, centre_face = mesh_closest_face(mesh, c, max_dist)
    near = centre_face >= 0
    has_foot = near
    if not near:
        # an octet added where an open mesh's surface crosses a hole can be far from every triangle
        has_foot, centre_foot = mesh_closest_point(mesh, c, far_dist)
    octet_dist[base // 8] = UNSET_DISTANCE
    if has_foot:
        octet_dist[base // 8] = wp.length(c - centre_foot)
        octet_proj[base // 8] = centre_foot
    if near and box_search == 1:
        node_lo = c - wp.vec3(0.5 * spacing)  # the box of the 8 node centres
        node_hi = c + wp.vec3(0.5 * spacing)
        # every node starts from its closest point on the centre's closest triangle (an upper bound)
        m = wp.mesh_get(mesh)
        a0 = m.points[m.indices[3 * centre_face]]
        b0 = m.points[m.indices[3 * centre_face + 1]]
        c0 = m.points[m.indices[3 * centre_face + 2]]
        ab0, ac0, d00, d01, d11 = triangle_edges(a0, b0, c0)
        best = wp.vector(UNSET_DISTANCE, length=8, dtype=float)
        foot = wp.matrix(0.0, shape=(8, 3), dtype=float)
        worst = float(0.0)
        # each node's closest triangle lies in its ball through that point: search the box around those balls
        box_lo = c
        box_hi = c  # grown around every ball below (starting at the centre can only widen it)
        for k in range(8):
            x = c + spacing * wp.vec3(float(k & 1) - 0.5, float((k >> 1) & 1) - 0.5, float((k >> 2) & 1) - 0.5)
            p0 = closest_on_triangle(x, a0, b0, c0, ab0, ac0, d00, d01, d11)
            best[k] = wp.length_sq(x - p0)
            foot[k] = p0
            worst = wp.max(worst, best[k])
            r = wp.sqrt(best[k]) * 1.0001 + 1.0e-4 * spacing
            box_lo = wp.min(box_lo, x - wp.vec3(r))
            box_hi = wp.max(box_hi, x + wp.vec3(r))
        candidates = wp.mesh_query_aabb(mesh, box_lo, box_hi)
        f = int(0)
        while wp.mesh_query_aabb_next(candidates, f):
            if f == centre_face:
                continue
            a = m.points[m.indices[3 * f]]
            b = m.points[m.indices[3 * f + 1]]
            cc = m.points[m.indices[3 * f + 2]]
            # no point of a triangle is nearer than its bounding box: the box's distance to the nodes' box bounds
            # all 8 nodes at once, its distance to a node that node, before the exact test (an exact test at the
            # centre, less half a diagonal, bounded them about as well at about the same cost)
            tri_lo = wp.min(a, wp.min(b, cc))
            tri_hi = wp.max(a, wp.max(b, cc))
            gap = wp.max(wp.max(tri_lo - node_hi, node_lo - tri_hi), wp.vec3(0.0))
            if wp.length_sq(gap) < worst:
                worst = float(0.0)
                ab, ac, d00, d01, d11 = triangle_edges(a, b, cc)
                for k in range(8):
                    x = c + spacing * wp.vec3(float(k & 1) - 0.5, float((k >> 1) & 1) - 0.5, float((k >> 2) & 1) - 0.5)
                    gap = wp.max(wp.max(tri_lo - x, x - tri_hi), wp.vec3(0.0))
                    if wp.length_sq(gap) < best[k]:
                        p = closest_on_triangle(x, a, b, cc, ab, ac, d00, d01, d11)
                        d = wp.length_sq(x - p)
                        if d < best[k]:
                            best[k] = d
                            foot[k] = p
                    worst = wp.max(worst, best[k])
        for k in range(8):
            x = node_center(origin, spacing, coords[base + k])
            if best[k] < UNSET_DISTANCE:
                p = wp.vec3(foot[k, 0], foot[k, 1], foot[k, 2])
                dist[base + k] = wp.length(x - p)
                proj[base + k] = p
            else:  # cannot happen but for rounding: the node's own query
                found, p = _node_closest_point(mesh, x, max_dist, far_dist)
                dist[base + k] = wp.where(found == 1, wp.length(x - p), UNSET_DISTANCE)
                proj[base + k] = p
        return
    for k in range(8):
        x = node_center(origin, spacing, coords[base + k])
        bound = max_dist
        if not near and has_foot:  # far from the mesh: the centre's closest point bounds each node's search
            bound = wp.length(x - centre_foot) * 1.0001 + 1.0e-4 * spacing
        found, p = _node_closest_point(mesh, x, bound, far_dist)
        dist[base + k] = wp.where(found == 1, wp.length(x - p), UNSET_DISTANCE)
        proj[base + k] = p


@wp.kernel(enable_backward=False)
def _finest_distance_kernel(
    mesh: wp.uint64,
    coords: wp.array[wp.vec3i],
    origin: wp.vec3,
    spacing: float,
    max_dist: float,
    far_dist: float,
    source_id: int,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
):
    """Exact closest point of each node of a dense finest level (Warp's mesh BVH)."""
    i = wp.tid()
    x = node_center(origin, spacing, coords[i])
    found, p = _node_closest_point(mesh, x, max_dist, far_dist)
    source[i] = source_id
    dist[i] = wp.where(found == 1, wp.length(x - p), UNSET_DISTANCE)
    proj[i] = p


# ---- signs ----


@wp.func_native("return wp::mesh_query_winding_number(mesh, x, accuracy);")
def _winding_number(mesh: wp.uint64, x: wp.vec3, accuracy: float) -> float:
    """The mesh's fast winding number at ``x`` (Barill et al., Warp's native solid-angle tree): what
    ``wp.mesh_query_point_sign_winding_number`` compares with its threshold, without the closest-point query it runs
    first (a third of its cost; a node's distance is known already)."""
    ...


@wp.kernel(enable_backward=False)
def _mesh_sign_kernel(
    mesh: wp.uint64,
    coords: wp.array[wp.vec3i],
    nodes: wp.array[wp.int32],
    origin: wp.vec3,
    spacing: float,
    sign: wp.array[wp.float32],
):
    """Sign oracle: inside where the generalised winding number is above 0.5 (robust on open and multi-shell
    meshes)."""
    t = wp.tid()
    i = nodes[t]
    x = node_center(origin, spacing, coords[i])
    sign[i] = wp.where(_winding_number(mesh, x, WINDING_ACCURACY) > 0.5, -1.0, 1.0)


@wp.kernel(enable_backward=False)
def _segments_clear_kernel(mesh: wp.uint64, p: wp.array[wp.vec3], q: wp.array[wp.vec3], clear: wp.array[wp.uint8]):
    """Whether each segment p[i] q[i] surely meets no triangle (``_segment_clear``)."""
    i = wp.tid()
    clear[i] = wp.where(_segment_clear(mesh, p[i], q[i]), wp.uint8(1), wp.uint8(0))


@wp.kernel(enable_backward=False)
def _band_gap_kernel(
    start: int,
    f: FieldArg,
    near_lo: wp.array[wp.vec3],
    near_hi: wp.array[wp.vec3],
    near_radius: wp.array[wp.float32],
    margin: float,
    region: wp.array[wp.uint8],
    capacity: int,
    count: wp.array[wp.int32],
    out: wp.array[wp.int64],
):
    """Octets next to the finest band whose covering coarse leaf has another sign than a node of the band octet
    beside them: a marching cube straddling the zero set there would be incomplete. One thread per band octet
    (8 consecutive finest nodes, octet ``start + tid``), only where the ``near`` boxes' bound (``_near_cap``) fails
    within ``margin`` when ``margin >= 0``, and only in the top cells flagged in ``region`` (empty: all); found octet
    codes are appended to ``out``."""
    t = start + wp.tid()
    first = 8 * t
    octet = wp.vec3i(f.coords[first][0] >> 1, f.coords[first][1] >> 1, f.coords[first][2] >> 1)
    size = 2.0 * f.voxel_size
    c = f.origin + size * wp.vec3(float(octet[0]) + 0.5, float(octet[1]) + 0.5, float(octet[2]) + 0.5)
    if not _in_region(f, region, c):
        return
    if margin >= 0.0 and not _near_cap(c, near_lo, near_hi, near_radius, margin):
        return
    for o in range(27):
        if o != 13:
            d = wp.vec3i(o % 3 - 1, (o // 3) % 3 - 1, o // 9 - 1)
            q = c + size * wp.vec3(float(d[0]), float(d[1]), float(d[2]))
            if inside_domain(f, q):
                nb = locate_leaf(f, q)
                if nb[1] > 0:
                    other = f.values[nb[0]] < 0.0
                    # only this octet's nodes on the side facing the neighbour share marching cubes with it
                    differs = int(0)
                    for n in range(8):
                        facing = int(1)
                        for a in range(3):
                            bit = (n >> a) & 1
                            if (d[a] > 0 and bit == 0) or (d[a] < 0 and bit == 1):
                                facing = int(0)
                        if facing == 1 and (f.values[first + n] < 0.0) != other:
                            differs = int(1)
                    if differs == 1:
                        slot = wp.atomic_add(count, 0, 1)
                        if slot < capacity:
                            out[slot] = morton_encode(octet + d)


@wp.kernel(enable_backward=False)
def _sign_change_kernel(
    start: int,
    f: FieldArg,
    node_level: wp.array[wp.int32],
    near_lo: wp.array[wp.vec3],
    near_hi: wp.array[wp.vec3],
    near_radius: wp.array[wp.float32],
    margin: float,
    region: wp.array[wp.uint8],
    marks: wp.array[wp.int32],
):
    """Mark coarse leaves that have a coarse face neighbour of the opposite sign: the zero set crosses them.
    Coarse node ``start + tid``; only where the ``near`` boxes' bound (``_near_cap``) fails within ``margin`` when
    ``margin >= 0``, and only in the top cells flagged in ``region`` (empty: all)."""
    t = start + wp.tid()
    i = f.fine_count + t
    marks[t] = 0
    if f.child[i] >= 0:
        return
    s = f.voxel_size * float(1 << node_level[i])
    c = node_center(f.origin, s, f.coords[i])
    if not _in_region(f, region, c):
        return
    if margin >= 0.0 and not _near_cap(c, near_lo, near_hi, near_radius, margin):
        return
    inside = f.values[i] < 0.0
    for k in range(6):
        # probe just across the face centre: the leaf found there touches this one
        d = wp.vec3(0.0)
        step = 0.5 * s + 0.25 * f.voxel_size
        d[k // 2] = wp.where(k % 2 == 0, -step, step)
        q = c + d
        if inside_domain(f, q):
            nb = locate_leaf(f, q)
            # sign changes next to the finest band are the band-gap kernel's business
            if nb[1] > 0 and (f.values[nb[0]] < 0.0) != inside:
                marks[t] = 1


@wp.func
def _in_region(f: FieldArg, region: wp.array[wp.uint8], x: wp.vec3) -> bool:
    """Whether the top-level cell holding ``x`` is flagged in ``region`` (one byte per top cell; empty: all are)."""
    if region.shape[0] == 0:
        return True
    return region[top_cell(f, x)] != wp.uint8(0)


@wp.func
def _near_cap(
    x: wp.vec3, cap_lo: wp.array[wp.vec3], cap_hi: wp.array[wp.vec3], cap_radius: wp.array[wp.float32], margin: float
) -> bool:
    """Whether the cones over an open mesh's holes (see ``hole_caps``; no caps: a closed mesh) may move the winding
    number by 1/4 or more somewhere within ``margin`` of ``x``: sum over caps c of (radius_c / d_c)^2 >= 1, d_c the
    distance from the box c to that ball."""
    total = float(0.0)
    for c in range(cap_radius.shape[0]):
        d = wp.length(wp.max(wp.max(cap_lo[c] - x, x - cap_hi[c]), wp.vec3(0.0))) - margin
        if d <= cap_radius[c]:
            return True
        total += (cap_radius[c] / d) * (cap_radius[c] / d)
    return total >= 1.0


@wp.func
def _take_sign(i: int, j: int, dist: wp.array[wp.float32], sign: wp.array[wp.float32], safety: float, spacing: float):
    """Give unsigned node ``i`` the sign of face neighbour ``j`` when their empty balls cover the edge between them."""
    if sign[j] != 0.0 and (dist[i] + dist[j]) * safety > spacing:
        sign[i] = sign[j]
        return 1
    return 0


@wp.func
def _may_cross(p: wp.vec3, q: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> bool:
    """Whether segment pq may meet triangle abc: False only when it surely does not (both ends clearly on one side of
    the plane, or the segment's line clearly outside an edge); touching, grazing and degenerate cases count as
    meeting."""
    n = wp.cross(b - a, c - a)
    d = q - p
    reach = wp.max(wp.length(a - p), wp.max(wp.length(b - p), wp.length(c - p))) + wp.length(d)
    # margins 10x above float32 rounding of the products they bound (all lengths cubed)
    tol = 1.0e-5 * wp.length(n) * reach
    sp = wp.dot(p - a, n)
    sq = wp.dot(q - a, n)
    if (sp > tol and sq > tol) or (sp < -tol and sq < -tol):
        return False
    tol = 1.0e-5 * reach * reach * wp.length(d)
    v0 = wp.dot(wp.cross(a - p, b - p), d)
    v1 = wp.dot(wp.cross(b - p, c - p), d)
    v2 = wp.dot(wp.cross(c - p, a - p), d)
    if (v0 > tol or v1 > tol or v2 > tol) and (v0 < -tol or v1 < -tol or v2 < -tol):
        return False
    return True


@wp.func
def _segment_clear(mesh: wp.uint64, p: wp.vec3, q: wp.vec3) -> bool:
    """Whether segment pq surely meets no triangle of the mesh."""
    pad = wp.vec3(1.0e-3 * wp.length(q - p))
    candidates = wp.mesh_query_aabb(mesh, wp.min(p, q) - pad, wp.max(p, q) + pad)
    m = wp.mesh_get(mesh)
    f = int(0)
    while wp.mesh_query_aabb_next(candidates, f):
        if _may_cross(p, q, m.points[m.indices[3 * f]], m.points[m.indices[3 * f + 1]], m.points[m.indices[3 * f + 2]]):
            return False
    return True


@wp.func
def _take_sign_across(
    i: int,
    j: int,
    dist: wp.array[wp.float32],
    sign: wp.array[wp.float32],
    safety: float,
    spacing: float,
    mesh: wp.uint64,
    x: wp.vec3,
    y: wp.vec3,
):
    """``_take_sign``, or with a mesh (``mesh`` != 0) also when the segment between the nodes (at ``x`` and ``y``)
    surely crosses no triangle: away from an open mesh's holes the winding number changes only across triangles."""
    if _take_sign(i, j, dist, sign, safety, spacing) == 1:
        return 1
    if mesh != wp.uint64(0) and sign[j] != 0.0:
        if _segment_clear(mesh, x, y):
            sign[i] = sign[j]
            return 1
    return 0


@wp.kernel(enable_backward=False)
def _propagate_sign_kernel(
    neighbours: wp.array2d[wp.int32],
    row0: int,
    lo: int,
    dist: wp.array[wp.float32],
    sign: wp.array[wp.float32],
    safety: float,
    spacing: float,
    coords: wp.array[wp.vec3i],
    origin: wp.vec3,
    cap_lo: wp.array[wp.vec3],
    cap_hi: wp.array[wp.vec3],
    cap_radius: wp.array[wp.float32],
    mesh: wp.uint64,
    changed: wp.array[wp.int32],
    span: int,
    reverse: int,
):
    """An unsigned node takes a signed face neighbour's sign when their empty balls cover the edge between them, or
    with a mesh (``mesh`` != 0) when the segment between them crosses no triangle. Signs only ever go from 0 to
    final, so sweeps may read and write in place (a sign travels along the launch's order within one sweep: sweeps
    alternate ``reverse``). Not near an open mesh's holes (see ``hole_caps``). Node ``i``'s neighbours are in row
    ``i - row0``; the launch covers nodes [lo, lo + span)."""
    i = lo + wp.where(reverse == 1, span - 1 - wp.tid(), wp.tid())
    if sign[i] != 0.0:
        return
    x = node_center(origin, spacing, coords[i])
    if _near_cap(x, cap_lo, cap_hi, cap_radius, spacing):
        return
    faces = int(6)  # not unrolled: one copy of the segment test (compile time)
    for k in range(faces):
        j = neighbours[i - row0, k]
        if j >= 0:
            y = node_center(origin, spacing, coords[j])
            if _take_sign_across(i, j, dist, sign, safety, spacing, mesh, x, y) == 1:
                wp.atomic_add(changed, 0, 1)
                return


@wp.kernel(enable_backward=False)
def _propagate_sign_octet_kernel(
    first: int,
    codes: wp.array[wp.int64],
    parent: wp.array[wp.int32],
    child: wp.array[wp.int32],
    neighbours: wp.array2d[wp.int32],
    row0: int,
    dist: wp.array[wp.float32],
    sign: wp.array[wp.float32],
    safety: float,
    spacing: float,
    origin: wp.vec3,
    cap_lo: wp.array[wp.vec3],
    cap_hi: wp.array[wp.vec3],
    cap_radius: wp.array[wp.float32],
    mesh: wp.uint64,
    changed: wp.array[wp.int32],
    span: int,
    reverse: int,
):
    """The same on the finest level, which has no neighbour table: one thread per octet (8 consecutive nodes in
    Morton order; the launch covers octets [first, first + span)). Three face neighbours of a node are in its own
    octet; the other three are the same child of the face-adjacent octets: the children of the octet's level-1 node's
    face neighbour (``neighbours``, node ``i`` in row ``i - row0``), when it has any. With a
    mesh (``mesh`` != 0) a node also takes the sign of a neighbour when the segment between them crosses no triangle
    (``_take_sign_across``), which signs most of the nodes too near the surface for empty balls without a winding
    number."""
    t = first + wp.where(reverse == 1, span - 1 - wp.tid(), wp.tid())
    base = 8 * t
    unset = int(0)
    for k in range(8):
        if sign[base + k] == 0.0:
            unset += 1
    if unset == 0:
        return
    octet = octree.morton_decode(codes[base] >> wp.int64(3))
    centre = origin + 2.0 * spacing * wp.vec3(float(octet[0]) + 0.5, float(octet[1]) + 0.5, float(octet[2]) + 0.5)
    if _near_cap(centre, cap_lo, cap_hi, cap_radius, 2.0 * spacing):
        return
    # first node of the octet across each face (-x, +x, -y, +y, -z, +z); -2: not looked up yet
    across = wp.vector(-2, -2, -2, -2, -2, -2, length=6, dtype=int)
    got = int(0)
    # loop bounds held in variables keep Warp from unrolling 2 x 8 x 3 copies of the segment test (compile time)
    sweeps = int(2)
    nodes = int(8)
    axes = int(3)
    for _sweep in range(sweeps):
        for k in range(nodes):
            i = base + k
            if sign[i] == 0.0:
                x = centre + spacing * wp.vec3(float(k & 1) - 0.5, float((k >> 1) & 1) - 0.5, float((k >> 2) & 1) - 0.5)
                for a in range(axes):
                    bit = (k >> a) & 1
                    step = wp.vec3(0.0)
                    step[a] = wp.where(bit == 0, spacing, -spacing)
                    if sign[i] == 0.0:
                        got += _take_sign_across(
                            i, base + (k ^ (1 << a)), dist, sign, safety, spacing, mesh, x, x + step
                        )
                    if sign[i] == 0.0:
                        bit = (k >> a) & 1
                        face = 2 * a + bit
                        if across[face] == -2:
                            # the octet's level-1 node's neighbour across the face, and its children if it has any
                            across[face] = -1
                            nb = neighbours[parent[base] - row0, face]
                            if nb >= 0:
                                across[face] = child[nb]
                        if across[face] >= 0:
                            got += _take_sign_across(
                                i, across[face] + (k ^ (1 << a)), dist, sign, safety, spacing, mesh, x, x - step
                            )
    if got > 0:
        wp.atomic_add(changed, 0, got)


@wp.kernel(enable_backward=False)
def _apply_sign_kernel(
    first: int, dist: wp.array[wp.float32], sign: wp.array[wp.float32], values: wp.array[wp.float32]
):
    i = first + wp.tid()
    s = sign[i]
    if s == 0.0:
        s = 1.0
    values[i] = s * dist[i]


# ---- the field ----


class AdaptiveField:
    """A hierarchical sparse octree of signed distances (negative inside), closed under booleans.

    Levels are stored finest first and concatenated; ``level_offsets[k]:level_offsets[k+1]`` is level ``k``.
    Intermediate levels are sorted by Morton code; the top level is dense in x-fastest order.
    """

    def __init__(
        self,
        *,
        voxel_size,
        levels,
        origin,
        top_dims,
        level_offsets,
        codes,
        coords,
        values,
        proj,
        child,
        source,
        field_ids,
        device,
        timings=None,
        stats=None,
    ):
        self.voxel_size = float(voxel_size)
        self.levels = int(levels)
        self.origin = np.asarray(origin, dtype=np.float64)
        self.top_dims = np.asarray(top_dims, dtype=np.int64)
        self.level_offsets = np.asarray(level_offsets, dtype=np.int64)
        self.codes, self.coords, self.values, self.proj = codes, coords, values, proj
        self.child, self.source = child, source
        self.field_ids = tuple(sorted(set(int(i) for i in field_ids)))
        self.device = device
        self.timings = dict(timings or {})
        self.stats = dict(stats or {})

    # -- geometry of the domain --
    @property
    def top_spacing(self) -> float:
        return self.voxel_size * 2 ** (self.levels - 1)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) corners of the domain, world space."""
        return self.origin.copy(), self.origin + self.top_dims * self.top_spacing

    @property
    def fine_dims(self) -> np.ndarray:
        return self.top_dims * 2 ** (self.levels - 1)

    @property
    def node_count(self) -> int:
        return int(self.level_offsets[-1])

    @property
    def level_counts(self) -> list[int]:
        return [int(n) for n in np.diff(self.level_offsets)]

    @property
    def field_id(self) -> int:
        return self.field_ids[0]

    def level_slice(self, level: int) -> slice:
        return slice(int(self.level_offsets[level]), int(self.level_offsets[level + 1]))

    def arg(self) -> FieldArg:
        f = FieldArg()
        f.origin = wp.vec3(*self.origin)
        f.voxel_size = self.voxel_size
        f.levels = self.levels
        f.top_dims = wp.vec3i(*(int(d) for d in self.top_dims))
        f.top_offset = int(self.level_offsets[self.levels - 1])
        lo, hi = self.bounds
        f.domain_min = wp.vec3(*lo)
        f.domain_max = wp.vec3(*hi)
        f.coords, f.child, f.values, f.source, f.proj = self.coords, self.child, self.values, self.source, self.proj
        f.codes = self.codes
        f.fine_count = int(self.level_offsets[1])
        return f

    def __repr__(self) -> str:
        return (
            f"AdaptiveField(voxel_size={self.voxel_size:g}, levels={self.levels}, nodes={self.node_count}, "
            f"level_counts={self.level_counts}, ids={list(self.field_ids)})"
        )

    # -- queries --
    def sample(self, points, method: str = "mls", *, return_gradient: bool = False):
        """Signed distance at world-space points.

        Args:
            points: (N, 3) array-like of world-space points.
            method: ``"mls"`` (moving least squares, Eq. 9-10) or ``"linear"`` (trilinear, for comparison).
            return_gradient: Also return the (N, 3) float32 MLS gradient.
        Returns:
            (N,) float32 signed distances, negative inside; outside the domain never below the distance to it.
        Raises:
            ValueError: If ``points`` is not (N, 3) or ``method`` is unknown.
        """
        pts = _as_points(points)
        if method not in ("mls", "linear"):
            raise ValueError(f"Expected 'method' to be 'mls' or 'linear', but got {method!r}.")
        n = len(pts)
        values = wp.empty(n, dtype=wp.float32, device=self.device)
        grads = wp.empty(n, dtype=wp.vec3, device=self.device)
        if n:
            arg, pts_wp, mode = self.arg(), wp.array(pts, dtype=wp.vec3, device=self.device), int(method != "mls")
            octree.launch_split(
                _sample_field_kernel,
                n,
                lambda lo, k: [arg, pts_wp[lo : lo + k], mode, values[lo : lo + k], grads[lo : lo + k]],
                self.device,
            )
        if return_gradient:
            return values.numpy(), grads.numpy()
        return values.numpy()

    def source_ids(self, points) -> np.ndarray:
        """(N,) int32: the id of the input field whose surface determines the value at each point."""
        pts = _as_points(points)
        ids = wp.empty(len(pts), dtype=wp.int32, device=self.device)
        if len(pts):
            arg, pts_wp = self.arg(), wp.array(pts, dtype=wp.vec3, device=self.device)
            octree.launch_split(
                _source_ids_kernel,
                len(pts),
                lambda lo, n: [arg, pts_wp[lo : lo + n], ids[lo : lo + n]],
                self.device,
            )
        return ids.numpy()

    def level_of_nodes(self) -> np.ndarray:
        return np.repeat(np.arange(self.levels, dtype=np.int32), np.diff(self.level_offsets))

    def node_centers(self) -> np.ndarray:
        """(N, 3) float64 world-space centres of all nodes, finest level first."""
        lv = self.level_of_nodes()
        spacing = self.voxel_size * (2.0**lv)
        return self.origin + (self.coords.numpy().astype(np.float64) + 0.5) * spacing[:, None]

    def debug_cells(self) -> dict:
        """Every stored node: centres (N,3) float32, sizes (N,), levels (N,), sdf (N,), leaf (N,) bool."""
        lv = self.level_of_nodes()
        return {
            "centers": self.node_centers().astype(np.float32),
            "sizes": (self.voxel_size * (2.0**lv)).astype(np.float32),
            "levels": lv,
            "sdf": self.values.numpy().copy(),
            "leaf": self.child.numpy() < 0,
        }

    def to_dense(self, bounds=None, spacing=None, *, max_bytes=None) -> dict:
        """Dense samples for debug volumes.

        Args:
            bounds: ((3,), (3,)) world box; defaults to the domain.
            spacing: Sample spacing; defaults to the finest voxel size.
            max_bytes: Refuse blocks larger than this (default: half the available memory).
        Returns:
            dict with ``values`` (X, Y, Z) float32 (x-major, index [i, j, k]), ``origin`` (3,) world position of
            sample [0, 0, 0], and ``spacing``.
        Raises:
            AasdfError: If the block would not fit in memory.
        """
        lo, hi = self.bounds if bounds is None else (np.asarray(bounds[0], float), np.asarray(bounds[1], float))
        spacing = self.voxel_size if spacing is None else float(spacing)
        if not spacing > 0:
            raise ValueError(f"Expected a positive 'spacing', but got {spacing}.")
        shape = np.maximum(np.ceil((hi - lo) / spacing).astype(np.int64), 1)
        budget = available_memory() // 2 if max_bytes is None else int(max_bytes)
        need = int(np.prod(shape)) * 4 * 8
        if need > budget:
            raise AasdfError(
                f"A dense block of {shape[0]}x{shape[1]}x{shape[2]} samples needs {need / 2**30:.1f} GiB,"
                f" more than the {budget / 2**30:.1f} GiB available; use a coarser spacing."
            )
        axes = [lo[a] + (np.arange(shape[a]) + 0.5) * spacing for a in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        values = self.sample(grid).reshape(tuple(shape))
        return {"values": values, "origin": lo + 0.5 * spacing, "spacing": spacing}

    def to_mesh(self, iso: float = 0.0):
        """Marching cubes over the finest level's narrow band: (V,3) float32 vertices, (F,3) int32 triangles."""
        from .extract import extract_octree_level, extract_surface

        n0 = self.level_counts[0]
        if self.levels == 1:  # the dense top level is the finest: no octets to walk
            return extract_surface(
                self.coords.numpy(), self.values.numpy(), origin=self.origin, spacing=self.voxel_size, iso=float(iso)
            )
        return extract_octree_level(
            self.coords[:n0],
            self.values[:n0],
            (self.child, self.level_offsets[self.levels - 1], self.top_dims, self.levels),
            origin=self.origin,
            spacing=self.voxel_size,
            iso=float(iso),
        )

    # -- booleans as operators --
    def __or__(self, other):
        from .boolean import union

        return union(self, other)

    def __and__(self, other):
        from .boolean import intersection

        return intersection(self, other)

    def __sub__(self, other):
        from .boolean import difference

        return difference(self, other)


# ---- validation and helpers ----


def available_memory() -> int:
    """Bytes of memory available to this process (best effort, 8 GiB when the platform does not say)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return 8 * 2**30


def _as_points(points) -> np.ndarray:
    pts = np.ascontiguousarray(points, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"Expected 'points' of shape (N, 3), but got {pts.shape}.")
    return pts


def _triangle_areas(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(T,) areas, component by component (numpy's cross and norm over (T, 3) arrays are several times slower)."""
    a, b, c = (verts[tris[:, k]] for k in range(3))
    e, f = b - a, c - a
    x = e[:, 1] * f[:, 2] - e[:, 2] * f[:, 1]
    y = e[:, 2] * f[:, 0] - e[:, 0] * f[:, 2]
    z = e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]
    return 0.5 * np.sqrt(x * x + y * y + z * z)


def validate_mesh(vertices, triangles) -> tuple[np.ndarray, np.ndarray]:
    """Check a mesh before any kernel runs; return float32 vertices and the non-degenerate int32 triangles."""
    verts, tris, _area = _validated_mesh(vertices, triangles)
    return verts, tris


def _validated_mesh(vertices, triangles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`validate_mesh`, and the (T,) float64 areas of the triangles it keeps."""
    verts = np.asarray(vertices)
    tris = np.asarray(triangles)
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise ValueError(f"Expected 'vertices' of shape (V, 3), but got {verts.shape}.")
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise ValueError(f"Expected 'triangles' of shape (T, 3), but got {tris.shape}.")
    if len(verts) == 0 or len(tris) == 0:
        raise AasdfError("The mesh is empty: it has no vertices or no triangles.")
    if not np.issubdtype(tris.dtype, np.integer):
        raise ValueError(f"Expected integer 'triangles', but got dtype {tris.dtype}.")
    verts64 = verts.astype(np.float64)
    if not np.all(np.isfinite(verts64)):
        bad = int(np.count_nonzero(~np.isfinite(verts64).all(axis=1)))
        raise AasdfError(f"The mesh has {bad} vertices with NaN or infinite coordinates.")
    if tris.min() < 0 or tris.max() >= len(verts):
        raise AasdfError(
            f"Triangle indices must lie in [0, {len(verts) - 1}], but range over "
            f"[{int(tris.min())}, {int(tris.max())}]."
        )
    tris = tris.astype(np.int32)
    area2 = 2.0 * _triangle_areas(verts64, tris)
    extent = float(max(np.ptp(verts64[:, k]) for k in range(3)))
    keep = area2 > (1e-12 * extent * extent)
    if not np.any(keep):
        raise AasdfError("The mesh is degenerate: all of its triangles have zero area.")
    return np.ascontiguousarray(verts64, dtype=np.float32), np.ascontiguousarray(tris[keep]), 0.5 * area2[keep]


def weld_positions(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same triangles over one vertex per distinct position: (P, 3) positions, sorted as ``np.unique(axis=0)``
    sorts them, and (T, 3) int64 indices (the geometry, and so every distance and winding number, is unchanged)."""
    verts = np.asarray(vertices)
    order = np.lexsort((verts[:, 2], verts[:, 1], verts[:, 0]))
    rows = verts[order]
    first = np.r_[True, (rows[1:] != rows[:-1]).any(axis=1)]  # first row of each run of equal positions
    index = np.empty(len(verts), dtype=np.int64)
    index[order] = np.cumsum(first) - 1
    return rows[first], index[np.asarray(triangles, dtype=np.int64)]


def edge_table(tris: np.ndarray, n_verts: int) -> dict:
    """The undirected edges of a triangle list, for the mesh checks below.

    Returns:
        ``{"pairs": (E, 2) int64 vertex pairs (low, high), "faces": (E,) faces per edge, "forward": (E,) of those
        listing it low -> high}``.
    """
    t = np.asarray(tris, dtype=np.int64)
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()  # every directed edge a -> b
    # one sort of the edges' keys with their direction in the lowest bit (no inverse permutation needed)
    keys = np.sort((np.minimum(a, b) * n_verts + np.maximum(a, b)) * 2 + (a < b))
    edge = keys >> 1
    start = np.flatnonzero(np.r_[True, edge[1:] != edge[:-1]])
    unique = edge[start]
    return {
        "pairs": np.stack([unique // n_verts, unique % n_verts], axis=1),
        "faces": np.diff(np.r_[start, len(keys)]),
        "forward": np.add.reduceat(keys & 1, start),
    }


def problem_faces(tris: np.ndarray, n_verts: int, edges: dict | None = None) -> np.ndarray:
    """(T,) int32, 1 for faces touching a vertex of an open, non-manifold or inconsistently oriented edge (a mesh
    without any is closed: no band refinement, signs spread everywhere). ``edges``: ``edge_table(tris, n_verts)``."""
    edges = edge_table(tris, n_verts) if edges is None else edges
    bad_edge = (edges["faces"] != 2) | (edges["forward"] != 1)
    bad_vertex = np.zeros(n_verts, dtype=bool)
    bad_vertex[edges["pairs"][bad_edge].ravel()] = True
    return bad_vertex[np.asarray(tris, dtype=np.int64)].any(axis=1).astype(np.int32)


MAX_HOLE_CAPS = 32  # more boundary pieces than this share one cone


def _boundary_pieces(pairs: np.ndarray) -> np.ndarray:
    """Connected piece of each edge of a boundary given as (E, 2) vertex pairs: (E,) labels 0..P-1."""
    ends, local = np.unique(pairs, return_inverse=True)
    local = local.reshape(-1, 2)
    label = np.arange(len(ends))
    while True:  # hook every vertex to the smallest label among its edges, then shortcut, until stable
        low = np.minimum(label[local[:, 0]], label[local[:, 1]])
        hooked = label.copy()
        np.minimum.at(hooked, local[:, 0], low)
        np.minimum.at(hooked, local[:, 1], low)
        hooked = hooked[hooked]
        if np.array_equal(hooked, label):
            break
        label = hooked
    return np.unique(label, return_inverse=True)[1].reshape(-1)[local[:, 0]]


def hole_caps(vertices: np.ndarray, triangles: np.ndarray, edges: dict | None = None):
    """Where an open mesh's winding number may be far from an integer: (box lo (K, 3), box hi (K, 3), radius (K,)),
    or None.

    Let G be the mesh's boundary: its edges whose two orientations do not cancel (open, or inconsistently oriented),
    with multiplicity, split into its K connected pieces G_c, and C_c the cone over G_c from the centre of G_c's
    bounding box. Each piece is a closed 1-cycle, so the mesh minus all cones is closed: its winding number is an
    integer that changes only across the mesh or a cone, and the mesh's winding number differs from it by the cones',
    each at most area(C_c) / (4 pi d_c^2) at distance d_c from C_c. With ``radius_c = sqrt(area(C_c) / pi)``, where
    the sum over c of (radius_c / d_c)^2 stays below 1, d_c now the distance to the box c (which holds C_c), their
    sum is below 1/4: there the winding number stays within 1/4 of an integer, so two points joined by a segment that
    crosses no triangle are on the same side of 0.5, and signs may spread between nodes as on a closed mesh (the
    kernels' ``_near_cap`` test). One cone per piece keeps the caps of holes far apart small; beyond
    ``MAX_HOLE_CAPS`` pieces a single cone over the whole boundary is used. Returns None when every edge cancels
    (closed, consistently oriented, possibly non-manifold). ``edges``: ``edge_table(triangles, len(vertices))`` when
    already at hand.
    """
    edges = edge_table(triangles, len(vertices)) if edges is None else edges
    net = 2 * edges["forward"] - edges["faces"]  # low -> high minus high -> low
    open_edges = net != 0
    if not open_edges.any():
        return None
    pairs = edges["pairs"][open_edges]
    piece = _boundary_pieces(pairs)
    if piece.max() + 1 > MAX_HOLE_CAPS:
        piece = np.zeros_like(piece)
    k = int(piece.max()) + 1
    a, b = (np.asarray(vertices, dtype=np.float64)[pairs[:, c]] for c in (0, 1))
    lo = np.full((k, 3), np.inf)
    hi = np.full((k, 3), -np.inf)
    np.minimum.at(lo, piece, np.minimum(a, b))
    np.maximum.at(hi, piece, np.maximum(a, b))
    apex = 0.5 * (lo + hi)[piece]
    tri_area = 0.5 * np.linalg.norm(np.cross(a - apex, b - apex), axis=1) * np.abs(net[open_edges])
    area = np.bincount(piece, weights=tri_area, minlength=k)
    return lo, hi, np.sqrt(area / math.pi)


def plan_domain(lo, hi, voxel_size: float, levels: int, margin_cells: float):
    """Domain origin (snapped to the shared world origin at the top spacing, Eq. 3) and top-level dims."""
    top = voxel_size * 2 ** (levels - 1)
    margin = margin_cells * voxel_size
    origin = np.floor((np.asarray(lo, np.float64) - margin) / top) * top
    dims = np.maximum(np.ceil((np.asarray(hi, np.float64) + margin - origin) / top).astype(np.int64), 1)
    return origin, dims


def check_budget(fine_dims, top_count, fine_nodes_estimate, pairs=0):
    """Refuse domains the Morton codes cannot address and node counts that would not fit in memory (``pairs``:
    (triangle, octet) codes to sort before de-duplication, about 32 bytes each with the sort buffers)."""
    if np.any(np.asarray(fine_dims) >= MAX_CELLS_PER_AXIS):
        raise AasdfError(
            f"The domain spans {int(np.max(fine_dims))} finest cells along an axis, more than the "
            f"{MAX_CELLS_PER_AXIS - 1} the octree can address; use a larger voxel size."
        )
    need = max((int(fine_nodes_estimate) + int(top_count)) * BUILD_BYTES_PER_NODE, 32 * int(pairs))
    budget = available_memory() // 2
    if need > budget:
        raise AasdfError(
            f"This voxel size needs about {need / 2**30:.1f} GiB ({int(fine_nodes_estimate):,} finest "
            f"nodes), more than the {budget / 2**30:.1f} GiB that can be used; use a larger voxel size."
        )


def byte_grid_fits(dims) -> bool:
    """Whether a dense grid of one byte per cell over ``dims`` is small enough to use (``octree.MASK_MAX_CELLS``, and
    an eighth of the memory available)."""
    cells = int(np.prod(np.asarray(dims, dtype=np.int64)))
    return cells <= min(octree.MASK_MAX_CELLS, available_memory() // 8)


def _device(device):
    return wp.get_device(device)


# ---- build ----


def plan_field(vertices, triangles, *, voxel_size, levels=4, padding=1) -> dict:
    """Validate a build and estimate what it needs, without running any kernel.

    Returns:
        dict with the cleaned ``vertices``/``triangles``, the domain (``origin``, ``top_dims``, ``fine_dims``,
        ``top_count``), an upper bound of the finest nodes (``fine_nodes``) and of the bytes the build needs
        (``bytes``), and the triangles' ``areas``.
    Raises:
        ValueError, AasdfError: As :func:`build_field` does for bad input.
    """
    voxel_size = float(voxel_size)
    if not np.isfinite(voxel_size) or voxel_size <= 0.0:
        raise AasdfError(f"The voxel size must be a positive number, but got {voxel_size}.")
    if int(levels) != levels or levels < 1:
        raise AasdfError(f"The number of levels must be an integer of at least 1, but got {levels}.")
    if int(padding) != padding or padding < 0:
        raise AasdfError(f"The padding must be a non-negative integer, but got {padding}.")
    levels, padding = int(levels), int(padding)
    verts, tris, area = _validated_mesh(vertices, triangles)
    lo = np.array([verts[:, k].min() for k in range(3)])
    hi = np.array([verts[:, k].max() for k in range(3)])
    origin, top_dims = plan_domain(lo, hi, voxel_size, levels, padding + 2)
    fine_dims = top_dims * 2 ** (levels - 1)
    # Upper bound of finest nodes: every triangle's padded AABB in octets, capped by a surface-area estimate for
    # large triangles.
    octet = 2.0 * voxel_size
    v64 = verts.astype(np.float64)
    box_count = np.ones(len(tris))
    for k in range(3):
        a, b, c = (v64[tris[:, m], k] for m in range(3))
        ext = (np.maximum(np.maximum(a, b), c) - np.minimum(np.minimum(a, b), c) + 2.0 * padding * voxel_size) / octet
        box_count *= np.ceil(ext + 1.0) + 1.0
    area_count = (np.sqrt(area) / octet + 2.0 + padding) ** 2 * (3.0 + padding)
    per_triangle = 8.0 * float(np.minimum(box_count, area_count).sum())
    # Many small triangles share their octets: the band around the whole surface (both sides, padding plus octet
    # rounding, a 1.5x margin) and the dense domain bound it too.
    band = 1.5 * 2.0 * (padding + 2) * float(area.sum()) / voxel_size**2
    fine_nodes = min(per_triangle, band, float(np.prod(fine_dims))) if levels > 1 else float(np.prod(fine_dims))
    top_count = int(np.prod(top_dims))
    return {
        "vertices": verts,
        "triangles": tris,
        "voxel_size": voxel_size,
        "levels": levels,
        "padding": padding,
        "origin": origin,
        "top_dims": top_dims,
        "fine_dims": fine_dims,
        "top_count": top_count,
        "fine_nodes": fine_nodes,
        "bytes": int((fine_nodes + top_count) * BUILD_BYTES_PER_NODE),
        "areas": area,
    }


def check_meshes(meshes, *, voxel_size, levels=4, padding=1) -> int:
    """Refuse, before any work, a set of builds that is invalid or would not fit in memory together.

    Args:
        meshes: Iterable of (vertices, triangles) pairs.
        voxel_size, levels, padding: As for :func:`build_field`.
    Returns:
        The estimated bytes of all the builds.
    Raises:
        AasdfError: The first invalid mesh (its index in the message), or the total being too large.
    """
    return sum(plan["bytes"] for plan in _checked_plans(meshes, voxel_size=voxel_size, levels=levels, padding=padding))


def _checked_plans(meshes, *, voxel_size, levels, padding) -> list[dict]:
    """:func:`check_meshes`, returning each mesh's :func:`plan_field`."""
    plans = []
    for k, (verts, tris) in enumerate(meshes):
        try:
            plan = plan_field(verts, tris, voxel_size=voxel_size, levels=levels, padding=padding)
            check_budget(plan["fine_dims"], plan["top_count"], plan["fine_nodes"])
        except AasdfError as err:
            raise AasdfError(f"Mesh {k}: {err}") from err
        plans.append(plan)
    total = sum(plan["bytes"] for plan in plans)
    budget = available_memory() // 2
    if total > budget:
        raise AasdfError(
            f"These fields need about {total / 2**30:.1f} GiB together, more than the {budget / 2**30:.1f} GiB "
            "that can be used; use a larger voxel size."
        )
    return plans


def build_fields(meshes, *, voxel_size, levels=4, padding=1, device=None, field_ids=None) -> list[AdaptiveField]:
    """Build the fields of several meshes at one voxel size, checked together first (:func:`check_meshes`), so an
    impossible request builds none.

    On the CPU the builds run at the same time, one Python thread each (up to the core count): every build has
    stretches that keep one core busy (sorts, in-place sweeps, small launches), which the other build fills. On
    CUDA they run one after the other.

    Args:
        meshes: Sequence of (vertices, triangles) pairs, as for :func:`build_field`.
        voxel_size, levels, padding, device: As for :func:`build_field`.
        field_ids: One id per mesh (default 0, 1, 2, ...).
    Returns:
        One AdaptiveField per mesh, in order.
    Raises:
        ValueError, AasdfError: As :func:`check_meshes` and :func:`build_field`; messages about one mesh start with
            "Mesh <k>: ".
    """
    meshes = list(meshes)
    field_ids = list(range(len(meshes))) if field_ids is None else [int(k) for k in field_ids]
    if len(field_ids) != len(meshes):
        raise ValueError(f"build_fields got {len(field_ids)} field ids for {len(meshes)} meshes")
    plans = _checked_plans(meshes, voxel_size=voxel_size, levels=levels, padding=padding)
    device = _device(device)
    fields: list = [None] * len(meshes)
    errors: dict = {}

    def build(k):
        try:
            fields[k] = _build_planned(plans[k], device=device, field_id=field_ids[k])
        except AasdfError as err:
            errors[k] = AasdfError(f"Mesh {k}: {err}")
            errors[k].__cause__ = err
        except Exception as err:  # noqa: BLE001 (re-raised below, in the caller's thread)
            errors[k] = err

    if device.is_cuda or len(meshes) < 2:
        for k in range(len(meshes)):
            build(k)
            if k in errors:
                raise errors[k]
        return fields
    for module in (octree._mark_unique_kernel.module, _mesh_sign_kernel.module):  # the modules a build launches
        wp.load_module(module, device=device)  # compiled or loaded once, before the threads
    workers = min(len(meshes), os.cpu_count() or 1)
    # worker w builds meshes w, w + workers, ...
    octree.run_tasks([lambda w=w: [build(k) for k in range(w, len(meshes), workers)] for w in range(workers)], device)
    if errors:
        raise errors[min(errors)]
    return fields


def build_field(vertices, triangles, *, voxel_size, levels=4, padding=1, device=None, field_id=0) -> AdaptiveField:
    """Build the adaptive signed distance field of a triangle mesh.

    Args:
        vertices: (V, 3) world-space vertex positions.
        triangles: (T, 3) integer vertex indices. Open, multi-shell, flipped or duplicated faces are handled:
            inside means generalised winding number >= 0.5.
        voxel_size: Edge length of the finest cells.
        levels: Number of levels, finest to dense top (>= 1).
        padding: Finest cells kept around each triangle (>= 0; 1 or more gives watertight surfaces).
        device: Warp device (``None``: Warp's default).
        field_id: Integer id carried per node through booleans (see ``source_ids``).
    Returns:
        AdaptiveField, negative inside.
    Raises:
        ValueError: On wrongly shaped or typed arguments.
        AasdfError: On empty, non-finite or fully degenerate meshes, out-of-range indices, non-positive voxel
            size, ``levels < 1``, ``padding < 0``, or a resolution that would not fit in memory.
    """
    plan = plan_field(vertices, triangles, voxel_size=voxel_size, levels=levels, padding=padding)
    check_budget(plan["fine_dims"], plan["top_count"], plan["fine_nodes"])
    return _build_planned(plan, device=device, field_id=field_id)


def _build_planned(plan: dict, *, device, field_id: int) -> AdaptiveField:
    """:func:`build_field` of a checked :func:`plan_field`."""
    verts, tris, origin, top_dims = plan["vertices"], plan["triangles"], plan["origin"], plan["top_dims"]
    fine_dims, top_count = plan["fine_dims"], plan["top_count"]
    voxel_size, levels, padding = plan["voxel_size"], plan["levels"], plan["padding"]
    octet = 2.0 * voxel_size
    device = _device(device)

    timings = {}
    t0 = time.perf_counter()
    # the BVH builds while the mesh checks and the cell enumeration run: on the CPU on a thread of its own (Warp's
    # native build releases the GIL)
    made = {}

    def make_mesh():
        try:
            made["mesh"] = wp.Mesh(
                points=wp.array(verts, dtype=wp.vec3, device=device),
                indices=wp.array(tris.reshape(-1), dtype=wp.int32, device=device),
                support_winding_number=True,
            )
        except Exception as err:  # noqa: BLE001 (re-raised in the caller's thread)
            made["error"] = err

    builder = threading.Thread(target=make_mesh) if device.is_cpu else None
    if builder is not None:
        builder.start()
    else:
        make_mesh()
    edges = edge_table(tris, len(verts))
    problem = problem_faces(tris, len(verts), edges)
    clean = not bool(problem.any())
    caps = None
    if not clean:
        # the checks are about the surface, not its indexing: seams that repeat a vertex at one position (UV or patch
        # seams) open edges only in the index, so they are judged on the mesh with those vertices merged
        seam_verts, seam_tris = weld_positions(verts, tris)
        if len(seam_verts) == len(verts):
            seam_verts, seam_tris = verts, tris  # nothing merged: keep the indexing the edge table has
        else:
            edges = edge_table(seam_tris, len(seam_verts))
            problem = problem_faces(seam_tris, len(seam_verts), edges)
            clean = not bool(problem.any())
        caps = None if clean else hole_caps(seam_verts, seam_tris, edges)
    diag = float(np.linalg.norm(fine_dims * voxel_size))
    # candidate triangles per octet grow as cell area / triangle area: search boxes only where that stays small
    box_search = int(float(plan["areas"].mean()) >= OCTET_SEARCH_MIN_AREA * voxel_size**2)
    timings["mesh_checks"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if levels == 1:
        base_octets = None  # the dense top level is the finest
    else:
        oct_dims = wp.vec3i(*(int(d) for d in fine_dims // 2))
        verts_wp = wp.array(verts, dtype=wp.vec3, device=device)
        tris_wp = wp.array(tris, dtype=wp.int32, device=device)
        args = [verts_wp, tris_wp, wp.vec3(*origin), octet, padding * voxel_size, oct_dims]
        end_bit = 3 * _bits(fine_dims // 2)
        if byte_grid_fits(fine_dims // 2):
            base_octets = octree.mark_then_compact(
                _octets_per_triangle_kernel,
                len(tris),
                args,
                fine_dims // 2,
                device,
                end_bit=end_bit,
                check=lambda total: check_budget(fine_dims, top_count, 8 * total),
            )
        else:
            octet_codes = octree.count_then_emit(
                _octets_per_triangle_kernel,
                len(tris),
                [*args, wp.empty(0, dtype=wp.uint8, device=device)],  # no mask
                device,
                check=lambda total: check_budget(fine_dims, top_count, min(8 * total, plan["fine_nodes"]), pairs=total),
            )
            base_octets = octree.sort_unique(octet_codes, end_bit=end_bit)
    timings["finest_cells"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if builder is not None:
        builder.join()
    timings["mesh_bvh"] = time.perf_counter() - t0  # what is left of the BVH build once the cells are found
    if "error" in made:
        raise made["error"]
    mesh = made["mesh"]
    lattices = None
    if caps is not None and levels > 1:
        # the surface across the holes, found before the first build instead of by a refinement round after it
        t0 = time.perf_counter()
        lattices = cap_lattices(mesh.id, caps, origin, fine_dims // 2, octet, base_octets.shape[0], device)
        if lattices is not None:
            band = base_octets.numpy()
            sheet = lattices["sheet"][~_in_sorted(band, lattices["sheet"])]  # where the band does not hold it already
            if len(sheet):
                check_budget(fine_dims, top_count, 8 * len(band) + 8 * 27 * len(sheet))
                base_octets = add_octets(base_octets, sheet, fine_dims // 2, end_bit=3 * _bits(fine_dims // 2))
        timings["cap_lattices"] = time.perf_counter() - t0

    def oracle(coords, nodes_np, spacing, sign):
        if len(nodes_np) == 0:
            return
        nodes = wp.array(nodes_np.astype(np.int32), dtype=wp.int32, device=device)
        origin_v = wp.vec3(*origin)
        octree.launch_split(
            _mesh_sign_kernel,
            len(nodes_np),
            lambda lo, n: [mesh.id, coords, nodes[lo : lo + n], origin_v, float(spacing), sign],
            device,
            min_dim=octree.EMIT_SPLIT_MIN_DIM,  # a winding number costs microseconds: split from a few thousand
            balance=True,  # winding numbers cost most near holes, which a Morton-ordered list bunches
        )

    def finest_signs(coords, sign, lo0, hi0):
        # Undecided finest nodes lie within about half a voxel of the surface, where the pseudo-normal sign is wrong
        # near open edges and where shells intersect or touch: they pay the winding number.
        idx = lo0 + np.flatnonzero(sign.numpy()[lo0:hi0] == 0.0)
        oracle(coords, idx, voxel_size, sign)
        return len(idx)

    def build(octets, query_radius, previous=None):
        # every node's place first, so each level's values are computed where they are kept
        layout = level_layout(octets, top_dims, levels, device, timings)
        t0 = time.perf_counter()
        n, n0 = int(layout["offsets"][-1]), int(layout["offsets"][1])
        fine_codes, fine_coords = layout["codes"][:n0], layout["coords"][:n0]
        dist = wp.empty(n, dtype=wp.float32, device=device)
        proj = wp.empty(n, dtype=wp.vec3, device=device)
        source = wp.empty(n, dtype=wp.int32, device=device)
        dist0, proj0, src0 = dist[:n0], proj[:n0], source[:n0]
        # Octets an earlier build of this mesh already has keep their closest points; only new ones are queried.
        first_nodes = np.arange(0, n0, 8)
        if previous is not None:
            where = match_levels(fine_codes, [0, n0], previous)
            no_known = wp.empty(0, dtype=wp.int32, device=device)
            octree.launch_split(
                _take_known_kernel,
                n0,
                lambda s, _n: [s, where, previous.values, previous.proj, previous.source, no_known, dist0, proj0, src0],
                device,
            )
            first_nodes = 8 * np.flatnonzero(where.numpy()[::8] < 0)  # matched octet by octet
        src0.fill_(int(field_id))
        origin_v = wp.vec3(*origin)
        if octets is not None:
            # octet by octet, in place
            octet_nodes = wp.array(first_nodes.astype(np.int32), dtype=wp.int32, device=device)
            octet_dist = wp.full(n0 // 8, octree.UNSET_DISTANCE, dtype=wp.float32, device=device)
            octet_proj = wp.empty(n0 // 8, dtype=wp.vec3, device=device)
            octet_points = (octet_dist, octet_proj)
            octree.launch_split(
                _finest_octet_distance_kernel,
                len(first_nodes),
                lambda lo, n: [
                    lo,
                    mesh.id,
                    fine_coords,
                    octet_nodes,
                    origin_v,
                    voxel_size,
                    float(query_radius),
                    diag,
                    dist0,
                    proj0,
                    octet_dist,
                    octet_proj,
                    box_search,
                ],
                device,
                min_dim=octree.EMIT_SPLIT_MIN_DIM,
                balance=True,  # octets near an open mesh's holes, or far from it, cost more
            )
        else:  # a single dense level: node by node
            octet_points = None
            octree.launch_split(
                _finest_distance_kernel,
                n0,
                lambda lo, n: [
                    mesh.id,
                    fine_coords[lo : lo + n],
                    origin_v,
                    voxel_size,
                    float(query_radius),
                    diag,
                    int(field_id),
                    dist0[lo : lo + n],
                    proj0[lo : lo + n],
                    src0[lo : lo + n],
                ],
                device,
            )
        timings["finest_distance"] = timings.get("finest_distance", 0.0) + time.perf_counter() - t0
        return assemble_field(
            origin=origin,
            top_dims=top_dims,
            voxel_size=voxel_size,
            levels=levels,
            layout=layout,
            dist=dist,
            proj=proj,
            source=source,
            known_signs=previous,
            oracle=oracle,
            finest_signs=finest_signs,
            device=device,
            field_ids=(field_id,),
            timings=timings,
            mesh_id=mesh.id,
            octet_points=octet_points,
            hole_caps=caps,
            sign_presets=None if lattices is None else lambda layout: cap_sign_presets(lattices, layout, levels),
        )

    # a band node lies within (padding + 1) cells (L-inf) of a triangle; misses fall back to the domain diagonal
    near_radius = diag if levels == 1 else (padding + 2) * voxel_size * 1.75
    field = build(base_octets, near_radius)
    # Across a hole of an open mesh the inside/outside boundary (winding number 0.5) runs away from any triangle,
    # through coarse leaves. Refine those leaves to the finest level so the surface there can be extracted too. A
    # closed, consistently oriented mesh (even a self-intersecting one) changes its winding number only across its
    # triangles, which the finest level covers: nothing to check.
    rounds = 0
    refine_seconds = 0.0
    region = None
    while levels > 1 and not clean and rounds < MAX_SIGN_REFINEMENTS:
        t_refine = time.perf_counter()
        # off the caps over the holes the winding number stays near an integer (see hole_caps): the zero set can
        # only leave the band near them (no caps: the edges cancel, it never does)
        extra = sign_change_octets(field, caps if caps is not None else NO_BOXES, region)
        refine_seconds += time.perf_counter() - t_refine
        if len(extra) == 0:
            break
        rounds += 1
        region = changed_top_cells(extra, top_dims, levels)
        check_budget(fine_dims, top_count, field.level_counts[0] + 8 * 27 * len(extra))
        t0 = time.perf_counter()
        base_octets = add_octets(base_octets, extra, fine_dims // 2, end_bit=3 * _bits(fine_dims // 2))
        timings["finest_cells"] += time.perf_counter() - t0
        queries = field.stats["sign_queries"]
        field = build(base_octets, near_radius, previous=field)
        field.stats["sign_queries"] = {k: v + queries.get(k, 0) for k, v in field.stats["sign_queries"].items()}
    field.stats["sign_refinements"] = rounds
    field.timings["sign_check"] = refine_seconds
    field.stats["clean_mesh"] = clean
    field.stats["problem_faces"] = int(problem.sum())
    field._mesh = mesh  # keeps the BVH alive for callers that want exact queries
    return field


def changed_top_cells(octets: np.ndarray, top_dims, levels: int) -> np.ndarray:
    """(top_dims) bool: the top-level cells a refinement round that adds ``octets`` (codes, and the octets next to
    them) may change, and their neighbours. The round changes nodes only in the top cells holding the added octets
    (their parents, siblings and ancestors), every node elsewhere keeps its value and sign, and a sign change
    involves a changed node and a face neighbour (or an octet next to it): the next check needs to look only there."""
    top_dims = np.asarray(top_dims, dtype=np.int64)
    cells = octree.morton_decode_np(octets) >> (levels - 2)  # octets are level-1 cells
    hit = np.zeros(top_dims + 4, dtype=bool)  # a margin of two cells: the octets next to them, then the neighbours
    hit[tuple((cells + 2).T)] = True
    grown = np.zeros_like(hit)
    for offset in itertools.product((-2, -1, 0, 1, 2), repeat=3):
        grown |= np.roll(hit, offset, axis=(0, 1, 2))
    return grown[2:-2, 2:-2, 2:-2]


# No boxes, in the form of :func:`hole_caps`' result.
NO_BOXES = (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))


def _box_arrays(boxes, device) -> list:
    """Warp arrays (lo, hi, radius) of boxes in the form of :func:`hole_caps`' result (None: no boxes)."""
    lo, hi, radius = NO_BOXES if boxes is None else boxes
    return [
        wp.array(np.asarray(lo, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device),
        wp.array(np.asarray(hi, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device),
        wp.array(np.asarray(radius, np.float32).reshape(-1), dtype=wp.float32, device=device),
    ]


def sign_change_octets(field: AdaptiveField, near=None, region=None) -> np.ndarray:
    """Octet codes the finest level lacks where the zero set leaves it: every coarse leaf whose face neighbour has
    the opposite sign, and every octet next to the band whose covering coarse leaf has another sign than a band node
    beside it (so every marching cube that straddles the zero set is complete).

    ``near``: boxes (lo (K, 3), hi (K, 3), radius (K,)) as from :func:`hole_caps`, outside which the zero set runs
    only through the band (no sign change away from a triangle): only leaves and octets within reach of them are
    checked (none for K = 0). None checks everywhere. ``region``: (top_dims) bool, the top-level cells whose leaves
    and octets are checked (None: all)."""
    n_coarse = field.node_count - field.level_counts[0]
    if n_coarse == 0:
        return np.zeros(0, dtype=np.int64)
    if near is not None and len(near[2]) == 0:
        return np.zeros(0, dtype=np.int64)
    top, h = field.top_spacing, field.voxel_size
    # Signs are compared between a leaf's centre and a face neighbour's (reached 0.5 s + h / 4 across a face), or an
    # octet's node and the centre of the leaf one octet away: every point of either segment lies within
    # sqrt(3) / 2 top + max(top / 2 + h / 4, 2 sqrt(3) h) of the leaf's or octet's centre (5 % slack).
    reach = 1.05 * (0.866 * top + max(0.5 * top + 0.25 * h, 3.465 * h))
    # one byte per top cell, x fastest as in the kernels (none: check everywhere)
    flags = np.zeros(0, np.uint8) if region is None else np.asarray(region, np.uint8).T.reshape(-1)
    near_args = [
        *_box_arrays(near, field.device),
        -1.0 if near is None else reach,
        wp.array(flags, dtype=wp.uint8, device=field.device),
    ]
    levels_np = field.level_of_nodes()
    marks = wp.empty(n_coarse, dtype=wp.int32, device=field.device)
    arg = field.arg()
    node_level = wp.array(levels_np, dtype=wp.int32, device=field.device)
    octree.launch_split(
        _sign_change_kernel, n_coarse, lambda lo, n: [lo, arg, node_level, *near_args, marks], field.device
    )
    n_octets = field.level_counts[0] // 8
    # each part of the split launch appends to its own buffer (CPU launches have no cross-thread atomics)
    parts = {}

    def gather_part(lo, n):
        capacity = max(1024, n // 4)
        while True:
            count = wp.zeros(1, dtype=wp.int32, device=field.device)
            gaps = wp.empty(capacity, dtype=wp.int64, device=field.device)
            wp.launch(_band_gap_kernel, dim=n, inputs=[lo, arg, *near_args, capacity, count, gaps], device=field.device)
            found = int(count.numpy()[0])
            if found <= capacity:
                parts[lo] = gaps.numpy()[:found]
                return
            capacity = found

    wp.load_module(_band_gap_kernel.module, device=field.device)
    octree.run_split(gather_part, n_octets, field.device, balance=True)  # only octets near the holes cost
    gap_octets = np.unique(np.concatenate([parts[k] for k in sorted(parts)] or [np.zeros(0, np.int64)]))
    n0 = field.level_counts[0]
    marked = n0 + np.flatnonzero(marks.numpy())
    if len(marked) == 0:
        return gap_octets
    coords = field.coords.numpy()[marked].astype(np.int64)
    lv = levels_np[marked]
    out = []
    for k in np.unique(lv):
        n = 2 ** (int(k) - 1)  # octets per axis in a level-k cell
        base = coords[lv == k] * n
        grid = np.stack(np.meshgrid(*([np.arange(n)] * 3), indexing="ij"), axis=-1).reshape(-1, 3)
        out.append((base[:, None, :] + grid[None, :, :]).reshape(-1, 3))
    return np.union1d(octree.morton_encode_np(np.concatenate(out)), gap_octets)


# One of each pair of opposite steps to the 26 neighbours of a cell.
_FORWARD_STEPS = [np.array(d) for d in itertools.product((-1, 0, 1), repeat=3) if d > (0, 0, 0)]


def _merge_boxes(first: np.ndarray, last: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Integer boxes (K, 3) inclusive, overlapping ones replaced by the box around them until none overlap (loops
    of one hole, or holes close together, are sampled once)."""
    boxes = [(a, b) for a, b in zip(first, last, strict=True)]
    merged = True
    while merged:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                (a, b), (c, d) = boxes[i], boxes[j]
                if np.all(a <= d) and np.all(c <= b):
                    boxes[i] = (np.minimum(a, c), np.maximum(b, d))
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return np.array([a for a, _ in boxes]), np.array([b for _, b in boxes])


def _inside_at(mesh_id, cells: np.ndarray, origin, size: float, device) -> np.ndarray:
    """(M,) bool: whether the centres of the cells (M, 3) of edge ``size`` are inside the mesh (the sign oracle's
    kernel, on every cell)."""
    sign = wp.empty(len(cells), dtype=wp.float32, device=device)
    cells_wp = wp.array(cells.astype(np.int32), dtype=wp.vec3i, device=device)
    every = wp.array(np.arange(len(cells), dtype=np.int32), dtype=wp.int32, device=device)
    octree.launch_split(
        _mesh_sign_kernel,
        len(cells),
        lambda start, n: [wp.uint64(mesh_id), cells_wp, every[start : start + n], wp.vec3(*origin), float(size), sign],
        device,
        min_dim=octree.EMIT_SPLIT_MIN_DIM,  # a winding number each
        balance=True,  # cells near the mesh cost more
    )
    return sign.numpy() < 0.0


def _in_sorted(keys: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(len(values),) bool: whether each value is one of the sorted ``keys``."""
    if len(keys) == 0:
        return np.zeros(len(values), dtype=bool)
    return keys[np.minimum(np.searchsorted(keys, values), len(keys) - 1)] == values


def _in_box(columns, first, last) -> np.ndarray:
    """Whether each point (``columns``: its x, y and z arrays) lies in the integer box [first, last] (inclusive)."""
    hit = np.ones(len(columns[0]), dtype=bool)
    for k in range(3):
        hit &= (columns[k] >= first[k]) & (columns[k] <= last[k])
    return hit


def _box_cells(first, last) -> np.ndarray:
    """(M, 3) cells of the box [first, last] (inclusive), in C order of (x, y, z)."""
    return np.argwhere(np.ones(np.asarray(last) - first + 1, dtype=bool)) + first


def _changes(grid: np.ndarray) -> np.ndarray:
    """Pairs (P, 2, 3) of 26-neighbour cells of a bool grid with different values."""
    pairs = []
    for step in _FORWARD_STEPS:
        ends = tuple(slice(max(0, -d), n - max(0, d)) for d, n in zip(step, grid.shape, strict=True))
        starts = tuple(slice(max(0, d), n - max(0, -d)) for d, n in zip(step, grid.shape, strict=True))
        at = np.argwhere(grid[ends] != grid[starts]) + np.maximum(0, -step)
        pairs.append(np.stack([at, at + step], axis=1))
    return np.concatenate(pairs)


def _clear_pairs(mesh_id, pairs: np.ndarray, origin, size: float, device) -> np.ndarray:
    """The pairs of cells (P, 2, 3) whose centres (cells of edge ``size``) are joined by a segment that surely
    meets no triangle."""
    if len(pairs) == 0:
        return pairs
    centres = (origin + size * (pairs + 0.5)).astype(np.float32)
    clear = wp.empty(len(pairs), dtype=wp.uint8, device=device)
    p, q = (wp.array(np.ascontiguousarray(centres[:, k]), dtype=wp.vec3, device=device) for k in (0, 1))
    octree.launch_split(
        _segments_clear_kernel,
        len(pairs),
        lambda s, n: [wp.uint64(mesh_id), p[s : s + n], q[s : s + n], clear[s : s + n]],
        device,
        min_dim=octree.EMIT_SPLIT_MIN_DIM,  # a box query each
        balance=True,  # pairs next to the mesh test many triangles
    )
    return pairs[clear.numpy() == 1]


def cap_lattices(mesh_id, caps, origin, octet_dims, octet: float, band_count: int, device):
    """Where an open mesh's surface crosses its holes, from winding numbers at the centres of octets (the level-1
    nodes) around each hole's cap: that surface spans the hole's boundary, where the boundary's solid angle is 2 pi,
    inside the hull of the boundary and so inside the cap's box. The box's octets and ``CAP_LATTICE_MARGIN`` more
    around it are sampled (overlapping boxes as one), where cells twice their size, sampled first, find enough of that
    surface (``CAP_LATTICE_MIN_SHEET``). Sampling only the octets of those cells that change sides, and the cells
    next to them, still sampled 64-91 % of the octets on Suzanne and the bunny: the triangles in a box change sides
    too.

    Returns ``{"lattices": [(first octet (3,), inside (nx, ny, nz) bool)], "sheet": sorted codes of the octets on
    either side of 0.5 from a neighbour (faces, edges or corners) with no triangle between their centres}``, or None
    when no box is sampled or the boxes hold more than ``CAP_LATTICE_MAX_RATIO`` octets per band octet
    (``band_count``)."""
    lo, hi, _radius = caps
    origin = np.asarray(origin, dtype=np.float64)
    top = np.asarray(octet_dims, dtype=np.int64) - 1
    first = np.clip(np.floor((np.asarray(lo) - origin) / octet).astype(np.int64) - CAP_LATTICE_MARGIN, 0, top)
    last = np.clip(np.ceil((np.asarray(hi) - origin) / octet).astype(np.int64) + CAP_LATTICE_MARGIN, 0, top)
    first, last = _merge_boxes(first, last)
    if (last - first + 1).prod(axis=1).sum() > CAP_LATTICE_MAX_RATIO * band_count:
        return None
    lattices, sheet = [], []
    for corner, end in zip(first, last, strict=True):
        # cells of two octets first, an eighth of the cost: a box where they find little of that surface (a hole
        # mostly filled, its surface within the triangles' band) is left to the refinement rounds, which it would
        # rarely need
        c0, c1 = corner // 2, end // 2
        coarse = _inside_at(mesh_id, _box_cells(c0, c1), origin, 2 * octet, device).reshape(c1 - c0 + 1)
        found = _clear_pairs(mesh_id, _changes(coarse) + c0, origin, 2 * octet, device)
        # a sheet of cells twice an octet's size is about 4 octets to each of its cells
        if 4 * len(np.unique(found.reshape(-1, 3), axis=0)) < CAP_LATTICE_MIN_SHEET * (end - corner + 1).prod():
            continue
        grid = _inside_at(mesh_id, _box_cells(corner, end), origin, octet, device).reshape(end - corner + 1)
        lattices.append((corner, grid))
        sheet.append(_clear_pairs(mesh_id, _changes(grid) + corner, origin, octet, device).reshape(-1, 3))
    if not lattices:
        return None
    codes = octree.morton_encode_np(np.concatenate(sheet))
    return {"lattices": lattices, "sheet": np.unique(codes)}


def add_octets(octets: wp.array, extra: np.ndarray, octet_dims, end_bit: int) -> wp.array:
    """Sorted unique octet codes: ``octets`` (sorted codes) and ``extra`` with one octet around each (the zero set
    across a hole leaves coarse leaves in a sheet, and what is added next to it would otherwise show up as new sign
    changes)."""
    device = octets.device
    grown = octree.dilate_octets(wp.array(extra, dtype=wp.int64, device=device), octet_dims, end_bit=end_bit)
    merged = wp.empty(octets.shape[0] + grown.shape[0], dtype=wp.int64, device=device)
    wp.copy(merged, octets, count=octets.shape[0])
    wp.copy(merged, grown, dest_offset=octets.shape[0], count=grown.shape[0])
    return octree.sort_unique(merged, end_bit=end_bit)


def cap_sign_presets(found: dict, layout: dict, levels: int):
    """Signs set before the top-down pass around an open mesh's holes, and the nodes that must not take their
    parent's: (sign (N,) float32, no_inherit (N,) uint8). The level-1 nodes of the lattices (:func:`cap_lattices`)
    take the winding numbers found there. A node takes its parent's sign when their empty balls cover the segment
    between them, which proves nothing where that segment may cross the surface across a hole: the finest nodes of
    the sheet octets, and the coarser nodes within a cell of a lattice, are left to their neighbours and the
    oracle."""
    codes, coords = layout["codes"].numpy(), layout["coords"].numpy()
    offsets = layout["offsets"]
    n = int(offsets[-1])
    sign = np.zeros(n, dtype=np.float32)
    no_inherit = np.zeros(n, dtype=np.uint8)
    lo1, hi1 = int(offsets[1]), int(offsets[2])
    level1 = [coords[lo1:hi1, k] for k in range(3)]  # column by column: faster than reductions over (N, 3)
    for corner, grid in found["lattices"]:
        within = np.flatnonzero(_in_box(level1, corner, corner + np.asarray(grid.shape) - 1))
        inside = grid[tuple(level1[k][within] - corner[k] for k in range(3))]
        sign[lo1 + within] = np.where(inside, -1.0, 1.0)
    # finest nodes in the sheet octets
    n0 = int(offsets[1])
    no_inherit[:n0] = np.repeat(_in_sorted(found["sheet"], codes[:n0:8] >> 3), 8)
    # coarser nodes within a cell of a lattice
    for k in range(2, levels):
        a, b = int(offsets[k]), int(offsets[k + 1])
        level = [coords[a:b, axis] for axis in range(3)]
        near = np.zeros(b - a, dtype=bool)
        for corner, grid in found["lattices"]:
            # level-k cells hold 2^(k-1) octets per axis
            near |= _in_box(level, (corner >> (k - 1)) - 1, ((corner + np.asarray(grid.shape) - 1) >> (k - 1)) + 1)
        no_inherit[a:b] = near
    return sign, no_inherit


@wp.kernel(enable_backward=False)
def _match_level_kernel(
    first: int,
    codes: wp.array[wp.int64],
    lo: int,
    prev_codes: wp.array[wp.int64],
    prev_lo: int,
    prev_hi: int,
    where: wp.array[wp.int32],
):
    """Where octet ``first + tid`` of the level at ``lo`` (8 consecutive nodes, sorted by code) is in the sorted range
    [prev_lo, prev_hi) of ``prev_codes`` (a level of complete octets too): its nodes' indices there, or -1."""
    i = lo + 8 * (first + wp.tid())
    j = octree.find_key(prev_codes, prev_lo, prev_hi, codes[i])
    for o in range(8):
        where[i + o] = wp.where(j >= 0, j + o, -1)


@wp.kernel(enable_backward=False)
def _take_known_kernel(
    first: int,
    where: wp.array[wp.int32],
    prev_values: wp.array[wp.float32],
    prev_proj: wp.array[wp.vec3],
    prev_source: wp.array[wp.int32],
    known: wp.array[wp.int32],
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
):
    """Node ``first + tid`` found in an earlier build (``where`` >= 0) takes its distance, closest point and source,
    and is marked ``known`` (when ``known`` is not empty)."""
    i = first + wp.tid()
    j = where[i]
    if j < 0:
        return
    dist[i] = wp.abs(prev_values[j])
    proj[i] = prev_proj[j]
    source[i] = prev_source[j]
    if known.shape[0] > 0:
        known[i] = 1


@wp.kernel(enable_backward=False)
def _take_known_sign_kernel(
    first: int, where: wp.array[wp.int32], prev_values: wp.array[wp.float32], sign: wp.array[wp.float32]
):
    """Node ``first + tid`` found in an earlier build takes its sign."""
    i = first + wp.tid()
    j = where[i]
    if j >= 0:
        sign[i] = wp.where(prev_values[j] < 0.0, -1.0, 1.0)


def match_levels(codes: wp.array, offsets, previous: AdaptiveField) -> wp.array:
    """For every node (levels at ``offsets``) its index in ``previous`` (an earlier field of the same domain and
    levels), level by level, or -1: (N,) int32 on the device. Levels below the top are complete octets sorted by code
    (matched octet by octet); the dense top level (when ``offsets`` reach it) is the same grid in both."""
    where = wp.empty(codes.shape[0], dtype=wp.int32, device=codes.device)
    for k in range(len(offsets) - 1):
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        ks = previous.level_slice(k)
        if k == previous.levels - 1:
            where[lo:hi].assign(np.arange(ks.start, ks.stop, dtype=np.int32))
            continue
        octree.launch_split(
            _match_level_kernel,
            (hi - lo) // 8,
            lambda s, _n, lo=lo, ks=ks: [s, codes, lo, previous.codes, ks.start, ks.stop, where],
            codes.device,
        )
    return where


def _bits(dims) -> int:
    return max(1, int(np.ceil(np.log2(float(np.max(dims)) + 1.0))))


def level_layout(octets, top_dims, levels: int, device, timings: dict | None = None) -> dict:
    """Where every node of a field goes, before any value is computed.

    The finest level is the children of ``octets`` (sorted unique octet codes), or with ``octets`` None (and
    ``levels`` 1) the dense top level itself. Each level above holds the parents of the level below and their
    siblings (Eq. 6), sorted by code; the top level is dense. Returns ``codes`` and ``coords`` of all levels in one
    pair of arrays (finest first), the level ``offsets``, each node's first ``child`` and ``parent`` (-1: none).
    """
    t0 = time.perf_counter()
    top_dims = np.asarray(top_dims, dtype=np.int64)
    fine_dims = top_dims * 2 ** (levels - 1)
    level_octets = [] if octets is None else [octets]
    parent_index = []  # per octet of a level, its parent's octet among the next level's (all but the last)
    for k in range(1, levels - 1):
        # every level is sorted by code, so the parents of its octets come in order
        dims_k = fine_dims >> k
        up, index = octree.parent_octets(
            level_octets[-1], 1, end_bit=3 * _bits(dims_k * 2), presorted=True, return_index=True
        )
        level_octets.append(up)
        parent_index.append(index)
    parent_index.append(wp.empty(0, dtype=wp.int32, device=device))  # the dense top level: by coordinates
    sizes = [8 * o.shape[0] for o in level_octets] + [int(np.prod(top_dims))]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    n = int(offsets[-1])
    codes = wp.empty(n, dtype=wp.int64, device=device)
    coords = wp.empty(n, dtype=wp.vec3i, device=device)
    for k, o in enumerate(level_octets):
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        octree.expand_octets(o, codes[lo:hi], coords[lo:hi])
    octree.dense_level(top_dims, codes[int(offsets[-2]) :], coords[int(offsets[-2]) :])
    child = wp.full(n, -1, dtype=wp.int32, device=device)
    parent = wp.full(n, -1, dtype=wp.int32, device=device)
    dims_v = wp.vec3i(*(int(d) for d in top_dims))
    for k, o in enumerate(level_octets):
        octree.launch_split(
            octree._link_octets_kernel,
            o.shape[0],
            lambda start, _n, k=k, o=o: [
                start,
                o,
                parent_index[k],
                int(offsets[k]),
                int(offsets[k + 1]),
                dims_v,
                child,
                parent,
            ],
            device,
        )
    if timings is not None:
        timings["levels_structure"] = timings.get("levels_structure", 0.0) + time.perf_counter() - t0
    return {"codes": codes, "coords": coords, "offsets": offsets, "child": child, "parent": parent}


def assemble_field(
    *,
    origin,
    top_dims,
    voxel_size,
    levels,
    layout,
    dist,
    proj,
    source,
    oracle,
    finest_signs,
    device,
    field_ids,
    timings,
    mesh_id=0,
    level_values=None,
    spread_signs=True,
    known_signs=None,
    hole_caps=None,
    octet_points=None,
    fine_values=None,
    sign_presets=None,
):
    """Solve the intermediate and top levels above a finest level and sign every node (shared by construction
    and booleans).

    ``layout``: every node's place (:func:`level_layout`); ``dist``/``proj`` (unsigned distances and projection
    points) and ``source``: one entry per node, the finest level's filled in. Signs are assigned top-down:
    ``oracle(coords, nodes, spacing, sign)`` writes the sign of the given nodes of one level; ``finest_signs(coords,
    sign, lo, hi)`` decides the finest nodes the parent left undecided. When ``fine_values`` (one entry per node, the
    finest level's signed values filled in) is given the finest level keeps those values (and the array becomes the
    field's values). When ``level_values(coords, lo,
    hi, spacing, dist, proj, source, sign)`` is given (booleans: the operands are sampled), it sets every coarse
    node's distance, projection, source and sign directly, in place of the FIM solve and the sign oracles.
    ``spread_signs`` lets signs spread between same-level neighbours; ``hole_caps`` (boxes lo, boxes hi, radii, from
    :func:`hole_caps`) keeps them from spreading near an open mesh's holes. ``octet_points`` (distances, closest
    points) of the finest octets' centres, where the finest level's computation found them: the level-1 nodes there.
    ``known_signs``: an earlier field of the same mesh and domain whose nodes' signs are reused where nodes match.
    ``sign_presets(layout)``: (signs (N,) float32, 0 where undecided; no_inherit (N,) uint8, nodes that must not take
    their parent's sign) set before the top-down pass (see :func:`cap_sign_presets`).
    """
    top_dims = np.asarray(top_dims, dtype=np.int64)
    fine_dims = top_dims * 2 ** (levels - 1)
    codes, coords, offsets = layout["codes"], layout["coords"], layout["offsets"]
    child, parent = layout["child"], layout["parent"]
    n, n0 = int(offsets[-1]), int(offsets[1])
    # same-level neighbours of the coarse nodes (node i in row i - n0): the finest level finds its own by octet, and
    # booleans sample their operands instead of solving
    neighbours = wp.full((n - n0 if level_values is None else 0, 6), -1, dtype=wp.int32, device=device)
    # Coarse nodes an earlier build of the same mesh and domain has keep their distances (refinement rounds).
    known = wp.zeros(n, dtype=wp.int32, device=device)
    # each node's index in the earlier build (-1: new), shared by distances and signs
    prev_index = match_levels(codes, offsets, known_signs) if known_signs is not None else None
    if known_signs is not None and level_values is None:
        octree.launch_split(
            _take_known_kernel,
            n - n0,
            lambda s, _n: [
                n0 + s,
                prev_index,
                known_signs.values,
                known_signs.proj,
                known_signs.source,
                known,
                dist,
                proj,
                source,
            ],
            device,
        )
    sweeps = {}
    origin_t = tuple(float(x) for x in origin)
    sign = wp.zeros(n, dtype=wp.float32, device=device)
    no_inherit = wp.empty(0, dtype=wp.uint8, device=device)
    if sign_presets is not None:
        preset, flags = sign_presets(layout)
        sign = wp.array(preset, dtype=wp.float32, device=device)
        no_inherit = wp.array(flags, dtype=wp.uint8, device=device)
    for k in range(1, levels):
        tk = time.perf_counter()
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        name = "top_level" if k == levels - 1 else f"level_{k}"
        if level_values is not None:
            level_values(coords, lo, hi, voxel_size * 2**k, dist, proj, source, sign)
            timings[name] = timings.get(name, 0.0) + time.perf_counter() - tk
            continue
        octree.level_neighbours(coords, lo, hi, fine_dims >> k, neighbours, row0=n0)
        tn = time.perf_counter()
        sweeps[k] = octree.solve_level(
            coords,
            child,
            neighbours,
            lo,
            hi,
            origin_t,
            voxel_size * 2**k,
            dist,
            proj,
            source,
            mesh_id=mesh_id,
            known=known,
            octet_points=octet_points if k == 1 else None,
            row0=n0,
            ordered_sweeps=k == levels - 1,  # the dense top level: far from the surface, information travels far
            tolerance=TOP_LEVEL_TOLERANCE if k == levels - 1 else 0.0,
        )
        timings[f"{name}_neighbours"] = timings.get(f"{name}_neighbours", 0.0) + tn - tk
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - tk

    # Signs, top-down: the top level from a sparse set of oracle seeds, every lower level from its parents; then
    # within each level from already signed neighbours (empty balls again); the oracle only for what is left.
    t0 = time.perf_counter()
    if known_signs is not None:
        octree.launch_split(_take_known_sign_kernel, n, lambda s, _n: [s, prev_index, known_signs.values, sign], device)
    top_lo, top_hi = int(offsets[levels - 1]), int(offsets[levels])
    oracle_counts = {}
    sign_sweeps = {}
    origin_v = wp.vec3(*origin_t)

    cap_args = _box_arrays(hole_caps, device)

    def spread(k, lo, hi):
        if not spread_signs:
            return lo + np.flatnonzero(sign.numpy()[lo:hi] == 0.0)
        changed = wp.zeros(1, dtype=wp.int32, device=device)
        # the finest level first spreads by empty balls alone, then (with a mesh) across segments that cross no
        # triangle, which costs a box query each and so runs only once the cheap test is exhausted
        phases = [0, int(mesh_id)] if mesh_id else [0]
        sweeps = {}
        for phase_mesh in phases:
            for sweep in range(MAX_SIGN_SWEEPS):  # noqa: B007 (the count is kept)
                changed.zero_()
                if k == 0:
                    # in place from two threads: a sign only ever goes from unset to final, so races are harmless
                    octree.launch_split(
                        _propagate_sign_octet_kernel,
                        (hi - lo) // 8,
                        lambda start, span, phase_mesh=phase_mesh, sweep=sweep: [
                            start,
                            codes,
                            parent,
                            child,
                            neighbours,
                            n0,
                            dist,
                            sign,
                            SIGN_SAFETY * 1.0,
                            float(voxel_size),
                            origin_v,
                            *cap_args,
                            wp.uint64(phase_mesh),
                            changed,
                            span,
                            sweep % 2,
                        ],
                        device,
                    )
                else:
                    # split the same way (racing increments from two threads still leave ``changed`` nonzero)
                    octree.launch_split(
                        _propagate_sign_kernel,
                        hi - lo,
                        lambda start, span, phase_mesh=phase_mesh, sweep=sweep: [
                            neighbours,
                            n0,
                            lo + start,
                            dist,
                            sign,
                            SIGN_SAFETY,
                            float(voxel_size * 2**k),
                            coords,
                            origin_v,
                            *cap_args,
                            wp.uint64(phase_mesh),
                            changed,
                            span,
                            sweep % 2,
                        ],
                        device,
                    )
                got = int(changed.numpy()[0])
                if got == 0:
                    break
                if phase_mesh != phases[-1] and (k == 0 or got < SIGN_SWEEP_SETTLED * (hi - lo)):
                    # the empty balls have settled (on the finest level one in-place sweep leaves a handful): the
                    # segments' phase signs the few nodes another sweep over the whole level would
                    break
            sweeps[phase_mesh] = sweep + 1
        sign_sweeps[k] = (sweeps[0], sweeps.get(int(mesh_id), 0))
        return lo + np.flatnonzero(sign.numpy()[lo:hi] == 0.0)

    if level_values is None and levels > 1:
        # Across a hole of an open mesh the sign changes where no triangle is near, so empty balls prove nothing
        # near it: signs spread only away from the holes' caps (``hole_caps``), the oracle decides the rest.
        stride = TOP_SEED_STRIDE if spread_signs else 1
        nx, ny, nz = (int(d) for d in top_dims)
        ix, iy, iz = (np.arange(min(stride // 2, n_axis - 1), n_axis, stride) for n_axis in (nx, ny, nz))
        seeds = top_lo + (ix[None, None, :] + nx * (iy[None, :, None] + ny * iz[:, None, None])).ravel()
        seeds = seeds[sign.numpy()[seeds] == 0.0]
        oracle(coords, seeds, voxel_size * 2 ** (levels - 1), sign)
        rest = spread(levels - 1, top_lo, top_hi)
        oracle(coords, rest, voxel_size * 2 ** (levels - 1), sign)
        oracle_counts[levels - 1] = len(seeds) + len(rest)
    for k in range(levels - 2, -1, -1) if level_values is None else ():
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        octree.launch_split(
            octree._inherit_sign_kernel,
            hi - lo,
            lambda start, _n, k=k, lo=lo: [
                coords,
                parent,
                lo + start,
                origin_v,
                voxel_size * 2**k,
                dist,
                sign,
                SIGN_SAFETY,
                no_inherit,
            ],
            device,
        )
        if k > 0:
            idx = spread(k, lo, hi)
            oracle(coords, idx, voxel_size * 2**k, sign)
            oracle_counts[k] = len(idx)
    if fine_values is None:
        if levels > 1:
            spread(0, 0, n0)
        oracle_counts[0] = finest_signs(coords, sign, 0, n0)
    if fine_values is None:
        values = wp.empty(n, dtype=wp.float32, device=device)
        octree.launch_split(_apply_sign_kernel, n, lambda start, _n: [start, dist, sign, values], device)
    else:  # the finest values are in place already
        values = fine_values
        octree.launch_split(_apply_sign_kernel, n - n0, lambda start, _n: [n0 + start, dist, sign, values], device)
    timings["signs"] = timings.get("signs", 0.0) + time.perf_counter() - t0

    return AdaptiveField(
        voxel_size=voxel_size,
        levels=levels,
        origin=origin,
        top_dims=top_dims,
        level_offsets=offsets,
        codes=codes,
        coords=coords,
        values=values,
        proj=proj,
        child=child,
        source=source,
        field_ids=field_ids,
        device=device,
        timings=timings,
        stats={"fim_sweeps": sweeps, "sign_queries": oracle_counts, "sign_sweeps": sign_sweeps},
    )
