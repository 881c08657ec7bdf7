"""Exact closest points of a mesh's field on its sparse levels (Ren et al., Sec. 4.2).

The finest level takes exact closest points octet by octet (:func:`finest_distances`): one BVH query at the octet's
centre gives its closest triangle, whose distance to each of the 8 nodes bounds where their closest triangles can be,
one box query lists those candidates and each node is tested against them. Meshes far finer than the cells query the
BVH node by node, and a dense single level does throughout. The octet centres' closest points are kept: they are the
next level's internal nodes'. The sparse levels above take theirs the same way (:func:`level_distances`), searching
only their leaves; the dense top level is left to fast sweeping and a bounded refinement (:mod:`.sweeping`,
:mod:`.fim`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import warp as wp

from .geometry import (
    UNSET_DISTANCE,
    closest_on_triangle,
    mesh_closest_face,
    triangle_frame,
)
from .octree import node_center
from .parallel import BALANCE_MIN_PIECE, EMIT_SPLIT_MIN_DIM, launch_split
from .search import OctetSearch


@wp.func
def _node_closest_point(mesh: wp.uint64, x: wp.vec3, max_dist: float, far_dist: float):
    """(found, closest point, its triangle or -1) of one node by the mesh BVH: within ``max_dist``, else within
    ``far_dist``."""
    p, face = mesh_closest_face(mesh, x, max_dist)
    if face < 0:
        # a node added where an open mesh's surface crosses a hole can be far from every triangle
        p, face = mesh_closest_face(mesh, x, far_dist)
    return wp.where(face >= 0, 1, 0), p, face


@wp.func
def _capsule_gap(x: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3, normal: wp.vec3, shortest: float) -> float:
    """A lower bound of the distance from ``x`` to triangle (a, b, c) (``normal``: (b - a) x (c - a)): its distance to
    the longest edge less the triangle's height over that edge. The corner opposite the longest edge has its foot on
    that edge (both other angles are acute), so every point of the triangle lies within the height of the edge. 0
    (no bound) when no edge is longer than ``shortest``: a small triangle's box bounds it about as well."""
    p = a
    q = b
    l2 = wp.length_sq(b - a)
    if wp.length_sq(c - b) > l2:
        p = b
        q = c
        l2 = wp.length_sq(c - b)
    if wp.length_sq(a - c) > l2:
        p = c
        q = a
        l2 = wp.length_sq(a - c)
    if l2 <= shortest * shortest:
        return 0.0
    t = wp.clamp(wp.dot(x - p, q - p) / l2, 0.0, 1.0)
    return wp.length(x - (p + t * (q - p))) - wp.length(normal) / wp.sqrt(l2)


# Consecutive octets per thread of the octet kernel on a CPU: each next to the one before takes its closest triangles
# as the centre's bound instead of a BVH query, where the triangles' mean area is at least OCTET_REUSE_MIN_AREA cell
# faces (a small triangle bounds the next octet loosely: its larger box costs more than the query spared). Measured,
# finest distances against a query per octet: spot (9.5 cell faces a triangle) 0.87x, beetle (17) 0.91x, cow (7.6)
# 0.93x, fandisk (5.3) 0.975x, homer (3.6) 0.945x, rocker-arm (3.1) 0.964x, the bunny (0.86) 1.12x at /256; 0.80-0.91x
# at /512 from 12 up, the bunny (3.4) 1.00-1.03x. Capping the bound instead (a query where it exceeds 1-2 cells)
# made every mesh 3-18 % slower.
OCTET_GROUP = 16


OCTET_REUSE_MIN_AREA = 3.0

# The octet kernel's bounds let through a triangle up to this factor (squared distances) beyond the best so far: its
# bounds and its distances round differently, and a triangle as near as the best but for rounding must be tested for
# the tie to go the same way whichever triangle came first.
TIE_SLACK = wp.constant(1.0001)


