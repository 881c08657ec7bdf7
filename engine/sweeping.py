"""Re-distancing: any field's values made the signed distance to its own zero surface, by sparse fast sweeping.

A boolean's values are exact only on one side of a seam (``min`` is a bound inside a union), and blends bend them
further. :func:`redistance` keeps the field's zero surface (its ``to_mesh`` triangles) and gives every node the
distance to it, with its sign: the finest band takes exact closest points on the surface's triangles (the build's
octet search, :mod:`.distance`); the coarser levels are solved level by level from the finer ones, as the build
solves them (:func:`.fim.solve_levels`), but each level's leaves by Museth's sparse and parallel fast sweeping
(:func:`solve_level`): the stored leaves sorted by the four keys i+j+k, i+j-k, i-j+k, i-j-k, swept in the 8 diagonal
orderings (each key ascending and descending), each sweep plane (nodes of one key, never face neighbours of each
other) updated in parallel. The update is the closest-point one of the build's fast iterative method (a node takes
the nearest of its face neighbours' closest points), and a bounded BVH query then makes each leaf exact.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from . import fim
from .distance import finest_distances
from .fim import nearest_projection
from .geometry import mesh_closest_point
from .octree import find_key, level_layout, match_levels, morton_decode, morton_encode, node_center
from .parallel import launch_split, run_tasks
from .sampling import LEAF_TOLERANCE, FieldArg, clamp_to_domain, locate_leaf

# Rounds of the 8 sweeps at most per level (a round that changes nothing ends the solve).
MAX_SWEEP_ROUNDS = 8


# Sweep planes with fewer nodes than this are swept one after the other in one launch (on one thread), where a
# launch per plane costs more than the plane (every CPU plane; small planes on CUDA).
PLANE_LAUNCH_MIN = 4096


# The four diagonal sort keys i + sy j + sz k: each is swept ascending and descending (8 orderings).
DIAGONALS = ((1, 1), (1, -1), (-1, 1), (-1, -1))


# ---- sweeping one level ----


@wp.kernel(enable_backward=False)
def _diagonal_keys_kernel(
    first: int,
    coords: wp.array[wp.vec3i],
    nodes: wp.array[wp.int32],
    sy: int,
    sz: int,
    shift: int,
    keys: wp.array[wp.int64],
    order: wp.array[wp.int32],
):
    """Sort key ``i + sy j + sz k + shift`` (non-negative) of node ``nodes[first + tid]``, and the node itself."""
    t = first + wp.tid()
    i = nodes[t]
    c = coords[i]
    keys[t] = wp.int64(c[0] + sy * c[1] + sz * c[2] + shift)
    order[t] = i


@wp.kernel(enable_backward=False)
def _ordered_sweep_kernel(
    order: wp.array[wp.int32],
    start: int,
    end: int,
    reverse: int,
    coords: wp.array[wp.vec3i],
    neighbours: wp.array2d[wp.int32],
    row0: int,
    origin: wp.vec3,
    spacing: float,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
    changed: wp.array[wp.int32],
    slot: int,
):
    """Sweep planes [start, end) of ``order`` (nodes sorted by a diagonal key) one after the other on one thread
    (``reverse``: from the end), each node taking the nearest of its face neighbours' closest points in place. Nodes
    of one plane are never face neighbours, so this is the plane-parallel sweep's result, node for node."""
    count = int(0)
    for t in range(end - start):
        idx = start + t
        if reverse == 1:
            idx = end - 1 - t
        i = order[idx]
        best, p, s = nearest_projection(
            node_center(origin, spacing, coords[i]), i, neighbours, row0, 0, dist, proj, source
        )
        if best < dist[i]:
            dist[i] = best
            proj[i] = p
            source[i] = s
            count += 1
    changed[slot] = changed[slot] + count


