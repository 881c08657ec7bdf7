"""Which of the operands' own triangles are the result's surface, decided with the fields.

A boolean result keeps its expression (:mod:`.expression`): the operand fields at its leaves. A triangle of a leaf
built from a mesh is *kept* when, everywhere on it,

- every other leaf's surface is farther than the band (its distance beyond the band at samples no farther apart than
  a voxel, with the samples' spacing as slack; a field that jumps across an open mesh's holes is also read a band
  away along the axes, where its sign must not change);
- none of its own mesh's defects is within the band: open, non-manifold or inconsistently oriented edges, duplicated
  triangles, and triangles its own field does not cross from inside to outside (internal faces of overlapping or
  self-intersecting shells);
- its leaf's field changes sign across it, and the expression, with every other leaf's sign as it is there, changes
  sign with it: the triangle is on the result's surface, facing its outside (flipped for a subtracted operand, turned
  outward for an inside-out shell).

Nothing here intersects meshes: the fields decide inside and outside, distances come from the leaves' meshes (exact,
through their BVHs) or fields. The band is ``BAND_VOXELS`` of the result's voxels, widened by the widest blend.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .expression import evaluate_signs, leaves, widest_blend
from .meshcheck import edge_table, problem_faces, weld_positions
from .parallel import launch_split

# Kept faces stay this many result voxels from any other surface and from their mesh's defects: the voxel surface of
# the seams is joined to them there (the join takes about a voxel of it).
BAND_VOXELS = 2.0

# A triangle's own field is read this many voxels in front of and behind it (its sign must change there).
SIDE_VOXELS = 0.5


# ---- samples ----
@wp.kernel(enable_backward=False)
def _grid_samples_kernel(
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    rows: wp.array[wp.int32],
    steps: wp.array[wp.int32],
    first: wp.array[wp.int32],
    points: wp.array[wp.vec3],
):
    """The points of a k-by-k barycentric grid on triangle ``rows[i]`` other than its corners (k = ``steps[i]``)."""
    i = wp.tid()
    t = rows[i]
    k = steps[i]
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    n = first[i]
    inv = 1.0 / float(k)
    for u in range(k + 1):
        for v in range(k + 1 - u):
            corner = (u == 0 and v == 0) or (u == k and v == 0) or (u == 0 and v == k)
            if not corner:
                points[n] = a + (float(u) * inv) * (b - a) + (float(v) * inv) * (c - a)
                n += 1


@wp.kernel(enable_backward=False)
def _mesh_distance_kernel(mesh: wp.uint64, points: wp.array[wp.vec3], max_dist: float, out: wp.array[wp.float32]):
    """Unsigned distance to the mesh, ``max_dist`` where it is farther."""
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, points[i], max_dist)
    out[i] = max_dist
    if q.result:
        out[i] = wp.length(points[i] - wp.mesh_eval_position(mesh, q.face, q.u, q.v))


def _triangle_samples(verts: np.ndarray, tris: np.ndarray, spacing: float, device):
    """Points on every triangle no farther apart than ``spacing``: the vertices, and on triangles longer than that a
    barycentric grid. Returns (points (S, 3) float32: the V vertices first, then the grids), the grid rows (G,) of
    the triangles that have one and the (G + 1,) offsets of their grids among the points after the vertices."""
    edges = verts[tris[:, [1, 2, 0]]] - verts[tris]
    longest = np.sqrt((edges.astype(np.float64) ** 2).sum(axis=2).max(axis=1))
    steps = np.maximum(np.ceil(longest / spacing), 1).astype(np.int64)
    rows = np.flatnonzero(steps > 1).astype(np.int32)
    counts = (steps[rows] + 1) * (steps[rows] + 2) // 2 - 3
    first = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(counts, out=first[1:])
    points = np.empty((len(verts) + int(first[-1]), 3), dtype=np.float32)
    points[: len(verts)] = verts
    if len(rows):
        out = wp.empty(int(first[-1]), dtype=wp.vec3, device=device)
        wp.launch(
            _grid_samples_kernel,
            len(rows),
            inputs=[
                wp.array(verts, dtype=wp.vec3, device=device),
                wp.array(tris, dtype=wp.int32, device=device),
                wp.array(rows, dtype=wp.int32, device=device),
                wp.array(steps[rows].astype(np.int32), dtype=wp.int32, device=device),
                wp.array(first[:-1].astype(np.int32), dtype=wp.int32, device=device),
                out,
            ],
            device=device,
        )
        points[len(verts) :] = out.numpy()
    return points, rows, first


def _per_triangle_min(values: np.ndarray, tris: np.ndarray, n_verts: int, rows, first) -> np.ndarray:
    """(T,) the least of ``values`` (one per sample of :func:`_triangle_samples`) over each triangle's samples."""
    least = values[:n_verts][tris].min(axis=1)
    if len(rows):
        grid = values[n_verts:]
        nonempty = first[1:] > first[:-1]
        if nonempty.any():
            lows = np.minimum.reduceat(grid, first[:-1][nonempty])
            sel = rows[nonempty]
            least[sel] = np.minimum(least[sel], lows)
    return least


