"""A kept surface's new faces where they pass through other faces, tiled again: no face crossing another at the seams.

Along a seam, the voxel surface, the strips that join it to the kept faces and the kept faces meet at small angles;
where a voxel face lies beside a kept sliver, or a strip's long edge passes over a notch of the voxel border, two faces
overlap within a few degrees of one plane and pass through each other. Each such place is made again:

1. the crossing pairs with a new face (:func:`.selfcross.crossing_pairs`, queried against the new faces only);
2. the patch: the new faces of those pairs and ``rings`` rings of new faces about them (kept faces never change);
3. each connected patch that is a disc (one border loop, Euler characteristic 1) tiled anew from its border alone, in
   the plane its border spans most (its Newell normal): the triangulation of that polygon whose worst triangle is best
   (a dynamic program over its chords, :func:`_tile_loops_kernel`), with no chord along an edge the surface already
   has; the polygon's projection is simple where a tiling is found, so the tiles neither fold nor overlap;
4. a tiling taken where it stays within ``TOLERANCE_VOXELS`` of the patch (each removed vertex from the tiles, each
   tile's centre and edge midpoints from the patch's faces);
5. the crossing pairs found again where tiles were laid; the places still crossing grown by a ring, ``RINGS`` rounds.

Written by hand: the tiling is a polygon triangulation with forbidden chords (a dynamic program each polygon, one
Warp thread each); no library in a user's Blender triangulates a polygon in Warp, and ear clipping, greedy, gets
stuck where the surface's own edges forbid the ears it would take.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .components import connected_components
from .geometry import closest_on_triangle, triangle_frame
from .meshcheck import any_corner, compacted
from .parallel import launch_split
from .selfcross import crossing_pairs
from .zipper import loop_labels

# Rings of new faces about the crossing faces removed in each round (a place still crossing after a round is tiled
# again from a wider patch).
RINGS = (1, 2, 3)
# A tiling is taken where no removed vertex lies farther than this from it, and no tile farther from the patch.
TOLERANCE_VOXELS = 0.3
# Border loops longer than this are not tiled (the dynamic program's work grows as the cube of it).
MAX_LOOP = 96
# Per-face and per-vertex arrays of a kept surface (:func:`.hybrid.kept_surface`).
FACE_KEYS = ("kept", "field_id", "triangle_id", "corner_bary", "voxel_face")
VERTEX_KEYS = ("verts", "vertex_field", "vertex_id")


@wp.func
def _turn(a: wp.vec2d, b: wp.vec2d, c: wp.vec2d) -> wp.float64:
    """Twice the signed area of (a, b, c): positive counter-clockwise."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


@wp.func
def _chord_clear(plane: wp.array[wp.vec2d], start: int, n: int, i: int, j: int) -> bool:
    """Whether chord i-j of the polygon ``plane[start : start + n]`` (counter-clockwise) lies inside it: it leaves
    both ends into the polygon's inside and neither crosses an edge nor passes through a corner."""
    a = plane[start + i]
    b = plane[start + j]
    zero = wp.float64(0.0)
    for end in range(2):
        at = wp.where(end == 0, i, j)
        to = wp.where(end == 0, b, a)
        p = plane[start + at]
        before = plane[start + (at + n - 1) % n]
        after = plane[start + (at + 1) % n]
        left_out = _turn(p, after, to) > zero
        left_in = _turn(before, p, to) > zero
        if _turn(before, p, after) > zero:
            if not (left_out and left_in):
                return False
        elif not (left_out or left_in):
            return False
    span = wp.length_sq(b - a)
    for e in range(n):
        f = (e + 1) % n
        c = plane[start + e]
        d = plane[start + f]
        if e != i and e != j:
            along = _turn(a, b, c)
            if wp.abs(along) <= wp.float64(1.0e-12) * span and wp.dot(c - a, c - b) < zero:
                return False  # a corner on the chord
        if e == i or e == j or f == i or f == j:
            continue
        if _turn(a, b, c) * _turn(a, b, d) < zero and _turn(c, d, a) * _turn(c, d, b) < zero:
            return False
    return True


@wp.func
def _shape(a: wp.vec2d, b: wp.vec2d, c: wp.vec2d) -> wp.float64:
    """A triangle's shape: its doubled signed area over the sum of its squared edges (negative: turned over)."""
    edges = wp.length_sq(b - a) + wp.length_sq(c - b) + wp.length_sq(a - c)
    return _turn(a, b, c) / wp.max(edges, wp.float64(1.0e-300))