@wp.kernel(enable_backward=False)
def _plane_sweep_kernel(
    order: wp.array[wp.int32],
    start: int,
    coords: wp.array[wp.vec3i],
    neighbours: wp.array2d[wp.int32],
    row0: int,
    origin: wp.vec3,
    spacing: float,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
    changed: wp.array[wp.int32],
    slot: int,
):
    """One sweep plane, a thread per node (``order[start + tid]``): the same update, no two threads touching
    neighbouring nodes."""
    i = order[start + wp.tid()]
    best, p, s = nearest_projection(node_center(origin, spacing, coords[i]), i, neighbours, row0, 0, dist, proj, source)
    if best < dist[i]:
        dist[i] = best
        proj[i] = p
        source[i] = s
        wp.atomic_add(changed, slot, 1)


@wp.kernel(enable_backward=False)
def _dense_sweep_kernel(
    lo: int,
    dims: wp.vec3i,
    flips: wp.vec3i,
    first_child: wp.array[wp.int32],
    known: wp.array[wp.int32],
    coords: wp.array[wp.vec3i],
    neighbours: wp.array2d[wp.int32],
    row0: int,
    origin: wp.vec3,
    spacing: float,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
    changed: wp.array[wp.int32],
    slot: int,
):
    """One sweep of a dense level (nodes from ``lo``, x fastest) in one of the 8 diagonal orderings, as loops over
    z, y, x in the directions ``flips`` (1: descending): the planes i +- j +- k in order, in memory order within
    rows. Leaves not ``known`` take the update in place."""
    count = int(0)
    for kk in range(dims[2]):
        k = wp.where(flips[2] == 1, dims[2] - 1 - kk, kk)
        for jj in range(dims[1]):
            j = wp.where(flips[1] == 1, dims[1] - 1 - jj, jj)
            base = lo + dims[0] * (j + dims[1] * k)
            for ii in range(dims[0]):
                i = base + wp.where(flips[0] == 1, dims[0] - 1 - ii, ii)
                if first_child[i] < 0 and known[i] == 0:
                    best, p, s = nearest_projection(
                        node_center(origin, spacing, coords[i]), i, neighbours, row0, 0, dist, proj, source
                    )
                    if best < dist[i]:
                        dist[i] = best
                        proj[i] = p
                        source[i] = s
                        count += 1
    changed[slot] = changed[slot] + count


def sweep_dense(
    coords,
    first_child,
    known,
    neighbours,
    lo,
    dims,
    origin,
    spacing,
    dist,
    proj,
    source,
    *,
    row0=0,
    max_rounds=MAX_SWEEP_ROUNDS,
):
    """Fast sweeping of a dense level's free leaves in the 8 loop orderings, rounds until one changes nothing (or
    ``max_rounds``). Returns the sweeps run."""
    device = coords.device
    dims_v = wp.vec3i(*(int(d) for d in dims))
    origin_v = wp.vec3(*origin)
    changed = wp.zeros(8, dtype=wp.int32, device=device)
    sweeps = 0
    for _ in range(max_rounds):
        changed.zero_()
        for o in range(8):
            flips = wp.vec3i(o & 1, (o >> 1) & 1, (o >> 2) & 1)
            wp.launch(
                _dense_sweep_kernel,
                dim=1,
                inputs=[
                    lo,
                    dims_v,
                    flips,
                    first_child,
                    known,
                    coords,
                    neighbours,
                    row0,
                    origin_v,
                    float(spacing),
                    dist,
                    proj,
                    source,
                    changed,
                    o,
                ],
                device=device,
            )
            sweeps += 1
        if not changed.numpy().any():
            break
    return sweeps