# ---- the leaves' distances ----
def mesh_leaf(field) -> bool:
    """Whether a leaf field's surface is its source mesh's triangles (a field built from a mesh that encloses a
    volume, without a thickness): only such leaves have faces to keep."""
    stats = field.stats
    return (
        "clean_mesh" in stats
        and stats.get("thickness") is None
        and not stats.get("flat", False)
        and len(field.sources) == 1
    )


def _leaf_mesh(field):
    """The leaf's source mesh where the leaf is placed: ``(verts (V,3) float32, tris (T,3) int32, source)``."""
    field_id, source = next(iter(field.world_sources().items()))
    return field_id, source


def _distance_to_leaf(field, points: np.ndarray, reach: float, device) -> np.ndarray:
    """(N,) float32 how far the leaf's surface is from each point (up to ``reach``; beyond: ``reach``), negative
    where the point is inside it. A clean closed mesh's leaf answers from its mesh (exact, through its BVH); any other
    from its field, whose value is a distance near its surface."""
    values = field.sample(points)
    if not (mesh_leaf(field) and field.stats.get("clean_mesh", False)):
        return np.clip(values, -reach, reach).astype(np.float32)
    _, source = _leaf_mesh(field)
    return np.copysign(mesh_distances(source.bvh(device), points, reach, device), values).astype(np.float32)


def mesh_distances(mesh: wp.Mesh, points: np.ndarray, reach: float, device) -> np.ndarray:
    """(N,) float32 unsigned distance from each point to ``mesh`` (``reach`` where it is farther)."""
    pts = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=device)
    out = wp.empty(len(points), dtype=wp.float32, device=device)
    launch_split(
        _mesh_distance_kernel,
        len(points),
        lambda lo, n: [mesh.id, pts[lo : lo + n], float(reach), out[lo : lo + n]],
        device,
    )
    return out.numpy()


# ---- classification ----
def _own_defects(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(T,) bool: triangles at an open, non-manifold or inconsistently oriented edge of the mesh (judged with vertices
    at one position merged), or repeating another triangle's corners."""
    welded_verts, welded = weld_positions(verts, tris)
    welded = np.asarray(welded, dtype=np.int32)
    bad = problem_faces(welded, len(welded_verts), edge_table(welded, len(welded_verts))).astype(bool)
    corners = np.sort(welded, axis=1)
    _, inverse, counts = np.unique(corners, axis=0, return_inverse=True, return_counts=True)
    return bad | (counts[inverse.reshape(-1)] > 1)


def _normals(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    n = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]]).astype(np.float64)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.maximum(length, 1e-30)).astype(np.float32)


AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float32)


def _far_from(field, points, band: float, slack: float, device) -> tuple[np.ndarray, np.ndarray]:
    """Per sample: whether the leaf's surface is farther than ``band`` (with ``slack`` for the samples' spacing), and
    the leaf's value there. A field with jumps (an open mesh's, across its holes) must also keep its sign a band away
    along each axis."""
    reach = band + slack + 1.0
    values = _distance_to_leaf(field, points, reach, device)
    far = np.abs(values) > band + slack
    if not field.stats.get("continuous", field.stats.get("clean_mesh", False)) and far.any():
        rows = np.flatnonzero(far)
        around = (points[rows][:, None, :] + band * AXES[None]).reshape(-1, 3)
        signs = np.sign(field.sample(around)).reshape(-1, 6)
        far[rows] &= (signs == np.sign(values[rows])[:, None]).all(axis=1)
    return far, values


