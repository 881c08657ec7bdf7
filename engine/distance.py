"""Unsigned distances and closest points of a mesh's field, level by level (Ren et al., Sec. 4.2).

The finest level takes exact closest points octet by octet (:func:`finest_octet_distance_kernel`: one BVH query at
the octet's centre bounds where the 8 nodes' closest triangles can be, one box query lists them). Each coarser level
(:func:`solve_level`) takes its internal nodes from their children (made exact by a bounded BVH query), solves its
leaves by the fast iterative method over same-level neighbours (closest points propagated, Jacobi sweeps on both
cores, or ordered in-place sweeps on the dense top level), and refines every leaf by a BVH search bounded by that
estimate: exact below the top level, within a tolerance on it.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .geometry import (
    UNSET_DISTANCE,
    closest_on_triangle,
    mesh_closest_face,
    mesh_closest_point,
    mesh_near_point,
    triangle_edges,
)
from .octree import node_center
from .parallel import EMIT_SPLIT_MIN_DIM, launch_split


@wp.func
def _node_closest_point(mesh: wp.uint64, x: wp.vec3, max_dist: float, far_dist: float):
    """(found, closest point) of one node by the mesh BVH: within ``max_dist``, else within ``far_dist``."""
    found, p = mesh_closest_point(mesh, x, max_dist)
    if not found:
        # a node added where an open mesh's surface crosses a hole can be far from every triangle
        found, p = mesh_closest_point(mesh, x, far_dist)
    return wp.where(found, 1, 0), p


@wp.kernel(enable_backward=False)
def finest_octet_distance_kernel(
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
def finest_distance_kernel(
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
def _init_from_children_kernel(
    coords: wp.array[wp.vec3i],
    first_child: wp.array[wp.int32],
    lo: int,
    origin: wp.vec3,
    spacing: float,
    mesh: wp.uint64,
    max_dist: float,
    known: wp.array[wp.int32],
    octet_dist: wp.array[wp.float32],
    octet_proj: wp.array[wp.vec3],
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
):
    """Internal nodes are sources: the nearest of their children's projection points (Ren et al.), which with a
    mesh is then made exact by a BVH query bounded by that distance. Leaves start unset. Nodes marked ``known`` keep
    the values they were given. ``octet_dist``/``octet_proj`` (per octet of the level below, empty if none): exact
    closest points of octet centres already found (UNSET_DISTANCE where not), which are this level's node centres."""
    i = lo + wp.tid()
    if known[i] == 1:
        return
    c = first_child[i]
    if c < 0:
        dist[i] = UNSET_DISTANCE
        return
    x = node_center(origin, spacing, coords[i])
    best = float(UNSET_DISTANCE)
    best_j = c
    for o in range(8):
        j = c + o
        if dist[j] < UNSET_DISTANCE:
            dj = wp.length(x - proj[j])
            if dj < best:
                best = dj
                best_j = j
    dist[i] = best
    proj[i] = proj[best_j]
    source[i] = source[best_j]
    if octet_dist.shape[0] > 0:
        if octet_dist[c // 8] < UNSET_DISTANCE:
            dist[i] = octet_dist[c // 8]
            proj[i] = octet_proj[c // 8]
            return
    if mesh != wp.uint64(0):
        found, p = mesh_closest_point(mesh, x, wp.min(best * 1.0001 + spacing * 1.0e-4, max_dist))
        if found:
            d = wp.length(x - p)
            if d < best:
                dist[i] = d
                proj[i] = p


@wp.func
def _nearest_projection(
    x: wp.vec3,
    i: int,
    neighbours: wp.array2d[wp.int32],
    row0: int,
    in0: int,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
):
    """The closest-point Eikonal update of node ``i`` (at ``x``): (distance, projection point, source) of the nearest
    projection point among its own and its face neighbours' (node ``j`` at entry ``j - in0``, its neighbours in row
    ``i - row0``); a neighbour's point must be nearer by a relative 1e-5 to win."""
    best = dist[i - in0]
    p = proj[i - in0]
    s = source[i - in0]
    for k in range(6):
        j = neighbours[i - row0, k]
        if j >= 0:
            if dist[j - in0] < UNSET_DISTANCE:
                dj = wp.length(x - proj[j - in0])
                if dj < best * 0.99999:
                    best = dj
                    p = proj[j - in0]
                    s = source[j - in0]
    return best, p, s


@wp.kernel(enable_backward=False)
def _fim_sweep_kernel(
    coords: wp.array[wp.vec3i],
    neighbours: wp.array2d[wp.int32],
    row0: int,
    nodes: wp.array[wp.int32],
    origin: wp.vec3,
    spacing: float,
    in0: int,
    dist_in: wp.array[wp.float32],
    proj_in: wp.array[wp.vec3],
    src_in: wp.array[wp.int32],
    out0: int,
    dist_out: wp.array[wp.float32],
    proj_out: wp.array[wp.vec3],
    src_out: wp.array[wp.int32],
    changed: wp.array[wp.int32],
):
    """One Jacobi sweep of the fast iterative method over a level's unknown leaves (``nodes``, one thread each): each
    takes the nearest projection point among its face neighbours (a closest-point Eikonal update); internal and
    known nodes stay fixed as sources (the caller keeps them in both buffers). Node ``i`` is entry ``i - in0`` of the
    inputs, ``i - out0`` of the outputs and row ``i - row0`` of ``neighbours``."""
    i = nodes[wp.tid()]
    best, p, s = _nearest_projection(
        node_center(origin, spacing, coords[i]), i, neighbours, row0, in0, dist_in, proj_in, src_in
    )
    if best < dist_in[i - in0]:
        wp.atomic_add(changed, 0, 1)
    dist_out[i - out0] = best
    proj_out[i - out0] = p
    src_out[i - out0] = s


@wp.kernel(enable_backward=False)
def _fim_ordered_sweep_kernel(
    coords: wp.array[wp.vec3i],
    first_child: wp.array[wp.int32],
    neighbours: wp.array2d[wp.int32],
    row0: int,
    lo: int,
    hi: int,
    reverse: int,
    origin: wp.vec3,
    spacing: float,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
    known: wp.array[wp.int32],
    changed: wp.array[wp.int32],
):
    """The same update in place, one thread visiting the level's nodes in index order (``reverse``: backwards), so an
    update reaches the next nodes within the sweep (Gauss-Seidel): on the dense top level, whose index order is
    x-fastest, alternating directions converge in a few sweeps where Jacobi sweeps need one per cell of distance."""
    count = int(0)
    for t in range(hi - lo):
        i = lo + t
        if reverse == 1:
            i = hi - 1 - t
        if first_child[i] < 0 and known[i] == 0:
            best, p, s = _nearest_projection(
                node_center(origin, spacing, coords[i]), i, neighbours, row0, 0, dist, proj, source
            )
            if best < dist[i]:
                dist[i] = best
                proj[i] = p
                source[i] = s
                count += 1
    changed[0] = count


def _refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance=0.0):
    """Closest points of a solved level's leaves (``_refine_leaves_kernel``), when there is a mesh."""
    if not mesh_id:
        return
    launch_split(
        _refine_leaves_kernel,
        n,
        lambda start, count: [
            coords,
            first_child,
            lo + start,
            origin_v,
            float(spacing),
            wp.uint64(mesh_id),
            known,
            dist,
            proj,
            float(tolerance),
        ],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # a BVH query per leaf: worth two threads from a few thousand
        balance=True,  # far from the surface a query costs more
    )


def solve_level(
    coords,
    first_child,
    neighbours,
    lo,
    hi,
    origin,
    spacing,
    dist,
    proj,
    source,
    mesh_id=0,
    known=None,
    max_sweeps=4096,
    octet_points=None,
    row0=0,
    ordered_sweeps=False,
    tolerance=0.0,
):
    """Initialise a level from its children (exactly from ``mesh_id`` when given) and run the fast iterative method
    until no leaf changes. Nodes flagged in ``known`` (N,) int32 keep their given distance and projection.
    ``octet_points``: (distances, closest points) of the octet centres of the level below, where already known.
    ``neighbours``: the level's rows of the table of :func:`level_neighbours` (node ``i`` in row ``i - row0``).
    ``ordered_sweeps``: on a CPU, sweep in place on one thread in alternating index order instead of Jacobi sweeps on
    both cores (far fewer sweeps where information travels far, as on the dense top level). ``tolerance``: relative
    error allowed to the leaves' closest points (0: exact)."""
    n = hi - lo
    if n == 0:
        return 0
    device = coords.device
    if known is None:
        known = wp.zeros(dist.shape[0], dtype=wp.int32, device=device)
    origin_v = wp.vec3(*origin)
    if octet_points is None:
        octet_points = (wp.empty(0, dtype=wp.float32, device=device), wp.empty(0, dtype=wp.vec3, device=device))
    launch_split(
        _init_from_children_kernel,
        n,
        lambda start, count: [
            coords,
            first_child,
            lo + start,
            origin_v,
            float(spacing),
            wp.uint64(mesh_id),
            4.0 * float(spacing),
            known,
            *octet_points,
            dist,
            proj,
            source,
        ],
        device,
    )
    if ordered_sweeps and device.is_cpu:
        # one CPU thread, in place, alternating directions (see _fim_ordered_sweep_kernel)
        changed = wp.zeros(1, dtype=wp.int32, device=device)
        sweeps = 0
        while sweeps < max_sweeps:
            wp.launch(
                _fim_ordered_sweep_kernel,
                dim=1,
                inputs=[coords, first_child, neighbours, row0, lo, hi, sweeps % 2, origin_v, float(spacing)],
                outputs=[dist, proj, source, known, changed],
                device=device,
            )
            sweeps += 1
            if int(changed.numpy()[0]) == 0:
                break
        _refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance)
        return sweeps
    # only the unknown leaves change: the sweeps run over them alone
    free = (first_child[lo:hi].numpy() < 0) & (known[lo:hi].numpy() == 0)
    nodes = wp.array(lo + np.flatnonzero(free).astype(np.int32), dtype=wp.int32, device=device)
    # the second buffer of the Jacobi sweeps holds this level only (entry i - lo), every other node as in the first
    dist_b = wp.clone(dist[lo:hi])
    proj_b = wp.clone(proj[lo:hi])
    src_b = wp.clone(source[lo:hi])
    changed = wp.zeros(1, dtype=wp.int32, device=device)
    bufs = [(0, dist, proj, source), (lo, dist_b, proj_b, src_b)]
    sweeps = 0
    while sweeps < max_sweeps and nodes.shape[0] > 0:
        changed.zero_()
        src_bufs, dst_bufs = bufs[sweeps % 2], bufs[(sweeps + 1) % 2]
        # Jacobi sweeps read one buffer and write the other: both cores may take half each
        launch_split(
            _fim_sweep_kernel,
            nodes.shape[0],
            lambda start, count, src_bufs=src_bufs, dst_bufs=dst_bufs: [
                coords,
                neighbours,
                row0,
                nodes[start : start + count],
                origin_v,
                float(spacing),
                *src_bufs,
                *dst_bufs,
                changed,
            ],
            device,
        )
        sweeps += 1
        if int(changed.numpy()[0]) == 0:
            break
    if sweeps % 2 == 1:
        wp.copy(dist, dist_b, dest_offset=lo, count=n)
        wp.copy(proj, proj_b, dest_offset=lo, count=n)
        wp.copy(source, src_b, dest_offset=lo, count=n)
    _refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance)
    return sweeps


@wp.kernel(enable_backward=False)
def _refine_leaves_kernel(
    coords: wp.array[wp.vec3i],
    first_child: wp.array[wp.int32],
    lo: int,
    origin: wp.vec3,
    spacing: float,
    mesh: wp.uint64,
    known: wp.array[wp.int32],
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    tolerance: float,
):
    """Closest point of a solved leaf, exact or within a relative ``tolerance`` (``mesh_near_point``): the FIM
    distance is an upper bound that caps the BVH search radius."""
    i = lo + wp.tid()
    if first_child[i] >= 0 or known[i] == 1:
        return
    x = node_center(origin, spacing, coords[i])
    found, p = mesh_near_point(mesh, x, dist[i] * 1.0001 + spacing * 1.0e-4, tolerance)
    if found:
        d = wp.length(x - p)
        if d < dist[i]:
            dist[i] = d
            proj[i] = p