@wp.kernel(enable_backward=False)
def _tile_loops_kernel(
    plane: wp.array[wp.vec2d],
    starts: wp.array[wp.int32],
    sizes: wp.array[wp.int32],
    square_starts: wp.array[wp.int32],
    forbidden: wp.array[wp.uint8],
    offset: int,
    usable: wp.array[wp.uint8],
    best: wp.array[wp.float64],
    split: wp.array[wp.int32],
    stack: wp.array[wp.int32],
    tiles: wp.array2d[wp.int32],
    tiled: wp.array[wp.uint8],
):
    """Per loop: the triangulation of its polygon (``plane``, counter-clockwise) whose worst shape is best, with no
    chord ``forbidden`` (per pair of corners, row-major in the loop's square), its n - 2 triangles of corner indices
    written to ``tiles`` from row ``starts[loop] - 2 * loop``; ``tiled`` 0 where there is none."""
    loop = wp.tid() + offset
    start = starts[loop]
    n = sizes[loop]
    sq = square_starts[loop]
    none = wp.float64(-1.0)
    for i in range(n):
        for j in range(n):
            near = j == i + 1 or i == j + 1 or (i == 0 and j == n - 1) or (j == 0 and i == n - 1)
            ok = near
            if not near and i < j and forbidden[sq + i * n + j] == wp.uint8(0):
                ok = _chord_clear(plane, start, n, i, j)
            if i < j:
                usable[sq + i * n + j] = wp.where(ok, wp.uint8(1), wp.uint8(0))
            best[sq + i * n + j] = wp.where(j == i + 1, wp.float64(1.0e300), none)
    for length in range(2, n):
        for i in range(n - length):
            j = i + length
            if usable[sq + i * n + j] == wp.uint8(0):
                continue
            top = none
            arg = int(-1)
            for k in range(i + 1, j):
                if usable[sq + i * n + k] == wp.uint8(0) or usable[sq + k * n + j] == wp.uint8(0):
                    continue
                left = best[sq + i * n + k]
                right = best[sq + k * n + j]
                if left <= none or right <= none:
                    continue
                shape = _shape(plane[start + i], plane[start + k], plane[start + j])
                if shape <= wp.float64(0.0):
                    continue
                worst = wp.min(shape, wp.min(left, right))
                if worst > top:
                    top = worst
                    arg = k
            best[sq + i * n + j] = top
            split[sq + i * n + j] = arg
    ok = best[sq + n - 1] > none
    tiled[loop] = wp.where(ok, wp.uint8(1), wp.uint8(0))
    if not ok:
        return
    # the triangles, read from the splits depth first (at most n intervals wait on the stack)
    row = start - 2 * loop
    top_ = 2 * start
    stack[top_] = 0
    stack[top_ + 1] = n - 1
    depth = int(1)
    while depth > 0:
        depth -= 1
        i = stack[top_ + 2 * depth]
        j = stack[top_ + 2 * depth + 1]
        if j - i < 2:
            continue
        k = split[sq + i * n + j]
        tiles[row, 0] = i
        tiles[row, 1] = k
        tiles[row, 2] = j
        row += 1
        stack[top_ + 2 * depth] = i
        stack[top_ + 2 * depth + 1] = k
        stack[top_ + 2 * depth + 2] = k
        stack[top_ + 2 * depth + 3] = j
        depth += 2


@wp.kernel(enable_backward=False)
def _nearest_in_range_kernel(
    points: wp.array[wp.vec3],
    first: wp.array[wp.int32],
    count: wp.array[wp.int32],
    corners: wp.array[wp.vec3],
    offset: int,
    distance: wp.array[wp.float32],
):
    """Per point: its distance to the nearest of triangles ``first`` .. ``first + count - 1`` (corners 3 a row)."""
    p = wp.tid() + offset
    x = points[p]
    nearest = float(1.0e30)
    for t in range(first[p], first[p] + count[p]):
        a = corners[3 * t]
        b = corners[3 * t + 1]
        c = corners[3 * t + 2]
        edges, inward, lengths, n = triangle_frame(a, b, c)
        nearest = wp.min(nearest, wp.length(x - closest_on_triangle(x, a, b, c, edges, inward, lengths, n)))
    distance[p] = nearest


