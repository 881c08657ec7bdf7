"""Distances of the levels above the finest: the fast iterative method and a bounded BVH refinement (Ren et al.,
Sec. 4.2).

Each coarser level (:func:`solve_level`, bottom-up in :func:`solve_levels`) takes its internal nodes from their
children (the nearest of their closest points, made exact by a BVH query bounded by that distance), solves its leaves
by the fast iterative method over same-level neighbours (closest points propagated: Jacobi sweeps on both cores, or
ordered in-place sweeps on the dense top level, where information travels far), and refines every leaf by a BVH search
bounded by that estimate: exact below the top level, within a tolerance on it. A mesh's build gives the sparse levels
their exact closest points octet by octet instead (``exact_level``, :func:`.distance.level_distances`) and its top
level by fast sweeping (``level_solver``, :func:`.sweeping.solve_level`), with the refinement here.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from .distance import take_known_kernel
from .geometry import (
    UNSET_DISTANCE,
    mesh_closest_point,
    mesh_near_point,
)
from .neighbours import level_neighbours
from .octree import node_center
from .parallel import EMIT_SPLIT_MIN_DIM, launch_split


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
    octet_first: int,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
):
    """Internal nodes are sources: the nearest of their children's projection points (Ren et al.), which with a
    mesh is then made exact by a BVH query bounded by that distance. Leaves start unset. Nodes marked ``known`` keep
    the values they were given. ``octet_dist``/``octet_proj`` (per octet of the level below from its octet
    ``octet_first``, empty if none): exact closest points of octet centres already found (UNSET_DISTANCE where not),
    which are this level's node centres."""
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
        if octet_dist[c // 8 - octet_first] < UNSET_DISTANCE:
            dist[i] = octet_dist[c // 8 - octet_first]
            proj[i] = octet_proj[c // 8 - octet_first]
            return
    if mesh != wp.uint64(0):
        found, p = mesh_closest_point(mesh, x, wp.min(best * 1.0001 + spacing * 1.0e-4, max_dist))
        if found:
            d = wp.length(x - p)
            if d < best:
                dist[i] = d
                proj[i] = p


@wp.func
def nearest_projection(
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
def fim_sweep_kernel(
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
    best, p, s = nearest_projection(
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
            best, p, s = nearest_projection(
                node_center(origin, spacing, coords[i]), i, neighbours, row0, 0, dist, proj, source
            )
            if best < dist[i]:
                dist[i] = best
                proj[i] = p
                source[i] = s
                count += 1
    changed[0] = count


def refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance=0.0):
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


def init_level(coords, first_child, lo, hi, origin, spacing, dist, proj, source, mesh_id, known, octet_points=None):
    """Start level nodes [lo, hi) from their children (``_init_from_children_kernel``): internal nodes take the
    nearest of their children's closest points (exact from ``mesh_id`` when given), leaves are unset, nodes flagged
    in ``known`` keep theirs. ``octet_points``: as for :func:`solve_level`."""
    device = coords.device
    if octet_points is None:
        octet_points = (wp.empty(0, dtype=wp.float32, device=device), wp.empty(0, dtype=wp.vec3, device=device), 0)
    origin_v = wp.vec3(*origin)
    launch_split(
        _init_from_children_kernel,
        hi - lo,
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
    ``octet_points``: (distances, closest points, index of the first octet) of the octet centres of the level below,
    where already known.
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
    init_level(coords, first_child, lo, hi, origin, spacing, dist, proj, source, mesh_id, known, octet_points)
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
        refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance)
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
            fim_sweep_kernel,
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
    refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance)
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


def _take_known_coarse(previous, prev_index, nodes, known, arrays, decoded) -> None:
    """The coarse nodes (``nodes``: from n0 to n) ``previous`` has (``prev_index``) take its distance, closest point
    and source into ``arrays`` (dist, proj, source), flagged in ``known`` (empty: not flagged); ``decoded``: its
    (closest points, node sources)."""
    n0, n = nodes
    prev_points, prev_sources = decoded
    launch_split(
        take_known_kernel,
        n - n0,
        lambda s, _n: [n0 + s, prev_index, previous.values, prev_points, prev_sources, known, *arrays],
        known.device if known.shape[0] else prev_index.device,
    )


def known_levels(layout: dict, previous, prev_index, dist, proj, source, decoded):
    """Every coarse node's distance, closest point and source taken from ``previous`` (which has them all: a field
    refined on demand, :mod:`.ondemand`; ``decoded``: its closest points and node sources), in
    place; returns the coarse nodes' same-level neighbours, as :func:`solve_levels` does."""
    codes, coords, offsets = layout["codes"], layout["coords"], layout["offsets"]
    device = codes.device
    levels = len(offsets) - 1
    n, n0 = int(offsets[-1]), int(offsets[1])
    fine_dims = (np.asarray(layout["top_dims"], dtype=np.int64)) * 2 ** (levels - 1)
    neighbours = wp.full((n - n0, 6), -1, dtype=wp.int32, device=device)
    unflagged = wp.empty(0, dtype=wp.int32, device=device)
    _take_known_coarse(previous, prev_index, (n0, n), unflagged, (dist, proj, source), decoded)
    for k in range(1, levels):
        octets = codes if k < levels - 1 else None  # (the dense top level is no level of octets)
        level_neighbours(coords, int(offsets[k]), int(offsets[k + 1]), fine_dims >> k, neighbours, n0, octets)
    return neighbours


def solve_levels(
    mesh_id,
    layout: dict,
    dist,
    proj,
    source,
    *,
    origin,
    voxel_size: float,
    top_tolerance: float,
    octet_points=None,
    previous=None,
    prev_index=None,
    decoded=None,
    timings: dict,
    level_solver=None,
    exact_level=None,
):
    """Distances and closest points of every level above the finest (:func:`solve_level`, bottom-up), in place.

    Args:
        mesh_id: ``wp.Mesh.id`` of the mesh.
        layout: Every node's place (:func:`.layout.level_layout`).
        dist, proj, source: (N,) arrays of :func:`finest_distances`, the finest level filled in.
        origin, voxel_size: The field's lattice.
        top_tolerance: Relative error allowed to the closest points of the dense top level's leaves.
        octet_points: The finest octets' centre closest points (:func:`.distance.finest_distances`).
        previous, prev_index, decoded: An earlier field of the same mesh and domain, each node's index in it, and
            its (closest points, node sources): its coarse nodes keep their distances.
        timings: Seconds per level are added here.
        level_solver: Solves one level (default :func:`solve_level`; the same arguments, e.g.
            ``sweeping.solve_level``).
        exact_level: Gives the levels below the top their exact closest points directly instead:
            ``exact_level(k, known, below)`` with the level below's octet points (as ``octet_points``) returns this
            level's (:func:`.distance.level_distances`); the level's source ids are copied from the finest level's
            first node (a mesh's field has one).
    Returns:
        ``(neighbours, sweeps)``: the (N - N0, 6) int32 table of every coarse node's same-level face neighbours
        (node ``i`` in row ``i - N0``, -1 where none), and the fast iterative method's sweeps per level.
    """
    codes, coords, offsets, child = layout["codes"], layout["coords"], layout["offsets"], layout["child"]
    device = codes.device
    levels = len(offsets) - 1
    n, n0 = int(offsets[-1]), int(offsets[1])
    fine_dims = (np.asarray(layout["top_dims"], dtype=np.int64)) * 2 ** (levels - 1)
    neighbours = wp.full((n - n0, 6), -1, dtype=wp.int32, device=device)
    # Coarse nodes an earlier build of the same mesh and domain has keep their distances (refinement rounds).
    known = wp.zeros(n, dtype=wp.int32, device=device)
    if previous is not None:
        _take_known_coarse(previous, prev_index, (n0, n), known, (dist, proj, source), decoded)
    origin_t = tuple(float(x) for x in origin)
    sweeps = {}
    for k in range(1, levels):
        tk = time.perf_counter()
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        name = "top_level" if k == levels - 1 else f"level_{k}"
        level_neighbours(coords, lo, hi, fine_dims >> k, neighbours, n0, codes if k < levels - 1 else None)
        tn = time.perf_counter()
        if exact_level is not None and k < levels - 1:
            octet_points = exact_level(k, known, octet_points)
            source[lo:hi].fill_(int(source[:1].numpy()[0]))
            sweeps[k] = 0
            timings[f"{name}_neighbours"] = timings.get(f"{name}_neighbours", 0.0) + tn - tk
            timings[name] = timings.get(name, 0.0) + time.perf_counter() - tk
            continue
        sweeps[k] = (level_solver or solve_level)(
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
            octet_points=octet_points if k == 1 or exact_level is not None else None,
            row0=n0,
            ordered_sweeps=k == levels - 1,  # the dense top level: far from the surface, information travels far
            tolerance=top_tolerance if k == levels - 1 else 0.0,
        )
        timings[f"{name}_neighbours"] = timings.get(f"{name}_neighbours", 0.0) + tn - tk
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - tk
    return neighbours, sweeps
