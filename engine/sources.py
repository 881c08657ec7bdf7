"""Where a field's surface came from: the triangles each operand's field was built from, and queries on them.

A built field keeps its mesh as a :class:`SourceMesh` (the world-space triangles it was built from, and their indices
among the caller's triangles, degenerate ones having been dropped); a boolean result keeps its operands' by field id.
:func:`closest_triangles` finds, for points on or near a surface, the closest triangle of one source mesh and the
barycentric coordinates of the closest point on it (Warp's BVH, built on first use and kept); :func:`barycentrics`
gives the coordinates of points on given triangles, so the corners of one result face can all be read off the one
source triangle their face came from (a source's UV seams then stay seams).

Memory: 28 bytes per triangle and 12 per vertex held with the field (positions, indices, index map), and once
queried the BVH of Warp's mesh, about 50 bytes per triangle more (a closed mesh's field keeps its build's, with its
winding-number data: about 130).
"""

from __future__ import annotations

import threading
import weakref

import numpy as np
import warp as wp

from .facing import facing_sources
from .geometry import mesh_closest_face
from .parallel import EMIT_SPLIT_MIN_DIM, host_view, launch_split
from .queries import face_nodes_kernel

# Placement -> {id(source): (source, the source placed)}: a placed field's sources made once for its placement and
# shared by its copies (refined, relabelled, read as built: they share the placement); entries go with it.
_PLACED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
# BVHs of placed copies that are gone kept per source and device, for the next copy to refit (:meth:`SourceMesh.bvh`).
SPARE_BVHS = 1


def placed_sources(sources: dict, placement) -> dict:
    """``sources`` ({field id: :class:`SourceMesh`}) placed by ``placement`` (``to_world``), each made once for that
    placement, so that what is built on them (a BVH) is shared by every reader."""
    known = _PLACED.setdefault(placement, {})
    out = {}
    for k, source in sources.items():
        hit = known.get(id(source))
        if hit is None or hit[0] is not source:
            hit = known[id(source)] = (source, source.placed(placement.to_world))
        out[k] = hit[1]
    return out