def diagonal_orders(coords: wp.array, nodes: wp.array, dims) -> list:
    """The nodes sorted by each of the four diagonal keys: ``[(order, plane_starts), ...]``, ``order`` (n,) int32 node
    indices, ``plane_starts`` (P + 1,) int64 where each plane (run of one key) starts in it, ending with n."""
    n = nodes.shape[0]
    device = nodes.device
    shift = int(2 * int(np.max(dims)) + 2)
    bits = int(np.ceil(np.log2(3.0 * float(np.max(dims)) + shift + 2.0)))
    results: list = [None] * len(DIAGONALS)

    def sort(q):
        sy, sz = DIAGONALS[q]
        keys = wp.empty(2 * n, dtype=wp.int64, device=device)
        order = wp.empty(2 * n, dtype=wp.int32, device=device)
        wp.launch(_diagonal_keys_kernel, dim=n, inputs=[0, coords, nodes, sy, sz, shift, keys, order], device=device)
        wp.utils.radix_sort_pairs(keys, order, n, end_bit=max(1, min(63, bits)))
        sorted_keys = keys[:n].numpy()
        starts = np.concatenate([[0], np.flatnonzero(np.diff(sorted_keys)) + 1, [n]]).astype(np.int64)
        results[q] = (order[:n], starts)

    wp.load_module(_diagonal_keys_kernel.module, device=device)
    run_tasks([lambda q=q: sort(q) for q in range(len(DIAGONALS))], device)  # each sort on a core of its own
    return results


def sweep_nodes(
    coords,
    neighbours,
    nodes,
    dims,
    origin,
    spacing,
    dist,
    proj,
    source,
    *,
    row0=0,
    max_rounds=MAX_SWEEP_ROUNDS,
    plane_parallel=None,
):
    """Museth's sparse fast sweeping of the closest-point update over ``nodes`` (int32 node indices of one level,
    every other node fixed), in place, in rounds of the 8 diagonal orderings until a round changes nothing.

    ``plane_parallel``: launch each plane of at least ``PLANE_LAUNCH_MIN`` nodes as a parallel launch (default: on
    CUDA); smaller planes, and every plane on the CPU, run in order in one launch (the same result). Returns the
    sweeps run."""
    n = nodes.shape[0]
    if n == 0:
        return 0
    device = nodes.device
    if plane_parallel is None:
        plane_parallel = device.is_cuda
    origin_v = wp.vec3(*origin)
    orders = diagonal_orders(coords, nodes, dims)
    changed = wp.zeros(2 * len(DIAGONALS), dtype=wp.int32, device=device)
    common = [coords, neighbours, row0, origin_v, float(spacing), dist, proj, source, changed]
    sweeps = 0
    for _ in range(max_rounds):
        changed.zero_()
        for q, (order, starts) in enumerate(orders):
            for reverse in (0, 1):
                slot = 2 * q + reverse
                _sweep(order, starts, reverse, common, slot, plane_parallel, device)
                sweeps += 1
        if not changed.numpy().any():
            break
    return sweeps


