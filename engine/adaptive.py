"""Adaptivity: the dual surface's vertices clustered over octree blocks where the surface is flat, checked 2-manifold.

Ju et al.'s octree simplification of dual contouring (2002) merges the cells of an octree bottom-up while the error
of the merged cell's vertex stays under a bound; Schaefer, Ju and Warren (2007) keep that 2-manifold by giving a
cell one vertex per surface component in it and merging only where each is a disk. This module does the same on the
extracted polygons, as vertex clustering over the octree's blocks:

1. Vertices are sorted into classes: smooth ones, ones inside a reconstructed crease line (rank 2, two crease
   edges) and corners, crease ends and vertices along a seam between two source regions (operands, or the regions
   the caller names: materials, UV islands), which never merge, so creases, corners and seams stay where they are;
   each edge gets the level from which it may join its ends (:mod:`.blockedges`, in Warp).
2. Level by level (blocks of 2, 4, 8... cells a side, up to :func:`max_level`), the vertices of a block that merged
   at the level below are split into components: smooth vertices joined by the mesh's edges, crease vertices by the
   crease edges, never across two source regions. A component merges into one vertex when it is a disk (V - E + F
   = 1 over the faces, edges and vertices inside it) and every vertex in it lies within :func:`tolerance` of the
   plane fitted through them (a crease component: of the line; :mod:`.flatness`, in Warp). The components are found
   over the clusters of the level below (:mod:`.components`, union-find in Warp), the edges and faces kept by their
   ends' cluster ids; those inside a merged component are counted once and leave: a level looks only at those
   across its clusters, and only the flatness test looks at the vertices.
3. Each merged component becomes one vertex at its vertices' mean (a smooth one taken a Newton step onto the
   field's surface); faces are re-indexed, repeated corners dropped, a face left with fewer than 3 corners
   vanishes. A vertex left in two faces only (a fin: a lone vertex between two merged ones, its two faces folded
   onto each other) drops out of them. A quad left bent (not planar and convex within :data:`.quads.QUAD_ANGLE`) is
   split along the diagonal between two crease vertices, else the less folded one.
4. The result is checked: every edge in exactly two faces, opposite ways, every vertex's faces one fan, no face
   repeating a corner, every merged face's centre within FACE_REACH tolerances of the field's surface and facing
   the way its gradient does there (none turned over), then no face with a merged corner passing through another
   face (:mod:`.mergecross`). The components at any failure (at a stray, turned or crossing face,
   its corners of the highest level alone) drop one level and the check runs again, until none fails (at worst
   every vertex is back at level 0: the surface as extracted), so the result is closed and 2-manifold always.
   A round samples the field only where the one before did not (clusters and triangles by their levels and ids).

Folds of the surface as extracted (dual contouring's, where a crease vertex is pulled onto its crease) are left as
they are: no merge made them.
"""

from __future__ import annotations

import numpy as np

from .blockedges import edge_levels
from .components import connected_components
from .flatness import far_components
from .mergecross import crossing_corners
from .normalsums import quad_normal_sums
from .quadric import CREASE_ANGLE
from .quads import QUAD_ANGLE

# A merged surface's faces keep their centres within this many times the tolerance of the field's surface (else
# their vertices' components drop a level, as at a manifold failure).
FACE_REACH = 3.0


# Crease lines of fewer vertices are no creases here (their vertices merge as smooth ones where flat enough).
MIN_CREASE = 6


# A merged smooth vertex this near the field's surface (voxels) takes no Newton step onto it: near a crease the linear
# values bend by as much, and a step there moved the merged planar faces of the low adaptivities off their plane
# (cube - bore at 0.05: Hausdorff p95 0.015 -> 0.017 voxel).
STAY_VOXELS = 0.05

# Rounds of the manifold check (step 4); after them any block still at a failure goes back to level 0. A failing
# block drops one level a round: dropped faster (by 2 from the third round, 3 from the fifth), blocks that would have
# passed a level or two lower went below it, and the highest adaptivities gave more polygons than 0.75 (cube - bore
# 1,534 at 0.75, 1,579 at 1; one level a round: 1,512 and 1,365 at the same Hausdorff p95; with only a stray face's
# largest merge dropping, :func:`_strays`, 1,476 and 1,175, in 6 and 8 rounds; fandisk - cylinder takes 9 at 1).
CHECK_ROUNDS = 8