class SourceMesh:
    """An operand's triangles as its field was built from them.

    Attributes:
        verts: (V, 3) float32 world-space vertices.
        tris: (T, 3) int32 triangles (the non-degenerate ones).
        triangle_ids: (T,) int32 index of each among the triangles the field was built from.
    """

    def __init__(self, verts, tris, triangle_ids):
        self.verts = np.ascontiguousarray(verts, dtype=np.float32)
        self.tris = np.ascontiguousarray(tris, dtype=np.int32)
        self.triangle_ids = np.ascontiguousarray(triangle_ids, dtype=np.int32)
        self._bvh = {}  # device -> wp.Mesh
        self._building = threading.Lock()  # (a second reader waits for the BVH the first is building)
        self._arrays = {}  # device -> (points, flat indices) as Warp arrays
        self._box = None  # (lowest, highest) corner of the vertices, found on first use
        self.refiner = None  # what builds its field's finest octets when asked (:mod:`.ondemand`); None: built whole
        self._unplaced = None  # the source this is a placed copy of (:meth:`placed`)
        self._spares = {}  # device -> BVHs of placed copies of this source that are gone (:meth:`bvh`)

    @property
    def nbytes(self) -> int:
        """Bytes held: the arrays, and the BVHs built, adopted or kept spare so far (estimated at the larger, a
        winding-number BVH's)."""
        held = self.verts.nbytes + self.tris.nbytes + self.triangle_ids.nbytes
        held += len(self._arrays) * (self.verts.nbytes + self.tris.nbytes)
        bvhs = len(self._bvh) + sum(len(spares) for spares in self._spares.values())
        return held + bvhs * (self.verts.nbytes + self.tris.nbytes + 130 * len(self.tris))

    def placed(self, to_world) -> SourceMesh:
        """These triangles with their vertices moved by ``to_world`` ((N, 3) -> (N, 3)): a placed field's source."""
        out = SourceMesh(to_world(self.verts), self.tris, self.triangle_ids)
        out._unplaced = self
        return out

    def arrays(self, device) -> tuple:
        """(points (V,) vec3, flat indices (3T,) int32) on ``device``, made on first use."""
        device = wp.get_device(device)
        if device.alias not in self._arrays:
            self._arrays[device.alias] = (
                wp.array(self.verts, dtype=wp.vec3, device=device),
                wp.array(self.tris.reshape(-1), dtype=wp.int32, device=device),
            )
        return self._arrays[device.alias]

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """(lowest, highest) (3,) float32 corner of the vertices' bounding box, found on first use."""
        if self._box is None:
            self._box = (self.verts.min(axis=0), self.verts.max(axis=0)) if len(self.verts) else (np.zeros(3),) * 2
        return self._box

    def adopt(self, mesh: wp.Mesh) -> None:
        """Keep ``mesh`` (Warp's mesh of these very triangles, made for the build) as the BVH on its device."""
        self._bvh[mesh.device.alias] = mesh

    def kept_bvh(self, device):
        """The BVH on ``device`` if at hand (made or adopted already), else None."""
        return self._bvh.get(wp.get_device(device).alias)

    def bvh(self, device) -> wp.Mesh:
        """Warp's mesh (with its BVH) of these triangles on ``device``, built on first use, once: a kept-faces judge's
        thread and its boolean ask for it at the same time (a scan's 69 k triangles: 28 ms of one core each). A placed
        copy takes the BVH of an earlier copy that is gone where there is one, its points moved and its boxes refitted
        (a drag places its operand anew on every move: the bunny's 1 ms against 25)."""
        device = wp.get_device(device)
        with self._building:
            if device.alias not in self._bvh:
                mesh = self._refitted(device)
                if mesh is None:
                    mesh = wp.Mesh(
                        points=wp.array(self.verts, dtype=wp.vec3, device=device),
                        indices=wp.array(self.tris.reshape(-1), dtype=wp.int32, device=device),
                    )
                if self._unplaced is not None:  # given back when this copy goes
                    weakref.finalize(self, self._unplaced._spare, device.alias, mesh)
                self._bvh[device.alias] = mesh
            return self._bvh[device.alias]

    def _refitted(self, device) -> wp.Mesh | None:
        """A spare BVH of the source this is a placed copy of, its points moved here and its boxes refitted."""
        unplaced = self._unplaced
        if unplaced is None:
            return None
        try:  # (a list's pop and append are atomic: no lock, which a copy going at any allocation could wait on)
            mesh = unplaced._spares.get(device.alias, []).pop()
        except IndexError:
            return None
        mesh.points.assign(self.verts)
        mesh.refit()
        return mesh

    def _spare(self, alias: str, mesh: wp.Mesh) -> None:
        """Keep ``mesh``, the BVH of a placed copy that is gone, for the next copy (one a device)."""
        spares = self._spares.setdefault(alias, [])
        if len(spares) < SPARE_BVHS:
            spares.append(mesh)


@wp.kernel(enable_backward=False)
def _closest_triangles_kernel(
    mesh: wp.uint64,
    points: wp.array[wp.vec3],
    max_dist: float,
    faces: wp.array[wp.int32],
    bary: wp.array[wp.vec3],
):
    """The closest triangle of the mesh to each point (-1 beyond ``max_dist``) and the barycentric coordinates of the
    closest point on it, in the order of the triangle's corners."""
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, points[i], max_dist)
    faces[i] = -1
    bary[i] = wp.vec3(0.0)
    if q.result:
        faces[i] = q.face
        # Warp's (u, v) weigh the first and second corners: p = u a + v b + (1 - u - v) c
        bary[i] = wp.vec3(q.u, q.v, 1.0 - q.u - q.v)


