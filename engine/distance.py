"""Exact closest points of a mesh's field on its finest level (Ren et al., Sec. 4.2).

The finest level takes exact closest points octet by octet (:func:`finest_distances`): one BVH query at the octet's
centre gives its closest triangle, whose distance to each of the 8 nodes bounds where their closest triangles can be,
one box query lists those candidates and each node is tested against them. Meshes far finer than the cells query the
BVH node by node, and a dense single level does throughout. The octet centres' closest points are kept: they are the
level-1 nodes' (:mod:`.fim`).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .geometry import (
    UNSET_DISTANCE,
    closest_on_triangle,
    mesh_closest_face,
    triangle_frame,
)
from .octree import node_center
from .parallel import EMIT_SPLIT_MIN_DIM, launch_split


@wp.func
def _node_closest_point(mesh: wp.uint64, x: wp.vec3, max_dist: float, far_dist: float):
    """(found, closest point, its triangle or -1) of one node by the mesh BVH: within ``max_dist``, else within
    ``far_dist``."""
    p, face = mesh_closest_face(mesh, x, max_dist)
    if face < 0:
        # a node added where an open mesh's surface crosses a hole can be far from every triangle
        p, face = mesh_closest_face(mesh, x, far_dist)
    return wp.where(face >= 0, 1, 0), p, face


@wp.func
def _capsule_gap(x: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3, normal: wp.vec3, shortest: float) -> float:
    """A lower bound of the distance from ``x`` to triangle (a, b, c) (``normal``: (b - a) x (c - a)): its distance to
    the longest edge less the triangle's height over that edge. The corner opposite the longest edge has its foot on
    that edge (both other angles are acute), so every point of the triangle lies within the height of the edge. 0
    (no bound) when no edge is longer than ``shortest``: a small triangle's box bounds it about as well."""
    p = a
    q = b
    l2 = wp.length_sq(b - a)
    if wp.length_sq(c - b) > l2:
        p = b
        q = c
        l2 = wp.length_sq(c - b)
    if wp.length_sq(a - c) > l2:
        p = c
        q = a
        l2 = wp.length_sq(a - c)
    if l2 <= shortest * shortest:
        return 0.0
    t = wp.clamp(wp.dot(x - p, q - p) / l2, 0.0, 1.0)
    return wp.length(x - (p + t * (q - p))) - wp.length(normal) / wp.sqrt(l2)


