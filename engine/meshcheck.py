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


def _triangle_areas(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(T,) areas, component by component (numpy's cross and norm over (T, 3) arrays are several times slower)."""
    a, b, c = (verts[tris[:, k]] for k in range(3))
    e, f = b - a, c - a
    x = e[:, 1] * f[:, 2] - e[:, 2] * f[:, 1]
    y = e[:, 2] * f[:, 0] - e[:, 0] * f[:, 2]
    z = e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0]
    return 0.5 * np.sqrt(x * x + y * y + z * z)


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
    area2 = 2.0 * _triangle_areas(verts64, tris)
    extent = float(max(np.ptp(verts64[:, k]) for k in range(3)))
    keep = area2 > (1e-12 * extent * extent)
    if not np.any(keep):
        raise AasdfError("The mesh is degenerate: all of its triangles have zero area.")
    verts32 = np.ascontiguousarray(verts64, dtype=np.float32)
    return verts32, np.ascontiguousarray(tris[keep]), 0.5 * area2[keep], np.flatnonzero(keep).astype(np.int32)


def weld_positions(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same triangles over one vertex per distinct position: (P, 3) positions, sorted as ``np.unique(axis=0)``
    sorts them, and (T, 3) int64 indices (the geometry, and so every distance and winding number, is unchanged)."""
    verts = np.asarray(vertices)
    order = np.lexsort((verts[:, 2], verts[:, 1], verts[:, 0]))
    rows = verts[order]
    first = np.r_[True, (rows[1:] != rows[:-1]).any(axis=1)]  # first row of each run of equal positions
    index = np.empty(len(verts), dtype=np.int64)
    index[order] = np.cumsum(first) - 1
    return rows[first], index[np.asarray(triangles, dtype=np.int64)]


def edge_table(tris: np.ndarray, n_verts: int) -> dict:
    """The undirected edges of a triangle list, for the mesh checks below.

    Returns:
        ``{"pairs": (E, 2) int64 vertex pairs (low, high), "faces": (E,) faces per edge, "forward": (E,) of those
        listing it low -> high}``.
    """
    t = np.asarray(tris, dtype=np.int64)
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()  # every directed edge a -> b
    # one sort of the edges' keys with their direction in the lowest bit (no inverse permutation needed)
    keys = np.sort((np.minimum(a, b) * n_verts + np.maximum(a, b)) * 2 + (a < b))
    edge = keys >> 1
    start = np.flatnonzero(np.r_[True, edge[1:] != edge[:-1]])
    unique = edge[start]
    return {
        "pairs": np.stack([unique // n_verts, unique % n_verts], axis=1),
        "faces": np.diff(np.r_[start, len(keys)]),
        "forward": np.add.reduceat(keys & 1, start),
    }


def problem_faces(tris: np.ndarray, n_verts: int, edges: dict | None = None) -> np.ndarray:
    """(T,) int32, 1 for faces touching a vertex of an open, non-manifold or inconsistently oriented edge (a mesh
    without any is closed: no band refinement, signs spread everywhere). ``edges``: ``edge_table(tris, n_verts)``."""
    edges = edge_table(tris, n_verts) if edges is None else edges
    bad_edge = (edges["faces"] != 2) | (edges["forward"] != 1)
    bad_vertex = np.zeros(n_verts, dtype=bool)
    bad_vertex[edges["pairs"][bad_edge].ravel()] = True
    return bad_vertex[np.asarray(tris, dtype=np.int64)].any(axis=1).astype(np.int32)


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


def hole_caps(vertices: np.ndarray, triangles: np.ndarray, edges: dict | None = None):
    """Where an open mesh's winding number may be far from an integer: (box lo (K, 3), box hi (K, 3), radius (K,)),
    or None.

    Let G be the mesh's boundary: its edges whose two orientations do not cancel (open, or inconsistently oriented),
    with multiplicity, split into its K connected pieces G_c, and C_c the cone over G_c from the centre of G_c's
    bounding box. Each piece is a closed 1-cycle, so the mesh minus all cones is closed: its winding number is an
    integer that changes only across the mesh or a cone, and the mesh's winding number differs from it by the cones',
    each at most area(C_c) / (4 pi d_c^2) at distance d_c from C_c. With ``radius_c = sqrt(area(C_c) / pi)``, where
    the sum over c of (radius_c / d_c)^2 stays below 1, d_c now the distance to the box c (which holds C_c), their
    sum is below 1/4: there the winding number stays within 1/4 of an integer, so two points joined by a segment that
    crosses no triangle are on the same side of 0.5, and signs may spread between nodes as on a closed mesh (the
    kernels' ``near_cap`` test). One cone per piece keeps the caps of holes far apart small; beyond
    ``MAX_HOLE_CAPS`` pieces a single cone over the whole boundary is used. Returns None when every edge cancels
    (closed, consistently oriented, possibly non-manifold). ``edges``: ``edge_table(triangles, len(vertices))`` when
    already at hand.
    """
    edges = edge_table(triangles, len(vertices)) if edges is None else edges
    net = 2 * edges["forward"] - edges["faces"]  # low -> high minus high -> low
    open_edges = net != 0
    if not open_edges.any():
        return None
    pairs = edges["pairs"][open_edges]
    piece = _boundary_pieces(pairs)
    if piece.max() + 1 > MAX_HOLE_CAPS:
        piece = np.zeros_like(piece)
    k = int(piece.max()) + 1
    a, b = (np.asarray(vertices, dtype=np.float64)[pairs[:, c]] for c in (0, 1))
    lo = np.full((k, 3), np.inf)
    hi = np.full((k, 3), -np.inf)
    np.minimum.at(lo, piece, np.minimum(a, b))
    np.maximum.at(hi, piece, np.maximum(a, b))
    apex = 0.5 * (lo + hi)[piece]
    tri_area = 0.5 * np.linalg.norm(np.cross(a - apex, b - apex), axis=1) * np.abs(net[open_edges])
    area = np.bincount(piece, weights=tri_area, minlength=k)
    return lo, hi, np.sqrt(area / math.pi)


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
    surface["verts"] = np.concatenate([verts, new_points.astype(np.float32)])
    surface["ranks"] = np.concatenate([surface["ranks"], np.ones(len(keys), dtype=np.int32)])
    first = np.unique(group, return_index=True)[1]
    surface["cells"] = np.concatenate([surface["cells"], surface["cells"][ends[first, 0]]])
    surface["tunnels"] = len(keys)