def tolerance(adaptivity: float) -> float:
    """Largest distance (voxels) of a merged block's vertices from its plane (or crease line): 0.01 voxel up to
    adaptivity 0.05 (only what is flat to float rounding: the planar faces merge, losing nothing), 0.22 at 0.5, 1.5
    at 1 (linear, then cubic and steeper: the high adaptivities trade accuracy for polygons, as Grid to Mesh's do;
    rocker-arm - cube at 1 gives 1,969 polygons at a Hausdorff p95 of 1.40 voxels, Grid to Mesh's 1 2,081 at 1.52).
    The faces between two merged vertices span two blocks, so on a curved surface they stray farther."""
    a = float(adaptivity)
    return 0.01 + 0.24 * max(a - 0.05, 0.0) / 0.95 + 0.75 * a**3 + 0.5 * a**8


# From this adaptivity on, a crease line whose mean fold is under :func:`hard_fold` is no crease (its vertices merge
# as smooth ones where flat enough), and neither is a corner off every crease line: at the high adaptivities the
# crease ends and corners of soft folds (along fillets, where a blend meets a face) held most of the vertices that never
# merged (rocker-arm - cube at adaptivity 1: 426 of 2,072, and as many again held beside them).
SOFT_FROM = 0.5

# The fold (degrees) under which a crease line is soft at adaptivity 1 (CREASE_ANGLE at SOFT_FROM, linear between).
# Judged by the line's mean fold: by each edge's, a seam whose fold varies along it (a sphere through a prism's
# sides) falls apart into short lines and crease ends that merge less than the line did (hex prism & sphere at
# adaptivity 1: 3,070 polygons against 884).
SOFT_FOLD = 45.0


def hard_fold(adaptivity: float) -> float:
    """Smallest mean fold (degrees) of a crease line kept as a crease at ``adaptivity``: CREASE_ANGLE up to
    SOFT_FROM, SOFT_FOLD at 1."""
    a = max(float(adaptivity) - SOFT_FROM, 0.0) / (1.0 - SOFT_FROM)
    return CREASE_ANGLE + (SOFT_FOLD - CREASE_ANGLE) * a


def max_level(adaptivity: float) -> int:
    """Largest block merged: 2^level cells a side, 2 (4 cells) at adaptivity up to 0.25 ... 6 (64 cells) at 1."""
    return max(1, int(np.ceil(6.0 * float(adaptivity))))


def simplify(field, surface: dict, adaptivity: float, regions=None, *, coarser: int = 0) -> dict:
    """Merge the polygons of an unplaced field's dual surface where it is flat (see the module's steps).

    Args:
        field: The unplaced ``AdaptiveField`` the surface came from (its lattice and sources).
        surface: ``verts`` (V, 3) float32, ``faces`` (C,) and ``sizes`` (P,) polygons, ``creases`` (E, 2),
            ``ranks`` (V,) quadric ranks (:func:`.dual.contour_dual`).
        adaptivity: In (0, 1].
        regions: Optional {field id: (T,) int label per source triangle}: vertices whose closest triangles have
            different labels never merge.
        coarser: The surface was contoured this many levels above the finest (cells of 2^coarser voxels,
            :mod:`.coarse`): its blocks are that lattice's, the tolerance and the largest block (in voxels) as on the
            finest; the field is still sampled at its finest.
    Returns:
        dict as ``surface`` (``verts``, ``faces``, ``sizes``, ``creases`` renumbered), unused vertices dropped.
    """
    verts = np.asarray(surface["verts"], dtype=np.float64)
    faces, sizes = np.asarray(surface["faces"], dtype=np.int32), np.asarray(surface["sizes"], dtype=np.int64)
    h = float(field.voxel_size) * 2**coarser
    local = (verts - np.asarray(field.origin, dtype=np.float64)) / h  # cells
    cell = np.floor(local - 0.5).astype(np.int64)
    creases = np.asarray(surface["creases"], dtype=np.int64).reshape(-1, 2)
    cls, lines = _classes(surface["ranks"], creases, surface.get("folds"), adaptivity, len(verts))
    label = _labels(field, surface["verts"], regions)
    corners = _padded(faces, sizes)
    edges = edge_levels(corners, cls, label, lines, cell, field.device)  # seams held (cls 0)
    tol, top = tolerance(adaptivity) / 2**coarser, max(max_level(adaptivity) - coarser, 1)
    level, ids, inner = _levels(local, edges, corners, cls, (tol, top), field.device)
    merged = _checked((field, h), local, (corners, inner), cls, level, ids, tol)
    return _renumbered((field, h), surface, creases, level, merged)