@wp.func
def _plane_barycentrics(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> wp.vec3:
    """Weights of a, b, c for the projection of ``p`` onto their plane (not clamped; zeros for a degenerate one)."""
    e0 = b - a
    e1 = c - a
    d = p - a
    d00 = wp.dot(e0, e0)
    d01 = wp.dot(e0, e1)
    d11 = wp.dot(e1, e1)
    den = d00 * d11 - d01 * d01
    if den <= 0.0:
        return wp.vec3(0.0)
    v = (d11 * wp.dot(d, e0) - d01 * wp.dot(d, e1)) / den
    w = (d00 * wp.dot(d, e1) - d01 * wp.dot(d, e0)) / den
    return wp.vec3(1.0 - v - w, v, w)


@wp.kernel(enable_backward=False)
def _face_sources_kernel(
    mesh: wp.uint64,
    corners: wp.array[wp.vec3],
    near: float,
    far: float,
    faces: wp.array[wp.int32],
    bary: wp.array[wp.vec3],
):
    """For face ``tid`` (corners 3 tid .. 3 tid + 2): the triangle of the mesh closest to its centre (searched within
    ``near``, then ``far``), and each corner's barycentric coordinates on that triangle."""
    f = wp.tid()
    a = corners[3 * f]
    b = corners[3 * f + 1]
    c = corners[3 * f + 2]
    centre = (a + b + c) / 3.0
    _foot, face = mesh_closest_face(mesh, centre, near)
    if face < 0:
        _foot, face = mesh_closest_face(mesh, centre, far)
    faces[f] = face
    for k in range(3):
        bary[3 * f + k] = wp.vec3(0.0)
    if face >= 0:
        m = wp.mesh_get(mesh)
        p0 = m.points[m.indices[3 * face]]
        p1 = m.points[m.indices[3 * face + 1]]
        p2 = m.points[m.indices[3 * face + 2]]
        bary[3 * f] = _plane_barycentrics(a, p0, p1, p2)
        bary[3 * f + 1] = _plane_barycentrics(b, p0, p1, p2)
        bary[3 * f + 2] = _plane_barycentrics(c, p0, p1, p2)


@wp.kernel(enable_backward=False)
def _corner_barycentrics_kernel(
    points: wp.array[wp.vec3],
    indices: wp.array[wp.int32],
    verts: wp.array[wp.vec3],
    tris: wp.array[wp.int32],
    rows: wp.array[wp.int32],
    faces: wp.array[wp.int32],
    bary: wp.array[wp.vec3],
):
    """The barycentric coordinates of the three corners of surface triangle ``rows[tid]`` (``verts``, ``tris``) on
    triangle ``faces[tid]`` of the mesh, written at that surface triangle's place in ``bary``."""
    k = wp.tid()
    f = rows[k]
    t = faces[k]
    p0 = points[indices[3 * t]]
    p1 = points[indices[3 * t + 1]]
    p2 = points[indices[3 * t + 2]]
    for c in range(3):
        bary[3 * f + c] = _plane_barycentrics(verts[tris[3 * f + c]], p0, p1, p2)


def corner_barycentrics(source: SourceMesh, faces, rows, verts, tris, bary, device):
    """Fill ``bary`` ((3F,) vec3 Warp array) at the surface triangles ``rows`` with their corners' barycentric
    coordinates on triangle ``faces[k]`` (an index into ``source.tris``) of row ``k``, projected onto its plane and not
    clamped. ``verts`` ((V,) vec3) and ``tris`` ((3F,) int32) are the surface's Warp arrays: nothing is gathered
    in numpy (three (F, 3, 3) arrays on 77 k faces: 6 ms)."""
    n = len(rows)
    if n == 0:
        return
    points, indices = source.arrays(device)
    rows_wp = wp.array(np.ascontiguousarray(rows, dtype=np.int32), dtype=wp.int32, device=device)
    faces_wp = wp.array(np.ascontiguousarray(faces, dtype=np.int32), dtype=wp.int32, device=device)
    launch_split(
        _corner_barycentrics_kernel,
        n,
        lambda lo, k: [points, indices, verts, tris, rows_wp[lo : lo + k], faces_wp[lo : lo + k], bary],
        device,
    )


def face_sources(source: SourceMesh, corners, near: float, device) -> tuple[np.ndarray, np.ndarray]:
    """The triangle of ``source`` closest to each face's centre and its corners' barycentric coordinates on it.

    Args:
        source: The mesh.
        corners: (F, 3, 3) float32 world-space corners of F faces.
        near: Radius the closest triangle is searched within first (faces farther away search the whole mesh).
        device: Warp device.
    Returns:
        (F,) int32 triangle indices among the caller's triangles (``source.triangle_ids``, -1 where none), and
        (F, 3, 3) float32 weights of that triangle's corners for each of the face's corners (projected onto its plane,
        not clamped: an affine map over the triangle extends linearly).
    """
    corners = np.ascontiguousarray(corners, dtype=np.float32).reshape(-1, 3)
    n = len(corners) // 3
    if n == 0:
        return np.zeros(0, np.int32), np.zeros((0, 3, 3), np.float32)
    mesh = source.bvh(device)
    pts = wp.array(corners, dtype=wp.vec3, device=device)
    faces = wp.empty(n, dtype=wp.int32, device=device)
    bary = wp.empty(3 * n, dtype=wp.vec3, device=device)
    lo = np.minimum(source.verts.min(axis=0), corners.min(axis=0))
    hi = np.maximum(source.verts.max(axis=0), corners.max(axis=0))
    far = 2.0 * float(np.linalg.norm(hi - lo)) + 1.0
    launch_split(
        _face_sources_kernel,
        n,
        lambda lo, k: [
            mesh.id,
            pts[3 * lo : 3 * (lo + k)],
            float(near),
            far,
            faces[lo : lo + k],
            bary[3 * lo : 3 * (lo + k)],
        ],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # a BVH query each
    )
    local = faces.numpy()
    tri_ids = np.where(local >= 0, source.triangle_ids[np.maximum(local, 0)], -1).astype(np.int32)
    return tri_ids, bary.numpy().reshape(n, 3, 3)


@wp.kernel(enable_backward=False)
def _mesh_distance_kernel(mesh: wp.uint64, points: wp.array[wp.vec3], max_dist: float, out: wp.array[wp.float32]):
    """Unsigned distance to the mesh, ``max_dist`` where it is farther."""
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, points[i], max_dist)
    out[i] = max_dist
    if q.result:
        out[i] = wp.length(points[i] - wp.mesh_eval_position(mesh, q.face, q.u, q.v))


