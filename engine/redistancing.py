"""Re-distancing: any field's values made the signed distance to its own zero surface.

A boolean's values are exact only on one side of a seam (``min`` is a bound inside a union), and blends bend them
further. :func:`redistance` keeps the field's zero surface (its ``to_mesh`` triangles) and gives every node the
distance to it, with its sign: the finest band is rebuilt around the surface and takes exact closest points on its
triangles (the build's octet search, :mod:`.distance`), but for the nodes at the ends of edges the surface crosses,
which keep their values (so the surface does not move); the coarser levels are solved level by level from the finer
ones, as the build solves them (:func:`.fim.solve_levels`): the dense top level's leaves by fast sweeping, the
sparse levels' by the fast iterative method (:func:`.sweeping.solve_level`, which measures both), and each leaf then
by a bounded BVH query.
"""

from __future__ import annotations

import functools
import time

import numpy as np
import warp as wp

from . import fim
from .distance import finest_distances
from .geometry import mesh_closest_point
from .layout import level_layout, match_levels
from .octree import find_key, morton_decode, morton_encode, node_center
from .ondemand import refined
from .parallel import launch_split
from .sampling import LEAF_TOLERANCE, FieldArg, clamp_to_domain, locate_leaf, node_source
from .search import OctetSearch
from .sweeping import solve_level

# Finest octets are kept where some node is within this many voxels of the surface (as a boolean keeps them).
KEEP_BAND = 2.5


# How :func:`.sweeping.solve_level` solves the sparse levels for each method.
SPARSE_SOLVERS = {"sweep": "fim", "diagonal": "diagonal"}


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
    where: wp.array[wp.int32],
    old_values: wp.array[wp.float32],
    interface: wp.array[wp.int32],
):
    """Whether finest node ``first + tid`` (of the re-distanced layout; node ``where[i]`` of the old field) ends an
    edge the surface crosses: a face neighbour of the other sign in the old field. Neighbours across such an edge
    both lie within a voxel diagonal of the surface, so both are in the kept band: found there, in the node's own
    octet by index, across its faces by code among the ``n0`` finest (sorted), or on a dense level (``dense``: its
    dims) by index."""
    i = first + wp.tid()
    c = coords[i]
    neg = old_values[where[i]] < 0.0
    interface[i] = 0
    for a in range(3):
        for s in range(2):
            q = c
            q[a] = q[a] + 2 * s - 1
            j = int(-1)
            if dense[0] > 0:
                if q[a] >= 0 and q[a] < dense[a]:
                    j = q[0] + dense[0] * (q[1] + dense[1] * q[2])
            elif (c[a] & 1) != s:  # the neighbour in the same octet
                j = i + wp.where(s == 1, 1, -1) * (1 << a)
            elif q[a] >= 0:
                j = find_key(codes, 0, n0, morton_encode(q))
            if j >= 0:
                if (old_values[where[j]] < 0.0) != neg:
                    interface[i] = 1


@wp.kernel(enable_backward=False)
def _interface_ratios_kernel(
    first: int,
    old: FieldArg,
    where: wp.array[wp.int32],
    interface: wp.array[wp.int32],
    dist: wp.array[wp.float32],
    ratios: wp.array[wp.float32],
):
    """Distance over old value's magnitude at finest node ``first + tid`` where it ends an edge the surface crosses
    (-1 elsewhere)."""
    i = first + wp.tid()
    j = where[i]
    ratios[i] = -1.0
    if interface[i] == 1:
        v = wp.abs(old.values[j])
        if v > 0.0:
            ratios[i] = dist[i] / v


@wp.func
def _old_side(old: FieldArg, j: int, spacing: float) -> float:
    """Old node ``j``'s value, or where it has children (a parent's value is what its level read of a boolean's
    operands, whose sign may be wrong a few voxels off the surface: a rocker arm chamfered with itself) the value of
    the leaf that holds its centre: its side of the surface (a finest leaf's centre lies within a voxel of it, and a
    node that stays a leaf lies farther than that from the surface)."""
    v = old.values[j]
    if j >= old.fine_count:
        if old.child[j - old.fine_count] >= 0:
            v = old.values[locate_leaf(old, node_center(old.origin, spacing, morton_decode(old.codes[j])))[0]]
    return v


