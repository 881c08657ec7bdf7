"""A kept surface's new faces made coarse where they are flat: half-edge collapses within one source triangle's plane.

The voxel surface of a seam's band and the strips that join it to the kept faces are as fine as the voxels, even
where they lie flat on a large face of an operand (a plate's face around a bore, a box's face along the seam of a
union). Here a new vertex is removed by moving it onto a neighbour (a half-edge collapse: no vertex moves, no new
position is made) when

- every face around it is new and has one source triangle (:meth:`.field.AdaptiveField.face_sources`), so what its
  corners read off that triangle (UVs, colours) is unchanged, and no face spans a material or UV seam;
- the neighbour lies within ``TOLERANCE_VOXELS`` of every face's plane around it, so the faces that take its place
  lie in the same planes (flat parts merge, a crease between two planes merges only along its line);
- no face turns over or gets thinner than ``MIN_QUALITY`` (or than the thinnest face it replaces), its faces are one
  fan and the edge's ends share exactly two neighbours (the link condition: the surface stays closed and 2-manifold).

On the CPU the collapses are made one after another in one thread, each vertex's checks reading the mesh as the
collapses before it left it (:mod:`.collapses`); on CUDA they run in rounds, each a set of vertices at least three
edges apart (so one collapse never changes what another's checks read), the shortest edges first. Kept faces and
their vertices never change.

Written by hand: the one decimator in a user's Blender is its Decimate modifier (``bpy``, which the engine never
imports), and general decimators (quadric edge collapse) move vertices and ignore the faces' sources; the checks here
run in Warp kernels over each vertex's fan, whose loops numpy cannot express without per-vertex Python.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .adaptive import tolerance
from .collapses import collapse_serial, face_passes, next_corner
from .defects import repeated_triangles
from .meshcheck import any_corner, compacted
from .parallel import launch_split
from .refine import position_hash

# A neighbour within this many voxels of the planes of every face around a vertex can take its place (at adaptivity
# 0; an adaptivity widens it as it widens the remeshed surface's, :func:`.adaptive.tolerance`).
TOLERANCE_VOXELS = tolerance(0.0)
# Faces' shape quality (4 sqrt(3) area / sum of squared edges; 1 for an equilateral triangle) never falls below this
# (or below the worst of the faces replaced, where that is worse).
MIN_QUALITY = 0.05
# Only faces of at least this quality have planes that bound a collapse (a sliver's plane is ill-defined).
PLANE_QUALITY = 0.2
# Both, as :func:`.collapses.collapse_serial` takes them.
QUALITIES = (MIN_QUALITY, PLANE_QUALITY)
# Rounds of collapses at most; they stop earlier when a round removes under MIN_ROUND_SHARE of the vertices left.
MAX_ROUNDS = 48
MIN_ROUND_SHARE = 0.01
# Passes of claims a round makes (:func:`claimed`).
CLAIM_PASSES = 3


@wp.func
def _one_fan(tris: wp.array[wp.int32], corners: wp.array[wp.int32], lo: int, hi: int) -> bool:
    """Whether the faces at a vertex (its corners ``lo``..``hi``) form one closed fan: walked from the first face,
    each step to the face whose previous vertex is this one's next, the walk returns after all of them."""
    start = corners[lo]
    at = start
    for step in range(hi - lo):
        target = next_corner(tris, at, 1)
        found = int(-1)
        for c in range(lo, hi):
            if next_corner(tris, corners[c], 2) == target:
                found = corners[c]
        if found < 0:
            return False
        at = found
        if at == start:
            return step == hi - lo - 1
    return False


@wp.func
def _collapse_ok(
    points: wp.array[wp.vec3],
    tris: wp.array[wp.int32],
    corners: wp.array[wp.int32],
    first: wp.array[wp.int32],
    u: int,
    v: int,
    tol: float,
    min_quality: float,
) -> bool:
    """Whether ``u`` may move onto its neighbour ``v`` (the module's checks)."""
    lo = first[u]
    hi = first[u + 1]
    pu = points[u]
    pv = points[v]
    vanish = int(0)
    for c in range(lo, hi):
        a = next_corner(tris, corners[c], 1)
        b = next_corner(tris, corners[c], 2)
        on_edge = a == v or b == v
        if not face_passes(pu, pv, points[a], points[b], on_edge, tol, wp.vec2(min_quality, PLANE_QUALITY)):
            return False
        if on_edge:
            vanish += 1
    if vanish != 2:
        return False
    common = int(0)
    for c in range(lo, hi):
        x = next_corner(tris, corners[c], 1)
        for d in range(first[v], first[v + 1]):
            if next_corner(tris, corners[d], 1) == x:
                common += 1
    return common == 2


