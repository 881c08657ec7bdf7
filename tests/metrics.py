"""Measurement oracles for tests and benchmarks, on (V,3) float vertices and (T,3) int triangles (no bpy).

``exact_boolean`` runs manifold3d's exact mesh booleans; ``mesh_volume`` and ``sample_surface`` are plain numpy;
``hausdorff``, ``winding_inside`` and ``exact_sdf`` query a ``wp.Mesh`` with NVIDIA Warp, so every distance is an
exact point-to-triangle distance (in float32), not a distance between samples. ``winding_inside`` and ``exact_sdf``
take the sign from the generalized winding number (Warp's fast one), which makes them usable on open meshes such as
the bunny; ``winding_numbers`` sums the solid angles of all triangles exactly (in float64), for subsamples.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import manifold3d
import numpy as np
import warp as wp

OPERATIONS = ("UNION", "INTERSECT", "DIFFERENCE")
_OP_TYPES = {
    "UNION": manifold3d.OpType.Add,
    "INTERSECT": manifold3d.OpType.Intersect,
    "DIFFERENCE": manifold3d.OpType.Subtract,
}


# ---- validation ----


def _check_mesh(verts, tris, name: str = "verts") -> tuple[np.ndarray, np.ndarray]:
    """Return float64 (V,3) vertices and int64 (T,3) triangles, or raise ValueError/TypeError."""
    verts = np.asarray(verts)
    tris = np.asarray(tris)
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise ValueError(f"Expected '{name}' of shape (V, 3), but got {verts.shape}.")
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise ValueError(f"Expected the triangles of '{name}' of shape (T, 3), but got {tris.shape}.")
    if tris.size and not np.issubdtype(tris.dtype, np.integer):
        raise TypeError(f"Expected integer triangle indices, but got {tris.dtype}.")
    tris = tris.astype(np.int64)
    if tris.size and (tris.min() < 0 or tris.max() >= len(verts)):
        raise ValueError(
            f"Triangle indices of '{name}' must lie in [0, {len(verts)}), but span [{tris.min()}, {tris.max()}]."
        )
    return verts.astype(np.float64), tris


def _check_points(points) -> np.ndarray:
    points = np.asarray(points, dtype=np.float32)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"Expected 'points' of shape (N, 3), but got {points.shape}.")
    return np.ascontiguousarray(points)


# ---- exact booleans (manifold3d) ----


def merge_vertices(verts, tris) -> tuple[np.ndarray, np.ndarray]:
    """Weld vertices with identical positions, then drop triangles that repeat an index and unused vertices.

    Args:
        verts: (V, 3) float vertex positions.
        tris: (T, 3) int triangle indices.
    Returns:
        (V', 3) float32 vertices and (T', 3) int32 triangles describing the same surface.
    """
    verts, tris = _check_mesh(verts, tris)
    unique, inverse = np.unique(verts.astype(np.float32), axis=0, return_inverse=True)
    tris = inverse.reshape(-1)[tris]
    keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])
    tris = tris[keep]
    used, compact = np.unique(tris, return_inverse=True)
    return unique[used].astype(np.float32), compact.reshape(-1, 3).astype(np.int32)


def to_manifold(verts, tris, name: str = "mesh") -> manifold3d.Manifold:
    """Build a ``manifold3d.Manifold`` after welding duplicate vertices (OBJ seams, triangle soups).

    Raises:
        ValueError: If manifold3d rejects the mesh (open, non-manifold, or inconsistently oriented).
    """
    verts, tris = merge_vertices(verts, tris)
    mesh = manifold3d.Mesh(vert_properties=verts, tri_verts=tris.astype(np.uint32))
    solid = manifold3d.Manifold(mesh)
    if solid.status() != manifold3d.Error.NoError and mesh.merge():
        solid = manifold3d.Manifold(mesh)  # second chance: manifold3d welds near-coincident open edges
    status = solid.status()
    if status != manifold3d.Error.NoError:
        raise ValueError(
            f"manifold3d rejected {name} ({len(verts)} vertices, {len(tris)} triangles): {status.name}. "
            "Exact booleans need closed, consistently oriented 2-manifold meshes."
        )
    return solid


def exact_boolean(op: str, verts_a, tris_a, verts_b, tris_b) -> tuple[np.ndarray, np.ndarray]:
    """Exact mesh boolean of two closed meshes with manifold3d; ``DIFFERENCE`` is *a minus b*.

    Args:
        op: ``"UNION"``, ``"INTERSECT"`` or ``"DIFFERENCE"``.
        verts_a, tris_a: (V, 3) float and (T, 3) int arrays of the first closed mesh.
        verts_b, tris_b: The second closed mesh.
    Returns:
        (V', 3) float32 vertices and (T', 3) int32 triangles (possibly empty).
    Raises:
        ValueError: If ``op`` is unknown or manifold3d rejects an operand as non-manifold.
    """
    if op not in _OP_TYPES:
        raise ValueError(f"Expected 'op' in {OPERATIONS}, but got {op!r}.")
    a = to_manifold(verts_a, tris_a, "operand a")
    b = to_manifold(verts_b, tris_b, "operand b")
    result = manifold3d.Manifold.batch_boolean([a, b], _OP_TYPES[op]).to_mesh()
    verts = np.asarray(result.vert_properties, dtype=np.float32)[:, :3]
    tris = np.asarray(result.tri_verts, dtype=np.int32).reshape(-1, 3)
    return np.ascontiguousarray(verts), tris


# ---- volumes and surface samples (numpy) ----


def mesh_volume(verts, tris) -> float:
    """Volume enclosed by a closed, outward-oriented mesh (divergence theorem, float64); negative if inverted."""
    verts, tris = _check_mesh(verts, tris)
    v = verts[tris]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def mesh_area(verts, tris) -> float:
    """Total surface area (float64)."""
    verts, tris = _check_mesh(verts, tris)
    v = verts[tris]
    return float(0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum())


def sample_surface(verts, tris, n: int, seed: int = 0) -> np.ndarray:
    """Draw ``n`` points uniformly (area-weighted) on the surface of a triangle mesh.

    Args:
        verts: (V, 3) float vertex positions.
        tris: (T, 3) int triangle indices, with positive total area.
        n: Number of points.
        seed: Seed for ``numpy.random.default_rng``; the same seed gives the same points.
    Returns:
        (n, 3) float32 points.
    Raises:
        ValueError: If the mesh has no area or ``n`` is negative.
    """
    verts, tris = _check_mesh(verts, tris)
    if n < 0:
        raise ValueError(f"Expected a non-negative 'n', but got {n}.")
    v = verts[tris]
    areas = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    total = areas.sum()
    if not total > 0.0:
        raise ValueError("Cannot sample a mesh with zero surface area.")
    rng = np.random.default_rng(seed)
    cdf = np.cumsum(areas)
    face = np.minimum(np.searchsorted(cdf, rng.random(n) * cdf[-1], side="right"), len(tris) - 1)
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)  # uniform barycentrics (Osada et al. 2002)
    a, b, c = v[face, 0], v[face, 1], v[face, 2]
    points = (1.0 - r1)[:, None] * a + (r1 * (1.0 - r2))[:, None] * b + (r1 * r2)[:, None] * c
    return points.astype(np.float32)


# ---- point queries (warp) ----


@wp.kernel(enable_backward=False)
def _unsigned_distance_kernel(
    mesh_id: wp.uint64, points: wp.array(dtype=wp.vec3), max_dist: float, distances: wp.array(dtype=wp.float32)
):
    """Exact distance from each point to the nearest triangle (``max_dist`` when none is closer)."""
    i = wp.tid()
    p = points[i]
    distances[i] = max_dist
    q = wp.mesh_query_point_no_sign(mesh_id, p, max_dist)
    if q.result:
        distances[i] = wp.length(p - wp.mesh_eval_position(mesh_id, q.face, q.u, q.v))


@wp.kernel(enable_backward=False)
def _winding_sdf_kernel(
    mesh_id: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    max_dist: float,
    accuracy: float,
    distances: wp.array(dtype=wp.float32),
    inside: wp.array(dtype=wp.int32),
):
    """Distance to the nearest triangle, negative where the generalized winding number is at least 0.5."""
    i = wp.tid()
    p = points[i]
    distances[i] = max_dist
    inside[i] = 0
    q = wp.mesh_query_point_sign_winding_number(mesh_id, p, max_dist, accuracy, 0.5)
    if q.result:
        d = wp.length(p - wp.mesh_eval_position(mesh_id, q.face, q.u, q.v))
        if q.sign < 0.0:
            d = -d
            inside[i] = 1
        distances[i] = d


@wp.kernel(enable_backward=False)
def _exact_winding_kernel(
    points: wp.array(dtype=wp.vec3d),
    verts: wp.array(dtype=wp.vec3d),
    tris: wp.array2d(dtype=wp.int32),
    out: wp.array(dtype=wp.float64),
):
    """The sum over all triangles of their solid angles at each point (Van Oosterom and Strackee), over 4 pi."""
    i = wp.tid()
    p = points[i]
    total = wp.float64(0.0)
    for t in range(tris.shape[0]):
        a = verts[tris[t, 0]] - p
        b = verts[tris[t, 1]] - p
        c = verts[tris[t, 2]] - p
        la = wp.length(a)
        lb = wp.length(b)
        lc = wp.length(c)
        det = wp.dot(a, wp.cross(b, c))
        den = la * lb * lc + wp.dot(a, b) * lc + wp.dot(b, c) * la + wp.dot(c, a) * lb
        total += wp.float64(2.0) * wp.atan2(det, den)
    out[i] = total / (wp.float64(4.0) * wp.acos(wp.float64(-1.0)))  # pi in float64 (a literal would be float32)


def winding_numbers(verts, tris, points, *, device=None) -> np.ndarray:
    """Exact generalized winding numbers: the solid angles of all triangles at each point, summed in float64.

    Costs points x triangles solid angles (about 40 ns each on this CPU): for subsamples of large meshes.

    Args:
        verts, tris: (V, 3) float and (T, 3) int arrays of a triangle mesh, closed or not, any orientation.
        points: (N, 3) array-like query points.
    Returns:
        (N,) float64 winding numbers (1 inside a closed outward mesh, -1 inside an inward one, 0 outside).
    """
    verts, tris = _check_mesh(verts, tris)
    _check_points(points)
    points = np.ascontiguousarray(points, dtype=np.float64)
    device = wp.get_device(device)
    out = wp.zeros(len(points), dtype=wp.float64, device=device)
    if len(points) == 0:
        return out.numpy()
    pts = wp.array(points, dtype=wp.vec3d, device=device)
    v = wp.array(verts, dtype=wp.vec3d, device=device)
    t = wp.array(tris.astype(np.int32), dtype=wp.int32, device=device)
    wp.load_module(_exact_winding_kernel.module, device=device)
    # two halves from two threads (a Warp CPU launch releases the GIL)
    bounds = np.linspace(0, len(points), 3).astype(int) if device.is_cpu else np.array([0, len(points)])
    with ThreadPoolExecutor(len(bounds) - 1) as pool:
        runs = [
            pool.submit(wp.launch, _exact_winding_kernel, dim=int(hi - lo), inputs=[pts[lo:hi], v, t, out[lo:hi]])
            for lo, hi in zip(bounds[:-1], bounds[1:], strict=True)
            if hi > lo
        ]
        for run in runs:
            run.result()
    return out.numpy()


def _wp_mesh(verts, tris, *, winding: bool, device=None) -> wp.Mesh:
    verts, tris = _check_mesh(verts, tris)
    if len(tris) == 0:
        raise ValueError("Expected a mesh with at least one triangle.")
    device = wp.get_device(device)
    points = wp.array(verts.astype(np.float32), dtype=wp.vec3, device=device)
    indices = wp.array(tris.astype(np.int32).reshape(-1), dtype=wp.int32, device=device)
    return wp.Mesh(points=points, indices=indices, support_winding_number=winding)


def _search_radius(mesh: wp.Mesh, points: np.ndarray) -> float:
    """A ``max_dist`` large enough that every point finds its nearest triangle."""
    verts = mesh.points.numpy()
    lo, hi = verts.min(axis=0).astype(np.float64), verts.max(axis=0).astype(np.float64)
    far = np.linalg.norm(points - 0.5 * (lo + hi), axis=1).max(initial=0.0)
    return float(2.0 * (far + np.linalg.norm(hi - lo)) + 1.0)


def _query(verts, tris, points, *, signed: bool, accuracy: float = 2.0, device=None):
    points = _check_points(points)
    mesh = _wp_mesh(verts, tris, winding=signed, device=device)
    device = mesh.device
    n = len(points)
    distances = wp.empty(n, dtype=wp.float32, device=device)
    if n == 0:
        return distances.numpy(), np.zeros(0, dtype=bool)
    max_dist = _search_radius(mesh, points)
    wp_points = wp.array(points, dtype=wp.vec3, device=device)
    if not signed:
        wp.launch(
            _unsigned_distance_kernel, dim=n, device=device, inputs=[mesh.id, wp_points, max_dist], outputs=[distances]
        )
        return distances.numpy(), None
    inside = wp.empty(n, dtype=wp.int32, device=device)
    inputs = [mesh.id, wp_points, max_dist, float(accuracy)]
    wp.launch(_winding_sdf_kernel, dim=n, device=device, inputs=inputs, outputs=[distances, inside])
    return distances.numpy(), inside.numpy().astype(bool)


def unsigned_distance(verts, tris, points, *, device=None) -> np.ndarray:
    """Exact distance from each of ``points`` (N, 3) to the nearest triangle of the mesh: (N,) float32."""
    return _query(verts, tris, points, signed=False, device=device)[0]


def winding_inside(verts, tris, points, *, accuracy: float = 2.0, device=None) -> np.ndarray:
    """Whether each point has generalized winding number ≥ 0.5 with respect to the mesh (open meshes allowed).

    Args:
        verts, tris: (V, 3) float and (T, 3) int arrays of a triangle mesh, closed or not.
        points: (N, 3) array-like query points.
        accuracy: Warp's fast-winding-number accuracy (the Barnes-Hut ``beta``; larger is more exact).
    Returns:
        (N,) bool array, True inside.
    """
    return _query(verts, tris, points, signed=True, accuracy=accuracy, device=device)[1]


def exact_sdf(verts, tris, points, *, accuracy: float = 2.0, device=None) -> np.ndarray:
    """Signed distance oracle: distance to the nearest triangle, negative where the winding number is ≥ 0.5.

    Args:
        verts, tris: (V, 3) float and (T, 3) int arrays of a triangle mesh, closed or not.
        points: (N, 3) array-like query points.
        accuracy: Warp's fast-winding-number accuracy, as in ``winding_inside``.
    Returns:
        (N,) float32 signed distances, negative inside.
    """
    return _query(verts, tris, points, signed=True, accuracy=accuracy, device=device)[0]


def hausdorff(verts_a, tris_a, verts_b, tris_b, n: int = 200_000, seed: int = 0, *, device=None) -> dict:
    """Two-sided surface deviation between meshes a and b from ``n`` surface samples on each side.

    Points sampled uniformly on a are measured with the exact point-to-triangle distance to b, and vice versa,
    so the error comes only from where the samples land, never from the spacing of a sample cloud.

    Args:
        verts_a, tris_a: (V, 3) float and (T, 3) int arrays of mesh a.
        verts_b, tris_b: Mesh b.
        n: Samples per surface.
        seed: Sampling seed (b uses ``seed + 1``).
    Returns:
        ``{"p95", "max", "mean"}``: for each statistic the larger of the two directions (a→b, b→a), and the
        directed values as ``"a_to_b"`` and ``"b_to_a"`` dicts with the same keys. All floats.
    """
    directed = {}
    for key, (vs, ts, vt, tt, s) in {
        "a_to_b": (verts_a, tris_a, verts_b, tris_b, seed),
        "b_to_a": (verts_b, tris_b, verts_a, tris_a, seed + 1),
    }.items():
        d = unsigned_distance(vt, tt, sample_surface(vs, ts, n, s), device=device).astype(np.float64)
        directed[key] = {"p95": float(np.percentile(d, 95.0)), "max": float(d.max()), "mean": float(d.mean())}
    result = {k: max(directed["a_to_b"][k], directed["b_to_a"][k]) for k in ("p95", "max", "mean")}
    result.update(directed)
    return result


@wp.kernel
def _closest_triangle_kernel(
    mesh: wp.uint64,
    points: wp.array[wp.vec3],
    max_dist: float,
    faces: wp.array[wp.int32],
    bary: wp.array[wp.vec3],
):
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, points[i], max_dist)
    faces[i] = -1
    if q.result:
        faces[i] = q.face
        bary[i] = wp.vec3(q.u, q.v, 1.0 - q.u - q.v)


def closest_triangles(verts, tris, points, *, device=None) -> tuple[np.ndarray, np.ndarray]:
    """The nearest triangle of the mesh to each point and the barycentric coordinates of the nearest point on it.

    Returns:
        (N,) int32 triangle indices and (N, 3) float32 weights of each triangle's corners (in ``tris`` order).
    """
    points = _check_points(points)
    mesh = _wp_mesh(verts, tris, winding=False, device=device)
    n = len(points)
    faces = wp.empty(n, dtype=wp.int32, device=mesh.device)
    bary = wp.zeros(n, dtype=wp.vec3, device=mesh.device)
    if n:
        wp_points = wp.array(points, dtype=wp.vec3, device=mesh.device)
        wp.launch(
            _closest_triangle_kernel,
            dim=n,
            device=mesh.device,
            inputs=[mesh.id, wp_points, _search_radius(mesh, points)],
            outputs=[faces, bary],
        )
    return faces.numpy(), bary.numpy()


@wp.func
def _segment_distance(p: wp.vec3d, a: wp.vec3d, b: wp.vec3d) -> wp.float64:
    d = b - a
    dd = wp.dot(d, d)
    t = wp.float64(0.0)
    if dd > wp.float64(0.0):
        t = wp.clamp(wp.dot(p - a, d) / dd, wp.float64(0.0), wp.float64(1.0))
    return wp.length(p - (a + t * d))


@wp.func
def _triangle_distance(p: wp.vec3d, a: wp.vec3d, b: wp.vec3d, c: wp.vec3d) -> wp.float64:
    """Distance from p to triangle a, b, c in float64: to its plane where p projects inside it (the three edge
    functions of the projection agree in sign), else to its nearest edge."""
    n = wp.cross(b - a, c - a)
    nn = wp.dot(n, n)
    edges = wp.min(wp.min(_segment_distance(p, a, b), _segment_distance(p, b, c)), _segment_distance(p, c, a))
    if nn <= wp.float64(0.0):
        return edges
    e0 = wp.dot(wp.cross(b - a, p - a), n)
    e1 = wp.dot(wp.cross(c - b, p - b), n)
    e2 = wp.dot(wp.cross(a - c, p - c), n)
    if e0 >= wp.float64(0.0) and e1 >= wp.float64(0.0) and e2 >= wp.float64(0.0):
        return wp.abs(wp.dot(p - a, n)) / wp.sqrt(nn)
    return edges


@wp.kernel(enable_backward=False)
def _distance_within_kernel(
    mesh_id: wp.uint64,
    verts: wp.array(dtype=wp.vec3d),
    tris: wp.array2d(dtype=wp.int32),
    points: wp.array(dtype=wp.vec3d),
    reach: wp.float64,
    distances: wp.array(dtype=wp.float64),
):
    """The float64 distance from each point to the nearest triangle whose box comes within ``reach`` of it."""
    i = wp.tid()
    p = points[i]
    r = wp.vec3(float(reach), float(reach), float(reach))
    pf = wp.vec3(float(p[0]), float(p[1]), float(p[2]))
    query = wp.mesh_query_aabb(mesh_id, pf - r, pf + r)
    t = int(0)  # noqa: UP018 (a dynamic Warp variable)
    best = reach
    while wp.mesh_query_aabb_next(query, t):
        d = _triangle_distance(p, verts[tris[t, 0]], verts[tris[t, 1]], verts[tris[t, 2]])
        best = wp.min(best, d)
    distances[i] = best


def distance_within(verts, tris, points, reach: float, *, device=None) -> np.ndarray:
    """Float64 distance from each point to the nearest triangle, for points within ``reach`` of the mesh (``reach``
    for the others): a check that points lie on a mesh of thin slivers, where the float32 closest point of
    :func:`unsigned_distance` can land a tenth of a voxel off.

    Args:
        verts, tris: (V, 3) float and (T, 3) int arrays of a triangle mesh.
        points: (N, 3) array-like query points.
        reach: how far to look (world units); keep it small: every triangle whose box comes that close is measured.
    Returns:
        (N,) float64 distances, at most ``reach``.
    """
    points = np.ascontiguousarray(_check_points(points), dtype=np.float64)
    mesh = _wp_mesh(verts, tris, winding=False, device=device)
    device = mesh.device
    out = wp.empty(len(points), dtype=wp.float64, device=device)
    if len(points):
        inputs = [
            mesh.id,
            wp.array(np.asarray(verts, dtype=np.float64), dtype=wp.vec3d, device=device),
            wp.array(np.asarray(tris, dtype=np.int32), dtype=wp.int32, device=device),
            wp.array(points, dtype=wp.vec3d, device=device),
            float(reach),
        ]
        wp.launch(_distance_within_kernel, dim=len(points), inputs=inputs, outputs=[out], device=device)
    return out.numpy()


# ---- creases (numpy) ----


def crease_points(verts, tris, angle: float = 30.0, step: float = 1e-3) -> np.ndarray:
    """Points every ``step`` (world units) along the edges of a closed mesh whose two triangles' normals differ by more
    than ``angle`` degrees: its creases, as an (N, 3) float64 point set (empty when it has none)."""
    v = verts.astype(np.float64)
    t = tris.astype(np.int64)
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    sides = np.sort(np.stack([t, np.roll(t, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
    face = np.repeat(np.arange(len(t)), 3)
    order = np.lexsort((sides[:, 1], sides[:, 0]))
    sides, face = sides[order], face[order]
    same = np.all(sides[1:] == sides[:-1], axis=1)
    pair = np.flatnonzero(same)
    fold = np.einsum("ij,ij->i", n[face[pair]], n[face[pair + 1]]) < np.cos(np.radians(angle))
    a, b = v[sides[pair[fold], 0]], v[sides[pair[fold], 1]]
    count = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / step).astype(int), 1)
    edge = np.repeat(np.arange(len(a)), count + 1)
    s = (np.arange(len(edge)) - np.repeat(np.cumsum(count + 1) - (count + 1), count + 1)) / count[edge]
    return a[edge] + s[:, None] * (b - a)[edge]


# ---- self-intersections (warp) ----


@wp.func
def _orient(a: wp.vec3d, b: wp.vec3d, c: wp.vec3d, d: wp.vec3d) -> float:
    """Sign of the volume of tetrahedron (a, b, c, d), in float64 (-1, 0 or 1)."""
    v = wp.dot(wp.cross(b - a, c - a), d - a)
    return wp.where(v > 0.0, 1.0, wp.where(v < 0.0, -1.0, 0.0))


@wp.func
def _segment_crosses(p: wp.vec3d, q: wp.vec3d, a: wp.vec3d, b: wp.vec3d, c: wp.vec3d) -> int:
    """Whether the open segment p-q passes through the interior of triangle a, b, c (touching does not count)."""
    sp = _orient(a, b, c, p)
    sq = _orient(a, b, c, q)
    if sp * sq >= 0.0:
        return 0
    s1 = _orient(p, q, a, b)
    s2 = _orient(p, q, b, c)
    s3 = _orient(p, q, c, a)
    if (s1 > 0.0 and s2 > 0.0 and s3 > 0.0) or (s1 < 0.0 and s2 < 0.0 and s3 < 0.0):
        return 1
    return 0


@wp.func
def _vertex(points: wp.array(dtype=wp.vec3), i: int) -> wp.vec3d:
    p = points[i]
    return wp.vec3d(wp.float64(p[0]), wp.float64(p[1]), wp.float64(p[2]))


@wp.kernel(enable_backward=False)
def _self_intersections_kernel(
    mesh_id: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    tris: wp.array2d(dtype=wp.int32),
    hits: wp.array(dtype=wp.int32),
):
    """Count the triangles that share no vertex with triangle ``tid`` and cross it (an edge of one through the
    other's interior, decided by float64 orientation signs; symmetric, so each crossing pair is counted at both)."""
    t = wp.tid()
    a = tris[t, 0]
    b = tris[t, 1]
    c = tris[t, 2]
    pa = _vertex(points, a)
    pb = _vertex(points, b)
    pc = _vertex(points, c)
    p0 = points[a]
    p1 = points[b]
    p2 = points[c]
    query = wp.mesh_query_aabb(mesh_id, wp.min(wp.min(p0, p1), p2), wp.max(wp.max(p0, p1), p2))
    other = int(0)  # noqa: UP018 (a dynamic Warp variable)
    count = int(0)  # noqa: UP018
    while wp.mesh_query_aabb_next(query, other):
        if other == t:
            continue
        u = tris[other, 0]
        v = tris[other, 1]
        w = tris[other, 2]
        if u == a or u == b or u == c or v == a or v == b or v == c or w == a or w == b or w == c:
            continue
        qu = _vertex(points, u)
        qv = _vertex(points, v)
        qw = _vertex(points, w)
        crossed = _segment_crosses(pa, pb, qu, qv, qw) + _segment_crosses(pb, pc, qu, qv, qw)
        crossed += _segment_crosses(pc, pa, qu, qv, qw) + _segment_crosses(qu, qv, pa, pb, pc)
        crossed += _segment_crosses(qv, qw, pa, pb, pc) + _segment_crosses(qw, qu, pa, pb, pc)
        if crossed > 0:
            count += 1
    hits[t] = count


def self_intersections(verts, tris, *, device=None) -> int:
    """How many pairs of triangles that share no vertex cross each other (0 for a surface that does not pass
    through itself).

    Args:
        verts, tris: (V, 3) float and (T, 3) int arrays of a triangle mesh.
    Returns:
        The number of crossing pairs: an edge of one triangle through the interior of the other, for every pair whose
        bounding boxes overlap (float64 orientation tests on the float32 vertices; touching does not count).
    """
    return int(_crossings(verts, tris, device).sum()) // 2


def self_intersecting_faces(verts, tris, *, device=None) -> np.ndarray:
    """(T,) bool: the triangles that another triangle sharing no vertex with them crosses (as
    :func:`self_intersections` counts them): where a surface passes through itself."""
    return _crossings(verts, tris, device) > 0


def _crossings(verts, tris, device) -> np.ndarray:
    """(T,) int32: how many triangles sharing no vertex with each one cross it."""
    mesh = _wp_mesh(verts, tris, winding=False, device=device)
    device = mesh.device
    tris_wp = wp.array(np.asarray(tris, dtype=np.int32), dtype=wp.int32, device=device)
    hits = wp.zeros(len(tris), dtype=wp.int32, device=device)
    wp.launch(
        _self_intersections_kernel,
        dim=len(tris),
        inputs=[mesh.id, mesh.points, tris_wp],
        outputs=[hits],
        device=device,
    )
    return hits.numpy()
