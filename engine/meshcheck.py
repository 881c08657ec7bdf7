"""Checks of triangle meshes on the host (numpy only): validation, welding, edges, and the caps over an open mesh's
holes.

:func:`checked_mesh` refuses what no build can use (empty, non-finite, out-of-range or fully degenerate input) and
drops zero-area triangles. :func:`edge_table` and :func:`problem_faces` find open, non-manifold and inconsistently
oriented edges, judged on the mesh with repeated positions welded (:func:`weld_positions`), and :func:`hole_caps`
bounds how far the winding number of an open mesh may be from an integer (see there). :func:`open_tunnels` gives the
dual contouring's doubled edges a vertex of their own.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import AasdfError

# Triangles per piece of the area computation: its float64 temporaries stay near 40 MB whatever the mesh's size.
AREA_CHUNK = 1 << 18


def triangle_areas(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(T,) areas, component by component (numpy's cross and norm over (T, 3) arrays are several times slower), a
    piece of ``AREA_CHUNK`` triangles at a time."""
    out = np.empty(len(tris), dtype=np.float64)
    for lo in range(0, len(tris), AREA_CHUNK):
        t = tris[lo : lo + AREA_CHUNK]
        a, b, c = (verts[t[:, k]] for k in range(3))
        e, f = b - a, c - a
        x = e[:, 1] * f[:, 2] - e[:, 2] * f[:, 1]
        y = e[:, 2] * f[:, 0] - e[:, 0] * f[:, 2]
        z = e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]
        out[lo : lo + AREA_CHUNK] = 0.5 * np.sqrt(x * x + y * y + z * z)
    return out


def validate_mesh(vertices, triangles) -> tuple[np.ndarray, np.ndarray]:
    """Check a mesh before any kernel runs; return float32 vertices and the non-degenerate int32 triangles."""
    verts, tris, _area, _kept = checked_mesh(vertices, triangles)
    return verts, tris


def checked_mesh(vertices, triangles) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`validate_mesh`, the (K,) float64 areas of the K triangles it keeps and their (K,) int32 indices among
    the given ones."""
    verts = np.asarray(vertices)
    tris = np.asarray(triangles)
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise ValueError(f"Expected 'vertices' of shape (V, 3), but got {verts.shape}.")
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise ValueError(f"Expected 'triangles' of shape (T, 3), but got {tris.shape}.")
    if len(verts) == 0 or len(tris) == 0:
        raise AasdfError("The mesh is empty: it has no vertices or no triangles.")
    if not np.issubdtype(tris.dtype, np.integer):
        raise ValueError(f"Expected integer 'triangles', but got dtype {tris.dtype}.")
    if not (np.issubdtype(verts.dtype, np.floating) or np.issubdtype(verts.dtype, np.integer)):
        raise ValueError(f"Expected real 'vertices', but got dtype {verts.dtype}.")  # (complex parts were dropped)
    verts64 = verts.astype(np.float64)
    if not np.all(np.isfinite(verts64)):
        bad = int(np.count_nonzero(~np.isfinite(verts64).all(axis=1)))
        raise AasdfError(f"The mesh has {bad} vertices with NaN or infinite coordinates.")
    if tris.min() < 0 or tris.max() >= len(verts):
        raise AasdfError(
            f"Triangle indices must lie in [0, {len(verts) - 1}], but range over "
            f"[{int(tris.min())}, {int(tris.max())}]."
        )
    tris = tris.astype(np.int32)
    area2 = 2.0 * triangle_areas(verts64, tris)
    extent = float(max(np.ptp(verts64[:, k]) for k in range(3)))
    keep = area2 > (1e-12 * extent * extent)
    if not np.any(keep):
        raise AasdfError("The mesh is degenerate: all of its triangles have zero area.")
    verts32 = np.ascontiguousarray(verts64, dtype=np.float32)
    return verts32, np.ascontiguousarray(tris[keep]), 0.5 * area2[keep], np.flatnonzero(keep).astype(np.int32)


def any_corner(marked: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(N,) bool: the rows ((N, K) vertex indices: faces, edges) with a corner ``marked`` (per vertex). Column by
    column: ``marked[rows].any(axis=1)`` gives the same, several times slower (numpy reduces a short axis slowly)."""
    out = marked[rows[:, 0]].copy()
    for k in range(1, rows.shape[1]):
        out |= marked[rows[:, k]]
    return out