def _checked(lattice, local, faces, cls, level, ids, tol) -> dict:
    """Step 3 and 4: the clusters of ``level`` (changed in place) collapsed (``faces``: corners (P, 4) and the level
    each is inside one component, :func:`_levels`) and checked, the components at a failure dropped (by a level a
    round, after CHECK_ROUNDS to level 0) until none fails. What a round finds of a cluster's position on the
    surface and of a triangle's distance from it is kept for the next (by the clusters' keys: their level and id).
    ``lattice``: (the field sampled, the cell size); ``local`` and ``tol`` in cells.
    Returns the surface that passed: ``cluster`` (V,), ``position`` (K, 3) cells, ``faces``, ``sizes``."""
    keys = int(ids[1].sum())
    known = {"position": np.full((keys, 3), np.nan), "mean": np.full((keys, 6), np.nan)}
    outward = quad_normal_sums(local, faces[0], lattice[0].device)  # as extracted, outward as the faces are
    vertices = np.concatenate([local, outward], axis=1)  # a cluster's normal: its vertices' faces' as extracted
    known.update(tris=np.zeros(0, np.int64), far=np.zeros(0, dtype=bool))
    code = _keys(level, ids, np.arange(len(level)))  # each vertex's cluster's key
    round_ = 0
    while True:  # ends: every round drops a merged component, and the surface as extracted passes
        cluster, (position, normals), feature, merged, key = _clusters(vertices, code, keys, cls, known["mean"])
        position = _onto_surface(lattice, (position, normals), ~feature & merged, tol, key, known["position"])
        collapsed = _collapse(*faces, cluster, level)
        new_faces, new_sizes = _split_bent_quads(position, feature, merged, *collapsed, tol)
        bad = _failures(len(position), new_faces, new_sizes)
        levels = np.zeros(len(position), dtype=np.int64)
        levels[cluster] = level  # each cluster's (its vertices share it)
        clusters = (position, normals, levels)
        bad |= _strays(lattice, clusters, new_faces, new_sizes, merged, FACE_REACH * tol, key, known)
        if not bad.any():  # (a round that passed the rest: merged faces through others, :mod:`.mergecross`)
            bad = crossing_corners(position, new_faces, new_sizes, merged, levels, lattice[0].device)
        if not bad.any() or not (level > 0).any():
            break
        drop = bad[cluster] & (level > 0)
        if not drop.any():  # a failure at vertices left alone: their merged neighbours'
            drop = _spread(bad, new_faces, new_sizes)[cluster] & (level > 0)
        if not drop.any():  # (a failure of the surface as extracted) nothing merged
            drop = level > 0
        level[drop] = 0 if round_ >= CHECK_ROUNDS - 1 else np.maximum(level[drop] - 1, 0)
        drop = np.flatnonzero(drop)
        code[drop] = _keys(level, ids, drop)
        round_ += 1
    return {"cluster": cluster, "position": position, "faces": new_faces, "sizes": new_sizes}


def _spread(bad, faces, sizes) -> np.ndarray:
    """``bad`` (K,) grown to every corner of the faces with a corner in it."""
    face_of = np.repeat(np.arange(len(sizes)), sizes)
    hit = np.zeros(len(sizes), dtype=bool)
    hit[face_of[bad[faces]]] = True
    out = bad.copy()
    out[faces[hit[face_of]]] = True
    return out


