"""Thin holes in the kept faces closed by themselves: a slit no voxel surface fits into.

The judge (:mod:`.keep`) leaves holes in the kept faces where a row of triangles is not the surface, or lies too
near a defect of the mesh: along a thin shell's crease, around a short open edge. Where such a hole is narrower than
the voxel surface's reach over the kept faces (:func:`.zipper.vertices_over`), the voxel surface has nothing left
inside it, and the hole's border loop pairs with no voxel loop, or with a scrap of one that its strip stretches to.
Rather than give up the kept faces around it, a ring at a time (a low-polygon mesh's ring is a large share of its
area), such a loop is closed by a strip across itself: two walks from the loop vertex farthest from its centre, one
along the loop and one against it, each step the shorter diagonal, as :func:`.zipper.zip_loops` steps between two
loops. The strip is taken when every diagonal is at most ``FILL_VOXELS`` long (the hole is a slit, not a cap) and it
faces the way the kept faces around it do (the loop is a hole, not a piece's outer border). Its triangles are new
faces on the loop's own vertices: no new vertex, no T-junction.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .adaptive import row_sums
from .meshcheck import any_corner
from .samples import triangle_samples

# A slit's strip has diagonals at most this many voxels long; a wider hole's, at most WIDE_VOXELS, where it lies
# within ON_VOXELS of the result's zero level all over (Suzanne's holes about its eyes and ears, where the voxel surface
# left inside is a scrap: shares with a ball 0.950 -> 0.955 with WIDE_VOXELS 6 -> 10).
FILL_VOXELS = 2.0
WIDE_VOXELS = 10.0
ON_VOXELS = 0.5


@wp.kernel(enable_backward=False)
def _fill_kernel(
    points: wp.array[wp.vec3],
    nxt: wp.array[wp.int32],
    prv: wp.array[wp.int32],
    start: wp.array[wp.int32],
    count: wp.array[wp.int32],
    first: wp.array[wp.int32],
    tris: wp.array[wp.vec3i],
    longest: wp.array[wp.float32],
):
    """One strip per loop: ``i`` walks the loop from its start as the kept faces list it, ``j`` against it from the
    vertex before; each step takes the shorter of the two next diagonals; the longest diagonal is kept per loop."""
    k = wp.tid()
    i = start[k]
    j = prv[i]
    out = first[k]
    most = float(0.0)
    for _ in range(count[k] - 2):
        ni = nxt[i]
        pj = prv[j]
        a = wp.length(points[ni] - points[j])
        b = wp.length(points[i] - points[pj])
        if a <= b:
            tris[out] = wp.vec3i(ni, i, j)
            i = ni
            most = wp.max(most, a)
        else:
            tris[out] = wp.vec3i(j, pj, i)
            j = pj
            most = wp.max(most, b)
        out += 1
    longest[k] = most


def _starts(points, members, labels, loops) -> np.ndarray:
    """Per loop (sorted labels ``loops``): its member farthest from the loop's centre (a slit's tip)."""
    rank = np.searchsorted(loops, labels)
    counts = np.bincount(rank, minlength=len(loops)).astype(np.float64)[:, None]
    centre = row_sums(rank, points[members], len(loops))
    far = np.linalg.norm(points[members] - (centre / counts)[rank], axis=1)
    order = np.lexsort((-far, rank))
    return members[order[np.r_[True, rank[order][1:] != rank[order][:-1]]]]


def _facing(points, tris, loop_of, kept_tris, halves, halves_loop, n_loops: int) -> np.ndarray:
    """(L,) float64: per loop, its strip's area vector dotted with the area vectors of the kept faces along it."""

    def area_vectors(t):
        p = points[t].astype(np.float64)
        return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])

    strip = row_sums(loop_of, area_vectors(tris), n_loops)
    # the kept face of each border half: the one listing that directed edge (among the faces at the halves' starts)
    n = len(points)
    start = np.zeros(n, dtype=bool)
    start[halves[:, 0]] = True
    t = np.asarray(kept_tris, dtype=np.int64)
    t = t[any_corner(start, t)]
    keys = t.ravel() * n + t[:, [1, 2, 0]].ravel()
    order = np.argsort(keys)
    at = order[np.searchsorted(keys[order], halves[:, 0] * n + halves[:, 1])] // 3
    kept = area_vectors(t[at])
    around = row_sums(halves_loop, kept, n_loops)
    return (strip * around).sum(axis=1)


