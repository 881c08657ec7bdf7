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


def fold_edges(verts: np.ndarray, tris: np.ndarray, degrees: float = 30.0, device=None) -> np.ndarray:
    """The edges of a closed, consistently oriented surface along which it folds by more than ``degrees``: the
    creases of a surface whose faces were not placed on tangent planes (kept faces joined to a voxel surface).

    Args:
        verts: (V, 3) float vertices; tris: (F, 3) int triangles; degrees: The least fold of a crease.
    Returns:
        (E, 2) int32 vertex pairs (low, high); empty when the surface is not closed and oriented.
    """
    found = surface_edges(tris, len(verts), device)
    if found is None:
        return np.zeros((0, 2), dtype=np.int32)
    edge_verts, corner_edge = found
    t = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    v = np.asarray(verts, dtype=np.float64)
    normals = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    order = np.argsort(corner_edge, kind="stable")  # each edge's two corners side by side
    faces = (order // 3).reshape(-1, 2)
    folds = np.einsum("ij,ij->i", normals[faces[:, 0]], normals[faces[:, 1]]) < np.cos(np.radians(degrees))
    edge_of_pair = corner_edge[order].reshape(-1, 2)[:, 0]
    return np.ascontiguousarray(edge_verts.reshape(-1, 2)[edge_of_pair[folds]], dtype=np.int32)