@wp.kernel(enable_backward=False)
def _finest_octet_distance_kernel(
    first: int,
    mesh: wp.uint64,
    coords: wp.array[wp.vec3i],
    octet_nodes: wp.array[wp.int32],
    origin: wp.vec3,
    spacing: float,
    max_dist: float,
    far_dist: float,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    tri: wp.array[wp.int32],
    octet_dist: wp.array[wp.float32],
    octet_proj: wp.array[wp.vec3],
    box_search: int,
    search: wp.uint64,
    frame: wp.mat33,
    turned: int,
    slivers: wp.array[wp.uint8],
):
    """Exact closest points of the 8 nodes of one finest octet (first node ``octet_nodes[first + tid]``, children in
    Morton order). One BVH query at the octet's centre gives its closest triangle; each node's distance to that
    triangle bounds its own (tighter than its distance to the centre's closest point: a smaller box, and fewer
    triangles pass the tests below), so the triangles whose boxes meet the box around those balls are all the
    candidates, and every node is tested against them directly — one BVH query per octet instead of eight. Octets
    far from the mesh (no triangle within ``max_dist`` of the centre, added where an open mesh's surface crosses a
    hole) do the same after a wider centre query: their balls are large, but the boxes' distances still skip most
    candidates (beetle /256: their 8 node queries took twice as long). Every octet queries node by node when
    ``box_search`` is 0 (a mesh whose triangles are much smaller than a cell would put hundreds in each box). The
    centre's closest point (the octet's parent node's) goes to ``octet_dist``/``octet_proj`` (UNSET_DISTANCE when not
    found). Each node's closest triangle goes to ``tri``. The BVH queries of the box search run on ``search``, the
    mesh turned by the rotation ``frame`` (:func:`search_frame`; ``turned`` 1, else the mesh itself and 0), with the
    same triangles: the tests themselves read the mesh's own. Only triangles flagged in ``slivers`` (:func:`slivers`;
    empty: none) take the capsule test."""
    t = first + wp.tid()
    base = octet_nodes[t]
    c = node_center(origin, spacing, coords[base]) + wp.vec3(0.5 * spacing)
    cs = c
    if turned == 1:
        cs = frame * c
    centre_foot, centre_face = mesh_closest_face(search, cs, max_dist)
    near = centre_face >= 0
    has_foot = near
    if not near:
        # an octet added where an open mesh's surface crosses a hole can be far from every triangle
        centre_foot, centre_face = mesh_closest_face(search, cs, far_dist)
        has_foot = centre_face >= 0
    if turned == 1:
        centre_foot = wp.transpose(frame) * centre_foot
    octet_dist[base // 8] = UNSET_DISTANCE
    if has_foot:
        octet_dist[base // 8] = wp.length(c - centre_foot)
        octet_proj[base // 8] = centre_foot
    if has_foot and box_search == 1:
        node_lo = c - wp.vec3(0.5 * spacing)  # the box of the 8 node centres
        node_hi = c + wp.vec3(0.5 * spacing)
        # every node starts from its closest point on the centre's closest triangle (an upper bound)
        m = wp.mesh_get(mesh)
        a0 = m.points[m.indices[3 * centre_face]]
        b0 = m.points[m.indices[3 * centre_face + 1]]
        c0 = m.points[m.indices[3 * centre_face + 2]]
        edges0, inward0, lengths0, n0 = triangle_frame(a0, b0, c0)
        best = wp.vector(UNSET_DISTANCE, length=8, dtype=float)
        foot = wp.matrix(0.0, shape=(8, 3), dtype=float)
        face = wp.vector(centre_face, length=8, dtype=int)
        worst = float(0.0)
        # each node's closest triangle lies in its ball through that point: search the box around those balls
        box_lo = c
        box_hi = c  # grown around every ball below (starting at the centre can only widen it)
        for k in range(8):
            x = c + spacing * wp.vec3(float(k & 1) - 0.5, float((k >> 1) & 1) - 0.5, float((k >> 2) & 1) - 0.5)
            p0 = closest_on_triangle(x, a0, b0, c0, edges0, inward0, lengths0, n0)
            best[k] = wp.length_sq(x - p0)
            foot[k] = p0
            worst = wp.max(worst, best[k])
            r = wp.sqrt(best[k]) * 1.0001 + 1.0e-4 * spacing
            box_lo = wp.min(box_lo, x - wp.vec3(r))
            box_hi = wp.max(box_hi, x + wp.vec3(r))
        if turned == 1:  # the box around the turned box
            mid = frame * (0.5 * (box_lo + box_hi))
            half = 0.5 * (box_hi - box_lo)
            reach = wp.vec3(
                wp.abs(frame[0, 0]) * half[0] + wp.abs(frame[0, 1]) * half[1] + wp.abs(frame[0, 2]) * half[2],
                wp.abs(frame[1, 0]) * half[0] + wp.abs(frame[1, 1]) * half[1] + wp.abs(frame[1, 2]) * half[2],
                wp.abs(frame[2, 0]) * half[0] + wp.abs(frame[2, 1]) * half[1] + wp.abs(frame[2, 2]) * half[2],
            )
            box_lo = mid - reach
            box_hi = mid + reach
        candidates = wp.mesh_query_aabb(search, box_lo, box_hi)
        f = int(0)
        while wp.mesh_query_aabb_next(candidates, f):
            if f == centre_face:
                continue
            a = m.points[m.indices[3 * f]]
            b = m.points[m.indices[3 * f + 1]]
            cc = m.points[m.indices[3 * f + 2]]
            # no point of a triangle is nearer than its bounding box: the box's distance to the nodes' box bounds
            # all 8 nodes at once, its distance to a node that node, before the exact test (an exact test at the
            # centre, less half a diagonal, bounded them about as well at about the same cost)
            tri_lo = wp.min(a, wp.min(b, cc))
            tri_hi = wp.max(a, wp.max(b, cc))
            gap = wp.max(wp.max(tri_lo - node_hi, node_lo - tri_hi), wp.vec3(0.0))
            near_box = wp.length_sq(gap) < worst
            if near_box:
                # nor nearer than its plane, which bounds all 8 nodes at once where the boxes of long slanted
                # triangles (a cylinder's sides) meet the nodes' box without coming near it
                normal = wp.cross(b - a, cc - a)
                off = wp.abs(wp.dot(normal, c - a)) - 0.5 * spacing * (
                    wp.abs(normal[0]) + wp.abs(normal[1]) + wp.abs(normal[2])
                )
                near_box = off <= 0.0 or off * off < worst * wp.length_sq(normal)
            if near_box and slivers.shape[0] > 0 and slivers[f] == wp.uint8(1):
                # nor nearer than its longest edge less its height: slivers beside the nearest one (a cylinder's
                # sides around the nodes) share its plane nearly, not its place
                beyond = _capsule_gap(c, a, b, cc, normal, 4.0 * spacing) - 0.8660254 * spacing  # less half a diagonal
                near_box = beyond <= 0.0 or beyond * beyond < worst
            if near_box:
                worst = float(0.0)
                edges, inward, lengths, n = triangle_frame(a, b, cc)
                for k in range(8):
                    x = c + spacing * wp.vec3(float(k & 1) - 0.5, float((k >> 1) & 1) - 0.5, float((k >> 2) & 1) - 0.5)
                    gap = wp.max(wp.max(tri_lo - x, x - tri_hi), wp.vec3(0.0))
                    plane = wp.dot(n, x - a)  # nor nearer than its plane (0 for a degenerate triangle)
                    if wp.length_sq(gap) < best[k] and plane * plane < best[k]:
                        p = closest_on_triangle(x, a, b, cc, edges, inward, lengths, n)
                        d = wp.length_sq(x - p)
                        if d < best[k]:
                            best[k] = d
                            foot[k] = p
                            face[k] = f
                    worst = wp.max(worst, best[k])
        for k in range(8):
            x = node_center(origin, spacing, coords[base + k])
            if best[k] < UNSET_DISTANCE:
                p = wp.vec3(foot[k, 0], foot[k, 1], foot[k, 2])
                dist[base + k] = wp.length(x - p)
                proj[base + k] = p
                tri[base + k] = face[k]
            else:  # cannot happen but for rounding: the node's own query
                found, p, node_face = _node_closest_point(mesh, x, max_dist, far_dist)
                dist[base + k] = wp.where(found == 1, wp.length(x - p), UNSET_DISTANCE)
                proj[base + k] = p
                tri[base + k] = node_face
        return
    for k in range(8):
        x = node_center(origin, spacing, coords[base + k])
        bound = max_dist
        if not near and has_foot:  # far from the mesh: the centre's closest point bounds each node's search
            bound = wp.length(x - centre_foot) * 1.0001 + 1.0e-4 * spacing
        found, p, node_face = _node_closest_point(mesh, x, bound, far_dist)
        dist[base + k] = wp.where(found == 1, wp.length(x - p), UNSET_DISTANCE)
        proj[base + k] = p
        tri[base + k] = node_face


@wp.kernel(enable_backward=False)
def _finest_distance_kernel(
    mesh: wp.uint64,
    coords: wp.array[wp.vec3i],
    origin: wp.vec3,
    spacing: float,
    max_dist: float,
    far_dist: float,
    source_id: int,
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
    tri: wp.array[wp.int32],
):
    """Exact closest point (and its triangle) of each node of a dense finest level (Warp's mesh BVH)."""
    i = wp.tid()
    x = node_center(origin, spacing, coords[i])
    found, p, face = _node_closest_point(mesh, x, max_dist, far_dist)
    source[i] = source_id
    dist[i] = wp.where(found == 1, wp.length(x - p), UNSET_DISTANCE)
    proj[i] = p
    tri[i] = face


@wp.kernel(enable_backward=False)
def take_known_kernel(
    first: int,
    where: wp.array[wp.int32],
    prev_values: wp.array[wp.float32],
    prev_proj: wp.array[wp.vec3],
    prev_source: wp.array[wp.int32],
    known: wp.array[wp.int32],
    dist: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
):
    """Node ``first + tid`` found in an earlier build (``where`` >= 0) takes its distance, closest point and source,
    and is marked ``known`` (when ``known`` is not empty)."""
    i = first + wp.tid()
    j = where[i]
    if j < 0:
        return
    dist[i] = wp.abs(prev_values[j])
    proj[i] = prev_proj[j]
    source[i] = prev_source[j]
    if known.shape[0] > 0:
        known[i] = 1


@wp.kernel(enable_backward=False)
def _take_known_triangles_kernel(
    first: int, where: wp.array[wp.int32], prev_tri: wp.array[wp.int32], tri: wp.array[wp.int32]
):
    """Finest node ``first + tid`` found in an earlier build takes its closest triangle."""
    i = first + wp.tid()
    j = where[i]
    if j >= 0:
        tri[i] = prev_tri[j]


# A triangle is a sliver, for the octets' capsule test, when its longest edge exceeds this many cells and its height
# over that edge is under SLIVER_HEIGHT cells.
SLIVER_LENGTH = 4.0
SLIVER_HEIGHT = 2.0


@wp.kernel(enable_backward=False)
def _sliver_kernel(
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    length: float,
    height: float,
    sliver: wp.array[wp.uint8],
):
    """Whether triangle ``tid``'s longest edge exceeds ``length`` and its height over that edge is under ``height``."""
    t = wp.tid()
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    longest = wp.sqrt(wp.max(wp.length_sq(b - a), wp.max(wp.length_sq(c - b), wp.length_sq(a - c))))
    sliver[t] = wp.uint8(0)
    if longest > length and wp.length(wp.cross(b - a, c - a)) < height * longest:
        sliver[t] = wp.uint8(1)


def slivers(verts: np.ndarray, tris: np.ndarray, spacing: float, device=None) -> wp.array:
    """(T,) uint8 Warp array: 1 for the long thin triangles (SLIVER_LENGTH, SLIVER_HEIGHT) whose longest edge less
    their height bounds their distance much better than their plane and box do (a cylinder's sides beside each
    other). Taken by every long triangle, the test cost meshes without slivers 6-8 % of their finest distances (cow,
    fandisk, homer)."""
    out = wp.empty(len(tris), dtype=wp.uint8, device=device)
    wp.launch(
        _sliver_kernel,
        dim=len(tris),
        inputs=[
            wp.array(verts, dtype=wp.vec3, device=device),
            wp.array(tris, dtype=wp.int32, device=device),
            SLIVER_LENGTH * spacing,
            SLIVER_HEIGHT * spacing,
            out,
        ],
        device=device,
    )
    return out


# A mesh is searched in another frame where that spares each octet at least this many candidate triangles (a turned
# box's 12 triangles gain nothing measurable; a turned cylinder of 512 slivers 230).
SEARCH_FRAME_SAVING = 16.0


@wp.kernel(enable_backward=False)
def _grown_boxes_kernel(
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    frame: wp.mat33,
    grow: float,
    volume: wp.array[wp.float32],
    cross: wp.array[wp.vec3],
):
    """The volume of triangle ``tid``'s bounding box in the rotation ``frame``, grown by ``grow`` on every axis, and
    (where ``cross`` is not empty) its edges' cross product."""
    t = wp.tid()
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    if cross.shape[0] > 0:
        cross[t] = wp.cross(b - a, c - a)
    a = frame * a
    b = frame * b
    c = frame * c
    size = wp.max(a, wp.max(b, c)) - wp.min(a, wp.min(b, c)) + wp.vec3(grow)
    volume[t] = size[0] * size[1] * size[2]


def search_frame(verts: np.ndarray, tris: np.ndarray, octet: float, device=None) -> np.ndarray | None:
    """A rotation (3, 3) under which the octets (of edge ``octet``) meet far fewer candidate triangles, or None.

    The octets' candidate search (:func:`_finest_octet_distance_kernel`) finds triangles by their boxes in the BVH. A
    mesh whose long or flat parts are slanted has boxes far larger than the triangles: a cylinder turned about two
    axes has sides 0.85 long and 0.006 wide whose boxes are a third of the diagonal on every axis and overlap all
    around it, so every octet beside it meets hundreds of them and its centre query walks most of the BVH. Distances
    do not change under a rotation: the queries may run on the mesh turned so its parts lie along the axes. Tried:
    the principal axes of the vertices (a cylinder's axis) and the frame of the two largest triangles' normals most
    apart (a box's faces). The candidates an octet meets are estimated as the volume of the triangles' boxes, each
    grown by an octet, over the volume of the band around the surface, at most every triangle."""
    count = len(tris)
    points = wp.array(verts, dtype=wp.vec3, device=device)
    corners = wp.array(tris, dtype=wp.int32, device=device)
    volume = wp.empty(count, dtype=wp.float32, device=device)
    cross = wp.empty(count, dtype=wp.vec3, device=device)

    def grown_volume(rotation, edges):
        turn = wp.mat33(*(float(x) for x in np.reshape(rotation, -1)))
        wp.launch(
            _grown_boxes_kernel,
            dim=count,
            inputs=[points, corners, turn, 2.0 * octet],
            outputs=[volume, edges],
            device=device,
        )
        return float(volume.numpy().sum(dtype=np.float64))

    own_volume = grown_volume(np.eye(3), cross)
    edges = cross.numpy()
    areas = np.linalg.norm(edges, axis=1)
    band = max(float(areas.sum(dtype=np.float64)) * octet, 1e-30)  # twice the area (the cross products') x octet

    def candidates(grown: float) -> float:
        return min(grown / band, float(count))

    own = candidates(own_volume)
    # no frame makes a triangle's grown box smaller than the octet's own cube: fine meshes stop here
    if own - candidates(count * (2.0 * octet) ** 3) < SEARCH_FRAME_SAVING:
        return None
    frames = []
    centred = np.asarray(verts, dtype=np.float64) - np.mean(verts, axis=0)
    frames.append(np.linalg.eigh(centred.T @ centred)[1].T)
    if areas.max() > 0.0:
        normals = edges / np.maximum(areas, 1e-30)[:, None]
        first = normals[np.argmax(areas)].astype(np.float64)
        large = normals[areas >= 0.5 * areas.max()]
        second = large[np.argmin(np.abs(large @ first))].astype(np.float64)
        second = second - (second @ first) * first
        if np.linalg.norm(second) > 1e-3:
            second /= np.linalg.norm(second)
            frames.append(np.stack([first, second, np.cross(first, second)]))
    no_edges = wp.empty(0, dtype=wp.vec3, device=device)
    counts = [candidates(grown_volume(frame, no_edges)) for frame in frames]
    best = int(np.argmin(counts))
    return frames[best] if own - counts[best] >= SEARCH_FRAME_SAVING else None


def finest_distances(
    mesh_id,
    layout: dict,
    *,
    origin,
    voxel_size: float,
    query_radius: float,
    far_dist: float,
    field_id: int,
    box_search: bool,
    previous=None,
    prev_index=None,
    search_id=None,
    frame=None,
    slivers=None,
):
    """Exact closest points of the finest level of ``layout`` (:func:`.octree.level_layout`) on a mesh.

    Args:
        mesh_id: ``wp.Mesh.id`` of the mesh.
        layout: Every node's place; its finest level is complete octets (or, with one level, the dense top level).
        origin, voxel_size: The field's lattice.
        query_radius: Radius within which every finest node has a triangle (larger searches fall back to
            ``far_dist``, the domain's diagonal).
        field_id: Source id written to the finest nodes.
        box_search: Octets search a box of candidate triangles (meshes whose triangles are not much smaller than a
            cell), else query the BVH node by node.
        previous, prev_index: An earlier field of the same mesh and domain and each node's index in it (-1: new;
            :func:`.octree.match_levels`): its octets keep their closest points.
        search_id, frame: With ``box_search`` and more than one level, the ``wp.Mesh.id`` of the mesh turned by the
            rotation ``frame`` (3, 3; :func:`search_frame`), whose BVH the octets search; None: the mesh's own.
        slivers: (T,) uint8 Warp array, 1 for the triangles :func:`slivers` flags (None: no triangle).
    Returns:
        ``(dist, proj, source, tri, octet_points)``: (N,) float32 unsigned distances, (N,) vec3 closest points and (N,)
        int32 source ids for every node of the layout, the finest level's filled in; (N0,) int32 the triangle (index
        into the mesh) of each finest node's closest point; ``octet_points`` the (distance, closest point) arrays of
        every finest octet's centre (UNSET_DISTANCE where not found), or None for a dense single level.
    """
    offsets, device = layout["offsets"], layout["codes"].device
    n, n0 = int(offsets[-1]), int(offsets[1])
    fine_coords = layout["coords"][:n0]
    dist = wp.empty(n, dtype=wp.float32, device=device)
    proj = wp.empty(n, dtype=wp.vec3, device=device)
    source = wp.empty(n, dtype=wp.int32, device=device)
    dist0, proj0, src0 = dist[:n0], proj[:n0], source[:n0]
    tri = wp.empty(n0, dtype=wp.int32, device=device)
    # Octets an earlier build of this mesh already has keep their closest points; only new ones are queried.
    first_nodes = np.arange(0, n0, 8)
    if previous is not None:
        launch_split(_take_known_triangles_kernel, n0, lambda s, _n: [s, prev_index, previous.tri, tri], device)
        no_known = wp.empty(0, dtype=wp.int32, device=device)
        prev_points, prev_sources = previous.closest_points, previous.node_sources()
        launch_split(
            take_known_kernel,
            n0,
            lambda s, _n: [
                s,
                prev_index,
                previous.values,
                prev_points,
                prev_sources,
                no_known,
                dist0,
                proj0,
                src0,
            ],
            device,
        )
        first_nodes = 8 * np.flatnonzero(prev_index.numpy()[:n0:8] < 0)  # matched octet by octet
    src0.fill_(int(field_id))
    origin_v = wp.vec3(*origin)
    if len(offsets) == 2:  # a single dense level: node by node
        launch_split(
            _finest_distance_kernel,
            n0,
            lambda lo, k: [
                mesh_id,
                fine_coords[lo : lo + k],
                origin_v,
                float(voxel_size),
                float(query_radius),
                float(far_dist),
                int(field_id),
                dist0[lo : lo + k],
                proj0[lo : lo + k],
                src0[lo : lo + k],
                tri[lo : lo + k],
            ],
            device,
        )
        return dist, proj, source, tri, None
    # octet by octet, in place
    octet_nodes = wp.array(first_nodes.astype(np.int32), dtype=wp.int32, device=device)
    octet_dist = wp.full(n0 // 8, UNSET_DISTANCE, dtype=wp.float32, device=device)
    octet_proj = wp.empty(n0 // 8, dtype=wp.vec3, device=device)
    launch_split(
        _finest_octet_distance_kernel,
        len(first_nodes),
        lambda lo, k: [
            lo,
            mesh_id,
            fine_coords,
            octet_nodes,
            origin_v,
            float(voxel_size),
            float(query_radius),
            float(far_dist),
            dist0,
            proj0,
            tri,
            octet_dist,
            octet_proj,
            int(box_search),
            mesh_id if search_id is None else search_id,
            wp.mat33(*(float(x) for x in np.reshape(np.eye(3) if frame is None else frame, -1))),
            int(frame is not None),
            wp.empty(0, dtype=wp.uint8, device=device) if slivers is None else slivers,
        ],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,
        balance=True,  # octets near an open mesh's holes, or far from it, cost more
    )
    return dist, proj, source, tri, (octet_dist, octet_proj)