@wp.kernel(enable_backward=False)
def _candidate_kernel(
    points: wp.array[wp.vec3],
    tris: wp.array[wp.int32],
    corners: wp.array[wp.int32],
    first: wp.array[wp.int32],
    movable: wp.array[wp.int32],
    group: wp.array[wp.int64],
    tol: float,
    min_quality: float,
    place: wp.array[wp.int32],
    active: wp.array[wp.int32],
    best: wp.array[wp.int32],
    length: wp.array[wp.float32],
):
    """Per vertex listed in ``active``: the nearest neighbour it may move onto (-1 for none) and how far that is
    (ties to the smaller ``place``, a hash of the position: the same choice however the vertices are numbered)."""
    i = wp.tid()
    u = active[i]
    best[i] = -1
    length[i] = 3.0e38
    lo = first[u]
    hi = first[u + 1]
    if movable[u] == 0 or hi - lo < 3:
        return
    g = group[corners[lo] // 3]
    for c in range(lo, hi):
        if group[corners[c] // 3] != g:
            return
    if not _one_fan(tris, corners, lo, hi):
        return
    for c in range(lo, hi):
        v = next_corner(tris, corners[c], 1)
        d = wp.length(points[v] - points[u])
        closer = d < length[i] or (d == length[i] and place[v] < place[best[i]])
        if closer and _collapse_ok(points, tris, corners, first, u, v, tol, min_quality):
            best[i] = v
            length[i] = d


@wp.kernel(enable_backward=False)
def _corners_kernel(
    flat: wp.array[wp.int32], first: wp.array[wp.int32], fill: wp.array[wp.int32], corners: wp.array[wp.int32]
):
    """Each corner into its vertex's list (a counting sort: the lists' order is any)."""
    i = wp.tid()
    v = flat[i]
    corners[first[v] + wp.atomic_add(fill, v, 1)] = i


@wp.func
def _ring_vertex(
    tris: wp.array[wp.int32], corners: wp.array[wp.int32], first: wp.array[wp.int32], u: int, c: int
) -> int:
    """Vertex ``c`` of ``u``'s closed 1-ring, ``c`` from ``first[u] - 1`` (``u`` itself) to ``first[u + 1] - 1``."""
    if c < first[u]:
        return u
    return next_corner(tris, corners[c], 1)


@wp.kernel(enable_backward=False)
def _claim_kernel(
    tris: wp.array[wp.int32],
    corners: wp.array[wp.int32],
    first: wp.array[wp.int32],
    rows: wp.array[wp.int32],
    keys: wp.array[wp.int32],
    check: int,
    claim: wp.array[wp.int32],
    won: wp.array[wp.int32],
):
    """Each candidate claims itself and its neighbours with its key (the smallest key wins each vertex); with
    ``check``, a second launch, whether it won every vertex it claimed (then it collapses). A candidate with a vertex
    held already (-1: an earlier pass's winner's) claims nothing and loses."""
    i = wp.tid()
    u = rows[i]
    ok = int(1)
    for c in range(first[u] - 1, first[u + 1]):
        if claim[_ring_vertex(tris, corners, first, u, c)] == -1:
            won[i] = 0
            return
    for c in range(first[u] - 1, first[u + 1]):
        w = _ring_vertex(tris, corners, first, u, c)
        if check == 0:
            wp.atomic_min(claim, w, keys[i])
        elif claim[w] != keys[i]:
            ok = 0
    won[i] = ok


@wp.kernel(enable_backward=False)
def _ring_marks_kernel(
    tris: wp.array[wp.int32],
    corners: wp.array[wp.int32],
    first: wp.array[wp.int32],
    seeds: wp.array[wp.int32],
    marks: wp.array[wp.int32],
):
    """Every vertex of each face at each of ``seeds`` marked (a mark only ever set: the same whatever the order)."""
    u = seeds[wp.tid()]
    for c in range(first[u], first[u + 1]):
        face = corners[c] // 3
        for k in range(3):
            marks[tris[face * 3 + k]] = 1


@wp.kernel(enable_backward=False)
def _claim_passes_kernel(
    tris: wp.array[wp.int32],
    corners: wp.array[wp.int32],
    first: wp.array[wp.int32],
    rows: wp.array[wp.int32],
    keys: wp.array[wp.int32],
    passes: int,
    claim: wp.array[wp.int32],
    state: wp.array[wp.int32],
):
    """One thread: the passes of :func:`_claim_kernel` one after the other, with the same winners (``state`` 1; 2: a
    candidate that met an earlier pass's winner's ring; ``claim`` starts free, ``len(rows)`` everywhere), without a
    launch and a copy to the host per pass."""
    n = rows.shape[0]
    for _p in range(passes):
        for i in range(n):  # claims: the smallest key takes each vertex
            if state[i] == 0:
                u = rows[i]
                for c in range(first[u] - 1, first[u + 1]):
                    if claim[_ring_vertex(tris, corners, first, u, c)] == -1:
                        state[i] = 2
                if state[i] == 0:
                    for c in range(first[u] - 1, first[u + 1]):
                        w = _ring_vertex(tris, corners, first, u, c)
                        claim[w] = wp.min(claim[w], keys[i])
        wins = int(0)
        for i in range(n):  # a candidate that holds every vertex it claimed collapses
            if state[i] == 0:
                u = rows[i]
                ok = int(1)
                for c in range(first[u] - 1, first[u + 1]):
                    if claim[_ring_vertex(tris, corners, first, u, c)] != keys[i]:
                        ok = 0
                if ok == 1:
                    state[i] = 3  # (won in this pass)
                    wins += 1
        for i in range(n):  # the winners' rings held, every other vertex claimed free again
            if state[i] == 0 or state[i] == 3:
                u = rows[i]
                for c in range(first[u] - 1, first[u + 1]):
                    w = _ring_vertex(tris, corners, first, u, c)
                    if claim[w] != -1:
                        claim[w] = wp.where(state[i] == 3, -1, n)
        for i in range(n):
            if state[i] == 3:
                state[i] = 1
        if wins == 0:
            return


def collapse_flat(
    points: np.ndarray, tris: np.ndarray, movable: np.ndarray, group: np.ndarray, tol: float, device, serial=None
):
    """Remove ``movable`` vertices of a closed, oriented triangle surface where flat (module docstring).

    Args:
        points: (V, 3) float32 vertices (none moves).
        tris: (F, 3) int triangles.
        movable: (V,) bool: the vertices that may be removed.
        group: (F,) int64: a vertex is removed only where all its faces share one group.
        tol: Distance (world units) a neighbour may lie off the planes of the faces around a removed vertex.
        serial: The collapses made one after another in one thread (:mod:`.collapses`), not in rounds; None: on the
            CPU.
    Returns:
        ``(tris, rows)``: the triangles left (on the same vertex indices) and which input face each one was.
    """
    tris = np.ascontiguousarray(tris, dtype=np.int32)
    n = len(points)
    if not len(tris) or not movable.any():
        return tris, np.arange(len(tris), dtype=np.int64)
    # only the faces at a movable vertex or its neighbours are read (the fans of both ends of an edge)
    near = np.zeros(n, dtype=bool)
    near[tris[any_corner(movable, tris)].ravel()] = True
    read = any_corner(near, tris)
    rows, rest = np.flatnonzero(read), np.flatnonzero(~read)
    tris, rest_tris = np.ascontiguousarray(tris[rows]), tris[rest]
    if wp.get_device(device).is_cpu if serial is None else serial:
        out, alive = collapse_serial(points, tris, movable, group[rows], tol, device, quality=QUALITIES)
        return np.concatenate([out, rest_tris]), np.concatenate([rows[alive], rest])
    pts = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
    place = position_hash(points)
    movable = movable.astype(np.int32)
    best, length = np.full(n, -1, dtype=np.int32), np.zeros(n, dtype=np.float32)
    active, targets = np.flatnonzero(movable).astype(np.int32), None
    left = len(active)
    for _ in range(MAX_ROUNDS):
        state = (active, targets, best, length, place)
        won_rows, targets = _round(pts, tris, movable, group[rows], state, float(tol), device)
        if not len(won_rows):
            break
        remap = np.arange(n, dtype=np.int32)
        remap[won_rows] = targets
        movable[won_rows] = 0
        best[won_rows] = -1
        tris = remap[tris]
        alive = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])
        tris, rows = np.ascontiguousarray(tris[alive]), rows[alive]
        if len(won_rows) < MIN_ROUND_SHARE * left:
            break
        left -= len(won_rows)
    return np.concatenate([tris, rest_tris]), np.concatenate([rows, rest])


