"""The edges of an extracted surface, found in kernels: what a mesh datablock needs besides its triangles.

A closed, consistently oriented 2-manifold triangle surface (what :meth:`.field.AdaptiveField.to_mesh` returns) lists
every edge twice, once in each direction. The edge takes the id of its low -> high half (numbered in corner order),
the high -> low half finds it among the low vertex's few outgoing halves. Written by hand because the general answers
(one sort of 3F keys, as :func:`.meshcheck.edge_table` does on the host, or Blender's own edge derivation) cost about
twice as much on the surfaces the add-on writes: a 590 k-triangle surface's edges take Blender 85-97 ms, these kernels
and writing their result into the mesh 40-46 ms.
Anything else (an open or non-manifold surface, a flipped face) is reported, not guessed: the caller then lets Blender
derive the edges.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .parallel import host_view, launch_split


@wp.kernel(enable_backward=False)
def _count_kernel(tris: wp.array2d[wp.int32], out_count: wp.array[wp.int32], tri_count: wp.array[wp.int32]):
    """Per triangle: its low -> high halves, counted per low vertex and per triangle."""
    t = wp.tid()
    n = int(0)
    for k in range(3):
        u = tris[t, k]
        v = tris[t, (k + 1) % 3]
        if u < v:
            wp.atomic_add(out_count, u, 1)
            n += 1
    tri_count[t] = n


@wp.kernel(enable_backward=False)
def _fill_kernel(
    tris: wp.array2d[wp.int32],
    tri_first: wp.array[wp.int32],
    cursor: wp.array[wp.int32],
    slots: wp.array[wp.vec2i],
    edge_verts: wp.array2d[wp.int32],
    corner_edge: wp.array[wp.int32],
):
    """Per triangle: its low -> high halves numbered in corner order, listed under their low vertex as (high vertex,
    edge)."""
    t = wp.tid()
    e = tri_first[t]
    for k in range(3):
        u = tris[t, k]
        v = tris[t, (k + 1) % 3]
        if u < v:
            slots[wp.atomic_add(cursor, u, 1)] = wp.vec2i(v, e)
            edge_verts[e, 0] = u
            edge_verts[e, 1] = v
            corner_edge[3 * t + k] = e
            e += 1


@wp.kernel(enable_backward=False)
def _twin_kernel(
    tris: wp.array2d[wp.int32],
    first: int,
    start: wp.array[wp.int32],
    out_count: wp.array[wp.int32],
    slots: wp.array[wp.vec2i],
    corner_edge: wp.array[wp.int32],
    matched: wp.array[wp.uint8],
    bad: wp.array[wp.int32],
):
    """Per triangle (from ``first``): each high -> low half takes the edge of its twin and marks it ``matched``; a
    half without exactly one twin (or a degenerate one) marks the surface ``bad``. No atomics (the launch may be split
    across CPU threads): with as many high -> low halves as edges, an edge two halves took leaves another unmatched."""
    t = first + wp.tid()
    for k in range(3):
        u = tris[t, k]
        v = tris[t, (k + 1) % 3]
        if u == v:
            bad[0] = 1
        elif u > v:
            found = int(-1)
            hits = int(0)
            for s in range(start[v], start[v] + out_count[v]):
                slot = slots[s]
                if slot[0] == u:
                    found = slot[1]
                    hits += 1
            if hits == 1:
                corner_edge[3 * t + k] = found
                matched[found] = wp.uint8(1)
            else:
                bad[0] = 1


def surface_edges(tris: np.ndarray, vertex_count: int, device=None) -> tuple[np.ndarray, np.ndarray] | None:
    """The edges of a closed, consistently oriented 2-manifold triangle surface.

    Args:
        tris: (F, 3) int triangles, indices below ``vertex_count``.
        vertex_count: How many vertices the surface has.
        device: Warp device (default: Warp's default).
    Returns:
        ``(edge_verts, corner_edge)``: (E, 2) int32 vertex pairs (low, high), and (3F,) int32 the edge from each corner
        to the next corner of its triangle (Blender's ``.edge_verts`` and ``.corner_edge``); ``None`` when the surface
        is not such a surface (an edge with one face or more than two, a face flipped against its neighbour).
    """
    tris = np.ascontiguousarray(tris, dtype=np.int32).reshape(-1, 3)
    if not len(tris):
        return None
    device = wp.get_device(device)
    t = host_view(tris, wp.int32, device)
    n = len(tris)
    out_count = wp.zeros(vertex_count, dtype=wp.int32, device=device)
    tri_count = wp.empty(n, dtype=wp.int32, device=device)
    wp.launch(_count_kernel, n, inputs=[t, out_count, tri_count], device=device)
    start = wp.empty(vertex_count, dtype=wp.int32, device=device)
    wp.utils.array_scan(out_count, start, inclusive=False)
    tri_first = wp.empty(n, dtype=wp.int32, device=device)
    wp.utils.array_scan(tri_count, tri_first, inclusive=False)
    edges = int(tri_first[n - 1 : n].numpy()[0] + tri_count[n - 1 : n].numpy()[0])
    if 2 * edges != 3 * n:  # a closed 2-manifold lists each edge once in each direction
        return None
    slots = wp.empty(edges, dtype=wp.vec2i, device=device)
    edge_verts = wp.empty((edges, 2), dtype=wp.int32, device=device)
    corner_edge = wp.empty(3 * n, dtype=wp.int32, device=device)
    cursor = wp.clone(start)
    wp.launch(_fill_kernel, n, inputs=[t, tri_first, cursor, slots, edge_verts, corner_edge], device=device)
    matched = wp.zeros(edges, dtype=wp.uint8, device=device)
    bad = wp.zeros(1, dtype=wp.int32, device=device)
    launch_split(
        _twin_kernel,
        n,
        lambda first, count: [t, first, start, out_count, slots, corner_edge, matched, bad],
        device,
    )
    if bad.numpy()[0] or not matched.numpy().all():
        return None
    return edge_verts.numpy(), corner_edge.numpy()


@wp.kernel(enable_backward=False)
def _edge_faces_kernel(tris: wp.array2d[wp.int32], corner_edge: wp.array[wp.int32], faces: wp.array2d[wp.int32]):
    """Per triangle: each corner's edge records the triangle, as its low -> high face (column 0) or its high -> low
    one (column 1): one of each on a closed, consistently oriented surface, so no two threads write one slot."""
    t = wp.tid()
    for k in range(3):
        side = wp.where(tris[t, k] < tris[t, (k + 1) % 3], 0, 1)
        faces[corner_edge[3 * t + k], side] = t


@wp.func
def _unit_normal(points: wp.array[wp.vec3d], tris: wp.array2d[wp.int32], t: int) -> wp.vec3d:
    """Triangle ``t``'s unit normal, as numpy finds it (the cross product's terms and the squares summed in order)."""
    a = points[tris[t, 0]]
    e = points[tris[t, 1]] - a
    f = points[tris[t, 2]] - a
    n = wp.vec3d(e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0])
    size = wp.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    return n / wp.max(size, wp.float64(1.0e-300))


@wp.kernel(enable_backward=False)
def _folds_kernel(
    points: wp.array[wp.vec3d],
    tris: wp.array2d[wp.int32],
    faces: wp.array2d[wp.int32],
    least: wp.float64,
    fold: wp.array[wp.uint8],
):
    """Per edge: 1 where the unit normals of its two faces (the lower-numbered first) meet at a cosine under
    ``least``."""
    i = wp.tid()
    p = _unit_normal(points, tris, wp.min(faces[i, 0], faces[i, 1]))
    q = _unit_normal(points, tris, wp.max(faces[i, 0], faces[i, 1]))
    fold[i] = wp.uint8(wp.where(p[0] * q[0] + p[1] * q[1] + p[2] * q[2] < least, 1, 0))


def fold_edges(verts: np.ndarray, tris: np.ndarray, degrees: float = 30.0, device=None, edges=None) -> np.ndarray:
    """The edges of a closed, consistently oriented surface along which it folds by more than ``degrees``: the
    creases of a surface whose faces were not placed on tangent planes (kept faces joined to a voxel surface). In
    kernels on the host's arrays (numpy's gathers of 167 k triangles' corners and of 250 k edges' normals took 30-45 ms,
    a stable sort of the corners by edge as many again).

    Args:
        verts: (V, 3) float vertices; tris: (F, 3) int triangles; degrees: The least fold of a crease.
        edges: :func:`surface_edges` of ``tris``, where found already (None: found here).
    Returns:
        (E, 2) int32 vertex pairs (low, high); empty when the surface is not closed and oriented.
    """
    found = surface_edges(tris, len(verts), device) if edges is None else edges
    if found is None:
        return np.zeros((0, 2), dtype=np.int32)
    edge_verts, corner_edge = found
    edge_verts = np.asarray(edge_verts).reshape(-1, 2)
    cpu = wp.get_device("cpu")
    t = host_view(np.ascontiguousarray(tris, dtype=np.int32).reshape(-1, 3), wp.int32, cpu)
    points = host_view(np.ascontiguousarray(verts, dtype=np.float64), wp.vec3d, cpu)
    faces = np.empty((len(edge_verts), 2), dtype=np.int32)
    fold = np.empty(len(edge_verts), dtype=np.uint8)
    w_faces, w_fold = host_view(faces, wp.int32, cpu), host_view(fold, wp.uint8, cpu)
    w_corner_edge = host_view(np.ascontiguousarray(corner_edge, dtype=np.int32), wp.int32, cpu)
    wp.launch(_edge_faces_kernel, dim=t.shape[0], inputs=[t, w_corner_edge, w_faces], device=cpu)
    least = wp.float64(np.cos(np.radians(degrees)))
    launch_split(
        _folds_kernel, len(edge_verts), lambda lo, k: [points, t, w_faces[lo : lo + k], least, w_fold[lo : lo + k]], cpu
    )
    return np.ascontiguousarray(edge_verts[fold > 0], dtype=np.int32)