def uncrossed(surface: dict, voxel: float, device) -> dict:
    """A kept surface (:func:`.hybrid.kept_surface`'s dict) with its new faces tiled again where they pass through
    other faces (the module's steps); kept faces and their vertices never change, every per-face and per-vertex array
    follows, a tile is a new face of no voxel face. ``stats["uncrossed"]``: places tiled; ``stats["crossing_left"]``:
    the crossing pairs with a new face the last round found (0 where its tiles cross nothing)."""
    tris, kept = surface["tris"].astype(np.int64), surface["kept"]
    origin = np.arange(len(tris))
    rows, places = np.flatnonzero(~kept), 0
    for rings in (*RINGS, 0):
        pairs = crossing_pairs(surface["verts"], tris, device, rows)
        if not len(pairs) or not rings:  # (the last round counts what is left)
            break
        patch = _patch(tris, kept, pairs, rings, len(surface["verts"]))
        gone, tiles, tiled = _tiled(surface["verts"], tris, patch, voxel, device)
        places += tiled
        alive = np.ones(len(tris), dtype=bool)
        alive[gone] = False
        still = np.unique(pairs[~kept[pairs]])
        tris = np.concatenate([tris[alive], tiles])
        kept = np.r_[kept[alive], np.zeros(len(tiles), dtype=bool)]
        origin = np.r_[origin[alive], np.full(len(tiles), -1)]
        rank = np.cumsum(alive) - 1
        rows = np.r_[rank[still[alive[still]]], np.arange(len(tiles)) + int(alive.sum())]
    return _rebuilt(surface, tris, origin, {"uncrossed": places, "crossing_left": len(pairs)})


def _patch(tris: np.ndarray, kept: np.ndarray, pairs: np.ndarray, rings: int, n_verts: int) -> np.ndarray:
    """(T,) bool the new faces of the crossing ``pairs`` and ``rings`` rings of new faces about them."""
    patch = np.zeros(len(tris), dtype=bool)
    patch[pairs[~kept[pairs]]] = True
    for _ in range(rings):
        marked = np.zeros(n_verts, dtype=bool)
        marked[tris[patch]] = True
        patch |= any_corner(marked, tris) & ~kept
    return patch


def _face_components(tris: np.ndarray, n_verts: int, device) -> np.ndarray:
    """(F,) the connected piece (through shared corners) of each face: its first corner's least vertex."""
    if not len(tris):
        return np.zeros(0, dtype=np.int64)
    root = connected_components(n_verts, tris[:, [0, 1]].ravel(), tris[:, [1, 2]].ravel(), device)
    return root[tris[:, 0]]


def _tiled(verts, tris: np.ndarray, patch: np.ndarray, voxel: float, device) -> tuple[np.ndarray, np.ndarray, int]:
    """The rows of the ``patch``'s faces given up, the tiles (Q, 3) int64 that take their place and how many pieces:
    the pieces that are discs, tiled in their plane (:func:`_tile_loops_kernel`) within ``TOLERANCE_VOXELS``."""
    rows = np.flatnonzero(patch)
    n = len(verts)
    piece = _face_components(tris[rows], n, device)
    order, starts, sizes, loop_piece = _border_loops(tris[rows], piece, n, device)
    if not len(sizes):
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3), dtype=np.int64), 0
    plane = _in_plane(verts, order, starts, sizes, voxel)
    forbidden = _forbidden_chords(tris[~patch], order, starts, sizes, n)
    local, done = tiled_polygons(plane, starts, sizes, forbidden, device)
    tile_loop = np.repeat(np.arange(len(sizes)), sizes - 2)
    tiles = order[starts[tile_loop][:, None] + local]
    done &= _close_enough(
        verts, tris[rows], piece, tris[~patch], tiles, tile_loop, order, sizes, loop_piece, voxel, device
    )
    good = np.isin(piece, loop_piece[done])
    return rows[good], tiles[done[tile_loop]], int(done.sum())