def _near(mesh, targets: np.ndarray, n: int, device) -> np.ndarray:
    """(V,) bool: the vertices within two edges of ``targets`` (of ``mesh``, :func:`vertex_corners`): the only ones
    whose checks a collapse onto them changes (their fans, or their neighbours' neighbours)."""
    mark = np.zeros(n, dtype=np.int32)
    mark[targets] = 1
    marks = wp.array(mark, dtype=wp.int32, device=device)
    seeds = np.asarray(targets, dtype=np.int32)
    for _ in range(2):
        w_seeds = wp.array(seeds, dtype=wp.int32, device=device)
        wp.launch(_ring_marks_kernel, dim=len(seeds), inputs=[*mesh, w_seeds, marks], device=device)
        mark = marks.numpy()
        seeds = np.flatnonzero(mark).astype(np.int32)
    return mark > 0


def _round(pts, tris: np.ndarray, movable: np.ndarray, group: np.ndarray, state, tol: float, device):
    """One round: the ``active`` vertices' best collapses found again (``best``, ``length`` kept between rounds,
    changed in place), then the vertices that collapse (at least three edges apart) and their targets."""
    active, targets, best, length, place = state
    n = len(best)
    w_tris, w_corners, w_first = vertex_corners(tris, n, device)
    if targets is not None:  # after a round: the movable vertices within two edges of its targets
        near = _near((w_tris, w_corners, w_first), targets, n, device)
        active = np.flatnonzero(near & (movable > 0)).astype(np.int32)
    w_movable = wp.array(movable, dtype=wp.int32, device=device)
    w_group = wp.array(np.ascontiguousarray(group, dtype=np.int64), dtype=wp.int64, device=device)
    w_active = wp.array(active, dtype=wp.int32, device=device)
    w_place = wp.array(place, dtype=wp.int32, device=device)
    w_best = wp.empty(len(active), dtype=wp.int32, device=device)
    w_length = wp.empty(len(active), dtype=wp.float32, device=device)
    launch_split(
        _candidate_kernel,
        len(active),
        lambda lo, m: [
            pts,
            w_tris,
            w_corners,
            w_first,
            w_movable,
            w_group,
            tol,
            MIN_QUALITY,
            w_place,
            w_active[lo : lo + m],
            w_best[lo : lo + m],
            w_length[lo : lo + m],
        ],  # fmt: skip
        device,
    )
    best[active], length[active] = w_best.numpy(), w_length.numpy()
    rows = np.flatnonzero(best >= 0).astype(np.int32)
    if not len(rows):
        return rows, rows
    keys = _keys(place[rows], length[rows], int(len(active)))
    won = claimed((w_tris, w_corners, w_first), rows, keys, n, device)
    chosen = rows[won]
    return chosen, best[chosen]