def all_corners(marked: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(N,) bool: the rows with every corner ``marked`` (as :func:`any_corner`)."""
    out = marked[rows[:, 0]].copy()
    for k in range(1, rows.shape[1]):
        out &= marked[rows[:, k]]
    return out


def defect_edges(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A mesh with vertices at one position taken as one (:func:`weld_positions`) and its edges that are open,
    non-manifold or inconsistently oriented: ``(positions, triangles (T, 3) int32, edges (E, 2) int64)``."""
    return defect_edge_kinds(vertices, triangles)[:3]


def defect_edge_kinds(vertices: np.ndarray, triangles: np.ndarray) -> tuple:
    """:func:`defect_edges`, and per defect edge whether it is open (one face: a hole's edge; else an edge of more than
    two faces, or of two that list it the same way)."""
    verts, tris = weld_positions(vertices, triangles)
    tris = np.asarray(tris, dtype=np.int32)
    edges = edge_table(tris, len(verts))
    bad = (edges["faces"] != 2) | (edges["forward"] != 1)
    return verts, tris, edges["pairs"][bad].astype(np.int64), edges["faces"][bad] == 1


def weld_positions(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same triangles over one vertex per distinct position: (P, 3) positions, sorted as ``np.unique(axis=0)``
    sorts them, and (T, 3) int64 indices (the geometry, and so every distance and winding number, is unchanged)."""
    verts = np.asarray(vertices)
    if verts.dtype == np.float32:  # by keys that sort as the values do (a quarter of the time of three float columns)
        keys = _ordered_bits(verts)
        order = np.lexsort((keys[:, 2], (keys[:, 0] << np.uint64(32)) | keys[:, 1]))
    else:
        order = np.lexsort((verts[:, 2], verts[:, 1], verts[:, 0]))
    rows = verts[order]
    first = np.r_[True, (rows[1:] != rows[:-1]).any(axis=1)]  # first row of each run of equal positions
    index = np.empty(len(verts), dtype=np.int64)
    index[order] = np.cumsum(first) - 1
    return rows[first], index[np.asarray(triangles, dtype=np.int64)]


def _ordered_bits(points: np.ndarray) -> np.ndarray:
    """(N, 3) uint64 keys of float32 ``points`` that order as their values do (-0 taken as 0; no NaN): the bits of a
    positive value with the sign bit set, a negative value's bits inverted."""
    bits = (points + np.float32(0.0)).view(np.uint32)
    negative = bits >> np.uint32(31) == 1
    return np.where(negative, ~bits, bits | np.uint32(1 << 31)).astype(np.uint64)


def position_groups(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(first, inverse)``: the least index of each distinct position among ``points`` ((N, 3) float32) and each
    point's group, as ``np.unique(points, axis=0, return_index=True, return_inverse=True)`` gives them but for the
    groups' order (here by the positions' bits): one lexicographic sort of the float bits (-0 taken as 0), about a
    quarter of the time of a sort of rows."""
    bits = (np.ascontiguousarray(points, dtype=np.float32) + np.float32(0.0)).view(np.uint32).astype(np.uint64)
    high = (bits[:, 0] << np.uint64(32)) | bits[:, 1]
    order = np.lexsort((bits[:, 2], high))  # stable: each group's least index first
    high, low = high[order], bits[order, 2]
    start = np.r_[True, (high[1:] != high[:-1]) | (low[1:] != low[:-1])] if len(order) else np.zeros(0, bool)
    inverse = np.empty(len(order), dtype=np.int64)
    inverse[order] = np.cumsum(start) - 1
    return order[start], inverse


def compacted(tris: np.ndarray, n_verts: int) -> tuple[np.ndarray, np.ndarray]:
    """``(used, local)``: the vertices (of ``n_verts``) the triangles use, in order, and the triangles on them ((T, 3)
    int64): ``np.unique(tris, return_inverse=True)`` by a mark and a running count instead of a sort."""
    t = np.asarray(tris, dtype=np.int64)
    mark = np.zeros(n_verts, dtype=bool)
    mark[t.ravel()] = True
    used = np.flatnonzero(mark)
    rank = np.cumsum(mark) - 1
    return used, rank[t].reshape(-1, 3)


def edge_table(tris: np.ndarray, n_verts: int) -> dict:
    """The undirected edges of a triangle list, for the mesh checks below.

    Returns:
        ``{"pairs": (E, 2) int32 vertex pairs (low, high), "faces": (E,) int32 faces per edge, "forward": (E,) int32 of
        those listing it low -> high}``. The temporaries are one key per directed edge (uint32 where it fits, else
        int64) and int32 otherwise, and are freed as soon as they are used (a 2 M-triangle mesh's checks ran at the
        build's peak memory).
    """
    t = np.asarray(tris, dtype=np.int32)
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()  # every directed edge a -> b
    # one sort of the edges' keys with their direction in the lowest bit (no inverse permutation needed), in 32 bits
    # where they fit (half the sort's time: 69 k triangles 11 -> 5 ms)
    key_type = np.uint32 if 2 * n_verts * n_verts < 2**32 else np.int64
    keys = np.minimum(a, b).astype(key_type)
    keys *= key_type(n_verts)
    keys += np.maximum(a, b).astype(key_type)
    keys *= key_type(2)
    keys += a < b
    del a, b
    keys.sort()
    forward = (keys & 1).astype(np.int32)
    keys >>= 1
    start = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    unique = keys[start]
    del keys
    pairs = np.empty((len(unique), 2), dtype=np.int32)
    pairs[:, 0] = unique // n_verts
    pairs[:, 1] = unique % n_verts
    del unique
    faces = np.diff(np.r_[start, 3 * len(t)]).astype(np.int32)
    return {"pairs": pairs, "faces": faces, "forward": np.add.reduceat(forward, start).astype(np.int32)}


def open_vertices(tris: np.ndarray, n_verts: int) -> np.ndarray:
    """The vertices of the edges of ``tris`` not in exactly two triangles, opposite ways (none: closed)."""
    table = edge_table(tris, n_verts)
    return np.unique(table["pairs"][(table["faces"] != 2) | (table["forward"] != 1)])


def problem_faces(tris: np.ndarray, n_verts: int, edges: dict | None = None) -> np.ndarray:
    """(T,) int32, 1 for faces touching a vertex of an open, non-manifold or inconsistently oriented edge (a mesh
    without any is closed: no band refinement, signs spread everywhere). ``edges``: ``edge_table(tris, n_verts)``."""
    edges = edge_table(tris, n_verts) if edges is None else edges
    bad_edge = (edges["faces"] != 2) | (edges["forward"] != 1)
    if not bad_edge.any():
        return np.zeros(len(tris), dtype=np.int32)
    bad_vertex = np.zeros(n_verts, dtype=bool)
    bad_vertex[edges["pairs"][bad_edge].ravel()] = True
    return bad_vertex[np.asarray(tris)].any(axis=1).astype(np.int32)


MAX_HOLE_CAPS = 32  # more boundary pieces than this share one cone


def _boundary_pieces(pairs: np.ndarray) -> np.ndarray:
    """Connected piece of each edge of a boundary given as (E, 2) vertex pairs: (E,) labels 0..P-1."""
    ends, local = np.unique(pairs, return_inverse=True)
    local = local.reshape(-1, 2)
    label = np.arange(len(ends))
    while True:  # hook every vertex to the smallest label among its edges, then shortcut, until stable
        low = np.minimum(label[local[:, 0]], label[local[:, 1]])
        hooked = label.copy()
        np.minimum.at(hooked, local[:, 0], low)
        np.minimum.at(hooked, local[:, 1], low)
        hooked = hooked[hooked]
        if np.array_equal(hooked, label):
            break
        label = hooked
    return np.unique(label, return_inverse=True)[1].reshape(-1)[local[:, 0]]


def _cycle_order(tails: np.ndarray, heads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An order of directed edges (tails -> heads, vertex ids) of a balanced graph (as many edges into each vertex as
    out of it) in which they form cycles, each edge followed by one leaving its head: (order (E,), first (E,) bool,
    whether each edge of the order starts a cycle). Each vertex's incoming edges are paired with its outgoing ones;
    the cycles of that pairing are listed by pointer jumping (list ranking), without a loop over the edges."""
    n = len(tails)
    succ = np.empty(n, dtype=np.int64)
    succ[np.argsort(heads, kind="stable")] = np.argsort(tails, kind="stable")
    pred = np.empty(n, dtype=np.int64)
    pred[succ] = np.arange(n)
    label, jump = np.arange(n), succ.copy()
    while True:  # each edge's cycle: its smallest edge
        low = np.minimum(label, label[jump])
        jump = jump[jump]
        if np.array_equal(low, label):
            break
        label = low
    ptr = np.where(label == np.arange(n), -1, pred)  # cut each cycle before its smallest edge
    rank = (ptr >= 0).astype(np.int64)
    while (ptr >= 0).any():
        valid = ptr >= 0
        safe = np.where(valid, ptr, 0)
        rank = rank + np.where(valid, rank[safe], 0)
        ptr = np.where(valid, ptr[safe], -1)
    order = np.lexsort((rank, label))
    return order, rank[order] == 0


def hole_boundary(vertices: np.ndarray, triangles: np.ndarray, edges: dict | None = None):
    """An open mesh's boundary as directed edges with their cones, and the caps bounding how far its winding number
    may be from an integer (see :func:`hole_caps`); None when every edge cancels.

    The boundary G is the mesh's edges whose two orientations do not cancel (open, or inconsistently oriented), each
    directed the way the triangles list it more often, as many times as more often. Its connected pieces G_c are
    closed: the cone over G_c from the centre of G_c's bounding box is one triangle (apex, end, start) per edge, and
    the mesh and all cones form a closed surface, whose winding number is an integer. The edges come piece by piece,
    in cycles (each edge starting where the one before it ends, but at the start of a cycle), so sums over them share
    the vertices' and the apexes' terms.

    Args:
        vertices: (V, 3) float positions (welded, see :func:`weld_positions`, so seams are not boundary).
        triangles: (T, 3) int indices.
        edges: ``edge_table(triangles, len(vertices))`` when already at hand.
    Returns:
        None, or ``{"start": (E, 3) float32, "end": (E, 3) float32, "apex": (E, 3) float32 the cone apex of each
        edge, "links": (E,) uint8, bit 0 set where an edge starts at the previous one's end and bit 1 where it has
        the previous one's apex, "caps": (box lo (K, 3), box hi (K, 3), radius (K,))}``.
    """
    edges = edge_table(triangles, len(vertices)) if edges is None else edges
    net = 2 * edges["forward"] - edges["faces"]  # low -> high minus high -> low
    open_edges = net != 0
    if not open_edges.any():
        return None
    pairs = edges["pairs"][open_edges]
    net = net[open_edges]
    piece = _boundary_pieces(pairs)
    if piece.max() + 1 > MAX_HOLE_CAPS:
        piece = np.zeros_like(piece)
    k = int(piece.max()) + 1
    verts = np.asarray(vertices, dtype=np.float64)
    a, b = (verts[pairs[:, c]] for c in (0, 1))
    lo = np.full((k, 3), np.inf)
    hi = np.full((k, 3), -np.inf)
    np.minimum.at(lo, piece, np.minimum(a, b))
    np.maximum.at(hi, piece, np.maximum(a, b))
    centre = 0.5 * (lo + hi)
    tri_area = 0.5 * np.linalg.norm(np.cross(a - centre[piece], b - centre[piece]), axis=1) * np.abs(net)
    area = np.bincount(piece, weights=tri_area, minlength=k)
    # one directed edge per unit of multiplicity, then cycles within each piece
    copies = np.repeat(np.arange(len(net)), np.abs(net))
    tails = np.where(net > 0, pairs[:, 0], pairs[:, 1])[copies]
    heads = np.where(net > 0, pairs[:, 1], pairs[:, 0])[copies]
    order, first = _cycle_order(tails, heads)
    order_piece = piece[copies][order]
    by_piece = np.argsort(order_piece, kind="stable")  # cycles stay whole: each lies in one piece
    order, first, order_piece = order[by_piece], first[by_piece], order_piece[by_piece]
    same_apex = np.r_[False, order_piece[1:] == order_piece[:-1]]
    return {
        "start": verts[tails[order]].astype(np.float32),
        "end": verts[heads[order]].astype(np.float32),
        "apex": centre[order_piece].astype(np.float32),
        "links": ((~first).astype(np.uint8) | (same_apex.astype(np.uint8) << 1)).astype(np.uint8),
        "caps": (lo, hi, np.sqrt(area / math.pi)),
    }


def hole_caps(vertices: np.ndarray, triangles: np.ndarray, edges: dict | None = None):
    """Where an open mesh's winding number may be far from an integer: (box lo (K, 3), box hi (K, 3), radius (K,)),
    or None.

    Let G be the mesh's boundary: its edges whose two orientations do not cancel (open, or inconsistently oriented),
    with multiplicity, split into its K connected pieces G_c, and C_c the cone over G_c from the centre of G_c's
    bounding box. Each piece is a closed 1-cycle, so the mesh minus all cones is closed: its winding number is an
    integer that changes only across the mesh or a cone, and the mesh's winding number differs from it by the cones',
    each at most area(C_c) / (4 pi d_c^2) at distance d_c from C_c. With ``radius_c = sqrt(area(C_c) / pi)``, where
    the sum over c of (radius_c / d_c)^2 stays below 1, d_c now the distance to the box c (which holds C_c), their
    sum is below 1/4: there the winding number w stays within 1/4 of an integer k, so |w| >= 1/2 (inside) exactly when
    k != 0, and two points joined by a segment that crosses no triangle (nor, being off the boxes, a cone) are on the
    same side, and signs may spread between nodes as on a closed mesh (the kernels' ``near_cap`` test). One cone per
    piece keeps the caps of holes far apart small; beyond ``MAX_HOLE_CAPS`` pieces a single cone over the whole
    boundary is used. Returns None when every edge cancels (closed, consistently oriented, possibly non-manifold).
    ``edges``: ``edge_table(triangles, len(vertices))`` when already at hand.
    """
    boundary = hole_boundary(vertices, triangles, edges)
    return None if boundary is None else boundary["caps"]


# Vertices within this share of the mesh's extent of one plane make a flat mesh (float32 rounding: 6e-8).
FLAT_TOLERANCE = 1.0e-6


def encloses_nothing(vertices: np.ndarray, boundary) -> bool:
    """Whether an open mesh encloses no volume because it is flat: its vertices on one plane (within
    ``FLAT_TOLERANCE``), however often its triangles cover that plane.

    Off the plane, w(x) = +-1/4pi times the integral over the plane of c dOmega_x, c the number of times the triangles
    cover a point (with their orientations). Where c is 0 or +-1 everywhere, |w| < 1/2 off the plane: nothing is inside.
    Where the sheet covers part of its plane twice (a plane arrayed over itself, two faces on one square), |w| comes
    near 1 beside that part, and the winding number would make a lens of it whose surface touches the sheet, not a
    2-manifold (a shell of it came out open). A flat mesh encloses no volume however it covers its plane: it is
    outside everywhere, and refused or given a wall as any sheet is.

    Args:
        vertices: (V, 3) float positions.
        boundary: :func:`hole_boundary` of the mesh (None: closed, never taken as flat here: a closed flat mesh's
            winding number is 0 off it).
    Returns:
        bool.
    """
    verts = np.asarray(vertices, dtype=np.float64)
    centre = verts.mean(axis=0)
    offsets = verts - centre
    extent = float(np.abs(offsets).max())
    if boundary is None or extent == 0.0:
        return False
    normal = np.linalg.eigh(offsets.T @ offsets)[1][:, 0]  # (ascending: the first axis is the plane's normal)
    return bool(np.abs(offsets @ normal).max() <= FLAT_TOLERANCE * extent)


def open_tunnels(surface: dict, quads: np.ndarray, sides: np.ndarray, points: np.ndarray) -> None:
    """Give the flagged sides of the flagged quads a vertex of their own (in place).

    Two cubes that each cross their shared face with one patch in two segments make the marching cubes surface a
    tunnel through that face, and their two dual vertices meet along two dual edges at once: one per segment. As an
    indexed mesh that would be one edge of four triangles. The sides of the second segment's quads (flagged by
    ``dual._quads_kernel``) get a vertex between the two cubes' vertices, at the middle of those quads' edge crossings,
    and each such quad becomes a fan around its first new vertex: the edge of the first segment stays, the second
    becomes a path through the new vertex.

    Args:
        surface: ``verts``, ``tris``, ``ranks``, ``cells`` of :func:`.dual.contour_dual`, quad q as rows 2q and 2q + 1
            (q0, q1, q2), (q0, q2, q3) where flagged.
        quads: (Q,) flagged quad indices; sides: (Q,) their bit masks (bit k: side q_k, q_k+1); points: (Q, 3) their
            edges' crossing points.
    """
    verts, tris = surface["verts"], surface["tris"]
    corners = np.concatenate([tris[2 * quads], tris[2 * quads + 1][:, 2:]], axis=1).astype(np.int64)  # (Q, 4)
    bit = (sides[:, None] >> np.arange(4)) & 1 == 1  # (Q, 4)
    row, k = np.nonzero(bit)
    ends = np.stack([corners[row, k], corners[row, (k + 1) % 4]], axis=1)
    keys, group = np.unique(ends.min(1) * len(verts) + ends.max(1), return_inverse=True)
    new_points = np.zeros((len(keys), 3), dtype=np.float64)
    np.add.at(new_points, group, points[row])
    new_points /= np.bincount(group, minlength=len(keys))[:, None]
    # each quad as a polygon of up to 8 slots (q0, m0, q1, m1, ...), started at its first new vertex
    slots = np.full((len(quads), 8), -1, dtype=np.int64)
    slots[:, 0::2] = corners
    slots[row, 2 * k + 1] = len(verts) + group
    start = 2 * np.argmax(bit, axis=1) + 1
    slots = np.take_along_axis(slots, (start[:, None] + np.arange(8)) % 8, axis=1)
    slots = np.take_along_axis(slots, np.argsort(slots < 0, axis=1, kind="stable"), axis=1)  # used slots first
    size = (slots >= 0).sum(axis=1)
    fan = np.stack([np.repeat(slots[:, :1], 6, axis=1), slots[:, 1:7], slots[:, 2:8]], axis=-1)  # (Q, 6, 3)
    fans = fan[np.arange(6)[None, :] < (size - 2)[:, None]]
    keep = np.ones(len(tris), dtype=bool)
    keep[2 * quads] = keep[2 * quads + 1] = False
    surface["tris"] = np.concatenate([tris[keep], fans.astype(np.int32)])
    if "whole" in surface:  # the fans are no quads
        surface["whole"] = surface["whole"][keep[1::2]]
    surface["verts"] = np.concatenate([verts, new_points.astype(np.float32)])
    surface["ranks"] = np.concatenate([surface["ranks"], np.ones(len(keys), dtype=np.int32)])
    first = np.unique(group, return_index=True)[1]
    surface["cells"] = np.concatenate([surface["cells"], surface["cells"][ends[first, 0]]])
    surface["tunnels"] = len(keys)