def _sweep(order, starts, reverse, common, slot, plane_parallel, device):
    """One sweep of ``order`` in plane order (``reverse``: descending): runs of small planes in one ordered launch,
    large planes (``plane_parallel``) a launch each."""
    n = int(starts[-1])
    if not plane_parallel:
        wp.launch(_ordered_sweep_kernel, dim=1, inputs=[order, 0, n, reverse, *common, slot], device=device)
        return
    sizes = np.diff(starts)
    planes = range(len(sizes) - 1, -1, -1) if reverse else range(len(sizes))
    run_lo = run_hi = -1  # a run of consecutive small planes, as node range [run_lo, run_hi)

    def flush():
        if run_hi > run_lo:
            wp.launch(
                _ordered_sweep_kernel, dim=1, inputs=[order, run_lo, run_hi, reverse, *common, slot], device=device
            )

    for p in planes:
        lo, hi = int(starts[p]), int(starts[p + 1])
        if hi - lo < PLANE_LAUNCH_MIN:
            if run_hi < run_lo or run_lo < 0:
                run_lo, run_hi = lo, hi
            elif reverse:
                run_lo = lo
            else:
                run_hi = hi
            continue
        flush()
        run_lo = run_hi = -1
        wp.launch(_plane_sweep_kernel, dim=hi - lo, inputs=[order, lo, *common, slot], device=device)
    flush()


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
    octet_points=None,
    row0=0,
    ordered_sweeps=False,
    tolerance=0.0,
    plane_parallel=None,
    dims=None,
    max_rounds=None,
):
    """:func:`.fim.solve_level` with the leaves solved by sparse fast sweeping (:func:`sweep_nodes`) instead of the
    fast iterative method: the same arguments (``ordered_sweeps`` is not needed: every sweep is ordered) and result.
    ``dims``: the level's extent in nodes (default: from the coordinates)."""
    n = hi - lo
    if n == 0:
        return 0
    device = coords.device
    if known is None:
        known = wp.zeros(dist.shape[0], dtype=wp.int32, device=device)
    fim.init_level(coords, first_child, lo, hi, origin, spacing, dist, proj, source, mesh_id, known, octet_points)
    if dims is None:
        dims = coords[lo:hi].numpy().max(axis=0) + 1
    if max_rounds is None:  # a BVH refinement follows: one round gives it its bound
        max_rounds = 1 if mesh_id else MAX_SWEEP_ROUNDS
    if ordered_sweeps and not device.is_cuda:
        sweeps = sweep_dense(
            coords,
            first_child,
            known,
            neighbours,
            lo,
            dims,
            origin,
            spacing,
            dist,
            proj,
            source,
            row0=row0,
            max_rounds=max_rounds,
        )
    else:
        free = (first_child[lo:hi].numpy() < 0) & (known[lo:hi].numpy() == 0)
        nodes = wp.array(lo + np.flatnonzero(free).astype(np.int32), dtype=wp.int32, device=device)
        sweeps = sweep_nodes(
            coords,
            neighbours,
            nodes,
            dims,
            origin,
            spacing,
            dist,
            proj,
            source,
            row0=row0,
            plane_parallel=plane_parallel,
            max_rounds=max_rounds,
        )
    origin_v = wp.vec3(*origin)
    fim.refine_leaves(coords, first_child, lo, n, origin_v, spacing, mesh_id, known, dist, proj, device, tolerance)
    return sweeps


# ---- re-distancing a field ----

# Finest octets are kept where some node is within this many voxels of the surface (as a boolean keeps them).
KEEP_BAND = 2.5


@wp.kernel(enable_backward=False)
def _near_octets_kernel(
    first: int,
    mesh: wp.uint64,
    codes: wp.array[wp.int64],
    origin: wp.vec3,
    spacing: float,
    radius: float,
    keep: wp.array[wp.int32],
):
    """Whether finest octet ``first + tid`` (its first node ``8 * (first + tid)``) has its centre within ``radius`` of
    the surface."""
    t = first + wp.tid()
    q = morton_decode(codes[8 * t] >> wp.int64(3))
    c = origin + 2.0 * spacing * wp.vec3(float(q[0]) + 0.5, float(q[1]) + 0.5, float(q[2]) + 0.5)
    found, p = mesh_closest_point(mesh, c, radius)
    keep[t] = wp.where(found, 1, 0)


@wp.kernel(enable_backward=False)
def _interface_nodes_kernel(
    first: int,
    coords: wp.array[wp.vec3i],
    codes: wp.array[wp.int64],
    n0: int,
    dense: wp.vec3i,
    values: wp.array[wp.float32],
    interface: wp.array[wp.int32],
):
    """Whether finest node ``first + tid`` ends an edge the surface crosses: a face neighbour of the other sign,
    found by its code among the ``n0`` finest (sorted), or on a dense level (``dense``: its dims) by index."""
    i = first + wp.tid()
    c = coords[i]
    neg = values[i] < 0.0
    interface[i] = 0
    for a in range(3):
        for s in range(2):
            q = c
            q[a] = q[a] + 2 * s - 1
            if q[a] >= 0:
                j = int(-1)
                if dense[0] > 0:
                    if q[a] < dense[a]:
                        j = q[0] + dense[0] * (q[1] + dense[1] * q[2])
                else:
                    j = find_key(codes, 0, n0, morton_encode(q))
                if j >= 0:
                    if (values[j] < 0.0) != neg:
                        interface[i] = 1