@wp.kernel(enable_backward=False)
def _sign_and_source_kernel(
    first: int,
    old: FieldArg,
    where: wp.array[wp.int32],
    interface: wp.array[wp.int32],
    scale: float,
    spacing: wp.array[wp.float32],
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    values: wp.array[wp.float32],
    source: wp.array[wp.int32],
):
    """Node ``first + tid`` (node ``where[i]`` of the old field, ``spacing[i]`` its level's) takes its new distance
    with its old side's sign (:func:`_old_side`), and the source id the old field has where its closest point lies. A
    finest node that ends an edge the surface crosses keeps its old value times ``scale`` (one factor for all: where
    the surface crosses an edge depends only on the ratio of its ends' values), so the surface stays where it was;
    its closest point is on the surface all the same (what reads closest points takes them for surface points)."""
    i = first + wp.tid()
    j = where[i]
    v = _old_side(old, j, spacing[i])
    values[i] = wp.where(v < 0.0, -dist[i], dist[i])
    if i < interface.shape[0]:
        if interface[i] == 1:
            values[i] = v * scale
    source[i] = node_source(old, locate_leaf(old, clamp_to_domain(old, proj[i]))[0])


def _signed(field, layout: dict, where, found: tuple):
    """The new layout's values (its distances ``found``: ``(dist, proj, source)``, ``source`` set in place) signed as
    the old ``field`` has them where ``where`` matches its nodes (:func:`_sign_and_source_kernel`), and the scale of
    the values kept at the surface's edges."""
    dist, proj, source = found
    n, old, h = int(layout["offsets"][-1]), field.arg(), field.voxel_size
    interface, scale = _interface(field, layout, where, dist)
    values = wp.empty(n, dtype=wp.float32, device=field.device)
    counts = np.diff(np.asarray(layout["offsets"], dtype=np.int64))
    spacing = wp.array(np.repeat(h * 2.0 ** np.arange(len(counts)), counts).astype(np.float32), device=field.device)
    launch_split(
        _sign_and_source_kernel,
        n,
        lambda s, _n: [s, old, where, interface, scale, spacing, dist, proj, values, source],
        field.device,
    )
    return values, scale


def surface_mesh(field):
    """``wp.Mesh`` (a BVH, no winding numbers) of the field's ``to_mesh`` surface, and its (V, 3) float32 vertices
    and (T, 3) int32 triangles; None for the mesh when the field has no surface."""
    verts, tris = field.to_mesh(sharp=False)
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


def _interface(field, layout: dict, where, dist) -> tuple:
    """The finest nodes at the ends of edges the surface crosses (``_interface_nodes_kernel``), and the factor that
    makes their old values distances (the median of distance over value there: 1 for a field of distances, a scaled
    field's scale)."""
    device, n0 = field.device, int(layout["offsets"][1])
    interface = wp.empty(n0, dtype=wp.int32, device=device)
    dense = wp.vec3i(*(int(d) for d in field.top_dims)) if field.levels == 1 else wp.vec3i(0, 0, 0)
    launch_split(
        _interface_nodes_kernel,
        n0,
        lambda s, _n: [s, layout["coords"], layout["codes"], n0, dense, where, field.values, interface],
        device,
    )
    old = field.arg()
    ratios = wp.empty(n0, dtype=wp.float32, device=device)
    launch_split(_interface_ratios_kernel, n0, lambda s, _n: [s, old, where, interface, dist, ratios], device)
    ratios_np = ratios.numpy()
    return interface, float(np.median(ratios_np[ratios_np >= 0.0])) if (ratios_np >= 0.0).any() else 1.0