def distances_to_each(meshes: list, points: np.ndarray, reach: float, device) -> np.ndarray:
    """(M, N) float32 :func:`mesh_distances` from each point to each of ``meshes`` (inf for a None among them)."""
    rows = [np.full(len(points), np.inf, np.float32) if m is None else mesh_distances(m, points, reach, device)
            for m in meshes]  # fmt: skip
    return np.stack(rows) if rows else np.zeros((0, len(points)), np.float32)


def mesh_distances(mesh: wp.Mesh, points: np.ndarray, reach: float, device) -> np.ndarray:
    """(N,) float32 unsigned distance from each point to ``mesh`` (``reach`` where it is farther)."""
    pts = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
    out = wp.empty(len(points), dtype=wp.float32, device=device)
    launch_split(
        _mesh_distance_kernel,
        len(points),
        lambda lo, n: [mesh.id, pts[lo : lo + n], float(reach), out[lo : lo + n]],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # a BVH query each
    )
    return out.numpy()


def closest_triangles(source: SourceMesh, points, device) -> tuple[np.ndarray, np.ndarray]:
    """The closest triangle of ``source`` to each point and the barycentric coordinates of the closest point on it.

    Args:
        source: The mesh.
        points: (N, 3) float32 world-space points.
        device: Warp device.
    Returns:
        (N,) int32 triangle indices among the caller's triangles (``source.triangle_ids``), and (N, 3) float32
        barycentric coordinates (weights of the triangle's three corners, summing to 1).
    """
    points = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    n = len(points)
    faces = wp.empty(n, dtype=wp.int32, device=device)
    bary = wp.empty(n, dtype=wp.vec3, device=device)
    if n == 0:
        return np.zeros(0, np.int32), np.zeros((0, 3), np.float32)
    mesh = source.bvh(device)
    pts = wp.array(points, dtype=wp.vec3, device=device)
    low, high = source.box()
    extent = np.maximum(high, points.max(axis=0)) - np.minimum(low, points.min(axis=0))
    reach = 2.0 * float(np.linalg.norm(extent)) + 1.0
    launch_split(
        _closest_triangles_kernel,
        n,
        lambda lo, k: [mesh.id, pts[lo : lo + k], reach, faces[lo : lo + k], bary[lo : lo + k]],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # a BVH query each
    )
    local = faces.numpy()
    found = local >= 0
    tri_ids = np.where(found, source.triangle_ids[np.maximum(local, 0)], -1).astype(np.int32)
    return tri_ids, bary.numpy()