@wp.kernel(enable_backward=False)
def _sign_and_source_kernel(
    first: int,
    old: FieldArg,
    where: wp.array[wp.int32],
    interface: wp.array[wp.int32],
    spacing: float,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    values: wp.array[wp.float32],
    source: wp.array[wp.int32],
):
    """Node ``first + tid`` (node ``where[i]`` of the old field) takes its new distance with its old value's sign
    (its side of the surface), and the source id the old field has where its closest point lies. A finest node that
    ends an edge the surface crosses keeps its old value, so the surface stays where it was, and a closest point
    consistent with it: its old one where that was (a build's, on the mesh's own sharp edges), else the point that
    far along the surface's normal."""
    i = first + wp.tid()
    j = where[i]
    v = old.values[j]
    values[i] = wp.where(v < 0.0, -dist[i], dist[i])
    source[i] = old.source[locate_leaf(old, clamp_to_domain(old, proj[i]))[0]]
    if j < old.fine_count:
        if interface[j] == 1:
            values[i] = v
            x = node_center(old.origin, spacing, old.coords[j])
            p = old.proj[j]
            if wp.abs(wp.length(x - p) - wp.abs(v)) > 1.0e-4 * spacing + 1.0e-5 * wp.abs(v):
                n = x - proj[i]
                ln = wp.length(n)
                p = x - wp.where(ln > 0.0, (wp.abs(v) / wp.max(ln, 1.0e-30)) * n, wp.vec3(0.0))
            proj[i] = p


def surface_mesh(field):
    """``wp.Mesh`` (a BVH, no winding numbers) of the field's ``to_mesh`` surface, and its (V, 3) float32 vertices
    and (T, 3) int32 triangles; None for the mesh when the field has no surface."""
    verts, tris = field.to_mesh()
    if len(tris) == 0:
        return None, verts, tris
    mesh = wp.Mesh(
        points=wp.array(verts, dtype=wp.vec3, device=field.device),
        indices=wp.array(tris.reshape(-1), dtype=wp.int32, device=field.device),
    )
    return mesh, verts, tris


def _near_band(field, mesh, timings) -> dict:
    """The layout of ``field``'s domain whose finest octets are those of ``field`` with a node within ``KEEP_BAND``
    voxels of the surface ``mesh`` (a blend's dilated band, say, carries far more)."""
    device, h = field.device, field.voxel_size
    octets = None
    if field.levels > 1:
        n_oct = field.level_counts[0] // 8
        keep = wp.empty(n_oct, dtype=wp.int32, device=device)
        radius = (KEEP_BAND + 0.5 * np.sqrt(3.0)) * h  # an octet's centre is within half a diagonal of its nodes
        origin_v = wp.vec3(*field.origin)
        launch_split(
            _near_octets_kernel, n_oct, lambda s, _n: [s, mesh.id, field.codes, origin_v, h, radius, keep], device
        )
        kept = np.flatnonzero(keep.numpy())
        octets = wp.array(field.codes.numpy()[8 * kept] >> 3, dtype=wp.int64, device=device)
    return level_layout(octets, field.top_dims, field.levels, device, timings)