def fill_slits(points, k_loops, candidates, kept_tris, halves, voxel: float, device, field=None):
    """Close the kept loops ``candidates`` (labels of ``k_loops`` = ``(next, members, labels)``, the border of
    ``kept_tris`` whose directed edges are ``halves``) that are slits (module docstring); a strip whose diagonals are
    longer than ``FILL_VOXELS`` but at most ``WIDE_VOXELS`` is taken where ``field`` (the result's, if given) is
    within ``ON_VOXELS`` of zero all over it, read about a voxel apart (it lies on the surface).

    Returns:
        ``(tris, filled)``: (F, 3) int32 the strips of the loops closed, and their labels.
    """
    nxt, members, labels = k_loops
    at = np.isin(labels[members], candidates)
    members = members[at]
    loop_labels = labels[members]
    loops, counts = np.unique(loop_labels, return_counts=True)
    loops, counts = loops[counts >= 3], counts[counts >= 3]
    keep = np.isin(loop_labels, loops)
    members, loop_labels = members[keep], loop_labels[keep]
    if not len(loops):
        return np.zeros((0, 3), dtype=np.int32), loops
    prv = np.arange(len(nxt), dtype=np.int64)
    prv[nxt[members]] = members
    starts = _starts(points, members, loop_labels, loops)
    sizes = counts - 2
    first = np.r_[0, np.cumsum(sizes)[:-1]]
    out = wp.empty(int(sizes.sum()), dtype=wp.vec3i, device=device)
    longest = wp.empty(len(loops), dtype=wp.float32, device=device)

    def arr(values):
        return wp.array(np.ascontiguousarray(values, dtype=np.int32), dtype=wp.int32, device=device)

    pts = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
    wp.launch(
        _fill_kernel,
        len(loops),
        inputs=[pts, arr(nxt), arr(prv), arr(starts), arr(counts), arr(first), out, longest],
        device=device,
    )
    tris = out.numpy().reshape(-1, 3).astype(np.int32)
    loop_of = np.repeat(np.arange(len(loops)), sizes)
    on_loop = np.isin(labels[halves[:, 0]], loops)
    halves_loop = np.searchsorted(loops, labels[halves[on_loop, 0]])
    facing = _facing(points, tris, loop_of, kept_tris, halves[on_loop], halves_loop, len(loops))
    longest = longest.numpy()
    ok = (longest <= FILL_VOXELS * voxel) & (facing > 0.0)
    wide = np.flatnonzero(~ok & (longest <= WIDE_VOXELS * voxel) & (facing > 0.0))
    if field is not None and len(wide):
        ok[wide] = _on_surface(field, points, tris, loop_of, wide, len(loops), voxel, device)
    return tris[ok[loop_of]], loops[ok]


def _on_surface(field, points, tris, loop_of, wide, n_loops: int, voxel: float, device) -> np.ndarray:
    """(W,) bool: whether each of the ``wide`` loops' strips lies within ``ON_VOXELS`` of the result's zero level at
    points about a voxel apart all over its triangles (:func:`.samples.triangle_samples`; the field is 1-Lipschitz)."""
    rows = np.flatnonzero(np.isin(loop_of, wide))
    used, local = np.unique(tris[rows], return_inverse=True)
    local = local.reshape(-1, 3)
    at, first = triangle_samples(points[used], local, np.full(len(rows), voxel), device)
    owner = np.r_[np.repeat(rows, 3), np.repeat(rows, np.diff(first))]
    off = np.abs(field.sample(np.r_[points[used][local].reshape(-1, 3), at[len(used) :]], method="linear"))
    worst = np.zeros(n_loops)
    np.maximum.at(worst, loop_of[owner], off)
    return worst[wide] <= ON_VOXELS * voxel