def vertex_corners(tris: np.ndarray, n: int, device) -> tuple:
    """``(tris, corners, first)`` on ``device``: the corners (rows of ``tris.ravel()``) at each of ``n`` vertices,
    vertex ``v``'s from ``first[v]`` to ``first[v + 1]`` (in any order)."""
    flat = np.ascontiguousarray(tris, dtype=np.int32).ravel()
    first = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(np.bincount(flat, minlength=n), out=first[1:])
    w_tris, w_first = wp.array(flat, dtype=wp.int32, device=device), wp.array(first, dtype=wp.int32, device=device)
    w_corners = wp.empty(len(flat), dtype=wp.int32, device=device)
    fill = wp.zeros(n, dtype=wp.int32, device=device)
    wp.launch(_corners_kernel, dim=len(flat), inputs=[w_tris, w_first, fill, w_corners], device=device)
    return w_tris, w_corners, w_first


def claimed(mesh, rows: np.ndarray, keys: np.ndarray, n: int, device, in_one: bool | None = None) -> np.ndarray:
    """(R,) bool: the candidates ``rows`` that collapse, their closed 1-rings disjoint (:func:`_claim_kernel`), of the
    ``n`` vertices of ``mesh`` (:func:`vertex_corners`). A pass's winners hold their rings; the candidates left that
    touch none of those claim again, up to ``CLAIM_PASSES`` passes (one pass lets about a tenth of a flat region's
    candidates go). ``in_one``: the passes in one thread (:func:`_claim_passes_kernel`, the same winners; None: on
    the CPU, where a pass's two launches and copies cost more than the claims, 0.6 ms a round on a plate's 1,800)."""
    if wp.get_device(device).is_cpu if in_one is None else in_one:
        state = wp.zeros(len(rows), dtype=wp.int32, device=device)
        claim = wp.full(n, len(rows), dtype=wp.int32, device=device)
        args = [wp.array(x, dtype=wp.int32, device=device) for x in (rows, keys)]
        wp.launch(_claim_passes_kernel, dim=1, inputs=[*mesh, *args, CLAIM_PASSES, claim, state], device=device)
        return state.numpy() == 1
    won = np.zeros(len(rows), dtype=bool)
    claim_np = np.full(n, len(rows), dtype=np.int32)
    left = np.arange(len(rows))
    for _ in range(CLAIM_PASSES):
        claim = wp.array(claim_np, dtype=wp.int32, device=device)
        out = wp.empty(len(left), dtype=wp.int32, device=device)
        w_rows = wp.array(rows[left], dtype=wp.int32, device=device)
        w_keys = wp.array(keys[left], dtype=wp.int32, device=device)
        for check in (0, 1):
            wp.launch(_claim_kernel, dim=len(left), inputs=[*mesh, w_rows, w_keys, check, claim, out], device=device)
        now = out.numpy() == 1
        if not now.any():
            break
        won[left[now]] = True
        # every pass's winners' rings are held (-1: no key takes them), the other vertices free again
        held = claim.numpy()  # -1, a key (0 to R - 1) or R (free)
        taken = np.zeros(len(rows) + 1, dtype=bool)
        taken[keys[left[now]]] = True
        claim_np = np.where((held == -1) | taken[held], -1, len(rows)).astype(np.int32)
        left = left[~now]
        if not len(left):
            break
    return won