# A sparse level above the finest searches boxes only where the triangles' mean area is at least this many of its cell
# faces, else node by node from its octet centre's closest point (its cells are 2^k voxels: a mesh boxed on the finest
# level may be far finer than them). Measured against boxes at every level (8 alternating builds): the bunny /256
# levels 1 and 2 46.5 + 24.5 -> 36.9 + 12.9 ms, rocker-arm /256 level 2 9.8 -> 7.6, homer /256 level 2 7.0 -> 5.4;
# at 0.15 (the finest level's threshold) only level 2 gained, at 1.0 level 1 lost.
LEVEL_BOX_MIN_AREA = 0.5


def _octet_distance_kernel(coarse: bool, reuse: bool):
    """The octet kernel of the finest level (``coarse`` False) or of a coarser sparse level (True: nodes known
    already are taken, see :func:`level_distances`, and no closest triangles are kept), whose octets take the
    triangles of the octet before them (``reuse``) or query the BVH at every centre. The parts a variant does not use
    are compiled out of it (the coarse ones cost the finest kernel 9-11 %, those of reuse 3-5 % without it)."""

    @wp.kernel(enable_backward=False)
    def kernel(
        first: int,
        group: int,
        mesh: wp.uint64,
        coords: wp.array[wp.vec3i],
        octet_nodes: wp.array[wp.int32],
        origin: wp.vec3,
        spacing: float,
        max_dist: float,
        far_dist: float,
        dist: wp.array[wp.float32],
        proj: wp.array[wp.vec3],
        tri: wp.array[wp.int32],
        octet_dist: wp.array[wp.float32],
        octet_proj: wp.array[wp.vec3],
        octet_first: int,
        box_search: int,
        search: wp.uint64,
        frame: wp.mat33,
        turned: int,
        slivers: wp.array[wp.uint8],
        known: wp.array[wp.int32],
        child: wp.array[wp.int32],
        below_dist: wp.array[wp.float32],
        below_proj: wp.array[wp.vec3],
        below_first: int,
    ):
        """Exact closest points of the 8 nodes of each of ``group`` consecutive octets (thread ``tid`` takes octets
        ``(first + tid) * group`` on, each given by its first node in ``octet_nodes``, children in Morton order).
        An octet's centre has a triangle near it: its closest one by a BVH query, or, next to the octet before it in
        the group (Morton order keeps most neighbours together), the nearest of that octet's nodes' closest
        triangles, which spares the query. Each node's distance to that triangle bounds its own, so the triangles
        whose boxes meet the box around those balls are all the candidates, and every node (and the centre, when
        its triangle was not queried) is tested against them directly — one box query per octet instead of eight
        closest-point queries. Octets far from the mesh (no triangle within ``max_dist`` of the centre, added where
        an open mesh's surface crosses a hole) do the same after a wider centre query: their balls are large, but
        the boxes' distances still skip most candidates (beetle /256: their 8 node queries took twice as long).
        A node as near two triangles takes the lower-numbered one, and the bounds let a triangle as near as the best
        (but for rounding: TIE_SLACK) through: which triangle a node takes does not depend on the octet before it, so
        a field built on demand and refined in steps is bit for bit the field refined at once (its nodes beside two
        overlapping boxes' coinciding faces took either, by the order the octets were built in).
        Every octet queries node by node when ``box_search`` is 0 (a mesh whose triangles are much smaller than a
        cell would put hundreds in each box). The centre's exact closest point (the octet's parent node's) goes to
        ``octet_dist``/``octet_proj`` at ``base // 8 - octet_first`` (UNSET_DISTANCE when not found). On the
        finest level each node's closest triangle goes to ``tri``; on a coarser one, nodes flagged in ``known``, or
        whose children's octet centre is in ``below_dist``/``below_proj`` (at ``child // 8 - below_first``), take
        those values and are not searched. The BVH queries of the box search run on ``search``, the mesh turned by
        the rotation ``frame`` (:func:`.search.search_frame`; ``turned`` 1, else the mesh itself and 0), with the
        same triangles: the tests themselves read the mesh's own. Only triangles flagged in ``slivers``
        (:func:`.search.slivers`; empty: none) take the capsule test."""
        t0 = (first + wp.tid()) * group
        t1 = wp.min(t0 + group, octet_nodes.shape[0])
        m = wp.mesh_get(mesh)
        prev_c = wp.vec3(0.0)
        prev_faces = wp.vector(-1, length=8, dtype=int)
        for t in range(t0, t1):
            base = octet_nodes[t]
            # bit k: node k's closest point is known already (``known``, or its children's centre from the level
            # below)
            given = int(0)
            for k in range(wp.static(8 if coarse else 0)):
                i = base + k
                if known.shape[0] > 0:
                    if known[i] == 1:
                        given = given | (1 << k)
                if child.shape[0] > 0 and ((given >> k) & 1) == 0:
                    j = child[i]
                    if j >= 0:
                        below = below_dist[j // 8 - below_first]
                        if below < UNSET_DISTANCE:
                            dist[i] = below
                            proj[i] = below_proj[j // 8 - below_first]
                            given = given | (1 << k)
            c = node_center(origin, spacing, coords[base]) + wp.vec3(0.5 * spacing)
            # next to the octet before: the nearest of its nodes' triangles to the centre, an upper bound
            centre_face = int(-1)
            centre_foot = c
            best_c = float(UNSET_DISTANCE)
            step = wp.abs(c - prev_c)
            reach_prev = wp.static(reuse) and wp.max(step[0], wp.max(step[1], step[2])) <= 2.001 * spacing
            if reach_prev and prev_faces[0] >= 0 and given != 255:
                for k in range(8):
                    g = prev_faces[k]
                    seen = int(0)
                    for e in range(k):
                        if prev_faces[e] == g:
                            seen = 1
                    if seen == 0:
                        a0 = m.points[m.indices[3 * g]]
                        b0 = m.points[m.indices[3 * g + 1]]
                        c0 = m.points[m.indices[3 * g + 2]]
                        edges0, inward0, lengths0, n0 = triangle_frame(a0, b0, c0)
                        p0 = closest_on_triangle(c, a0, b0, c0, edges0, inward0, lengths0, n0)
                        d0 = wp.length_sq(c - p0)
                        if d0 < best_c:
                            best_c = d0
                            centre_foot = p0
                            centre_face = g
                if best_c > max_dist * max_dist:
                    centre_face = -1
            exact_centre = centre_face < 0
            near = True
            if exact_centre:
                cs = c
                if turned == 1:
                    cs = frame * c
                centre_foot, centre_face = mesh_closest_face(search, cs, max_dist)
                near = centre_face >= 0
                if not near:
                    # an octet added where an open mesh's surface crosses a hole can be far from every triangle
                    centre_foot, centre_face = mesh_closest_face(search, cs, far_dist)
                if turned == 1:
                    centre_foot = wp.transpose(frame) * centre_foot
                best_c = wp.length_sq(c - centre_foot)
            has_foot = centre_face >= 0
            octet_dist[base // 8 - octet_first] = UNSET_DISTANCE
            if has_foot and exact_centre:
                octet_dist[base // 8 - octet_first] = wp.length(c - centre_foot)
                octet_proj[base // 8 - octet_first] = centre_foot
            if wp.static(reuse):
                prev_faces[0] = -1
            if wp.static(coarse):
                if given == 255:
                    continue
            if has_foot and box_search == 1:
                node_lo = c - wp.vec3(0.5 * spacing)  # the box of the 8 node centres
                node_hi = c + wp.vec3(0.5 * spacing)
                # every node starts from its closest point on the centre's triangle (an upper bound)
                a0 = m.points[m.indices[3 * centre_face]]
                b0 = m.points[m.indices[3 * centre_face + 1]]
                c0 = m.points[m.indices[3 * centre_face + 2]]
                edges0, inward0, lengths0, n0 = triangle_frame(a0, b0, c0)
                best = wp.vector(UNSET_DISTANCE, length=8, dtype=float)
                foot = wp.matrix(0.0, shape=(8, 3), dtype=float)
                face = wp.vector(centre_face, length=8, dtype=int)
                # each node's closest triangle lies in its ball through that point: search the box around those
                # balls, and around the centre's when its triangle was not queried
                worst = float(0.0)
                box_lo = c
                box_hi = c
                if wp.static(reuse) and not exact_centre:
                    worst = best_c
                    r = wp.sqrt(best_c) * 1.0001 + 1.0e-4 * spacing
                    box_lo = c - wp.vec3(r)
                    box_hi = c + wp.vec3(r)
                for k in range(8):
                    if wp.static(coarse):
                        if ((given >> k) & 1) == 1:
                            continue
                    x = c + spacing * wp.vec3(float(k & 1) - 0.5, float((k >> 1) & 1) - 0.5, float((k >> 2) & 1) - 0.5)
                    p0 = closest_on_triangle(x, a0, b0, c0, edges0, inward0, lengths0, n0)
                    best[k] = wp.length_sq(x - p0)
                    foot[k] = p0
                    worst = wp.max(worst, best[k])
                    r = wp.sqrt(best[k]) * 1.0001 + 1.0e-4 * spacing
                    box_lo = wp.min(box_lo, x - wp.vec3(r))
                    box_hi = wp.max(box_hi, x + wp.vec3(r))
                if turned == 1:  # the box around the turned box
                    mid = frame * (0.5 * (box_lo + box_hi))
                    half = 0.5 * (box_hi - box_lo)
                    reach = wp.vec3(
                        wp.abs(frame[0, 0]) * half[0] + wp.abs(frame[0, 1]) * half[1] + wp.abs(frame[0, 2]) * half[2],
                        wp.abs(frame[1, 0]) * half[0] + wp.abs(frame[1, 1]) * half[1] + wp.abs(frame[1, 2]) * half[2],
                        wp.abs(frame[2, 0]) * half[0] + wp.abs(frame[2, 1]) * half[1] + wp.abs(frame[2, 2]) * half[2],
                    )
                    box_lo = mid - reach
                    box_hi = mid + reach
                candidates = wp.mesh_query_aabb(search, box_lo, box_hi)
                f = int(0)
                while wp.mesh_query_aabb_next(candidates, f):
                    if f == centre_face:
                        continue
                    a = m.points[m.indices[3 * f]]
                    b = m.points[m.indices[3 * f + 1]]
                    cc = m.points[m.indices[3 * f + 2]]
                    # no point of a triangle is nearer than its bounding box: the box's distance to the nodes' box
                    # bounds all 8 nodes at once, its distance to a node that node, before the exact test (an exact
                    # test at the centre, less half a diagonal, bounded them about as well at about the same cost)
                    tri_lo = wp.min(a, wp.min(b, cc))
                    tri_hi = wp.max(a, wp.max(b, cc))
                    gap = wp.max(wp.max(tri_lo - node_hi, node_lo - tri_hi), wp.vec3(0.0))
                    near_box = wp.length_sq(gap) <= worst * TIE_SLACK
                    if near_box:
                        # nor nearer than its plane, which bounds all 8 nodes at once where the boxes of long slanted
                        # triangles (a cylinder's sides) meet the nodes' box without coming near it
                        normal = wp.cross(b - a, cc - a)
                        off = wp.abs(wp.dot(normal, c - a)) - 0.5 * spacing * (
                            wp.abs(normal[0]) + wp.abs(normal[1]) + wp.abs(normal[2])
                        )
                        near_box = off <= 0.0 or off * off <= worst * TIE_SLACK * wp.length_sq(normal)
                    if near_box and slivers.shape[0] > 0 and slivers[f] == wp.uint8(1):
                        # nor nearer than its longest edge less its height (less half a diagonal): slivers beside
                        # the nearest one (a cylinder's sides around the nodes) share its plane nearly, not its place
                        beyond = _capsule_gap(c, a, b, cc, normal, 4.0 * spacing) - 0.8660254 * spacing
                        near_box = beyond <= 0.0 or beyond * beyond <= worst * TIE_SLACK
                    if near_box:
                        worst = float(0.0)
                        edges, inward, lengths, n = triangle_frame(a, b, cc)
                        if wp.static(reuse) and not exact_centre:
                            gap = wp.max(wp.max(tri_lo - c, c - tri_hi), wp.vec3(0.0))
                            plane = wp.dot(n, c - a)
                            if wp.length_sq(gap) < best_c and plane * plane < best_c:
                                p = closest_on_triangle(c, a, b, cc, edges, inward, lengths, n)
                                d = wp.length_sq(c - p)
                                if d < best_c:
                                    best_c = d
                                    centre_foot = p
                            worst = best_c
                        for k in range(8):
                            if wp.static(coarse):
                                if ((given >> k) & 1) == 1:
                                    continue
                            x = c + spacing * wp.vec3(
                                float(k & 1) - 0.5, float((k >> 1) & 1) - 0.5, float((k >> 2) & 1) - 0.5
                            )
                            gap = wp.max(wp.max(tri_lo - x, x - tri_hi), wp.vec3(0.0))
                            plane = wp.dot(n, x - a)  # nor nearer than its plane (0 for a degenerate triangle)
                            if wp.length_sq(gap) <= best[k] * TIE_SLACK and plane * plane <= best[k] * TIE_SLACK:
                                p = closest_on_triangle(x, a, b, cc, edges, inward, lengths, n)
                                d = wp.length_sq(x - p)
                                if d < best[k] or (d == best[k] and f < face[k]):  # (a tie: the lower number)
                                    best[k] = d
                                    foot[k] = p
                                    face[k] = f
                            worst = wp.max(worst, best[k])
                if wp.static(reuse) and not exact_centre:
                    octet_dist[base // 8 - octet_first] = wp.length(c - centre_foot)
                    octet_proj[base // 8 - octet_first] = centre_foot
                for k in range(8):
                    if wp.static(coarse):
                        if ((given >> k) & 1) == 1:
                            continue
                    x = node_center(origin, spacing, coords[base + k])
                    p = wp.vec3(foot[k, 0], foot[k, 1], foot[k, 2])
                    node_face = face[k]
                    if best[k] >= UNSET_DISTANCE:  # cannot happen but for rounding: the node's own query
                        found, p, node_face = _node_closest_point(mesh, x, max_dist, far_dist)
                    dist[base + k] = wp.where(node_face >= 0, wp.length(x - p), UNSET_DISTANCE)
                    proj[base + k] = p
                    if wp.static(not coarse):
                        tri[base + k] = node_face
                if wp.static(reuse):
                    prev_faces = face
                    prev_c = c
                continue
            for k in range(8):
                if wp.static(coarse):
                    if ((given >> k) & 1) == 1:
                        continue
                x = node_center(origin, spacing, coords[base + k])
                bound = max_dist
                if (wp.static(coarse) or not near) and has_foot:  # the centre's closest point bounds each node's search
                    bound = wp.length(x - centre_foot) * 1.0001 + 1.0e-4 * spacing
                found, p, node_face = _node_closest_point(mesh, x, bound, far_dist)
                dist[base + k] = wp.where(found == 1, wp.length(x - p), UNSET_DISTANCE)
                proj[base + k] = p
                if wp.static(not coarse):
                    tri[base + k] = node_face

    return kernel


# the kernel of each (coarse, reuse) variant
_OCTET_KERNELS = {
    (coarse, reuse): _octet_distance_kernel(coarse, reuse) for coarse in (False, True) for reuse in (False, True)
}


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
    tri: wp.array[wp.int32],
):
    """Exact closest point (and its triangle) of each node of a dense finest level (Warp's mesh BVH)."""
    i = wp.tid()
    x = node_center(origin, spacing, coords[i])
    found, p, face = _node_closest_point(mesh, x, max_dist, far_dist)
    source[i] = source_id
    dist[i] = wp.where(found == 1, wp.length(x - p), UNSET_DISTANCE)
    proj[i] = p
    tri[i] = face


@wp.kernel(enable_backward=False)
def take_known_kernel(
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
def _take_known_triangles_kernel(
    first: int, where: wp.array[wp.int32], prev_tri: wp.array[wp.int32], tri: wp.array[wp.int32]
):
    """Finest node ``first + tid`` found in an earlier build takes its closest triangle."""
    i = first + wp.tid()
    j = where[i]
    if j >= 0:
        tri[i] = prev_tri[j]


def _take_known_octets(previous, prev_index, decoded, arrays) -> np.ndarray:
    """The finest nodes ``previous`` has (``prev_index``) take its distance, closest point, source and triangle into
    ``arrays`` (dist, proj, source, tri of the finest level; ``decoded``: its closest points and node sources);
    returns the first node of each octet it does not have (matched octet by octet)."""
    dist0, proj0, src0, tri = arrays
    n0, device = tri.shape[0], tri.device
    launch_split(_take_known_triangles_kernel, n0, lambda s, _n: [s, prev_index, previous.tri, tri], device)
    no_known = wp.empty(0, dtype=wp.int32, device=device)
    args = [prev_index, previous.values, *decoded, no_known, dist0, proj0, src0]
    launch_split(take_known_kernel, n0, lambda s, _n: [s, *args], device)
    return 8 * np.flatnonzero(prev_index.numpy()[:n0:8] < 0)


def finest_distances(
    search: OctetSearch,
    layout: dict,
    *,
    origin,
    voxel_size: float,
    field_id: int,
    previous=None,
    prev_index=None,
    decoded=None,
):
    """Exact closest points of the finest level of ``layout`` (:func:`.layout.level_layout`) on a mesh.

    Args:
        search: The mesh and how its octets search it (:class:`.search.OctetSearch`): its ``query_radius`` is a
            radius within which every finest node has a triangle (larger searches fall back to ``far_dist``, the
            domain's diagonal); with ``box_search`` octets search a box of candidate triangles (meshes whose
            triangles are not much smaller than a cell), else query the BVH node by node; with more than one level
            they may search the mesh turned by ``frame`` (``search_id``, :func:`.search.search_frame`); the
            ``slivers`` take the capsule test (:func:`.search.slivers`).
        layout: Every node's place; its finest level is complete octets (or, with one level, the dense top level).
        origin, voxel_size: The field's lattice.
        field_id: Source id written to the finest nodes.
        previous, prev_index: An earlier field of the same mesh and domain and each node's index in it (-1: new;
            :func:`.layout.match_levels`): its octets keep their closest points; ``decoded``: its (closest points,
            node sources), decoded once for every step that reads them.
    Returns:
        ``(dist, proj, source, tri, octet_points)``: (N,) float32 unsigned distances, (N,) vec3 closest points and (N,)
        int32 source ids for every node of the layout, the finest level's filled in; (N0,) int32 the triangle (index
        into the mesh) of each finest node's closest point; ``octet_points`` the (distance, closest point) arrays of
        every finest octet's centre (UNSET_DISTANCE where not found), or None for a dense single level.
    """
    offsets, device = layout["offsets"], layout["codes"].device
    n, n0 = int(offsets[-1]), int(offsets[1])
    fine_coords = layout["coords"][:n0]
    dist = wp.empty(n, dtype=wp.float32, device=device)
    proj = wp.empty(n, dtype=wp.vec3, device=device)
    source = wp.empty(n, dtype=wp.int32, device=device)
    dist0, proj0, src0 = dist[:n0], proj[:n0], source[:n0]
    tri = wp.empty(n0, dtype=wp.int32, device=device)
    # Octets an earlier build of this mesh already has keep their closest points; only new ones are queried.
    first_nodes = np.arange(0, n0, 8)
    if previous is not None:
        first_nodes = _take_known_octets(previous, prev_index, decoded, (dist0, proj0, src0, tri))
    src0.fill_(int(field_id))
    origin_v = wp.vec3(*origin)
    if len(offsets) == 2:  # a single dense level: node by node
        launch_split(
            _finest_distance_kernel,
            n0,
            lambda lo, k: [
                search.mesh_id,
                fine_coords[lo : lo + k],
                origin_v,
                float(voxel_size),
                float(search.query_radius),
                float(search.far_dist),
                int(field_id),
                dist0[lo : lo + k],
                proj0[lo : lo + k],
                src0[lo : lo + k],
                tri[lo : lo + k],
            ],
            device,
        )
        return dist, proj, source, tri, None
    # octet by octet, in place
    octet_nodes = wp.array(first_nodes.astype(np.int32), dtype=wp.int32, device=device)
    octet_points = (
        wp.full(n0 // 8, UNSET_DISTANCE, dtype=wp.float32, device=device),
        wp.empty(n0 // 8, dtype=wp.vec3, device=device),
        0,
    )
    _launch_octets(search, fine_coords, octet_nodes, origin_v, voxel_size, dist0, proj0, tri, octet_points)
    return dist, proj, source, tri, octet_points


def _launch_octets(search, coords, octet_nodes, origin_v, spacing, dist, proj, tri, octet_points, given=None):
    """Launch the octet kernel over ``octet_nodes`` (the first node of each octet), writing the octets' centre
    points into ``octet_points`` (distances, closest points, index of the first octet) and, with ``given``
    (``known`` flags, first child links, the level below's octet points), taking the nodes known already."""
    device = coords.device
    reuse = not device.is_cuda and search.mean_area >= OCTET_REUSE_MIN_AREA * spacing**2
    kernel = _OCTET_KERNELS[(given is not None, reuse)]
    group = OCTET_GROUP if reuse else 1
    if given is None:
        empty = wp.empty(0, dtype=wp.int32, device=device)
        none_below = (wp.empty(0, dtype=wp.float32, device=device), wp.empty(0, dtype=wp.vec3, device=device), 0)
        given = (empty, empty, none_below)
    known, child, below = given
    frame = wp.mat33(*(float(x) for x in np.reshape(np.eye(3) if search.frame is None else search.frame, -1)))
    slivers = wp.empty(0, dtype=wp.uint8, device=device) if search.slivers is None else search.slivers
    launch_split(
        kernel,
        (octet_nodes.shape[0] + group - 1) // group,
        lambda lo, k: [
            lo,
            group,
            search.mesh_id,
            coords,
            octet_nodes,
            origin_v,
            float(spacing),
            float(search.query_radius),
            float(search.far_dist),
            dist,
            proj,
            tri,
            *octet_points,
            int(search.box_search),
            search.search_id,
            frame,
            int(search.frame is not None),
            slivers,
            known,
            child,
            *below,
        ],
        device,
        min_dim=max(1, EMIT_SPLIT_MIN_DIM // group),
        balance=True,  # octets near an open mesh's holes, or far from it, cost more
        min_piece=max(1, BALANCE_MIN_PIECE // group),
    )


def level_distances(search: OctetSearch, layout: dict, k: int, dist, proj, known, below, *, origin, voxel_size):
    """Exact closest points of the nodes of sparse level ``k`` (> 0) of ``layout``, octet by octet as on the finest
    level (the same kernel, :func:`finest_distances`): a node whose children's octet centre is known from the level
    below (``below``: that level's octet points) takes it, a node flagged in ``known`` keeps its values, and only the
    rest are searched. Replaces the fast iterative method and its BVH refinement below the top level, which were
    slower (homer /512: levels 1 and 2 35.5 + 21 ms against 27.6 + 11) and not always exact (beetle's level 2 up to
    0.07 voxel off: the refinement's bound missed).

    Returns:
        This level's octet points (the next level's internal nodes), as ``below``.
    """
    offsets, coords = layout["offsets"], layout["coords"]
    lo, hi = int(offsets[k]), int(offsets[k + 1])
    device = coords.device
    spacing = voxel_size * 2**k
    octet_points = (
        wp.full((hi - lo) // 8, UNSET_DISTANCE, dtype=wp.float32, device=device),
        wp.empty((hi - lo) // 8, dtype=wp.vec3, device=device),
        lo // 8,
    )
    level = dataclasses.replace(
        search,
        query_radius=4.0 * spacing,  # a coarse node lies within a few of its cells of the mesh
        box_search=search.box_search and search.mean_area >= LEVEL_BOX_MIN_AREA * spacing**2,
    )
    octet_nodes = wp.array(np.arange(lo, hi, 8, dtype=np.int32), dtype=wp.int32, device=device)
    no_tri = wp.empty(0, dtype=wp.int32, device=device)
    origin_v = wp.vec3(*(float(x) for x in origin))
    given = (known, layout["child"], below)
    _launch_octets(level, coords, octet_nodes, origin_v, spacing, dist, proj, no_tri, octet_points, given)
    return octet_points
