"""A boolean's surface that keeps the operands' own faces: new surface only along the seams (hybrid booleans).

After Pavić, Campen and Kobbelt's *Hybrid Booleans* (2010): the operands' polygons are kept wherever the result's
surface is theirs, and new surface is made only in a band along the intersections. Here the band's surface is the
field's own voxel surface (sharp, as :meth:`.field.AdaptiveField.to_mesh` gives it), so whatever the field decides
(open meshes capped across their holes, self-intersecting or inside-out shells, blends) holds there as everywhere:

1. :func:`.keep.kept_triangles`: which triangles of which operand are the surface, facing which way (where those
   kept are under 5 % of the operands' area and of the result's, the voxel surface instead: :mod:`.littlekept`);
2. the voxel surface less its faces with a corner over the kept ones (:func:`.zipper.vertices_over`), and less the
   teeth of its border left (faces with two edges on it, which the strips beside them would fold over);
3. the border loops of both (kept vertices at one position welded), paired; a failing kept loop that is a slit closed by
   itself (:func:`.slits.fill_slits`), unpaired kept loops facing each other zipped to each other
   (:func:`.twins.zip_twins`), and the loops that still cannot be paired given up (kept faces or voxel faces at them;
   where a strip stretches at a few steps, or a loop crowds another, first only the kept faces there), until all pair;
4. a strip between each pair (:func:`.zipper.zip_loops`; two steps folding over each other flipped,
   :func:`.zipper.unfolded`), and the three parts as one surface, checked closed and consistently oriented; where the
   join cannot be made, the voxel surface alone (``stats["kept_fallback"]``);
5. where the join gave up large kept faces (a low-polygon mesh's), the triangles judged again clear of the places it
   failed and joined again (:mod:`.rejoin`);
6. after the new faces are made coarse where flat, those that pass through other faces tiled again (:mod:`.uncross`;
   at an adaptivity, where pairs are left, made again with the merges about them held back: :mod:`.heldback`);
7. where some still do, the triangles judged again clear of those faces and joined again, round after round while
   fewer are left (:mod:`.clearing`); where many still do (``CROSSED_SHARE``: a kept sliver given up whole left its
   neighbour's long edge to a fan of strips) on clean meshes, the voxel surface, coarse where flat.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .assembly import assembled, voxel_surface_only
from .carried import carried, remember
from .clearing import cleared
from .earlyjudge import early_verdicts
from .edgehash import EdgeCounts, directed_edges
from .expression import leaves
from .heldback import finished
from .keep import kept_triangles
from .keptmesh import kept_mesh
from .littlekept import LITTLE_KEPT, little_kept, whole_along_seams
from .meshcheck import all_corners, any_corner
from .normalsums import triangle_normal_sums
from .ownpart import gives_own_faces_up
from .parallel import run_tasks
from .quads import quad_halves_first, triangulate
from .rejoin import joined_again
from .slits import fill_slits
from .sources import mesh_distances
from .twins import zip_twins
from .zipper import (
    LOCAL_ROUNDS,
    MAX_ROUNDS,
    NEAR_VOXELS,
    OVER_VOXELS,
    PAIR_VOXELS,
    STRETCH_VOXELS,
    WIDEN_RINGS,
    border_halves,
    loop_labels,
    nearest_points,
    pinched,
    teeth,
    unfolded,
    vertex_components,
    vertices_over,
    zip_loops,
)


def _drop_pinched(tris: np.ndarray, alive: np.ndarray, n_verts: int, was=None, rounds: int = 8) -> tuple:
    """``alive`` less the faces at vertices where two border loops touch, until none does, and the border halves of
    what is left. ``was``: ``(mask, halves)`` a superset of ``alive`` and its border, known already (a closed surface:
    every face, no border); then, as after each round, only the faces at its border's and at the dropped faces'
    vertices are read (a border edge's ends are such vertices, and any face listing its reverse touches them)."""
    halves = border_halves(tris[alive], n_verts) if was is None else _border_after(tris, alive, n_verts, *was)
    for _ in range(rounds):
        bad = pinched(halves, n_verts)
        if not bad.any():
            break
        before, alive = alive, alive & ~any_corner(bad, tris)
        halves = _border_after(tris, alive, n_verts, before, halves)
    return alive, halves


def _border_after(tris, alive, n_verts: int, before, halves) -> np.ndarray:
    """The border halves of ``tris[alive]``, those of ``tris[before]`` being ``halves``: a half's status changes only
    with a face listing its edge, all of whose corners are then corners of a face that changed, so the halves with an
    end at none of those stay and the rest are read off the faces at them (all of ``tris[alive]`` where the faces that
    changed are as many: the voxel surface less the part over the kept faces)."""
    changed = before ^ alive
    if np.count_nonzero(alive) <= np.count_nonzero(changed):
        return border_halves(tris[alive], n_verts)
    hot = np.zeros(n_verts, dtype=bool)
    hot[tris[changed].ravel()] = True
    near = border_halves(tris[alive & any_corner(hot, tris)], n_verts)
    return np.concatenate([halves[~all_corners(hot, halves)], near[all_corners(hot, near)]])


def _loops(halves: np.ndarray, n: int, reverse: bool):
    """``(next, members, labels)`` of a border's loops over ``n`` vertices (``reverse``: walked against the faces)."""
    tails, heads = (halves[:, 1], halves[:, 0]) if reverse else (halves[:, 0], halves[:, 1])
    nxt = np.arange(n, dtype=np.int64)
    nxt[tails] = heads
    members = np.unique(tails)
    labels = loop_labels(nxt, members)
    return nxt, members[labels[members] >= 0], labels  # (a path that does not close is no loop: left unpaired)


def _pair_loops(points, k_loops, v_loops, reach: float, device) -> dict:
    """Each kept loop's voxel loop: the one most of its vertices are nearest to (within ``reach``). Returns the pairs
    (kept label, voxel label) and the loops of either side left unpaired."""
    k_members, v_members = k_loops[1], v_loops[1]
    k_labels, v_labels = k_loops[2][k_members], v_loops[2][v_members]
    near = nearest_points(points[v_members], points[k_members], reach, device)
    has = near >= 0
    votes = np.stack([k_labels[has], v_labels[near[has]]], axis=1)
    pairs, counts = np.unique(votes, axis=0, return_counts=True) if len(votes) else (np.zeros((0, 2), np.int64), [])
    # the most voted voxel loop of every kept loop, then every voxel loop to its most voting kept loop
    order = np.lexsort((-np.asarray(counts), pairs[:, 0])) if len(pairs) else np.zeros(0, np.int64)
    pairs, counts = pairs[order], np.asarray(counts)[order]
    best = np.r_[True, pairs[1:, 0] != pairs[:-1, 0]] if len(pairs) else np.zeros(0, bool)
    pairs, counts = pairs[best], counts[best]
    order = np.lexsort((-counts, pairs[:, 1])) if len(pairs) else np.zeros(0, np.int64)
    pairs = pairs[order]
    unique_v = np.r_[True, pairs[1:, 1] != pairs[:-1, 1]] if len(pairs) else np.zeros(0, bool)
    pairs = pairs[unique_v]
    return {
        "pairs": pairs,
        "kept_unpaired": np.setdiff1d(np.unique(k_labels), pairs[:, 0]),
        "voxel_unpaired": np.setdiff1d(np.unique(v_labels), pairs[:, 1]),
    }


def hybrid_surface(
    field, voxel_verts: np.ndarray, voxel_tris: np.ndarray, judged: list | None = None, partial: bool = False
) -> dict:
    """The result's surface with its operands' faces kept (see the module docstring).

    Args:
        field: An unplaced boolean result (:class:`.field.AdaptiveField` with an ``expression``).
        voxel_verts, voxel_tris: Its voxel surface ((V, 3) float32, (F, 3) int32), closed and oriented.
        judged: Its operands' triangles judged (:func:`.keep.kept_triangles`), when found already.
        partial: The voxel surface is a boolean's along its seams alone (:mod:`.ondemand`), open where they end:
            every voxel face at its open edges must lie over kept faces, else it is given up (``kept_fallback``).
    Returns:
        dict: ``verts`` (N, 3) float32, ``tris`` (M, 3) int32; per face ``kept`` bool, ``field_id`` and
        ``triangle_id`` int32 (the source triangle of a kept face, -1 for new faces); per vertex ``vertex_field``
        and ``vertex_id`` (the source vertex of a kept face's corner, -1 for new vertices); ``corner_bary`` (M, 3, 3)
        float32 each kept face's corners as weights of its source triangle's corners (zeros for new faces);
        ``voxel_face`` (M,) int64 the voxel triangle each new face is (-1 for kept faces and strips); ``stats``.
    """
    device, voxel = field.device, field.voxel_size
    kept = kept_mesh(kept_triangles(field) if judged is None else judged)
    n_k = len(kept["verts"])
    points = np.concatenate([kept["verts"], voxel_verts]).astype(np.float32)
    k_tris, v_tris = kept["tris"], np.asarray(voxel_tris, dtype=np.int64) + n_k
    n = len(points)
    k_alive, k_border = _undoubled(k_tris, n)
    judged_alive = k_alive
    v_gone, closed = np.zeros(len(v_tris), dtype=bool), np.ones(len(v_tris), dtype=bool)
    ways = triangle_normal_sums(points, v_tris, n_k, device)  # the voxel surface's way at each of its vertices
    over = vertices_over(points, k_tris[k_alive], k_border, np.arange(n_k, n), voxel, device, ways)
    trouble = []
    if partial and not _edges_covered(voxel_tris, len(voxel_verts), over[n_k:]):
        return voxel_surface_only(voxel_verts, voxel_tris, ENDS_SHORT)
    was = (closed, np.zeros((0, 2), np.int64))
    for rounds in range(MAX_ROUNDS):
        v_alive, v_border = _voxel_left(v_tris, ~v_gone & ~any_corner(over, v_tris), n, was)
        was = (v_alive, v_border)  # (the next round's border read where its faces changed)
        k_loops, v_loops = _loops(k_border, n, reverse=False), _loops(v_border, n, reverse=True)
        k_loops, paired, strips, stretched, far = _paired_strips(
            points, (k_tris[k_alive], k_border), k_loops, v_loops, n_k, field
        )
        kept_failed, far, whole = _failing(points, k_loops, paired, stretched, far, rounds, voxel, device)
        if not len(kept_failed) and not len(far) and not len(paired["voxel_unpaired"]):
            joined = np.concatenate([k_tris[k_alive], v_tris[v_alive], strips.astype(np.int64)])
            seams = (k_border, v_border, strips)
            kept_failed, whole = _loops_at_unpaired_edges(joined, seams, k_loops, v_loops, paired["pairs"], n), False
            if not len(kept_failed):
                break
        before = k_alive
        k_alive, k_border, v_gone, at = _give_up(
            points, (k_tris, k_alive, k_border, k_loops), (v_tris, v_alive, v_loops, v_gone), kept_failed,
            paired["voxel_unpaired"], whole, PAIR_VOXELS * voxel, device, far,
        )  # fmt: skip
        over = _still_over(points, (k_tris, k_alive, k_border, ways), before, over, voxel, device)
        trouble.append(at)
    else:
        return voxel_surface_only(voxel_verts, voxel_tris, "loops left unpaired")
    given_up, parts = np.flatnonzero(judged_alive & ~k_alive), (k_tris, k_alive, (v_tris, v_alive), strips)
    surface = assembled(points, kept, *parts, voxel_verts, voxel_tris, device, (given_up, voxel) if partial else None)
    return {**surface, "trouble": _trouble(points, k_tris[given_up], trouble, voxel)}


def _voxel_left(v_tris, alive, n: int, was) -> tuple:
    """The voxel faces ``alive`` less those at pinched vertices and the teeth of their border (:func:`.zipper.teeth`),
    and their border halves (``was`` as :func:`_drop_pinched` takes it)."""
    alive, border = _drop_pinched(v_tris, alive, n, was)
    return _drop_pinched(v_tris, alive & ~teeth(v_tris, alive, border, n), n, (alive, border))


def _judged(field, avoid: np.ndarray) -> list:
    """The operands' triangles judged clear of ``avoid``: as the judge started beside the boolean found them
    (:mod:`.earlyjudge`), else judged here."""
    early = early_verdicts(field, avoid)
    return kept_triangles(field, avoid=avoid) if early is None else early


def _joined(field, join, judged: list, avoid: np.ndarray, retry: bool = True) -> dict:
    """The surface ``join`` makes of the ``judged`` triangles (judged clear of the points ``avoid`` carried from the
    last boolean over the leaves, :mod:`.carried`), joined again where it gave large faces up (:mod:`.rejoin`); the
    points its judge kept clear of remembered for the next. Should the join fall back with points carried, it is made
    as a first boolean's (their judge clear of nothing), with ``retry``; without, the fallback is returned (and what
    was remembered stays)."""
    surface, avoided = joined_again(field, join(judged), join, judged, avoid)
    if surface["stats"]["kept_fallback"] and len(avoid):
        if not retry:
            return surface
        judged = kept_triangles(field)
        surface, avoided = joined_again(field, join(judged), join, judged)
    remember(field, avoided if not surface["stats"]["kept_fallback"] else np.zeros((0, 3)))
    return surface


def _edges_covered(tris: np.ndarray, n_verts: int, over: np.ndarray) -> bool:
    """Whether every face of ``tris`` at an open edge has a corner ``over`` kept faces (and so leaves): whether the
    faces that stay have each edge's twin (among the faces at their corners: the seams' few, not the whole
    surface's)."""
    stay = ~any_corner(over, tris)
    if not stay.any():
        return True
    corners = np.zeros(n_verts, dtype=bool)
    corners[tris[stay].ravel()] = True
    a, b, _, _ = directed_edges(tris[any_corner(corners, tris)], n_verts)
    c, d, _, _ = directed_edges(tris[stay], n_verts)
    return bool((EdgeCounts(a, b, n_verts).of(d, c) > 0).all())


# A join's failures worth a second judge are at kept faces given up with an edge longer than this many voxels (the
# second keeps a few voxels about them clear, :mod:`.rejoin`: smaller faces lose no more in the first).
LARGE_FACE_VOXELS = 3.0


def _still_over(points, kept, before: np.ndarray, over: np.ndarray, voxel: float, device) -> np.ndarray:
    """:func:`.zipper.vertices_over` after the kept faces alive ``before`` were given up down to ``kept`` (tris,
    alive, border, and the voxel surface's way at each point): kept faces are only given up, so a vertex not over them
    stays so, and one farther than the reach (and margin) from every face given up keeps its closest kept point and
    sees no new border within it: only the vertices over them within that of the faces given up are read again."""
    tris, alive, border, ways = kept
    gone = tris[before & ~alive]
    if not len(gone):
        return over
    reach = (OVER_VOXELS + 0.01) * voxel
    mesh = wp.Mesh(
        points=wp.array(points, dtype=wp.vec3, device=device),
        indices=wp.array(np.ascontiguousarray(gone, dtype=np.int32).reshape(-1), dtype=wp.int32, device=device),
    )
    rows = np.flatnonzero(over)
    again = rows[mesh_distances(mesh, points[rows], reach, device) < reach]
    out = over.copy()
    out[again] = vertices_over(points, tris[alive], border, again, voxel, device, ways)[again]
    return out


def _trouble(points, given_up, at: list, voxel: float) -> dict:
    """The vertices kept faces were given up ``at`` (per round) that are corners of a large face given up: ``points``
    (P, 3), and the large faces' ``area``."""
    corners = points[given_up].astype(np.float64)
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    large = longest > LARGE_FACE_VOXELS * voxel
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    at = np.intersect1d(np.concatenate([np.zeros(0, np.int64), *at]), given_up[large])
    return {"points": points[at], "area": float(area[large].sum())}


def _paired_strips(points, kept, k_loops, v_loops, n_kept: int, field):
    """The loops paired (:func:`_pair_loops`) and their strips (:func:`_strips`), with the kept loops that fail and
    are slits closed by themselves (:func:`.slits.fill_slits`) and left out of the pairing, which runs again without
    them, and the kept loops left unpaired or stretched that face each other zipped to each other
    (:func:`.twins.zip_twins`).
    Returns ``(k_loops, paired, strips, stretched, far)``: the kept loops left to pair, and as there."""
    voxel, device = field.voxel_size, field.device
    reach = PAIR_VOXELS * voxel

    def pair(k_loops):  # the pairs, their strips, and where those stretch
        paired = _pair_loops(points, k_loops, v_loops, reach, device)
        return (paired, *_strips(points, k_loops, v_loops, paired["pairs"], reach, n_kept, device))

    paired, strips, stretched, far = pair(k_loops)
    failed = np.r_[paired["kept_unpaired"], stretched]
    if not len(failed):
        return k_loops, paired, strips, stretched, far
    fills, filled = fill_slits(points, k_loops, failed, kept[0], kept[1], voxel, device, field)
    if len(filled):
        k_loops = _without_loops(k_loops, filled)
        paired, strips, stretched, far = pair(k_loops)
    # kept loops left unpaired, or stretched to a scrap of voxel surface, that face each other are zipped to each other
    near = NEAR_VOXELS * voxel
    twins, twinned = zip_twins(points, k_loops, np.r_[paired["kept_unpaired"], stretched], reach, near, device)
    if len(twinned):
        k_loops = _without_loops(k_loops, twinned)
        if np.isin(stretched, twinned).any():  # their voxel loops are paired no more
            paired, strips, stretched, far = pair(k_loops)
        else:
            paired = {**paired, "kept_unpaired": np.setdiff1d(paired["kept_unpaired"], twinned)}
    return k_loops, paired, np.concatenate([strips, fills, twins]), stretched, far


def _without_loops(loops, labels):
    """``loops`` (next, members, labels) less the loops ``labels``."""
    return loops[0], loops[1][~np.isin(loops[2][loops[1]], labels)], loops[2]


def _failing(points, k_loops, paired, stretched, far, rounds: int, voxel: float, device):
    """What a round's loops that failed give up: ``(kept_failed, far, whole)``, the kept loops that give up the kept
    faces at them, the kept vertices that give up the faces at them, and whether a loop gives up the piece it bounds.
    A stretched strip gives up the kept faces where it stretches (a kept finger narrower than a voxel, which the
    voxel surface does not follow), and the kept faces along its whole loop only after LOCAL_ROUNDS; an unpaired loop
    crowding another one gives up first only the kept faces where it does; a loop failing again gives up the kept
    piece it bounds."""
    local = rounds < LOCAL_ROUNDS
    if not local:  # a loop stretched at a few steps gives up the kept faces there, round after round
        stretched, far = _mostly_side_by_side(k_loops, stretched, far, len(points))
    kept_failed = np.r_[paired["kept_unpaired"], stretched[:0] if local else stretched]
    if local:
        crowded, kept_failed = _crowding(points, k_loops, kept_failed, PAIR_VOXELS * voxel, device)
        far = np.r_[far, crowded]
    return kept_failed, far, rounds > LOCAL_ROUNDS


def _mostly_side_by_side(k_loops, stretched, far, n_verts: int):
    """Of the ``stretched`` kept loops, those with at most ``SIDE_BY_SIDE`` of their vertices ``far`` (at a step of
    their strip where it stretches) give up only the kept faces at those vertices; the rest give up faces all
    along. Returns ``(stretched, far)``: the loops that give up faces all along, and the vertices the others give up
    faces at."""
    labels = k_loops[2]
    length = np.bincount(labels[k_loops[1]], minlength=n_verts)[stretched]
    at_far = np.bincount(labels[far], minlength=n_verts)[stretched]
    some = stretched[at_far <= SIDE_BY_SIDE * length]
    return np.setdiff1d(stretched, some), far[np.isin(labels[far], some)]


# A stretched loop with at most this share of its vertices where it stretches gives up kept faces only there.
SIDE_BY_SIDE = 0.25


def _crowding(points, k_loops, unpaired, reach: float, device):
    """The vertices of the ``unpaired`` kept loops within ``reach`` of another kept loop's vertex (the kept faces
    between the two are too narrow for the voxel surface: it spans the holes on either side of a narrow kept bridge
    as one, or goes round a kept island a voxel off a larger piece's border with it), and the unpaired loops without
    such vertices."""
    members, labels = k_loops[1], k_loops[2]
    mine = np.isin(labels[members], unpaired)
    near = nearest_points(points[members[~mine]], points[members[mine]], reach, device)
    crowded = members[mine][near >= 0]
    return crowded, np.setdiff1d(unpaired, labels[crowded])


def _loops_at_unpaired_edges(tris, seams, k_loops, v_loops, pairs, n_verts: int) -> np.ndarray:
    """The kept loops at an edge of the joined surface that is not used once each way (directly, or through the
    voxel loop paired with them): empty when the join is closed and consistently oriented. Only the edges at the
    ``seams`` (the kept faces' border, the voxel faces' and the strips' vertices) are read: the kept faces alive and
    the voxel faces alive each use their other edges once each way, and share no vertex but through the strips."""
    hot = np.zeros(n_verts, dtype=bool)
    for part in seams:
        hot[np.asarray(part, dtype=np.int64).ravel()] = True
    near = tris[any_corner(hot, tris)]
    a, b, _, _ = directed_edges(near, n_verts)
    table = EdgeCounts(a, b, n_verts)
    wrong = ((table.repeats() > 1) | (table.reverses() == 0)) & (hot[a] | hot[b])
    bad = np.unique(np.concatenate([a[wrong], b[wrong]]))
    through_voxel_loops = pairs[np.isin(pairs[:, 1], v_loops[2][bad]), 0]
    failed = np.unique(np.r_[k_loops[2][bad], through_voxel_loops])
    return failed[failed >= 0]


def _undoubled(tris: np.ndarray, n_verts: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_drop_pinched` of the kept faces less those that list an edge another face lists the same way (pieces
    that overlap): ``(alive, border halves)``. Where none does (most joins), the border is read off the same count of
    their edges."""
    a, b, _, _ = directed_edges(tris, n_verts)
    counts = EdgeCounts(a, b, n_verts)
    alive = ~(counts.repeats() > 1).reshape(-1, 3).any(axis=1)
    if not alive.all():
        return _drop_pinched(tris, alive, n_verts)
    open_ = counts.reverses() == 0
    return _drop_pinched(tris, alive, n_verts, (alive, np.stack([a[open_], b[open_]], axis=1)))


def _give_up(points, kept, voxel, kept_failed, voxel_failed, whole: bool, reach: float, device, far):
    """After a round with loops left unpaired: the kept faces and voxel faces given up for the next one.

    A kept loop that failed gives up the kept faces at it (``whole``: a small kept piece it bounds whole, a large one
    a few rings of faces deep, see :func:`_widened`), and the kept vertices ``far`` where a strip stretched the faces
    at them (``whole``: as deep; a finger of kept faces the strip stretches to, given up at its tip a vertex a round,
    outlasted the rounds). A voxel loop that
    failed gives up its piece of the voxel surface when that is an island (a tenth of the voxel faces or less, left
    over kept faces), else the kept faces near it (at the kept border, or anywhere where no border is in reach).
    Returns the kept faces' mask and border halves, the given-up voxel faces' mask, and the kept vertices the faces
    were given up at (before the widening)."""
    (k_tris, k_alive, k_border, k_loops), (v_tris, v_alive, v_loops, v_gone) = kept, voxel
    n = len(points)
    at_failed = np.isin(k_loops[2], kept_failed)
    at_failed[far] = True
    failed_at = at_failed.copy()
    if whole:
        at_failed = _widened(k_tris, k_alive, at_failed, n, device)
    if len(voxel_failed):
        at_loop = np.isin(v_loops[2], voxel_failed)
        pieces = vertex_components(v_tris[v_alive], n, device)
        sizes = np.bincount(pieces[v_tris[v_alive][:, 0]], minlength=n)
        failed = np.unique(pieces[at_loop])
        islands = failed[sizes[failed] * 10 <= int(v_alive.sum())]
        v_gone = v_gone | (any_corner(np.isin(pieces, islands), v_tris) & v_alive)
        open_loop = np.flatnonzero(at_loop & ~np.isin(pieces, islands))
        members = np.unique(k_border[:, 0])  # every kept border vertex: a loop zipped to its twin's too
        near = nearest_points(points[members], points[open_loop], reach, device)
        at_failed[members[near[near >= 0]]] = failed_at[members[near[near >= 0]]] = True
        # a loop with no kept border in reach (voxel surface over the middle of kept faces, across a gap they leave)
        # gives up the kept faces in reach of it instead
        stuck = open_loop[~np.isin(v_loops[2][open_loop], v_loops[2][open_loop[near >= 0]])]
        if len(stuck):
            inner = np.unique(k_tris[k_alive].ravel())
            near = nearest_points(points[inner], points[stuck], reach, device)
            at_failed[inner[near[near >= 0]]] = failed_at[inner[near[near >= 0]]] = True
    at_failed[far] = failed_at[far] = True
    alive, border = _drop_pinched(k_tris, k_alive & ~any_corner(at_failed, k_tris), n, (k_alive, k_border))
    if (alive != k_alive).any():  # the voxel faces over the kept ones given up come back: judged afresh
        v_gone = np.zeros_like(v_gone)
    return alive, border, v_gone, np.flatnonzero(failed_at)


# Kept pieces of at most this many faces are fragments: a loop of theirs failing twice gives them up whole.
SMALL_PIECE = 256


def _widened(tris, alive, at: np.ndarray, n: int, device, rings: int = WIDEN_RINGS) -> np.ndarray:
    """``at`` (per vertex) grown over the kept pieces it touches: a small piece whole (a tenth of the kept faces or
    less, and at most SMALL_PIECE faces: a fragment), a larger one ``rings`` rings of faces deep (a scan's one large
    piece, or a messy mesh's many, is not given up for a loop at its edge)."""
    faces = tris[alive]
    pieces = vertex_components(faces, n, device)
    sizes = np.bincount(pieces[faces[:, 0]], minlength=n)
    touched = np.unique(pieces[at])
    small = touched[(sizes[touched] * 10 <= len(faces)) & (sizes[touched] <= SMALL_PIECE)]
    grown = at | np.isin(pieces, small)
    for _ in range(rings):
        reached = np.zeros(n, dtype=bool)
        reached[faces[any_corner(grown, faces)].ravel()] = True
        grown |= reached
    return grown


def _strips(points, k_loops, v_loops, pairs, reach: float, n_kept: int, device):
    """The strips between paired loops, the kept loops whose strip has a step where the two loops are farther apart
    than ``reach`` (they do not run side by side all along), and the kept vertices (below ``n_kept``) at those
    steps."""
    k_next, k_members, k_labels = k_loops
    v_next, v_members, v_labels = v_loops
    k_count = np.bincount(k_labels[k_members], minlength=len(points))[pairs[:, 0]]
    v_count = np.bincount(v_labels[v_members], minlength=len(points))[pairs[:, 1]]
    near = NEAR_VOXELS * reach / PAIR_VOXELS
    strips, gaps = zip_loops(points, k_next, v_next, pairs[:, 0], pairs[:, 1], k_count, v_count, device, near)
    if not len(strips):
        return strips, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    counts = k_count + v_count
    strips = unfolded(points, strips, counts, n_kept)
    first = np.r_[0, np.cumsum(counts)[:-1]]
    reach = STRETCH_VOXELS * reach / PAIR_VOXELS
    far = np.unique(strips[gaps > reach])
    return strips, pairs[np.maximum.reduceat(gaps, first) > reach, 0], far[far < n_kept].astype(np.int64)


# Why a join along the seams alone falls back where the kept faces given up reach past their voxel surface (the whole
# result is then made and joined, as at any fallback of a first join or of a clearing that leaves faces crossing:
# bunny ∩ cow at /256, 9 pairs left crossing along the seams, none made whole; cow ∩ a placed box, 10 and none).
ENDS_SHORT = "the seams' surface ends short of the kept faces"

# Faces left crossing are judged again clear of; more than this share of the new faces still crossing on clean meshes
# gives the voxel surface (the join broke down: a turned 40-sided cylinder through a box, 7-20 %; kept faces meeting
# at a corner of the voxel surface leave up to 0.2 %; messy meshes' thin parts may keep a few).
CROSSED_SHARE = 0.005


def _crossed_through(surface: dict) -> bool:
    """Whether more pairs of faces pass through each other than CROSSED_SHARE of the new faces."""
    return surface["stats"]["crossing_left"] > CROSSED_SHARE * max(int(np.count_nonzero(~surface["kept"])), 1)


def _clear_of_crossings(field, join, surface: dict, finish) -> dict:
    """``surface`` made again clear of its faces left crossing, round after round while fewer are (:mod:`.clearing`):
    the surface ``join`` makes of the triangles judged again (:func:`_joined`, a join that falls back ends the rounds),
    made by ``finish``."""
    joined = lambda judged, avoid: _joined(field, join, judged, avoid, retry=False)  # noqa: E731
    return cleared(field, joined, surface, finish, _crossed_through)


def _kept_and_new(field, voxel_surface: tuple, judged: tuple, finish, partial: bool) -> dict | None:
    """The kept faces (``judged``: the operands' triangles judged, and the points they were judged clear of) joined to
    the ``voxel_surface`` (verts, tris), made by ``finish``, judged again clear of where faces are left passing through
    others (:func:`_clear_of_crossings`); the voxel surface alone where that leaves a clean boolean crossed through.
    ``partial``: the voxel surface is a boolean's along its seams alone; None where its whole result should be joined
    instead: its join fell back, its clearing ended at a join that fell back with faces still left crossing (one that
    gave up kept faces past the seams' surface, ``ENDS_SHORT``, or whose loops the seams' surface left unpaired: the
    whole's voxel surface is under every kept face), or it was left crossed through."""
    verts, tris = voxel_surface
    join = lambda triangles: hybrid_surface(field, verts, tris, triangles, partial)  # noqa: E731
    surface = _joined(field, join, *judged)
    if partial and surface["stats"]["kept_fallback"]:
        return None
    surface = finish(surface)
    if surface["stats"]["crossing_left"]:
        surface = _clear_of_crossings(field, join, surface, finish)
        if partial and surface["stats"].get("clearing_ended") and surface["stats"]["crossing_left"]:
            return None
    if _crossed_through(surface) and _clean(field):  # the join failed where it must not: remeshed
        if partial:
            return None
        surface = finish(voxel_surface_only(verts, tris, "kept faces and new ones left passing through each other"))
    return surface


def _clean(field) -> bool:
    """Whether every leaf of a boolean is a closed, clean mesh's field that does not pass through itself (or no
    mesh's: an offset, a shell): where the kept surface never passes through itself (a messy mesh's thin parts may, a
    few faces, and so may a closed mesh that passes through itself about its crossings: the cow at its head)."""
    voxel = field.voxel_size
    return all(
        leaf.stats.get("clean_mesh", True) and not (leaf.sources and gives_own_faces_up(leaf, voxel))
        for leaf in leaves(field.expression)
    )


def kept_surface(
    field, *, sharp: bool | None = None, adaptivity: float = 0.0, regions: dict | None = None, whole=None
) -> dict:
    """The zero surface of ``field`` keeping the operands' own faces wherever it is theirs and no other surface or
    defect of theirs is near, with new (voxel) surface only along the seams (:func:`hybrid_surface`), made coarse
    where flat (:func:`.coarsen.coarsened`: ``adaptivity`` and ``regions`` as there); a field that is no boolean of
    meshes (a built field, an offset, a shell) keeps nothing: its voxel surface.

    Returns:
        dict: ``verts`` (N, 3) float32, ``tris`` (M, 3) int32 (closed, counter-clockwise seen from outside), per face
        ``kept`` bool, ``field_id`` and ``triangle_id`` int32 (its source triangle, -1 for new faces), per vertex
        ``vertex_field`` and ``vertex_id`` int32 (a kept corner's source vertex, else -1), ``corner_bary`` (M, 3, 3)
        float32, ``voxel_face`` (M,) int64 (the voxel quad half a new face is, else -1), ``quads`` (the first
        ``2 * quads`` faces are the halves of whole quads, ``a b c`` and ``a c d``: :func:`.quads.quad_halves_first`),
        ``stats``.

    ``whole``: gives the whole result where ``field`` is a boolean made along its seams alone (its voxel surface
    there: :mod:`.ondemand`), should the join fail (its fallback is the whole voxel surface).
    """
    if field.placement is not None:  # joined in its own frame, then placed
        frame_whole = None if whole is None else (lambda: whole().in_frame())
        surface = kept_surface(field.in_frame(), sharp=sharp, adaptivity=adaptivity, regions=regions, whole=frame_whole)
        surface["verts"], surface["tris"] = field.placement.place_surface(surface["verts"], surface["tris"])
        # a reflection turned every face over: the quads' halves read in quad order again
        return quad_halves_first(surface) if field.placement.mirrors else surface
    found = {}  # the voxel surface and the operands' triangles judged, side by side (independent work)
    avoid = carried(field)  # where the last boolean over a leaf gave its faces up (:mod:`.carried`)
    run_tasks(
        [lambda: found.update(mesh=field.to_mesh(sharp=sharp, quads=True))]
        + ([lambda: found.update(judged=_judged(field, avoid))] if field.expression is not None else []),
        field.device,
    )
    verts, faces, sizes = found["mesh"]
    tris = triangulate(faces, sizes)
    finish = lambda s: finished(field, s, adaptivity, regions)  # noqa: E731
    if field.expression is None or not (len(tris) or whole):  # (along the seams alone: there may be none)
        why = "not a boolean of meshes" if field.expression is None else "the result is empty"
        surface = voxel_surface_only(verts, tris, why, failed=False)
    elif little_kept(found["judged"], verts, tris):  # remeshed (:mod:`.littlekept`); along the seams: the whole's
        if whole is not None and not whole_along_seams(found["judged"], verts, tris, field.voxel_size, field.device):
            return kept_surface(whole(), sharp=sharp, adaptivity=adaptivity, regions=regions)
        surface = voxel_surface_only(verts, tris, LITTLE_KEPT, failed=False)
        if adaptivity > 0.0:  # (at 0 the remeshed surface as it is: what Keep Original Faces off gives)
            surface = finish(surface)
        surface["stats"]["along_seams"] = whole is not None  # (the seams' surface: its sources read there)
    else:
        surface = _kept_and_new(field, (verts, tris), (found["judged"], avoid), finish, whole is not None)
        if surface is None:  # along the seams alone, where they could not be joined there: the whole result's
            return kept_surface(whole(), sharp=sharp, adaptivity=adaptivity, regions=regions)
    quads = int(np.count_nonzero(np.asarray(sizes) == 4))  # the first, rows 2q and 2q + 1 of ``tris``
    surface["voxel_face"] = np.where(surface["voxel_face"] < 2 * quads, surface["voxel_face"], -1)
    return quad_halves_first(surface)