def _renumbered(lattice, surface, creases, level, merged) -> dict:
    """The checked surface in world units, unmerged vertices exactly where they were, unused vertices dropped."""
    cluster, position, new_faces = merged["cluster"], merged["position"], merged["faces"]
    field, h = lattice
    out_verts = (np.asarray(field.origin, dtype=np.float64) + h * position).astype(np.float32)
    alone = level == 0
    out_verts[cluster[alone]] = surface["verts"][alone]
    used = np.zeros(len(out_verts), dtype=bool)
    used[new_faces] = True
    ends = np.sort(cluster[creases], axis=1).astype(np.int64)  # each pair once, as one integer (unique rows: 5x)
    pair = np.unique(ends[:, 0] * len(out_verts) + ends[:, 1])
    crease = np.stack([pair // len(out_verts), pair % len(out_verts)], axis=1)
    crease = crease[(crease[:, 0] != crease[:, 1]) & used[crease].all(axis=1)]
    number = np.cumsum(used) - 1
    return {
        "verts": out_verts[used],
        "faces": number[new_faces].astype(np.int32),
        "sizes": merged["sizes"].astype(np.int32),
        "creases": number[crease].astype(np.int32),
    }


def _strays(lattice, clusters, faces, sizes, merged, reach: float, key, known: dict) -> np.ndarray:
    """(K,) the vertices of faces whose fan triangles' centres lie more than ``reach`` voxels from the field's
    surface (a face between two merged vertices across a curved part) or that face against their corners' clusters'
    normals (``clusters``: position, normal and level of each: turned over, a fold where a merged vertex moved past
    its neighbours, as a concave quad's fan or a face across a narrow part); only faces with a ``merged`` corner, and
    of each only the corners of its highest level (the largest merge drops; a neighbour merged less stays where it
    passes: dropped as well, it went below where it would have stopped, and higher adaptivities gave more polygons
    than lower ones, the plate 770 at 0.85 against 670 at 0.75). The triangles' results are ``known`` (``tris``: sorted
    keys of their corners' clusters, ``far``) for the next round, and taken from there."""
    tris = _fans(faces, sizes)
    touched = merged[tris]
    tris = tris.take(np.flatnonzero(touched[:, 0] | touched[:, 1] | touched[:, 2]), axis=0)
    far = np.zeros(len(tris), dtype=bool)
    if len(key) and int(key.max()) < 1 << 21:  # a triangle's clusters' keys in one integer
        tri_key = (key[tris[:, 0]] << 42) | (key[tris[:, 1]] << 21) | key[tris[:, 2]]
        at = np.minimum(np.searchsorted(known["tris"], tri_key), max(len(known["tris"]) - 1, 0))
        seen = known["tris"][at] == tri_key if len(known["tris"]) else np.zeros(len(tris), dtype=bool)
        far[seen] = known["far"][at[seen]]
    else:
        tri_key, seen = None, np.zeros(len(tris), dtype=bool)
    new = np.flatnonzero(~seen)
    field, h = lattice
    position, normals, levels = clusters
    t0, t1, t2 = tris[new].T
    c0, c1, c2 = position.T[:, t0], position.T[:, t1], position.T[:, t2]  # (3, m): numpy's rows are faster
    centres = np.asarray(field.origin, dtype=np.float64)[:, None] + h * ((c0 + c1 + c2) / 3.0)
    around = normals.T[:, t0] + normals.T[:, t1] + normals.T[:, t2]
    turned = _dot(_cross(c1 - c0, c2 - c0), around) < 0.0
    value = field.sample(np.ascontiguousarray(centres.T, dtype=np.float32), method="linear")
    far[new] = (np.abs(value) > reach * h) | turned
    if tri_key is not None:
        order = np.argsort(np.concatenate([known["tris"], tri_key[new]]))
        known["tris"] = np.concatenate([known["tris"], tri_key[new]])[order]
        known["far"] = np.concatenate([known["far"], far[new]])[order]
    bad = np.zeros(len(position), dtype=bool)
    strays = tris.take(np.flatnonzero(far), axis=0)
    top = levels[strays]
    bad[strays[top == top.max(axis=1)[:, None]]] = True
    return bad


def _onto_surface(lattice, clusters, moved, tol: float, key, known) -> np.ndarray:
    """The clusters' positions (``clusters``: (K, 3) cells and (K, 3) normals) with the rows ``moved`` that lie more
    than half ``tol`` off the field's surface taken one Newton step onto it along their normal (a merged smooth vertex,
    its vertices' mean, lies off a curved surface by the sagitta; on a flat one it stays, where the trilinear values
    bend near a crease; the field's linear samples carry no gradient, and an MLS one costs 6.5 times as much). The
    rows' results are ``known`` (by the clusters' ``key``, NaN where not yet) for the next round, and taken from
    there."""
    position, normals = clusters
    rows = np.flatnonzero(moved & np.isnan(known[key, 0]))
    if len(rows):
        field, h = lattice
        points = np.asarray(field.origin, dtype=np.float64) + h * position[rows]
        value = field.sample(points.astype(np.float32), method="linear").astype(np.float64)
        unit = normals[rows] / np.maximum(np.linalg.norm(normals[rows], axis=1), 1e-300)[:, None]
        step = value[:, None] * unit / h
        step[np.abs(value) <= max(0.5 * tol * h, STAY_VOXELS * field.voxel_size)] = 0.0
        known[key[rows]] = position[rows] - np.clip(step, -1.0, 1.0)  # at most a voxel a side: a mean beside a
        # thin part stays put
    out = position.copy()
    rows = np.flatnonzero(moved)
    out[rows] = known[key[rows]]
    return out


def _fans(faces, sizes) -> np.ndarray:
    """(T, 3) the fans of polygons (quads first, then triangles: by rows; others one by one)."""
    quads = np.count_nonzero(sizes == 4)
    if quads == len(sizes) or (sizes[quads:] == 3).all() and (not quads or sizes[quads - 1] == 4):
        square = faces[: 4 * quads].reshape(-1, 4)
        halves = np.stack([square[:, :3], square[:, [0, 2, 3]]], axis=1).reshape(-1, 3)
        return np.concatenate([halves, faces[4 * quads :].reshape(-1, 3)])
    start = np.cumsum(sizes) - sizes
    count = sizes - 2
    poly = np.repeat(np.arange(len(sizes)), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    first = start[poly]
    return np.stack([faces[first], faces[first + k + 1], faces[first + k + 2]], axis=1)


def _labels(field, verts, regions) -> np.ndarray:
    """(V,) int64 source region of each vertex: its operand's field id times 2^32, plus with ``regions`` the region
    of its closest source triangle (found only where an operand has more than one: labels are compared, never
    read)."""
    if regions is not None and all(len(labels) == 0 or np.ptp(labels) == 0 for labels in regions.values()):
        regions = None  # each operand one region (one material, no UV seam): its id tells them apart
    if regions is None:
        if len(field.field_ids) < 2:
            return np.zeros(len(verts), np.int64)
        return field.source_ids(verts).astype(np.int64) << np.int64(32)
    ids, tris, _ = field.closest_sources(verts)
    region = np.zeros(len(verts), dtype=np.int64)
    for field_id, labels in regions.items():
        rows = np.flatnonzero((ids == field_id) & (tris >= 0))
        region[rows] = np.asarray(labels, dtype=np.int64)[tris[rows]]
    return ids.astype(np.int64) * (np.int64(1) << 32) + region


def row_sums(index, values, n) -> np.ndarray:
    """(n, W) sums of the rows of ``values`` (N, W) by ``index`` (N,): one bincount per column (np.add.at is
    several times slower)."""
    return np.stack([np.bincount(index, weights=values[:, k], minlength=n) for k in range(values.shape[1])], axis=1)


def _classes(ranks, creases, folds, adaptivity, n) -> tuple[np.ndarray, np.ndarray]:
    """(V,) int8 what may merge with what: 1 smooth vertices, 2 vertices inside a crease line (rank 2, two crease
    edges), 0 corners and crease ends (never merge); and the creases kept as such. A crease line of fewer than
    MIN_CREASE vertices (a soft fold found here and there along a fillet) is no crease: its vertices are smooth; nor,
    above SOFT_FROM, one whose mean fold (``folds``: (E,) degrees, or None) is under :func:`hard_fold`."""
    creases = np.asarray(creases, dtype=np.int64).reshape(-1, 2)
    if len(creases):
        root = connected_components(n, creases[:, 0], creases[:, 1])
        line = root[creases[:, 0]]
        keep = np.bincount(root, minlength=n)[line] >= MIN_CREASE
        if folds is not None and adaptivity > SOFT_FROM:
            mean = np.bincount(line, weights=folds, minlength=n) / np.maximum(np.bincount(line, minlength=n), 1)
            keep &= mean[line] >= hard_fold(adaptivity)
        creases = creases[keep]
    degree = np.bincount(creases.ravel(), minlength=n)
    ranks = np.asarray(ranks)
    alone = 1 if adaptivity >= SOFT_FROM else np.where(ranks <= 2, 1, 0)  # a corner off every crease line
    cls = np.where(degree == 0, alone, np.where((degree == 2) & (ranks == 2), 2, 0))
    return cls.astype(np.int8), creases


def _levels(local, edges, corners, cls, bounds, device=None):
    """Level by level, the components of each block's vertices that merge (see the module's step 2). The edges and
    faces looked at are kept by the ids of their ends' clusters at the level below, and the clusters' counts of
    vertices, edges and faces inside carried up: a level's steps are over its clusters (but the flatness test).
    ``bounds``: (tolerance in cells, the largest level).

    Returns:
        ``level`` (V,) the largest level each vertex merged at (0: none); ``ids`` (L + 1, V): per level each vertex's
        component there (its cluster when that is its level; -1 where it did not merge at that level), with
        ``numbers`` (L + 1,) how many components each level numbers (V at level 0); and ``inner`` (P,) the level at
        which each face is inside a component that merged (the largest integer for none): gone once its vertices
        reach it (a cluster's vertices are all at one level, the clusters of a level unions of those below).
    """
    n = len(local)
    level = np.zeros(n, dtype=np.int8)
    ids, numbers = [np.arange(n, dtype=np.int32)], [n]
    tol, top = bounds
    live = cls > 0  # corners and crease ends never merge: their edges and faces never count
    points = _flatness_points(local, cls, device)
    u, v, joins = edges  # (:func:`.blockedges.edge_levels`)
    inner = np.full(len(corners), np.iinfo(np.int64).max)  # the level each face is inside one component
    face = np.flatnonzero(_all_columns(live[corners]))  # the faces looked at, and their corners' clusters below
    corners = corners[face]
    below = np.where(live, np.arange(n, dtype=np.int32), np.int32(-1))  # each vertex's cluster below (-1: none)
    clusters = np.flatnonzero(live)  # the clusters below
    held = None  # vertices, edges and faces inside each cluster below (at level 1: one vertex each)
    for lv in range(1, top + 1):
        if not len(clusters):
            break
        # joinable within one block: the edges ranked up to the level
        root = connected_components(numbers[-1], u, v, device, rank=joins, up_to=lv)
        number, k = _numbered(root[clusters], numbers[-1])  # the components, numbered 0 .. k - 1
        comp_of = np.zeros(numbers[-1], dtype=np.int32)  # each cluster below in one component
        comp_of[clusters] = number
        u, v, corners = comp_of[u], comp_of[v], comp_of[corners]
        one = _one_value(corners)
        counts = _inside(number, None if lv == 1 else held[clusters], u, v, corners[one, 0], k)
        ok = _merged(points, below, clusters, number, counts, k, tol, device)
        at = np.full(numbers[-1], -1, dtype=np.int32)
        at[clusters] = np.where(ok[number], number, -1)
        below = np.where(below >= 0, at[below], np.int32(-1))
        ids.append(below)
        numbers.append(k)
        level[below >= 0] = lv
        clusters, held = np.flatnonzero(ok), counts
        merged = ok[corners]
        inner[face[one & merged[:, 0]]] = lv
        if lv == top:
            break
        # the edges and faces inside a component are counted: they leave, as do those at a component not merged
        keep = ok[u] & ok[v] & (u != v)
        u, v, joins = u[keep], v[keep], joins[keep]
        keep = _all_columns(merged) & ~one
        corners, face = corners[keep], face[keep]
    return level, (np.stack(ids), np.array(numbers)), inner


def _flatness_points(local, cls, device):
    """The vertices (voxels) and whether each is measured against a line (a crease's), as :func:`.far_components`
    takes them (converted once for every level)."""
    import warp as wp

    device = wp.get_device(device)
    points = wp.array(np.ascontiguousarray(local, dtype=np.float64), dtype=wp.vec3d, device=device)
    return points, wp.array((cls == 2).astype(np.int8), dtype=wp.int8, device=device)


def _inside(number, held, u, v, within, k) -> np.ndarray:
    """(k, 4) the vertices, edges and faces inside each component: those ``held`` (N, 3) inside its clusters of the
    level below (``number`` (N,) their components; None: single vertices), and the edges ``u``-``v`` across them
    (by their ends' components) and the faces ``within`` one (their component each); and how many clusters of the
    level below it joins."""
    out = np.zeros((k, 4), dtype=np.int64)
    out[:, 3] = np.bincount(number, minlength=k)
    if held is None:  # single vertices
        out[:, 0] = out[:, 3]
    else:
        for j in range(3):
            out[:, j] = np.rint(np.bincount(number, weights=held[:, j], minlength=k)).astype(np.int64)
    out[:, 1] += np.bincount(u[u == v], minlength=k)
    out[:, 2] += np.bincount(within, minlength=k)
    return out


def _all_columns(flags) -> np.ndarray:
    """(N,) each row of ``flags`` (N, 4) all set (column by column: faster than ``all(axis=1)``)."""
    return flags[:, 0] & flags[:, 1] & flags[:, 2] & flags[:, 3]


def _any_column(flags) -> np.ndarray:
    """(N,) any of each row of ``flags`` (N, 4) set."""
    return flags[:, 0] | flags[:, 1] | flags[:, 2] | flags[:, 3]


def _one_value(values) -> np.ndarray:
    """(N,) each row of ``values`` (N, 4) all one value."""
    return (values[:, 0] == values[:, 1]) & (values[:, 1] == values[:, 2]) & (values[:, 2] == values[:, 3])


def _merged(points, below, clusters, number, inside, k, tol, device) -> np.ndarray:
    """(k,) the components that merge: a disk (V - E + F = 1 over the vertices, edges and faces ``inside`` (k, 4)
    it, :func:`_inside`), every vertex within ``tol`` of the plane through its vertices (a crease's: of the line;
    ``points`` as :func:`_flatness_points`, ``below`` (V,) each vertex's cluster of the ``clusters`` (N,), in the
    components ``number`` (N,); not tested again for a component that is one cluster of the level below: it
    passed)."""
    ok = inside[:, 0] - inside[:, 1] + inside[:, 2] == 1
    tested = ok & (inside[:, 0] > 1) & (inside[:, 3] != 1)  # a single vertex is flat
    if tested.any():
        vertices, on_line = points
        comp = np.full(int(clusters[-1]) + 1, -1, dtype=np.int32)  # each cluster's component tested (-1: none)
        comp[clusters] = np.where(tested[number], number, -1)
        ok &= ~far_components(vertices, below, comp, on_line, k, tol, device)
    return ok


def _numbered(keys, n: int):
    """Keys (N,) in 0 .. n - 1 numbered 0 .. m - 1 in their order (as ``np.unique``'s inverse, without a sort);
    returns the numbers and m."""
    seen = np.zeros(n, dtype=bool)
    seen[keys] = True
    number = np.cumsum(seen) - 1
    return number[keys], int(number[-1]) + 1 if n else 0


def _padded(faces, sizes) -> np.ndarray:
    """(P, 4) corners of triangles and quads, a triangle's last corner repeated."""
    quads = np.count_nonzero(sizes == 4)
    if quads == len(sizes) or (quads and sizes[quads - 1] == 4 and (sizes[quads:] == 3).all()):  # quads first
        tris = faces[4 * quads :].reshape(-1, 3)
        return np.concatenate([faces[: 4 * quads].reshape(-1, 4), tris[:, [0, 1, 2, 2]]])
    start = np.cumsum(sizes) - sizes
    return faces[start[:, None] + np.minimum(np.arange(4), sizes[:, None] - 1)]


def _keys(level, ids, rows) -> np.ndarray:
    """(R,) the key of the cluster of each vertex of ``rows``: its component at its ``level`` (``ids`` as
    :func:`_levels`' ids and numbers; itself at level 0), the levels' ids one after the other (the same cluster has
    the same key in every round of the check)."""
    ids, numbers = ids
    offset = np.cumsum(numbers) - numbers
    at = level[rows]
    return offset[at] + ids[at, rows]


def _clusters(vertices, code, keys: int, cls, known):
    """Each vertex's cluster (by its key ``code``, :func:`_keys`, of ``keys``), the clusters' positions (voxels: the
    mean of their vertices') and normals (the sum of their vertices'), from ``vertices`` (V, 6): each vertex's
    position and normal; whether each cluster is a crease or corner vertex, whether it merged vertices, and its key.
    The means and normals ``known`` (keys, 6) by key (NaN where not yet) are taken from there and added to: a key's
    vertices are the same in every round."""
    n = len(vertices)
    cluster, k = _numbered(code, keys)
    first = np.empty(k, dtype=np.int64)
    first[cluster] = np.arange(n)  # a vertex of each (all of one class)
    count = np.bincount(cluster, minlength=k)
    key = code[first]
    new = np.isnan(known[key, 0])
    rows = np.flatnonzero(new[cluster])  # the vertices of clusters new in this round
    sums = row_sums(cluster[rows], vertices[rows], k)[new]
    sums[:, :3] /= count[new, None]
    known[key[new]] = sums
    found = known[key]
    return cluster, (found[:, :3], found[:, 3:]), cls[first] != 1, count > 1, key


def _collapse(corners, inner, cluster, level):
    """Faces (``corners`` (P, 4), :func:`_padded`) re-indexed to clusters, corners equal to the one before them
    dropped, faces left with fewer than 3 corners gone (those ``inner`` a component at a level their vertices reach
    first: all their corners one cluster); then the corners at a vertex left in two faces only (a fin:
    two faces folded onto each other, where a lone vertex sits between two merged ones) dropped the same way, the
    vertex gone. Returns faces, sizes."""
    rows = np.flatnonzero(level[corners[:, 0]] < inner)  # the others vanish
    corners = cluster.take(corners.take(rows, axis=0))  # (take and compress: boolean rows index 5-10x slower)
    keep = corners != corners[:, [3, 0, 1, 2]]  # not a corner equal to the one before it
    sizes = keep.view(np.int8) @ np.ones(4, dtype=np.int8)
    alive = sizes >= 3
    keep &= alive[:, None]
    faces, sizes = corners.ravel().compress(keep.ravel()), sizes.compress(alive)
    for _ in range(2):
        fin = np.bincount(faces, minlength=len(cluster)) == 2
        if not fin.any():
            break
        faces, sizes = _dropped(faces, sizes, ~fin[faces])
    return faces, sizes


def _dropped(corners, sizes, keep):
    """Polygons (``corners`` (C,), ``sizes`` (P,)) without the corners not ``keep`` and those equal to the corner
    before them; faces left with fewer than 3 corners gone."""
    face_of = np.repeat(np.arange(len(sizes)), sizes)
    corners, face_of = corners[keep], face_of[keep]
    count = np.bincount(face_of, minlength=len(sizes))
    start = np.cumsum(count) - count
    within = np.arange(len(corners)) - start[face_of]
    prev = np.where(within == 0, start[face_of] + count[face_of] - 1, np.arange(len(corners)) - 1)
    keep = corners != corners[prev]
    count = np.bincount(face_of[keep], minlength=len(sizes))
    alive = count >= 3
    keep &= alive[face_of]
    return corners[keep], count[alive]


def _failures(n_verts, faces, sizes) -> np.ndarray:
    """Vertices at which the polygons (triangles and quads) are not a closed, oriented 2-manifold: a face repeating a
    corner, an edge not in exactly two faces opposite ways, a vertex whose faces are no single fan."""
    bad = np.zeros(n_verts, dtype=bool)
    if not len(sizes):
        return bad
    corners = _padded(faces, sizes)
    c0, c1, c2, c3 = corners.T
    quad = sizes == 4
    repeated = (c0 == c1) | (c0 == c2) | (c1 == c2) | (quad & ((c0 == c3) | (c1 == c3) | (c2 == c3)))
    bad[corners[repeated].ravel()] = True
    # each undirected edge (with the bit of its direction) exactly twice, once each way: sorted, two in a row; the
    # edges of the padded rows (a triangle's third c2 -> c2 left out)
    tail = np.concatenate([c0, c1, c2.compress(quad), c3]).astype(np.int64)
    head = np.concatenate([c1, c2, c3.compress(quad), c0]).astype(np.int64)
    n = np.int64(n_verts)
    low, high = np.minimum(tail, head), np.maximum(tail, head)
    keys = np.sort(2 * (low * n + high) + (tail > head))
    undirected = keys >> 1
    start = np.flatnonzero(np.r_[True, undirected[1:] != undirected[:-1]])
    paired = np.diff(np.r_[start, len(keys)]) == 2
    paired[paired] = keys[start[paired]] != keys[start[paired] + 1]  # one each way
    undirected = undirected[start]
    wrong = undirected[~paired]
    bad[wrong // n] = True
    bad[wrong % n] = True
    ends = np.concatenate([undirected // n, undirected % n])
    fan = np.bincount(ends, minlength=n_verts) != np.bincount(faces, minlength=n_verts)
    return bad | fan


def _split_bent_quads(position, feature, merged, faces, sizes, tol):
    """Quads with a ``merged`` corner no longer planar and convex (folded by more than QUAD_ANGLE, or their
    diagonals more than ``tol`` voxels apart) split in two: along the diagonal between two crease or corner vertices
    where only one diagonal is (the crease stays an edge), else along the less folded one; returns faces, sizes
    (quads first, then triangles)."""
    start = np.cumsum(sizes) - sizes
    is_quad = sizes == 4
    quads = faces[start[is_quad][:, None] + np.arange(4)]
    tris = faces[start[~is_quad][:, None] + np.arange(3)] if (~is_quad).any() else np.zeros((0, 3), np.int64)
    moved = np.flatnonzero(_any_column(merged[quads]))  # a quad as extracted stays as it was
    p0, p1, p2, p3 = position.T[:, quads[moved].T].transpose(1, 0, 2)  # (3, m) each: numpy's rows are faster
    c02 = _fold(p0, p1, p2, p3)
    c13 = _fold(p1, p2, p3, p0)
    straight = np.minimum(c02, c13) >= np.cos(np.radians(QUAD_ANGLE))
    normal = _cross(p2 - p0, p3 - p1)
    twist = np.abs(_dot(p0 + p2 - p1 - p3, normal))
    straight &= 0.5 * twist <= tol * np.sqrt(_dot(normal, normal))
    flat = np.ones(len(quads), dtype=bool)
    flat[moved[~straight]] = False
    bent = quads[moved[~straight]]
    crease02 = feature[bent[:, 0]] & feature[bent[:, 2]]
    crease13 = feature[bent[:, 1]] & feature[bent[:, 3]]
    along02 = np.where(crease02 != crease13, crease02, c02[~straight] >= c13[~straight])
    halves = np.where(
        along02[:, None, None],
        np.stack([bent[:, [0, 1, 2]], bent[:, [0, 2, 3]]], axis=1),
        np.stack([bent[:, [1, 2, 3]], bent[:, [1, 3, 0]]], axis=1),
    ).reshape(-1, 3)
    keep = quads.take(np.flatnonzero(flat), axis=0)
    out_faces = np.concatenate([keep.ravel(), halves.ravel(), tris.ravel()])
    out_sizes = np.r_[np.full(len(keep), 4), np.full(len(halves) + len(tris), 3)]
    return out_faces, out_sizes


def _fold(a, b, c, d) -> np.ndarray:
    """(m,) the cosine of the fold of quads ``a b c d`` ((3, m) each) along ``a c`` (-1 where one half is a line)."""
    n1, n2 = _cross(b - a, c - a), _cross(c - a, d - a)
    den = np.sqrt(_dot(n1, n1)) * np.sqrt(_dot(n2, n2))
    return np.where(den > 0.0, _dot(n1, n2) / np.maximum(den, 1e-300), -1.0)


def _cross(a, b) -> np.ndarray:
    """(3, m) cross products of (3, m) columns of vectors (a few times faster than ``np.cross`` over (m, 3) rows)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _dot(a, b) -> np.ndarray:
    """(m,) dot products of (3, m) columns of vectors."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
