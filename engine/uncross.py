"""A kept surface's faces where they pass through other faces, tiled again: no face crossing another at the seams.

Along a seam, the voxel surface, the strips that join it to the kept faces and the kept faces meet at small angles;
where a voxel face lies beside a kept sliver, or a strip's long edge passes over a notch of the voxel border, two faces
overlap within a few degrees of one plane and pass through each other. Each such place is made again, in rounds:

1. the crossing pairs with a new face (:func:`.selfcross.crossing_pairs`, queried against the new faces only);
2. the patch: the new faces of those pairs and ``rings`` rings of new faces about them (in the last rounds kept faces
   too, where kept faces fold with the seam: a kept sliver over its neighbour leaves no border that could be tiled);
3. each connected patch that is a disc (one border loop, Euler characteristic 1) tiled anew in the plane its border
   spans most (its Newell normal): the triangulation of that polygon whose worst triangle is best, with no chord along
   an edge the surface already has (:func:`.tiling.tiled_polygons`), then the patch's vertices inside the polygon
   inserted (:func:`.tiling.with_points`; in some rounds none: a vertex that stands out of the patch stays out); the
   polygon's projection is simple where a tiling is found, so the tiles neither fold nor overlap;
4. a tiling taken where it stays within ``TOLERANCE_VOXELS`` of the patch (each removed vertex from the tiles, each
   tile's centre and edge midpoints from the patch's faces, either with the faces beside the border);
5. the crossing pairs found again where tiles were laid and where tiling failed, for the next round (``ROUNDS``);
6. last, a place no plane tiles (a patch folded across a sharp crease, a crumpled corner where three surfaces meet)
   made a fan about one of its own vertices, where the fan stays within ``FAN_TOLERANCE_VOXELS`` of it and none of
   its faces passes through another;
7. the places still crossing after every round relaxed where that uncrosses them (:mod:`.relax`: their free vertices
   smoothed within a third of a voxel of where they were, or within the reach an adaptivity gives new faces:
   ``stats["tolerance"]`` of :func:`.coarsen.coarsened`, as :data:`.adaptive.FACE_REACH` tolerances).

Kept faces that stay keep their positions and sources bit for bit; tiles are new faces.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .adaptive import FACE_REACH
from .components import connected_components, edge_neighbours
from .geometry import closest_on_triangle, triangle_frame
from .meshcheck import any_corner, compacted
from .parallel import launch_split
from .relax import RELAX_VOXELS, relaxed
from .selfcross import crossing_pairs
from .tiling import tiled_polygons, with_points
from .zipper import loop_labels

# Per round: rings of faces about the crossing faces removed, and what the tiles keep or take: "inner" (the patch's
# vertices inside the border), "border" (the border alone), "kept" (kept faces in the patch too, and inner vertices),
# "fan" (new faces only, a fan about one of the patch's vertices: a patch folded across a crease, or a crumpled corner
# where three surfaces meet, has no plane to be tiled in).
# A place still crossing after a round is tiled again from a wider patch; measured on messy meshes, borders alone
# after inner vertices mend folds that stand out, and kept faces given up last mend kept slivers folded with the seam.
ROUNDS = (
    *((1, "inner"), (2, "inner"), (3, "inner"), (1, "border"), (2, "border"), (1, "kept"), (2, "kept"), (3, "kept")),
    *((1, "fan"), (2, "fan")),
)
# Kept faces given up in the last rounds are at most this large (square voxels): slivers along the seam, never a
# low-polygon mesh's large faces (the beetle lost 1.2 % of what should be kept when any kept face could go; the
# teapot's seams keep 9 crossing pairs with faces up to 2 square voxels given up, 20 with 0.5).
SMALL_AREA_VOXELS = 2.0
# A tiling is taken where no removed vertex lies farther than this from it, and no tile farther from the patch
# (measured with a ball, crossing pairs left at 0.3 / 0.4 / 0.5: teapot 9 / 8 / 7, cow 17 / 7 / 7, beetle 118 / 100 /
# 97; the CAD pairs' surfaces the same at all three).
TOLERANCE_VOXELS = 0.4
# A fan (the last rounds, where no tiling is found) is taken within this: it cuts across the crease or the crumpled
# corner it replaces (the cow with a ball: its seam's corner fanned within 0.6, not 0.4).
FAN_TOLERANCE_VOXELS = 0.6
# Border loops longer than this are not tiled (the dynamic program's work grows as the cube of it).
MAX_LOOP = 96
# Per-face and per-vertex arrays of a kept surface (:func:`.hybrid.kept_surface`).
FACE_KEYS = ("kept", "field_id", "triangle_id", "corner_bary", "voxel_face")
VERTEX_KEYS = ("verts", "vertex_field", "vertex_id")


@wp.kernel(enable_backward=False)
def _nearest_in_range_kernel(
    points: wp.array[wp.vec3],
    first: wp.array[wp.int32],
    count: wp.array[wp.int32],
    corners: wp.array[wp.vec3],
    within: float,
    offset: int,
    distance: wp.array[wp.float32],
):
    """Per point: its distance to the nearest of triangles ``first`` .. ``first + count - 1`` (corners 3 a row), or
    the first one found ``within`` that (at most ``within``: where the caller asks only whether one lies so near)."""
    p = wp.tid() + offset
    x = points[p]
    nearest = float(1.0e30)
    t = first[p]
    while t < first[p] + count[p] and nearest > within:
        a = corners[3 * t]
        b = corners[3 * t + 1]
        c = corners[3 * t + 2]
        edges, inward, lengths, n = triangle_frame(a, b, c)
        nearest = wp.min(nearest, wp.length(x - closest_on_triangle(x, a, b, c, edges, inward, lengths, n)))
        t += 1
    distance[p] = nearest


def uncrossed(surface: dict, voxel: float, device) -> dict:
    """A kept surface (:func:`.hybrid.kept_surface`'s dict) with its faces tiled again where they pass through
    other faces (the module's steps); every per-face and per-vertex array follows, a tile is a new face of no voxel
    face. ``stats["uncrossed"]``: places tiled; ``stats["relaxed"]``: places relaxed; ``stats["crossing_left"]``: the
    crossing pairs with a new face left; ``stats["crossing_at"]``: (P, 3) float32 the centres of their faces."""
    tris, kept = surface["tris"].astype(np.int64), surface["kept"]
    origin = np.arange(len(tris))
    pairs, places = crossing_pairs(surface["verts"], tris, device, np.flatnonzero(~kept)), 0
    for rings, mode in ROUNDS:
        if not len(pairs):
            break
        patch = _patch(surface["verts"], tris, kept, pairs, rings, voxel if mode == "kept" else 0.0)
        if mode == "fan":
            gone, tiles, tiled = _fanned(surface["verts"], tris, patch, voxel, device)
        else:
            gone, tiles, tiled = _tiled(surface["verts"], tris, patch, voxel, device, mode != "border")
        alive = np.ones(len(tris), dtype=bool)
        alive[gone] = False
        if not tiled or not _sound(np.concatenate([tris[alive], tiles]), len(tiles), len(surface["verts"])):
            continue  # nothing changed: the same pairs for the next round
        places += tiled
        still = np.unique(pairs[~kept[pairs]])
        tris = np.concatenate([tris[alive], tiles])
        kept = np.r_[kept[alive], np.zeros(len(tiles), dtype=bool)]
        origin = np.r_[origin[alive], np.full(len(tiles), -1)]
        rows = np.r_[(np.cumsum(alive) - 1)[still[alive[still]]], np.arange(len(tiles)) + int(alive.sum())]
        pairs = crossing_pairs(surface["verts"], tris, device, rows)  # where tiles were laid, and where none were
    reach = max(RELAX_VOXELS, FACE_REACH * surface["stats"].get("tolerance", 0.0))  # an adaptive surface's own
    verts, pairs, loose = relaxed(surface["verts"], tris, kept, pairs, voxel, device, reach)
    at = verts[tris[np.unique(pairs)]].mean(axis=1).astype(np.float32)  # (where the faces left crossing lie)
    stats = {"uncrossed": places, "relaxed": loose, "crossing_left": len(pairs), "crossing_at": at}
    return _rebuilt({**surface, "verts": verts}, tris, origin, stats)


def _sound(tris: np.ndarray, tiles: int, n_verts: int) -> bool:
    """Whether each edge of the last ``tiles`` faces of ``tris`` is one face's that way and one other's the other way
    (a guard: the tiling's chords avoid the surface's edges, so this holds unless two pieces' tiles meet)."""
    on = np.zeros(n_verts, dtype=bool)
    on[tris[len(tris) - tiles :]] = True
    near = tris[any_corner(on, tris)]
    keys, counts = np.unique(near.ravel() * n_verts + near[:, [1, 2, 0]].ravel(), return_counts=True)
    ends = tris[len(tris) - tiles :]
    found = []
    for a, b in ((ends.ravel(), ends[:, [1, 2, 0]].ravel()), (ends[:, [1, 2, 0]].ravel(), ends.ravel())):
        at = np.minimum(np.searchsorted(keys, a * n_verts + b), len(keys) - 1)
        found.append((keys[at] == a * n_verts + b) & (counts[at] == 1))
    return bool(np.all(found))


def _patch(verts, tris: np.ndarray, kept: np.ndarray, pairs: np.ndarray, rings: int, small: float) -> np.ndarray:
    """(T,) bool the faces of the crossing ``pairs`` and ``rings`` rings of faces about them: new faces, and kept faces
    of at most ``SMALL_AREA_VOXELS`` square voxels of size ``small`` (none where it is 0)."""

    def taken(rows: np.ndarray) -> np.ndarray:
        corners = verts[tris[rows]].astype(np.float64)
        area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
        return rows[~kept[rows] | (area <= SMALL_AREA_VOXELS * small * small)]

    patch = np.zeros(len(tris), dtype=bool)
    patch[taken(np.unique(pairs))] = True
    for _ in range(rings):
        marked = np.zeros(len(verts), dtype=bool)
        marked[tris[patch]] = True
        patch[taken(np.flatnonzero(any_corner(marked, tris) & ~patch))] = True
    return patch


def _face_components(tris: np.ndarray, n_verts: int, device) -> np.ndarray:
    """(F,) the connected piece (through shared edges) of each face, numbered 0 .. P - 1."""
    if not len(tris):
        return np.zeros(0, dtype=np.int64)
    root = connected_components(len(tris), *edge_neighbours(tris, n_verts), device)
    return np.unique(root, return_inverse=True)[1].reshape(-1)


def _tiled(
    verts, tris: np.ndarray, patch: np.ndarray, voxel: float, device, with_inner: bool
) -> tuple[np.ndarray, np.ndarray, int]:
    """The rows of the ``patch``'s faces given up, the tiles (Q, 3) int64 that take their place and how many pieces:
    the pieces that are discs, tiled in their border's plane (:func:`.tiling.tiled_polygons`) with their inner
    vertices that fall inside it (:func:`.tiling.with_points`; none unless ``with_inner``), where the tiles lie within
    ``TOLERANCE_VOXELS`` of the patch."""
    rows = np.flatnonzero(patch)
    n = len(verts)
    piece = _face_components(tris[rows], n, device)
    order, starts, sizes, loop_piece = _border_loops(tris[rows], piece, n, device)
    if not len(sizes):
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3), dtype=np.int64), 0
    inner, inner_sizes = _inner_vertices(tris[rows], piece, order, sizes, loop_piece, n)
    inner_starts = np.cumsum(inner_sizes) - inner_sizes
    plane, inner_plane = _in_plane(verts, order, starts, sizes, inner, inner_sizes, voxel)
    outside = _beside(tris, patch, n)
    local, done = tiled_polygons(plane, starts, sizes, _forbidden_chords(outside, order, starts, sizes, n), device)
    taken = inner_sizes if with_inner else inner_sizes * 0
    local, counts, inserted = with_points(plane, starts, sizes, local, done, inner_plane, inner_starts, taken, device)
    loop_of = lambda sizes_: np.repeat(np.arange(len(sizes)), sizes_)  # noqa: E731
    points = np.r_[order, inner][
        np.lexsort((np.r_[np.zeros(len(order)), np.ones(len(inner))], np.r_[loop_of(sizes), loop_of(inner_sizes)]))
    ]
    tile_loop = loop_of(counts)
    tiles = points[(starts + inner_starts)[tile_loop][:, None] + local]
    lost = (inner[~inserted], loop_of(inner_sizes)[~inserted])
    done = (counts > 0) & _close_enough(
        verts, tris[rows], piece, outside, tiles, tile_loop, lost, loop_piece, voxel, device
    )
    good = np.isin(piece, loop_piece[done])
    return rows[good], tiles[done[tile_loop]], int(done.sum())


def _fanned(verts, tris: np.ndarray, patch: np.ndarray, voxel: float, device) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`_tiled`'s results with fans: each disc piece of the ``patch`` with inner vertices made a fan about the
    one nearest their mean (its other inner vertices dropped), where the fan lies within ``FAN_TOLERANCE_VOXELS`` of the
    patch and none of its faces passes through another face. A fan needs no plane; its edges are the border's and new
    ones to a vertex only the patch used, so it joins the surface as the patch did."""
    rows, n = np.flatnonzero(patch), len(verts)
    piece = _face_components(tris[rows], n, device)
    order, starts, sizes, loop_piece = _border_loops(tris[rows], piece, n, device)
    inner, inner_sizes = _inner_vertices(tris[rows], piece, order, sizes, loop_piece, n) if len(sizes) else (order,) * 2
    if not len(inner):
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3), dtype=np.int64), 0
    inner_loop = np.repeat(np.arange(len(sizes)), inner_sizes)
    points = verts[inner].astype(np.float64)
    mean = np.stack([np.bincount(inner_loop, points[:, k], len(sizes)) for k in range(3)], axis=1)
    mean /= np.maximum(inner_sizes, 1)[:, None]
    by = np.lexsort((np.linalg.norm(points - mean[inner_loop], axis=1), inner_loop))
    first = by[np.r_[True, inner_loop[by][1:] != inner_loop[by][:-1]]]  # per loop with inner vertices, the nearest
    centre = np.full(len(sizes), -1, dtype=np.int64)
    centre[inner_loop[first]] = inner[first]
    step = np.arange(len(order))
    loop = np.repeat(np.arange(len(sizes)), sizes)
    step = starts[loop] + (step - starts[loop] + 1) % sizes[loop]  # the next vertex along each loop
    has = centre[loop] >= 0
    tiles, tile_loop = np.stack([order, order[step], centre[loop]], axis=1)[has], loop[has]
    lost = np.ones(len(inner), dtype=bool)
    lost[first] = False
    outside, dropped = _beside(tris, patch, n), (inner[lost], inner_loop[lost])
    done = (centre >= 0) & _close_enough(
        verts, tris[rows], piece, outside, tiles, tile_loop, dropped, loop_piece, voxel, device, FAN_TOLERANCE_VOXELS
    )
    laid = done[tile_loop]
    gone = rows[np.isin(piece, loop_piece[done])]
    done[_crossing_loops(verts, tris, gone, tiles[laid], tile_loop[laid], device)] = False
    good = np.isin(piece, loop_piece[done])
    return rows[good], tiles[done[tile_loop]], int(done.sum())


def _beside(tris: np.ndarray, patch: np.ndarray, n: int) -> np.ndarray:
    """The faces outside the ``patch`` with a corner on it: the only ones its loops, tiles and inner vertices touch
    (what :func:`_forbidden_chords` and :func:`_close_enough` read of the faces outside; the rest of a surface of tens
    of thousands of faces is left unread, where a round often tiles nothing)."""
    on = np.zeros(n, dtype=bool)
    on[tris[patch]] = True
    return tris[any_corner(on, tris) & ~patch]


def _crossing_loops(verts, tris: np.ndarray, gone: np.ndarray, tiles: np.ndarray, tile_loop, device) -> np.ndarray:
    """The loops (``tile_loop`` per tile) whose tiles pass through a face of ``tris`` without its rows ``gone`` and
    with all the ``tiles`` laid."""
    alive = np.ones(len(tris), dtype=bool)
    alive[gone] = False
    both = np.concatenate([tris[alive], tiles])
    pairs = crossing_pairs(verts, both, device, np.arange(int(alive.sum()), len(both)))
    hit = pairs[pairs >= int(alive.sum())] - int(alive.sum())
    return np.unique(tile_loop[hit])


def _inner_vertices(faces, piece, order, sizes, loop_piece, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The vertices of each bordered piece's faces that are not on its border, loop after loop, and how many each."""
    loop_at = np.full(int(piece.max()) + 1, -1, dtype=np.int64)
    loop_at[loop_piece] = np.arange(len(sizes))
    vertex_loop = np.full(n, -1, dtype=np.int64)
    vertex_loop[faces.ravel()] = np.repeat(loop_at[piece], 3)
    vertex_loop[order] = -1
    inner = np.flatnonzero(vertex_loop >= 0)
    inner = inner[np.argsort(vertex_loop[inner], kind="stable")]
    return inner, np.bincount(vertex_loop[inner], minlength=len(sizes))


def _border_loops(faces: np.ndarray, piece: np.ndarray, n: int, device) -> tuple:
    """The border loop of each piece of ``faces`` (``piece`` per face, 0 .. P - 1, connected through edges) that is a
    disc (one loop, no vertex on it twice, Euler characteristic 1, at most one vertex shared with other pieces: two
    pieces' tiles could join the same two vertices) of 3 to ``MAX_LOOP`` vertices: ``order`` (the loops' vertices one
    after another, the faces on their left), ``starts``, ``sizes`` and the ``piece`` of each loop. The loops are
    followed along border half-edges, so pieces that touch at a vertex each have theirs."""
    u, w = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    border = ~np.isin(w * n + u, u * n + w)
    bu, bw, bp = u[border], w[border], np.repeat(piece, 3)[border]
    if not len(bu):
        return bu, bu, bu, bu
    count = lambda at: np.bincount(at, minlength=int(piece.max()) + 1)  # noqa: E731
    leaving = bp * n + bu
    by_start = np.argsort(leaving, kind="stable")
    at = np.minimum(np.searchsorted(leaving[by_start], bp * n + bw), len(bu) - 1)
    found = leaving[by_start][at] == bp * n + bw
    nxt = np.where(found, by_start[at], np.arange(len(bu)))
    twice = np.r_[False, leaving[by_start][1:] == leaving[by_start][:-1]]
    bad = count(np.r_[bp[by_start][twice], bp[~found]]) > 0
    corners = np.unique(np.repeat(piece, 3) * n + u)
    shared = np.bincount(corners % n, minlength=n)[corners % n] > 1
    bad |= count(corners[shared] // n) > 1
    edges = np.unique(np.repeat(piece, 3) * n * n + np.minimum(u, w) * n + np.maximum(u, w))
    bad |= count(corners // n) - count(edges // (n * n)) + count(piece) != 1
    keep = np.flatnonzero(~bad[bp])
    label = loop_labels(nxt, keep, device)
    bad |= count(np.unique(np.stack([bp[keep], label[keep]], axis=1), axis=0)[:, 0]) != 1
    size = count(bp)
    bad |= (size < 3) | (size > MAX_LOOP)
    keep = keep[~bad[bp[keep]]]
    if not len(keep):
        return keep, keep, keep, keep
    position = _loop_positions(nxt, keep, label, int(size[~bad].max()))
    keep = keep[np.lexsort((position[keep], label[keep]))]
    _, starts, sizes = np.unique(label[keep], return_index=True, return_counts=True)
    return bu[keep], starts, sizes, bp[keep[starts]]


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


def _in_plane(verts, order, starts, sizes, inner, inner_sizes, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) and (M, 2) float64 each loop's vertices and its ``inner`` vertices in the plane its loop spans most
    (Newell's normal, from the loop's centre), in voxels: counter-clockwise where the loop's faces lie on its left."""
    loop = np.repeat(np.arange(len(sizes)), sizes)
    points = verts[order].astype(np.float64)
    centre = np.add.reduceat(points, starts, axis=0) / sizes[:, None]
    points -= centre[loop]
    step = np.arange(len(order)) + 1
    step[starts + sizes - 1] = starts
    normal = np.add.reduceat(np.cross(points, points[step]), starts, axis=0)
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    axis = np.eye(3)[np.argmin(np.abs(normal), axis=1)]
    across = np.cross(normal, axis)
    across /= np.maximum(np.linalg.norm(across, axis=1), 1e-300)[:, None]
    up = np.cross(normal, across)
    inner_loop = np.repeat(np.arange(len(sizes)), inner_sizes)
    inside = verts[inner].astype(np.float64) - centre[inner_loop]
    return tuple(
        np.stack([np.einsum("ij,ij->i", x, across[at]), np.einsum("ij,ij->i", x, up[at])], 1) / voxel
        for x, at in ((points, loop), (inside, inner_loop))
    )


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


def _close_enough(
    verts, patch_faces, piece, outside, tiles, tile_loop, lost, loop_piece, voxel, device, tolerance=None
):
    """(L,) bool per loop: its patch and its tiles lie within ``tolerance`` (voxels, default ``TOLERANCE_VOXELS``) of
    each other, each with the faces around the loop: every vertex the patch loses (``lost``: vertices and their loops)
    near the tiled surface, every tile's centre and edge midpoints near the patch's (a vertex of a fold over the faces
    beside it lies near those)."""
    n, count = len(verts), len(loop_piece)
    loop_at = np.full(int(piece.max()) + 1, -1, dtype=np.int64)
    loop_at[loop_piece] = np.arange(count)
    face_loop = loop_at[piece]
    vertex_loop = np.full(n, -1, dtype=np.int64)
    vertex_loop[tiles.ravel()] = np.repeat(tile_loop, 3)
    near = np.flatnonzero(any_corner(vertex_loop >= 0, outside))
    at = vertex_loop[outside[near]].ravel()
    key = np.unique((at * len(outside) + np.repeat(near, 3))[at >= 0])
    beside = np.stack([key // len(outside), key % len(outside)], axis=1)  # (loop, outside face) pairs
    corner = verts[tiles].astype(np.float64)
    samples = np.concatenate([corner.mean(axis=1)[:, None], (corner + corner[:, [1, 2, 0]]) / 2], axis=1)
    tiled = face_loop >= 0
    far = np.zeros(count, dtype=bool)
    for points, loops, faces, at in (
        (verts[lost[0]], lost[1], np.r_[tiles, outside[beside[:, 1]]], np.r_[tile_loop, beside[:, 0]]),
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
        reach = (TOLERANCE_VOXELS if tolerance is None else tolerance) * voxel
        distance = _nearest_in_range(points, first[loops], per[loops], verts[faces[by_loop]], device, reach)
        far[loops[distance > reach]] = True
    return ~far


def _nearest_in_range(points, first, count, corners, device, within: float = -1.0) -> np.ndarray:
    """(P,) float32 each point's distance to the nearest of its range of triangles (``_nearest_in_range_kernel``; with
    ``within``, one found within that is taken: whether the nearest lies within it is all that is told)."""
    if not len(points):
        return np.zeros(0, dtype=np.float32)
    args = [
        wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device),
        wp.array(first.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(count.astype(np.int32), dtype=wp.int32, device=device),
        wp.array(np.ascontiguousarray(corners, dtype=np.float32).reshape(-1, 3), dtype=wp.vec3, device=device),
    ]
    distance = wp.zeros(len(points), dtype=wp.float32, device=device)
    launch_split(_nearest_in_range_kernel, len(points), lambda lo, _n: [*args, float(within), lo, distance], device)
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
    n_kept = int(out["kept"].sum())
    out["stats"] = {**surface["stats"], "kept_faces": n_kept, "new_faces": len(tris) - n_kept, **stats}
    return out