def closest_points(source: SourceMesh, points, device) -> np.ndarray:
    """(N, 3) float64 the closest point of ``source``'s triangles to each of ``points`` (:func:`closest_triangles`;
    NaN where none was found)."""
    tris, bary = closest_triangles(source, points, device)
    found = np.flatnonzero(tris >= 0)
    out = np.full((len(tris), 3), np.nan)
    corners = source.verts[source.tris[np.searchsorted(source.triangle_ids, tris[found])]].astype(np.float64)
    out[found] = np.einsum("nk,nkd->nd", bary[found].astype(np.float64), corners)
    return out


@wp.kernel(enable_backward=False)
def _interpolate_kernel(
    first: int,
    values: wp.array2d[wp.float32],
    corners: wp.array2d[wp.int32],
    stacked: wp.array[wp.int32],
    weights: wp.array3d[wp.float32],
    out: wp.array2d[wp.float32],
):
    """Per face (from ``first``): each of its corners weights the values at its source triangle's three corners."""
    f = first + wp.tid()
    t = stacked[f]
    for c in range(3):
        for j in range(values.shape[1]):
            acc = float(0.0)
            for k in range(3):
                acc += weights[f, c, k] * values[corners[t, k], j]
            out[3 * f + c, j] = acc


def interpolate_corners(values, corners, stacked, weights, device=None) -> np.ndarray:
    """Values at the corners of F faces, each read off its source triangle by barycentric weights (what a result's
    UV maps and colours are). A kernel: numpy's gathers and batched 3x3 products took 40 ms on 540 k faces.

    Args:
        values: (N, W) float values at the source triangles' corners.
        corners: (T, 3) int indices into ``values`` of each source triangle's corners.
        stacked: (F,) int the source triangle of each face (within ``corners``).
        weights: (F, 3, 3) float per face corner, the weights of its source triangle's corners.
        device: Warp device (default: Warp's default).
    Returns:
        (3F, W) float32, face after face, corner after corner.
    """
    device = wp.get_device(device)
    values = np.ascontiguousarray(values, dtype=np.float32)
    values = values.reshape(len(values), -1)
    count = len(stacked)
    out = wp.empty((3 * count, values.shape[1]), dtype=wp.float32, device=device)
    host = [
        values,
        np.ascontiguousarray(corners, dtype=np.int32).reshape(-1, 3),
        np.ascontiguousarray(stacked, dtype=np.int32),
        np.ascontiguousarray(weights, dtype=np.float32).reshape(-1, 3, 3),
    ]
    args = [host_view(a, wp.dtype_from_numpy(a.dtype), device) for a in host]
    args.append(out)
    launch_split(_interpolate_kernel, count, lambda lo, n: [lo, *args], device)
    return out.numpy()