def _keys(places: np.ndarray, length: np.ndarray, salt: int) -> np.ndarray:
    """Each candidate's rank: by a hash of its vertex's place and the round's ``salt`` (more candidates win a round
    than ranked by length, which neighbours share; a new order each round), length breaking ties."""
    spread = ((places.astype(np.uint64) + np.uint64(salt)) * np.uint64(2654435761)) % np.uint64(1 << 31)
    keys = np.empty(len(places), dtype=np.int32)
    keys[np.lexsort((length, spread))] = np.arange(len(places), dtype=np.int32)
    return keys


def coarsened(field, surface: dict, adaptivity: float = 0.0, regions: dict | None = None, held=None) -> dict:
    """A kept surface (:func:`.hybrid.kept_surface`'s dict) with its new faces collapsed where flat, and the split
    pieces of each kept source triangle collapsed at the midpoints inside them (module docstring): kept faces stay on
    their source triangles' planes and keep every source vertex; every per-face and per-vertex array follows (a kept
    face's corner weights are its corners' own). ``stats["coarsened"]``: how many faces went; ``stats["tolerance"]``:
    the tolerance they went within (voxels).

    ``adaptivity`` (0 to 1) widens the tolerance as :func:`.adaptive.tolerance` (curved parts of the band merge too)
    and lets new faces merge across source triangles within a region: ``regions`` ({field id: (T,) label per source
    triangle}: materials, UV islands), else within an operand. ``held``: (V,) bool vertices that stay (none goes).
    """
    tris, kept = surface["tris"], surface["kept"]
    if not len(tris):
        return surface
    group = _groups(field, surface, adaptivity, regions)
    movable = (surface["vertex_id"] < 0) & (True if held is None else ~held)  # new vertices, split sources' midpoints
    tol = tolerance(adaptivity) * field.voxel_size
    out_tris, rows = collapse_flat(surface["verts"], tris, movable, group, tol, field.device)
    out_tris, rows = _without_twins(out_tris, rows, len(surface["verts"]))
    used, local = compacted(out_tris, len(surface["verts"]))
    out = dict(surface)
    out["verts"] = surface["verts"][used]
    out["tris"] = local.reshape(-1, 3).astype(np.int32)
    for key in ("kept", "field_id", "triangle_id"):
        out[key] = surface[key][rows]
    # a new face whose corners moved is no voxel face any more (nor half of a quad)
    out["voxel_face"] = np.where((out_tris == tris[rows]).all(axis=1), surface["voxel_face"][rows], -1)
    out["corner_bary"] = _moved_corners(tris, surface["corner_bary"], group, out_tris, rows)
    for key in ("vertex_field", "vertex_id"):
        out[key] = surface[key][used]
    gone_kept = int(kept.sum() - out["kept"].sum())
    stats = surface["stats"]
    out["stats"] = {
        **stats,
        "kept_faces": stats["kept_faces"] - gone_kept,
        "new_faces": stats["new_faces"] - (len(tris) - len(rows) - gone_kept),
        "coarsened": len(tris) - len(rows),
        "tolerance": tolerance(adaptivity),
    }
    return out