def _border_loops(faces: np.ndarray, piece: np.ndarray, n: int, device) -> tuple:
    """The border loop of each piece of ``faces`` (``piece`` per face) that is a disc (one loop, no vertex on it
    twice, Euler characteristic 1) of 3 to ``MAX_LOOP`` vertices: ``order`` (the loops' vertices one after another,
    the faces on their left), ``starts``, ``sizes`` and the ``piece`` of each loop."""
    u, w = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    border = ~np.isin(w * n + u, u * n + w)
    bu, bw = u[border], w[border]
    pieces, face_piece = np.unique(piece, return_inverse=True)
    count = lambda at: np.bincount(at, minlength=len(pieces))  # noqa: E731
    vertex_piece = np.full(n, -1, dtype=np.int64)
    vertex_piece[u] = np.repeat(face_piece, 3)
    nxt = np.full(n, -1, dtype=np.int64)
    nxt[bu] = bw
    members = np.unique(bu)
    label = loop_labels(nxt, members, device)
    twice = np.bincount(bu, minlength=n)[members] > 1
    bad = count(vertex_piece[members[twice | (label[members] < 0)]]) > 0
    bad |= count(np.unique(np.stack([vertex_piece[members], label[members]], axis=1), axis=0)[:, 0]) != 1
    edges = np.unique(np.minimum(u, w) * n + np.maximum(u, w))
    bad |= count(vertex_piece[np.unique(u)]) - count(vertex_piece[edges // n]) + count(face_piece) != 1
    size = count(vertex_piece[members])
    bad |= (size < 3) | (size > MAX_LOOP)
    keep = members[~bad[vertex_piece[members]]]
    if not len(keep):
        return keep, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), keep
    position = _loop_positions(nxt, keep, label, int(size[~bad].max()))
    keep = keep[np.lexsort((position[keep], label[keep]))]
    _, starts, sizes = np.unique(label[keep], return_index=True, return_counts=True)
    return keep, starts, sizes, pieces[vertex_piece[keep[starts]]]


def _loop_positions(nxt: np.ndarray, members: np.ndarray, label: np.ndarray, longest: int) -> np.ndarray:
    """(n,) each member's steps from its loop's head (its least member) along ``nxt``: pointer jumping back to the
    head, ``log2(longest)`` rounds of numpy."""
    jump = np.arange(len(nxt))
    back = np.full(len(nxt), -1, dtype=np.int64)
    back[nxt[members]] = members
    head = label[members] == members
    jump[members] = np.where(head, members, back[members])
    steps = np.zeros(len(nxt), dtype=np.int64)
    steps[members] = ~head
    for _ in range(int(np.ceil(np.log2(max(longest, 2))))):
        steps[members] += steps[jump[members]]
        jump[members] = jump[jump[members]]
    return steps


def _in_plane(verts, order: np.ndarray, starts: np.ndarray, sizes: np.ndarray, voxel: float) -> np.ndarray:
    """(N, 2) float64 each loop's vertices in the plane its loop spans most (Newell's normal, from the loop's centre),
    in voxels: counter-clockwise where the loop's faces lie on its left."""
    loop = np.repeat(np.arange(len(sizes)), sizes)
    points = verts[order].astype(np.float64)
    points -= (np.add.reduceat(points, starts, axis=0) / sizes[:, None])[loop]
    step = np.arange(len(order)) + 1
    step[starts + sizes - 1] = starts
    normal = np.add.reduceat(np.cross(points, points[step]), starts, axis=0)
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    axis = np.eye(3)[np.argmin(np.abs(normal), axis=1)]
    across = np.cross(normal, axis)
    across /= np.maximum(np.linalg.norm(across, axis=1), 1e-300)[:, None]
    up = np.cross(normal, across)
    return np.stack([np.einsum("ij,ij->i", points, across[loop]), np.einsum("ij,ij->i", points, up[loop])], 1) / voxel


def _squares(sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each loop's square of corner pairs, row-major one after another: the squares' starts, and per cell its loop,
    row and column."""
    square = sizes * sizes
    first = np.cumsum(square) - square
    loop = np.repeat(np.arange(len(sizes)), square)
    cell = np.arange(int(square.sum())) - first[loop]
    return first, loop, cell // sizes[loop], cell % sizes[loop]


def _forbidden_chords(outside: np.ndarray, order, starts, sizes, n: int) -> np.ndarray:
    """(sum of sizes squared,) uint8 per pair of a loop's corners: 1 where an edge of the ``outside`` faces joins
    them (a tile along it would make that edge a third face's)."""
    on = np.zeros(n, dtype=bool)
    on[order] = True
    near = outside[any_corner(on, outside)]
    a, b = near.ravel(), near[:, [1, 2, 0]].ravel()
    edges = np.unique(np.minimum(a, b) * n + np.maximum(a, b))
    _, loop, row, column = _squares(sizes)
    p, q = order[starts[loop] + row], order[starts[loop] + column]
    return np.isin(np.minimum(p, q) * n + np.maximum(p, q), edges).astype(np.uint8)


def tiled_polygons(plane, starts, sizes, forbidden, device) -> tuple[np.ndarray, np.ndarray]:
    """Each loop's tiles ((sum of sizes - 2, 3) int64 corner indices of its loop, loop after loop) and whether it has
    them (:func:`_tile_loops_kernel`)."""
    first, _, _, _ = _squares(sizes)
    cells = int((sizes * sizes).sum())
    arrays = {
        "plane": wp.array(plane, dtype=wp.vec2d, device=device),
        "starts": wp.array(starts.astype(np.int32), dtype=wp.int32, device=device),
        "sizes": wp.array(sizes.astype(np.int32), dtype=wp.int32, device=device),
        "square_starts": wp.array(first.astype(np.int32), dtype=wp.int32, device=device),
        "forbidden": wp.array(forbidden, dtype=wp.uint8, device=device),
    }
    usable = wp.zeros(cells, dtype=wp.uint8, device=device)
    best = wp.zeros(cells, dtype=wp.float64, device=device)
    split = wp.zeros(cells, dtype=wp.int32, device=device)
    stack = wp.zeros(2 * len(plane), dtype=wp.int32, device=device)
    tiles = wp.zeros((len(plane) - 2 * len(sizes), 3), dtype=wp.int32, device=device)
    tiled = wp.zeros(len(sizes), dtype=wp.uint8, device=device)
    outputs = [usable, best, split, stack, tiles, tiled]
    launch_split(_tile_loops_kernel, len(sizes), lambda lo, _n: [*arrays.values(), lo, *outputs], device, min_dim=2)
    return tiles.numpy().astype(np.int64), tiled.numpy() > 0


def _close_enough(verts, patch_faces, piece, outside, tiles, tile_loop, order, sizes, loop_piece, voxel, device):
    """(L,) bool per loop: its patch and its tiles lie within ``TOLERANCE_VOXELS`` of each other, each with the faces
    around the loop: every vertex the patch loses near the tiled surface, every tile's centre and edge midpoints near
    the patch's (a vertex of a fold over the faces beside it lies near those)."""
    n, count = len(verts), len(sizes)
    loop_at = np.full(n, -1, dtype=np.int64)
    loop_at[loop_piece] = np.arange(count)
    face_loop = loop_at[piece]
    vertex_loop = np.full(n, -1, dtype=np.int64)
    vertex_loop[order] = np.repeat(np.arange(count), sizes)
    beside = np.unique(np.stack([vertex_loop[outside].ravel(), np.repeat(np.arange(len(outside)), 3)], 1), axis=0)
    beside = beside[beside[:, 0] >= 0]
    patch_loop = np.full(n, -1, dtype=np.int64)
    patch_loop[patch_faces.ravel()] = np.repeat(face_loop, 3)
    lost = np.flatnonzero((patch_loop >= 0) & (vertex_loop < 0))
    corner = verts[tiles].astype(np.float64)
    samples = np.concatenate([corner.mean(axis=1)[:, None], (corner + corner[:, [1, 2, 0]]) / 2], axis=1)
    tiled = face_loop >= 0
    far = np.zeros(count, dtype=bool)
    for points, loops, faces, at in (
        (verts[lost], patch_loop[lost], np.r_[tiles, outside[beside[:, 1]]], np.r_[tile_loop, beside[:, 0]]),
        (
            samples.reshape(-1, 3),
            np.repeat(tile_loop, 4),
            np.r_[patch_faces[tiled], outside[beside[:, 1]]],
            np.r_[face_loop[tiled], beside[:, 0]],
        ),
    ):
        by_loop = np.argsort(at, kind="stable")
        per = np.bincount(at, minlength=count)
        first = np.cumsum(per) - per
        distance = _nearest_in_range(points, first[loops], per[loops], verts[faces[by_loop]], device)
        far[loops[distance > TOLERANCE_VOXELS * voxel]] = True
    return ~far


def _nearest_in_range(points, first, count, corners, device) -> np.ndarray:
    """(P,) float32 each point's distance to the nearest of its range of triangles (``_nearest_in_range_kernel``)."""
    if not len(points):
        return np.zeros(0, dtype=np.float32)
    args = [
        wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device),
        wp.array(first.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(count.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(np.ascontiguousarray(corners, dtype=np.float32).reshape(-1, 3), dtype=wp.vec3, device=device),
    ]
    distance = wp.zeros(len(points), dtype=wp.float32, device=device)
    launch_split(_nearest_in_range_kernel, len(points), lambda lo, _n: [*args, lo, distance], device)
    return distance.numpy()


def _rebuilt(surface: dict, tris: np.ndarray, origin: np.ndarray, stats: dict) -> dict:
    """``surface`` on faces ``tris`` (per face its row in ``surface``, -1 for a tile), on the vertices they use."""
    used, local = compacted(tris, len(surface["verts"]))
    out = dict(surface)
    out["tris"] = local.reshape(-1, 3).astype(np.int32)
    was, tile = np.maximum(origin, 0), origin < 0
    for key in FACE_KEYS:
        values = surface[key][was]
        values[tile] = 0 if key in ("kept", "corner_bary") else -1
        out[key] = values
    for key in VERTEX_KEYS:
        out[key] = surface[key][used]
    added = len(tris) - len(surface["tris"])
    out["stats"] = {**surface["stats"], "new_faces": surface["stats"]["new_faces"] + added, **stats}
    return out