def redistance(field, *, method: str = "sweep", top_tolerance: float = LEAF_TOLERANCE, surface=None):
    """The field's values replaced by the signed distance to its own zero surface (its ``to_mesh`` triangles).

    The surface stays where it is: the finest nodes at the ends of edges it crosses keep their values up to one
    common factor (the median of distance over value there: 1 for a field of distances, and a field scaled as a whole
    comes back to distances), so ``to_mesh`` gives the same triangles; every other node takes its exact distance to
    the surface with its old sign (a node that had children, the sign of the leaf that held its centre). The finest
    band is rebuilt around the surface (octets with a node within ``KEEP_BAND`` voxels of it), the coarser levels
    solved from it level by level.

    Args:
        field: AdaptiveField, e.g. a boolean or blend result whose values are bounds rather than distances.
        method: How each coarser level's leaves get their first estimate before a bounded BVH query makes them
            exact (the same result; :mod:`.sweeping` measures which is faster where): ``"sweep"`` (the dense top
            level by fast sweeping in the 8 diagonal orderings, the sparse levels by the fast iterative method),
            ``"diagonal"`` (Museth's sparse sweeping, sorted by the keys i+-j+-k, on every level) or ``"fim"`` (the
            build's fast iterative method throughout).
        top_tolerance: Relative error allowed to the closest points of the dense top level's leaves, as the build
            allows (0: exact; a large top level's exact queries cost 4x: (spot | fandisk) - sphere with 3 levels at
            /256, 0.17 -> 0.75 s, for a far p95 error of 0.04 % instead of 0.10 %).
        surface: Its :func:`surface_mesh`, when made already.
    Returns:
        AdaptiveField on the same domain and levels: values the signed distance to the surface, ``proj`` each node's
        closest surface point, ``source`` the id the field had there; ``stats["exact_distance"]`` and
        ``stats["surface_points"]`` True. A field without surface comes back as it is.
    Raises:
        TypeError: If ``field`` is not an AdaptiveField.
        ValueError: If ``method`` is unknown or ``top_tolerance`` is not in [0, LEAF_TOLERANCE].
    """
    if not callable(getattr(field, "arg", None)) or not hasattr(field, "level_offsets"):
        raise TypeError(f"Expected 'field' to be an AdaptiveField, but got {type(field).__name__}.")
    if method not in ("sweep", "diagonal", "fim"):
        raise ValueError(f"Expected 'method' to be 'sweep', 'diagonal' or 'fim', but got {method!r}.")
    if not 0.0 <= float(top_tolerance) <= LEAF_TOLERANCE:
        raise ValueError(f"Expected 'top_tolerance' in [0, {LEAF_TOLERANCE}], but got {top_tolerance}.")
    field = refined(field, view=True)  # built on demand: its whole band (:mod:`.ondemand`)
    timings = {}
    t0 = time.perf_counter()
    mesh, _verts, tris = surface_mesh(field) if surface is None else surface
    timings["surface"] = time.perf_counter() - t0
    if mesh is None:
        return field
    h, levels = field.voxel_size, field.levels
    t0 = time.perf_counter()
    layout = _near_band(field, mesh, timings)
    where = match_levels(layout["codes"], layout["offsets"], field)
    timings["band"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    diag = float(np.linalg.norm(field.fine_dims * h))
    radius = (KEEP_BAND + np.sqrt(3.0) + 0.5) * h if levels > 1 else diag
    dist, proj, source, _tri, octet_points = finest_distances(
        OctetSearch(mesh.id, radius, diag, True), layout, origin=field.origin, voxel_size=h, field_id=field.field_ids[0]
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
            level_solver=None if method == "fim" else functools.partial(solve_level, sparse=SPARSE_SOLVERS[method]),
        )
    t0 = time.perf_counter()
    values, scale = _signed(field, layout, where, (dist, proj, source))
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
        stats={
            "sweeps": sweeps,
            "surface_triangles": len(tris),
            "interface_scale": scale,
            "exact_distance": True,
            "surface_points": True,
        },
    )