def kept_triangles(field, *, band_voxels: float = BAND_VOXELS) -> list[dict]:
    """The triangles of each mesh leaf of a boolean's expression that are its surface (see the module docstring).

    Args:
        field: An unplaced :class:`.field.AdaptiveField` with an ``expression`` (a boolean result).
        band_voxels: How far (result voxels) kept triangles stay from other surfaces and their own defects.
    Returns:
        One dict per mesh leaf: ``field_id``, ``source`` (the placed :class:`.sources.SourceMesh`), ``kept`` (T,) bool
        over the source's triangles and ``flip`` (T,) bool (the triangle faces the result's inside as it stands).
    """
    expression = getattr(field, "expression", None)
    if expression is None:
        return []
    voxel = field.voxel_size
    band = band_voxels * voxel + widest_blend(expression)
    slack = voxel / math.sqrt(3.0)
    device = field.device
    all_leaves = leaves(expression)
    out = []
    for i, leaf in enumerate(all_leaves):
        if not mesh_leaf(leaf):
            continue
        field_id, source = _leaf_mesh(leaf)
        verts, tris = source.verts, source.tris
        if not len(tris):
            continue
        centres = verts[tris].mean(axis=1)
        own, flip = _own_side(leaf, verts, tris, centres, voxel)
        defects = _own_defects(verts, tris) | (own == 0)
        points, rows, first = _triangle_samples(verts, tris, voxel, device)
        kept = ~defects & _away_from(verts, tris, defects, points, rows, first, band + slack, device)
        signs = []
        for j, other in enumerate(all_leaves):
            if j == i:
                signs.append(None)
                continue
            far, values = _far_from(other, points, band, slack, device)
            sign = np.sign(values).astype(np.int8)
            kept &= _per_triangle_min(far.astype(np.int8), tris, len(verts), rows, first) > 0
            # one sign over the whole triangle
            kept &= _per_triangle_min(sign, tris, len(verts), rows, first) == -_per_triangle_min(
                -sign, tris, len(verts), rows, first
            )
            signs.append(sign[tris[:, 0]])
        on_surface, result_flip = _on_result_surface(expression, i, signs, voxel, len(tris))
        kept &= on_surface
        out.append({"field_id": field_id, "source": source, "kept": kept, "flip": flip ^ result_flip})
    return out


def _own_side(leaf, verts, tris, centres, voxel):
    """Per triangle: +1 where its own field is inside behind it and outside in front, -1 the other way round (an
    inside-out face), 0 where it does not change sign (an internal face); and whether it faces its leaf's inside."""
    offset = SIDE_VOXELS * voxel * _normals(verts, tris)
    front = leaf.sample(centres + offset)
    back = leaf.sample(centres - offset)
    side = np.where((back < 0) & (front > 0), 1, np.where((back > 0) & (front < 0), -1, 0))
    return side, side < 0


def _away_from(verts, tris, defects, points, rows, first, reach, device) -> np.ndarray:
    """(T,) bool: the triangles that come nowhere within ``reach`` of a ``defects`` triangle."""
    bad = np.flatnonzero(defects)
    if len(bad) == 0:
        return np.ones(len(tris), dtype=bool)
    mesh = wp.Mesh(
        points=wp.array(verts, dtype=wp.vec3, device=device),
        indices=wp.array(tris[bad].reshape(-1), dtype=wp.int32, device=device),
    )
    far = (mesh_distances(mesh, points, 2.0 * reach, device) > reach).astype(np.int8)
    return _per_triangle_min(far, tris, len(verts), rows, first) > 0


def _on_result_surface(expression, index: int, other_signs: list, voxel: float, count: int):
    """Per triangle of leaf ``index``: whether the expression changes sign when that leaf's value does (every other
    leaf's sign as at the triangle), and whether the result's inside is then on the leaf's outside (a flip)."""
    tiny = 1e-3 * voxel
    values = [np.full(count, -tiny, np.float32) if v is None else v.astype(np.float32) for v in other_signs]
    inside = evaluate_signs(expression, values)
    values[index] = np.full(count, tiny, np.float32)
    outside = evaluate_signs(expression, values)
    crosses = (inside < 0) != (outside < 0)
    return crosses, crosses & (outside < 0)
