"""The flat collapses of :mod:`.coarsen` made one after another, in one CPU thread.

:func:`.coarsen.collapse_flat` removes a vertex by moving it onto a neighbour where every check of the module holds
(one source triangle, the neighbour within the tolerance of its faces' planes, no face turned over or thinner, one
fan, the link condition). Its rounds find each candidate's collapse in parallel and keep a set of them at least three
edges apart, so that no collapse changes what another's checks read; a round costs its passes over the mesh (the
vertices' corner lists built again, the candidates, the claims), 2-3 ms on the CPU, and a flat region needs 8-11
rounds (each keeps about a tenth of its candidates).

Here the checks read the mesh as it stands after every collapse before them, so no two collapses need to be apart:
one thread visits the vertices in an order set by a hash of their positions (the same whatever the numbering; in the
surface's own order, neighbours one after another, it took a quarter less time but made chains of collapses along
thin parts: the beetle with a ball kept 103 pairs of faces passing through each other, 77 in rounds, 69 so), moves
each onto its nearest neighbour that passes the checks (ties to the smaller hash of the position), and updates the
faces and the vertices' corner lists in place (a collapse relabels the corners of the vertex that goes and links its
list into its neighbour's; the two faces on the edge die). A vertex whose check failed is visited again only once
the mesh within two edges of it has changed. Passes repeat until one collapses nothing. On the CPU this is one
launch where the rounds take dozens; on CUDA, where one thread is slow and the rounds' launches fill the device, the
rounds stay.

Written by hand: the collapse order and the corner lists changing under it are the algorithm (no library decimator
keeps the faces' sources or moves no vertex).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .refine import position_hash

# Passes at most (each after the first revisits only the vertices whose surroundings changed; flat regions need 3-5).
MAX_PASSES = 64


@wp.func
def next_corner(tris: wp.array[wp.int32], corner: int, step: int) -> int:
    """The vertex ``step`` (1 or 2) corners on from ``corner`` (a row of ``tris.ravel()``) in its face."""
    face = corner // 3
    return tris[face * 3 + (corner % 3 + step) % 3]


@wp.func
def face_quality(a: wp.vec3, b: wp.vec3, c: wp.vec3) -> float:
    """4 sqrt(3) area / sum of squared edges: 1 for an equilateral triangle, 0 for a degenerate one."""
    doubled = wp.length(wp.cross(b - a, c - a))
    edges = wp.length_sq(b - a) + wp.length_sq(c - b) + wp.length_sq(a - c)
    if edges <= 0.0:
        return 0.0
    return 1.7320508 * 2.0 * doubled / edges


@wp.func
def face_passes(
    pu: wp.vec3, pv: wp.vec3, pa: wp.vec3, pb: wp.vec3, on_edge: bool, tol: float, quality: wp.vec2
) -> bool:
    """Whether face ``u a b`` allows ``u`` to move onto ``v`` (``on_edge``: the face holds the edge u-v, and vanishes):
    ``v`` within ``tol`` of its plane, and the face ``v a b`` that takes its place neither turned over, nor thinner
    than ``quality[0]`` (or than the face was), nor with ``u`` farther than ``tol`` from its plane. Only faces of at
    least ``quality[1]`` bound a plane (a thin face's plane is ill-defined)."""
    n_old = wp.cross(pa - pu, pb - pu)
    area = wp.length(n_old)
    q_old = face_quality(pu, pa, pb)
    if q_old >= quality[1] and wp.abs(wp.dot(n_old, pv - pu)) > tol * area:
        return False
    if on_edge:
        return True
    n_new = wp.cross(pa - pv, pb - pv)
    if wp.dot(n_new, n_old) <= 0.5 * wp.length(n_new) * area:
        return False
    q_new = face_quality(pv, pa, pb)
    if q_new < wp.min(quality[0], q_old):
        return False
    return not (q_new >= quality[1] and wp.abs(wp.dot(n_new, pu - pv)) > tol * wp.length(n_new))


@wp.struct
class ListedMeshArg:
    """A triangle mesh whose vertices' corners are linked lists: vertex ``v``'s from ``head[v]``, each corner's next
    ``link[c]`` (-1 ends it); a corner of a face no longer ``alive`` is skipped where it stands."""

    points: wp.array[wp.vec3]
    tris: wp.array[wp.int32]
    alive: wp.array[wp.int32]
    head: wp.array[wp.int32]
    link: wp.array[wp.int32]


@wp.func
def _degree(m: ListedMeshArg, u: int) -> int:
    count = int(0)
    c = m.head[u]
    while c >= 0:
        if m.alive[c // 3] == 1:
            count += 1
        c = m.link[c]
    return count


@wp.func
def _one_fan(m: ListedMeshArg, u: int, degree: int) -> bool:
    """Whether the live faces at ``u`` form one closed fan (as :func:`.coarsen._one_fan`)."""
    start = int(-1)
    c = m.head[u]
    while c >= 0 and start < 0:
        if m.alive[c // 3] == 1:
            start = c
        c = m.link[c]
    at = start
    for step in range(degree):
        target = next_corner(m.tris, at, 1)
        found = int(-1)
        d = m.head[u]
        while d >= 0:
            if m.alive[d // 3] == 1 and next_corner(m.tris, d, 2) == target:
                found = d
            d = m.link[d]
        if found < 0:
            return False
        at = found
        if at == start:
            return step == degree - 1
    return False


@wp.func
def _one_group(m: ListedMeshArg, group: wp.array[wp.int64], u: int) -> bool:
    g = wp.int64(-1)
    first = int(1)
    c = m.head[u]
    while c >= 0:
        if m.alive[c // 3] == 1:
            if first == 1:
                g = group[c // 3]
                first = 0
            elif group[c // 3] != g:
                return False
        c = m.link[c]
    return True


@wp.func
def _collapse_ok(m: ListedMeshArg, u: int, v: int, tol: float, min_quality: float, plane_quality: float) -> bool:
    """Whether ``u`` may move onto its neighbour ``v``: every live face at ``u`` passes (:func:`face_passes`), two of
    them hold the edge, and ``u`` and ``v`` share exactly two neighbours (the link condition)."""
    pu = m.points[u]
    pv = m.points[v]
    vanish = int(0)
    c = m.head[u]
    while c >= 0:
        if m.alive[c // 3] == 1:
            a = next_corner(m.tris, c, 1)
            b = next_corner(m.tris, c, 2)
            on_edge = a == v or b == v
            if not face_passes(pu, pv, m.points[a], m.points[b], on_edge, tol, wp.vec2(min_quality, plane_quality)):
                return False
            if on_edge:
                vanish += 1
        c = m.link[c]
    if vanish != 2:
        return False
    common = int(0)
    c = m.head[u]
    while c >= 0:
        if m.alive[c // 3] == 1:
            x = next_corner(m.tris, c, 1)
            d = m.head[v]
            while d >= 0:
                if m.alive[d // 3] == 1 and next_corner(m.tris, d, 1) == x:
                    common += 1
                d = m.link[d]
        c = m.link[c]
    return common == 2


@wp.func
def _best_target(
    m: ListedMeshArg, group: wp.array[wp.int64], place: wp.array[wp.int32], u: int, tol: float, quality: wp.vec2
) -> int:
    """The nearest neighbour ``u`` may move onto (ties to the smaller ``place``), -1 for none (as
    :func:`.coarsen._candidate_kernel`); ``quality``: the least quality, and the least of a face whose plane counts."""
    degree = _degree(m, u)
    if degree < 3 or not _one_group(m, group, u):
        return -1
    best = int(-1)
    length = float(3.0e38)
    fan = int(-1)  # whether the faces at ``u`` are one fan: asked once a neighbour passes (most fail the planes first)
    c = m.head[u]
    while c >= 0:
        if m.alive[c // 3] == 1:
            v = next_corner(m.tris, c, 1)
            d = wp.length(m.points[v] - m.points[u])
            closer = d < length or (d == length and best >= 0 and place[v] < place[best])
            if closer and _collapse_ok(m, u, v, tol, quality[0], quality[1]):
                if fan < 0:
                    fan = wp.where(_one_fan(m, u, degree), 1, 0)
                if fan == 0:
                    return -1
                best = v
                length = d
        c = m.link[c]
    return best


@wp.func
def _unlink_dead(m: ListedMeshArg, x: int):
    """``x``'s corners of faces no longer alive taken out of its list (the others keep their order)."""
    last = int(-1)
    c = m.head[x]
    while c >= 0:
        after = m.link[c]
        if m.alive[c // 3] == 1:
            if last < 0:
                m.head[x] = c
            else:
                m.link[last] = c
            last = c
        c = after
    if last < 0:
        m.head[x] = -1
    else:
        m.link[last] = -1


@wp.func
def _collapse(m: ListedMeshArg, u: int, v: int):
    """``u`` moved onto ``v``: the faces on their edge die, ``u``'s other corners become ``v``'s. The dead faces'
    corners leave the lists of ``v`` and of the two faces' third corners: a list walked later holds live corners only
    (kept, a flat region's last vertices walked the dead corners of every collapse onto them: boxes side by side,
    moved, 16 k movable vertices in 85 ms)."""
    c = m.head[u]
    tail = int(-1)
    while c >= 0:
        face = c // 3
        if m.alive[face] == 1:
            a = next_corner(m.tris, c, 1)
            b = next_corner(m.tris, c, 2)
            if a == v or b == v:
                m.alive[face] = 0
                _unlink_dead(m, wp.where(a == v, b, a))
            else:
                m.tris[c] = v
        tail = c
        c = m.link[c]
    if tail >= 0:
        m.link[tail] = m.head[v]
        m.head[v] = m.head[u]
    m.head[u] = -1
    _unlink_dead(m, v)


@wp.func
def _mark_about(m: ListedMeshArg, v: int, changed: wp.array[wp.int32], t: int):
    """Every vertex within two edges of ``v`` marked as changed at ``t`` (their checks read what a collapse onto ``v``
    changed: the fans of ``v`` and of its neighbours)."""
    changed[v] = t
    c = m.head[v]
    while c >= 0:
        if m.alive[c // 3] == 1:
            for step in range(1, 3):
                w = next_corner(m.tris, c, step)
                changed[w] = t
                d = m.head[w]
                while d >= 0:
                    if m.alive[d // 3] == 1:
                        changed[next_corner(m.tris, d, 1)] = t
                        changed[next_corner(m.tris, d, 2)] = t
                    d = m.link[d]
        c = m.link[c]


@wp.kernel(enable_backward=False)
def _collapse_serial_kernel(
    m: ListedMeshArg,
    group: wp.array[wp.int64],
    place: wp.array[wp.int32],
    order: wp.array[wp.int32],
    tol: float,
    quality: wp.vec2,
    passes: int,
    changed: wp.array[wp.int32],
    checked: wp.array[wp.int32],
    moved: wp.array[wp.int32],
):
    """One thread: the corner lists linked (``m.head`` all -1 before), then passes over the movable vertices
    ``order``, each moved onto its best target where one passes (``moved``: -1 where none did); a vertex is checked
    again only once its surroundings changed."""
    for k in range(m.tris.shape[0]):  # each vertex's corners linked (the last first)
        c = m.tris.shape[0] - 1 - k
        m.link[c] = m.head[m.tris[c]]
        m.head[m.tris[c]] = c
    t = int(1)
    for _p in range(passes):
        count = int(0)
        for i in range(order.shape[0]):
            u = order[i]
            if moved[u] < 0 and checked[u] <= changed[u]:
                checked[u] = t
                t += 1
                v = _best_target(m, group, place, u, tol, quality)
                if v >= 0:
                    _collapse(m, u, v)
                    moved[u] = v
                    _mark_about(m, v, changed, t)
                    t += 1
                    count += 1
        if count == 0:
            return


def collapse_serial(points, tris: np.ndarray, movable: np.ndarray, group: np.ndarray, tol: float, device, *, quality):
    """The flat collapses of ``movable`` vertices (arguments as :func:`.coarsen.collapse_flat`, ``quality``: its
    least face quality and the least of a face whose plane bounds a collapse) made in one thread (module docstring).

    Returns:
        ``(tris, rows)``: the faces left on the same vertex indices, and which input face each one is.
    """
    flat = np.ascontiguousarray(tris, dtype=np.int32).ravel()
    n = len(points)
    place = position_hash(points)
    visit = np.flatnonzero(movable).astype(np.int32)
    visit = visit[np.lexsort((visit, place[visit]))]  # by a hash of their positions (module docstring)
    mesh = ListedMeshArg()
    mesh.points = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
    mesh.tris = wp.array(flat, dtype=wp.int32, device=device)
    mesh.alive = wp.ones(len(flat) // 3, dtype=wp.int32, device=device)
    mesh.head = wp.full(n, -1, dtype=wp.int32, device=device)
    mesh.link = wp.empty(len(flat), dtype=wp.int32, device=device)  # (linked by the kernel)
    moved = wp.full(n, -1, dtype=wp.int32, device=device)
    inputs = [
        mesh,
        wp.array(np.ascontiguousarray(group, dtype=np.int64), dtype=wp.int64, device=device),
        wp.array(place, dtype=wp.int32, device=device),
        wp.array(visit, dtype=wp.int32, device=device),
        float(tol),
        wp.vec2(*quality),
        MAX_PASSES,
        wp.zeros(n, dtype=wp.int32, device=device),
        wp.zeros(n, dtype=wp.int32, device=device),
        moved,
    ]  # fmt: skip
    wp.launch(_collapse_serial_kernel, dim=1, inputs=inputs, device=device)
    rows = np.flatnonzero(mesh.alive.numpy())
    return mesh.tris.numpy().reshape(-1, 3)[rows], rows