def _without_twins(tris: np.ndarray, rows: np.ndarray, n_verts: int) -> tuple[np.ndarray, np.ndarray]:
    """``tris`` (and their ``rows``) without the pairs of faces on the same three vertices (turned opposite ways: on a
    closed 2-manifold surface such a pair shares each of its edges with nothing else, a part of its own that encloses
    nothing; collapses along a thin part of the beetle's band left one)."""
    twin = repeated_triangles(tris, n_verts)
    return (tris, rows) if not twin.any() else (tris[~twin], rows[~twin])


def _groups(field, surface: dict, adaptivity: float, regions) -> np.ndarray:
    """(F,) int64 per face: its source triangle (a kept face's own, a new face's from the field), new faces apart; with
    an ``adaptivity``, a new face's region of its operand (``regions``' label of its source triangle, else 0)."""
    tris, kept = surface["tris"], surface["kept"]
    field_ids, triangle_ids = surface["field_id"].astype(np.int64), surface["triangle_id"].astype(np.int64)
    new = np.flatnonzero(~kept)
    if len(new):
        found_fields, found_triangles, _ = field.face_sources(surface["verts"], tris[new])
        found_fields, found_triangles = found_fields.astype(np.int64), found_triangles.astype(np.int64)
        if adaptivity > 0.0:
            found_triangles = _regions_of(found_fields, found_triangles, regions)
        field_ids, triangle_ids = field_ids.copy(), triangle_ids.copy()
        field_ids[new], triangle_ids[new] = found_fields, found_triangles
    group = (field_ids << 33) + ((triangle_ids & 0xFFFFFFFF) << 1)
    group[new] += 1
    return group


def _regions_of(field_ids: np.ndarray, triangle_ids: np.ndarray, regions) -> np.ndarray:
    """Each source triangle's region label (0 where ``regions`` names none for its operand)."""
    out = np.zeros(len(triangle_ids), dtype=np.int64)
    for field_id, labels in (regions or {}).items():
        rows = np.flatnonzero((field_ids == field_id) & (triangle_ids >= 0))
        out[rows] = np.asarray(labels, dtype=np.int64)[triangle_ids[rows]]
    return out


def _moved_corners(tris, corner_bary, group, out_tris, rows) -> np.ndarray:
    """(F', 3, 3) the faces' corner weights after collapses: a corner now at another vertex takes that vertex's
    weights from a face of the same source triangle it was a corner of (its ring was one source triangle's)."""
    bary = corner_bary[rows].copy()
    moved = np.argwhere(out_tris != tris[rows])
    if not len(moved):
        return bary
    n = int(max(tris.max(), 1)) + 1
    target = out_tris[moved[:, 0], moved[:, 1]]
    # (source triangle, vertex) of the corners before at a vertex some corner moved to: the only ones looked up
    is_target = np.zeros(n, dtype=bool)
    is_target[target] = True
    corner = np.flatnonzero(is_target[tris.ravel()])
    keys = group[corner // 3] * n + tris.ravel()[corner]
    order = np.argsort(keys, kind="stable")
    wanted = group[rows[moved[:, 0]]] * n + target
    at = corner[order[np.minimum(np.searchsorted(keys[order], wanted), len(keys) - 1)]]
    bary[moved[:, 0], moved[:, 1]] = corner_bary.reshape(-1, 3)[at]
    return bary