def barycentrics(source: SourceMesh, triangle_ids, points) -> np.ndarray:
    """Barycentric coordinates of each point's projection onto the plane of its triangle (not clamped to the triangle,
    so an affine map over the triangle, such as its UVs, extends linearly).

    Args:
        source: The mesh.
        triangle_ids: (N,) int indices among the caller's triangles (``source.triangle_ids``); -1 gives zeros.
        points: (N, 3) world-space points.
    Returns:
        (N, 3) float32 weights of each triangle's corners, summing to 1.
    """
    triangle_ids = np.asarray(triangle_ids, dtype=np.int64)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((len(points), 3), dtype=np.float32)
    # from the caller's triangle indices back to the kept triangles
    lookup = np.full(int(source.triangle_ids.max()) + 1 if len(source.triangle_ids) else 0, -1, dtype=np.int64)
    lookup[source.triangle_ids] = np.arange(len(source.triangle_ids))
    valid = (triangle_ids >= 0) & (triangle_ids < len(lookup))
    local = np.where(valid, lookup[np.clip(triangle_ids, 0, max(len(lookup) - 1, 0))], -1)
    valid &= local >= 0
    corners = source.verts.astype(np.float64)[source.tris[local[valid]]]  # (M, 3, 3)
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    e0, e1, d = b - a, c - a, points[valid] - a
    d00, d01, d11 = (e0 * e0).sum(1), (e0 * e1).sum(1), (e1 * e1).sum(1)
    d20, d21 = (d * e0).sum(1), (d * e1).sum(1)
    den = d00 * d11 - d01 * d01
    den = np.where(np.abs(den) > 0.0, den, 1.0)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    out[valid] = np.stack([1.0 - v - w, v, w], axis=1)
    return out


def face_sources_of(field, verts, tris):
    """:meth:`.field.AdaptiveField.face_sources` of ``field`` (see there): the face's leaf's operand and, where that
    leaf is a finest node, the triangle of its closest point, else the triangle closest to the face's centre.
    ``verts`` (V, 3) float32 in the field's own frame (barycentric coordinates do not change with a similarity)."""
    tris = np.asarray(tris)
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise ValueError(f"Expected 'tris' of shape (F, 3), but got {tris.shape}.")
    n = len(tris)
    # every row of ``bary`` a kernel does not write is zeroed below (zeroing all of it first took 8 ms of 48 on
    # 540 k faces)
    verts_wp = host_view(verts, wp.vec3, field.device)
    flat = np.ascontiguousarray(tris, dtype=np.int32).ravel()
    tris_wp = host_view(flat, wp.int32, field.device)
    ids = wp.empty(n, dtype=wp.int32, device=field.device)
    node_tri = wp.empty(n, dtype=wp.int32, device=field.device)
    bary = wp.empty(3 * n, dtype=wp.vec3, device=field.device)
    if n:
        arg = field.arg()
        launch_split(face_nodes_kernel, n, lambda lo, k: [arg, lo, verts_wp, tris_wp, ids, node_tri], field.device)
    ids, node_tri = ids.numpy(), node_tri.numpy()
    facing_sources(field, verts, flat.reshape(-1, 3), ids, node_tri)  # along creases: the triangle the face lies on
    tri_ids = np.full(n, -1, dtype=np.int32)
    unknown_rows = []
    for field_id in np.flatnonzero(np.bincount(ids[ids >= 0])):  # the ids present (a sort of F ids: 7 ms)
        source = field.sources.get(int(field_id))
        if source is None:
            continue
        rows = np.flatnonzero(ids == field_id)
        # the triangle of the finest node holding the face's centre: found by the build, no search needed
        known = rows[node_tri[rows] >= 0]
        tri_ids[known] = source.triangle_ids[node_tri[known]]
        corner_barycentrics(source, node_tri[known], known, verts_wp, tris_wp, bary, field.device)
        unknown_rows.append((source, rows[node_tri[rows] < 0]))
    bary = bary.numpy().reshape(n, 3, 3)
    for source, unknown in unknown_rows:
        # elsewhere (a field that does not keep its finest nodes' triangles): the closest one, by the BVH
        if len(unknown):
            near = 0.5 * field.voxel_size  # a face lies within a fraction of a voxel of its source, but in fillets
            corners = verts[tris[unknown]]
            tri_ids[unknown], bary[unknown] = face_sources(source, corners, near, field.device)
    bary[tri_ids < 0] = 0.0  # no source: never written
    return ids, tri_ids, bary