def redistance(field, *, method: str = "sweep", top_tolerance: float = 0.0):
    """The field's values replaced by the signed distance to its own zero surface (its ``to_mesh`` triangles).

    The surface stays where it is: the finest nodes at the ends of edges it crosses keep their values (so
    ``to_mesh`` gives the same triangles), every other node takes its exact distance to the surface with its old
    sign. The finest band is rebuilt around the surface (octets with a node within ``KEEP_BAND`` voxels of it), the
    coarser levels solved from it level by level.

    Args:
        field: AdaptiveField, e.g. a boolean or blend result whose values are bounds rather than distances.
        method: How each coarser level's leaves get their first estimate before a bounded BVH query makes them
            exact: ``"sweep"`` (sparse fast sweeping, :func:`solve_level`) or ``"fim"`` (the build's fast iterative
            method). The same result; see :func:`solve_level` for which is faster where.
        top_tolerance: Relative error allowed to the closest points of the dense top level's leaves (0: exact; the
            build allows ``LEAF_TOLERANCE``).
    Returns:
        AdaptiveField on the same domain and levels: values the signed distance to the surface, ``proj`` each node's
        closest surface point, ``source`` the id the field had there; ``stats["exact_distance"]`` True. A field
        without surface comes back as it is.
    Raises:
        TypeError: If ``field`` is not an AdaptiveField.
        ValueError: If ``method`` is unknown or ``top_tolerance`` is not in [0, LEAF_TOLERANCE].
    """
    if not callable(getattr(field, "arg", None)) or not hasattr(field, "level_offsets"):
        raise TypeError(f"Expected 'field' to be an AdaptiveField, but got {type(field).__name__}.")
    if method not in ("sweep", "fim"):
        raise ValueError(f"Expected 'method' to be 'sweep' or 'fim', but got {method!r}.")
    if not 0.0 <= float(top_tolerance) <= LEAF_TOLERANCE:
        raise ValueError(f"Expected 'top_tolerance' in [0, {LEAF_TOLERANCE}], but got {top_tolerance}.")
    timings = {}
    t0 = time.perf_counter()
    mesh, _verts, tris = surface_mesh(field)
    timings["surface"] = time.perf_counter() - t0
    if mesh is None:
        return field
    device, h, levels = field.device, field.voxel_size, field.levels
    t0 = time.perf_counter()
    layout = _near_band(field, mesh, timings)
    where = match_levels(layout["codes"], layout["offsets"], field)
    timings["band"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    diag = float(np.linalg.norm(field.fine_dims * h))
    dist, proj, source, octet_points = finest_distances(
        mesh.id,
        layout,
        origin=field.origin,
        voxel_size=h,
        query_radius=(KEEP_BAND + np.sqrt(3.0) + 0.5) * h if levels > 1 else diag,
        far_dist=diag,
        field_id=field.field_ids[0],
        box_search=True,
    )
    timings["finest_distance"] = time.perf_counter() - t0
    sweeps = {}
    if levels > 1:
        _neighbours, sweeps = fim.solve_levels(
            mesh.id,
            layout,
            dist,
            proj,
            source,
            origin=field.origin,
            voxel_size=h,
            top_tolerance=float(top_tolerance),
            octet_points=octet_points,
            timings=timings,
            level_solver=solve_level if method == "sweep" else None,
        )
    t0 = time.perf_counter()
    n, n_old0 = int(layout["offsets"][-1]), field.level_counts[0]
    interface = wp.empty(n_old0, dtype=wp.int32, device=device)
    dense = wp.vec3i(*(int(d) for d in field.top_dims)) if levels == 1 else wp.vec3i(0, 0, 0)
    launch_split(
        _interface_nodes_kernel,
        n_old0,
        lambda s, _n: [s, field.coords, field.codes, n_old0, dense, field.values, interface],
        device,
    )
    values = wp.empty(n, dtype=wp.float32, device=device)
    old = field.arg()
    launch_split(
        _sign_and_source_kernel, n, lambda s, _n: [s, old, where, interface, h, dist, proj, values, source], device
    )
    timings["signs"] = time.perf_counter() - t0
    return type(field).from_layout(
        layout,
        voxel_size=h,
        origin=field.origin,
        values=values,
        proj=proj,
        source=source,
        field_ids=field.field_ids,
        timings=timings,
        stats={"sweeps": sweeps, "surface_triangles": len(tris), "exact_distance": True},
    )
