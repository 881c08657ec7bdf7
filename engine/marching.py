"""The core of marching cubes on cubes whose corners are shared samples: Warp's sparse marching cubes tables and
passes, each pass split over the CPU cores.

:func:`polygonise` takes the active cubes as (M, 8) indices of samples and returns shared vertices and triangles (the
passes of Warp's ``_extract_from_dedup``, run here so a launch can be split over the cores, and so Warp's own module
with its other kernels is never generated). Also the helpers both extractions share: the empty mesh and the nudge
that keeps vertices off lattice samples.
"""

from __future__ import annotations

import numpy as np
import warp as wp
import warp.geometry

from .octree import morton_decode
from .parallel import launch_split
from .plan import check_resolvable

try:  # the marching-cubes core of Warp's sparse_marching_cubes_from_cells, given already shared corners
    from warp._src.geometry import sparse_marching_cubes as _warp_mc
    from warp._src.geometry.sparse_marching_cubes import _extract_from_dedup as _shared_corner_marching_cubes
except ImportError:  # another Warp version: the public entry point, which sorts to share corners
    _warp_mc = _shared_corner_marching_cubes = None

# Whether Warp's marching-cubes core can be run on corners this module shares (else: Warp's public entry point).
HAS_SHARED_CORNER_CORE = _shared_corner_marching_cubes is not None


# Corner c of a cube with minimum corner (i, j, k) is the sample (i, j, k) + CORNER_OFFSETS[c], in the order Warp's
# sparse marching cubes expects its (M, 8) corner values.
CORNER_OFFSETS = np.asarray(warp.geometry.IsoSurfaceMarchingCubes.CUBE_CORNER_OFFSETS, dtype=np.int64)


# Samples closer to ``iso`` than this fraction of ``spacing`` are pushed to exactly that distance (keeping their side),
# so that no marching cubes vertex lands on, or within float32 noise of, a lattice sample, which would make vertices
# of different edges coincide and triangles collapse. It moves vertices by at most about this fraction of a cell.
_ISO_NUDGE = 1.0e-3


# ... and never less than this many float32 ulps of the largest world coordinate, for lattices far from the origin.
_ISO_NUDGE_ULPS = 4.0


@wp.kernel(enable_backward=False)
def _mark_used_corners_kernel(cube_corners: wp.array2d[wp.int32], used: wp.array[wp.int32]):
    """Flag the samples some active cube uses (every writer writes 1, so races are harmless)."""
    o = wp.tid()
    for c in range(8):
        used[cube_corners[o, c]] = 1


@wp.kernel(enable_backward=False)
def _renumber_corners_kernel(used_scan: wp.array[wp.int32], cube_corners: wp.array2d[wp.int32]):
    o = wp.tid()
    for c in range(8):
        cube_corners[o, c] = used_scan[cube_corners[o, c]] - 1


def polygonise(cube_corners, n, point_kernel, point_inputs, lo, origin, spacing):
    """Warp's marching-cubes core on the active cubes (``cube_corners``: (M, 8) indices of ``n`` samples). Only the
    samples some cube uses take part: they are compacted, and ``point_kernel(first, used, used_scan, *point_inputs,
    base, spacing, points, point_values)`` writes the positions of samples ``first + tid`` (``base``: world position
    of lattice point ``lo``, taken in double precision) and their values, split over the CPU cores."""
    device = cube_corners.device
    used = wp.zeros(n, dtype=wp.int32, device=device)
    n_cubes = cube_corners.shape[0]
    launch_split(_mark_used_corners_kernel, n_cubes, lambda s, c: [cube_corners[s : s + c], used], device)
    used_scan = wp.empty(n, dtype=wp.int32, device=device)
    wp.utils.array_scan(used, used_scan, inclusive=True)
    n_used = int(used_scan[-1:].numpy()[0])
    base = wp.vec3(*(float(x) for x in origin + (np.asarray(lo, np.float64) + 0.5) * spacing))
    points = wp.empty(n_used, dtype=wp.vec3, device=device)
    point_values = wp.empty(n_used, dtype=wp.float32, device=device)
    launch_split(
        point_kernel,
        n,
        lambda s, _c: [s, used, used_scan, *point_inputs, base, float(spacing), points, point_values],
        device,
    )
    launch_split(_renumber_corners_kernel, n_cubes, lambda s, c: [used_scan, cube_corners[s : s + c]], device)
    used = used_scan = None
    return _split_marching_cubes(cube_corners, points, point_values, device)


@wp.func
def _cube_case(cube_corners: wp.array2d[wp.int32], corner_values: wp.array[wp.float32], iso: wp.float32, cube: int):
    """The 8-bit marching-cubes case of a cube: bit c set when corner c is at or above ``iso``."""
    case = int(0)
    for c in range(8):
        if corner_values[cube_corners[cube, c]] >= iso:
            case = case | (1 << c)
    return case


@wp.func
def _edge_slot(
    cube_corners: wp.array2d[wp.int32],
    cube: int,
    local_edge: int,
    edge_owner: wp.array[wp.int32],
    edge_axis: wp.array[wp.int32],
):
    """Slot of a cube's local edge among all edges: its owner corner * 3 + axis (shared by the cubes around it)."""
    return cube_corners[cube, edge_owner[local_edge]] * 3 + edge_axis[local_edge]


@wp.kernel(enable_backward=False)
def _mark_active_edges_kernel(
    first: int,
    cube_corners: wp.array2d[wp.int32],
    corner_values: wp.array[wp.float32],
    iso: wp.float32,
    case_to_tri_range: wp.array[wp.int32],
    tri_local_inds: wp.array[wp.int32],
    edge_owner: wp.array[wp.int32],
    edge_upper: wp.array[wp.int32],
    edge_axis: wp.array[wp.int32],
    edge_active: wp.array[wp.int32],
    edge_upper_corner: wp.array[wp.int32],
):
    """Mark the edges cube ``first + tid``'s triangles cross, each as slot owner corner * 3 + axis (cubes sharing an
    edge write the same values to its slot: a harmless race)."""
    cube = first + wp.tid()
    case = _cube_case(cube_corners, corner_values, iso, cube)
    for k in range(case_to_tri_range[case], case_to_tri_range[case + 1]):
        local_edge = tri_local_inds[k]
        slot = _edge_slot(cube_corners, cube, local_edge, edge_owner, edge_axis)
        edge_active[slot] = 1
        edge_upper_corner[slot] = cube_corners[cube, edge_upper[local_edge]]


@wp.kernel(enable_backward=False)
def _count_faces_kernel(
    first: int,
    cube_corners: wp.array2d[wp.int32],
    corner_values: wp.array[wp.float32],
    iso: wp.float32,
    case_to_tri_range: wp.array[wp.int32],
    face_count: wp.array[wp.int32],
):
    """Triangles of cube ``first + tid``."""
    cube = first + wp.tid()
    case = _cube_case(cube_corners, corner_values, iso, cube)
    face_count[cube] = (case_to_tri_range[case + 1] - case_to_tri_range[case]) // 3


@wp.kernel(enable_backward=False)
def _emit_vertices_kernel(
    first: int,
    edge_active: wp.array[wp.int32],
    edge_vertex_index: wp.array[wp.int32],
    edge_upper_corner: wp.array[wp.int32],
    corner_positions: wp.array[wp.vec3],
    corner_values: wp.array[wp.float32],
    iso: wp.float32,
    verts: wp.array[wp.vec3],
):
    """Warp's ``_emit_vertices_kernel`` for edge slot ``first + tid`` (slot = owner corner * 3 + axis)."""
    slot = first + wp.tid()
    if edge_active[slot] == 0:
        return
    lower = slot // 3
    upper = edge_upper_corner[slot]
    t = wp.clamp((iso - corner_values[lower]) / (corner_values[upper] - corner_values[lower]), 0.0, 1.0)
    verts[edge_vertex_index[slot] - 1] = wp.lerp(corner_positions[lower], corner_positions[upper], t)


@wp.kernel(enable_backward=False)
def _emit_faces_kernel(
    first: int,
    cube_corners: wp.array2d[wp.int32],
    corner_values: wp.array[wp.float32],
    iso: wp.float32,
    case_to_tri_range: wp.array[wp.int32],
    tri_local_inds: wp.array[wp.int32],
    edge_owner: wp.array[wp.int32],
    edge_axis: wp.array[wp.int32],
    edge_vertex_index: wp.array[wp.int32],
    face_scan: wp.array[wp.int32],
    indices: wp.array[wp.int32],
):
    """Warp's ``_emit_faces_kernel`` for cube ``first + tid`` (``face_scan``: inclusive scan of faces per cube)."""
    cube = first + wp.tid()
    case = _cube_case(cube_corners, corner_values, iso, cube)
    tri_start = case_to_tri_range[case]
    n_tri = (case_to_tri_range[case + 1] - tri_start) // 3
    if n_tri == 0:
        return
    out = int(0)
    if cube > 0:
        out = face_scan[cube - 1]
    for tri in range(n_tri):
        for k in range(3):
            local_edge = tri_local_inds[tri_start + 3 * tri + k]
            slot = _edge_slot(cube_corners, cube, local_edge, edge_owner, edge_axis)
            indices[3 * (out + tri) + k] = edge_vertex_index[slot] - 1


def _split_marching_cubes(cube_corners, corner_positions, corner_values, device):
    """Warp's marching-cubes core (``_extract_from_dedup``, threshold 0, its case and edge tables) with every pass
    split over the CPU cores (see ``launch_split``). Same vertices and triangles, in the same order."""
    n_cubes = cube_corners.shape[0]
    n_slots = 3 * corner_positions.shape[0]
    case_table = _warp_mc._get_mc_case_to_tri_range_table(device)
    tri_table = _warp_mc._get_mc_tri_local_inds_table(device)
    owner = _warp_mc._get_edge_owner_table(device)
    upper = _warp_mc._get_edge_upper_table(device)
    axis = _warp_mc._get_edge_axis_table(device)
    iso = wp.float32(0.0)
    # one vertex per crossed edge; cubes sharing an edge write the same values to its slot (a harmless race)
    edge_active = wp.zeros(n_slots, dtype=wp.int32, device=device)
    edge_upper_corner = wp.empty(n_slots, dtype=wp.int32, device=device)
    launch_split(
        _mark_active_edges_kernel,
        n_cubes,
        lambda s, c: [
            s,
            cube_corners,
            corner_values,
            iso,
            case_table,
            tri_table,
            owner,
            upper,
            axis,
            edge_active,
            edge_upper_corner,
        ],
        device,
    )
    edge_vertex_index = wp.empty(n_slots, dtype=wp.int32, device=device)
    wp.utils.array_scan(edge_active, edge_vertex_index, inclusive=True)
    n_verts = int(edge_vertex_index[-1:].numpy()[0])
    verts = wp.empty(n_verts, dtype=wp.vec3, device=device)
    if n_verts == 0:
        return verts, wp.empty(0, dtype=wp.int32, device=device)
    launch_split(
        _emit_vertices_kernel,
        n_slots,
        lambda s, c: [
            s,
            edge_active,
            edge_vertex_index,
            edge_upper_corner,
            corner_positions,
            corner_values,
            iso,
            verts,
        ],
        device,
    )
    edge_active = edge_upper_corner = None
    face_count = wp.empty(n_cubes, dtype=wp.int32, device=device)
    launch_split(
        _count_faces_kernel, n_cubes, lambda s, c: [s, cube_corners, corner_values, iso, case_table, face_count], device
    )
    face_scan = wp.empty(n_cubes, dtype=wp.int32, device=device)
    wp.utils.array_scan(face_count, face_scan, inclusive=True)
    n_faces = int(face_scan[-1:].numpy()[0])
    indices = wp.empty(3 * n_faces, dtype=wp.int32, device=device)
    launch_split(
        _emit_faces_kernel,
        n_cubes,
        lambda s, c: [
            s,
            cube_corners,
            corner_values,
            iso,
            case_table,
            tri_table,
            owner,
            axis,
            edge_vertex_index,
            face_scan,
            indices,
        ],
        device,
    )
    return verts, indices


def empty_mesh() -> tuple[np.ndarray, np.ndarray]:
    """``verts`` (0, 3) float32 and ``tris`` (0, 3) int32."""
    return np.zeros((0, 3), dtype=np.float32), np.zeros((0, 3), dtype=np.int32)


def iso_nudge(origin: np.ndarray, lo: np.ndarray, hi: np.ndarray, spacing: float) -> float:
    """How far samples are pushed off the level (see ``_ISO_NUDGE``) for a lattice spanning ``lo``..``hi``.

    Vertices are float32 world positions: their resolution where the lattice lies bounds the nudge from below, and
    refuses (:func:`.plan.check_resolvable`) lattices so far from the origin that float32 cannot resolve a fraction
    of a cell there.
    """
    ulp = check_resolvable(origin + (lo + 0.5) * spacing, origin + (hi + 1.5) * spacing, spacing)
    return max(_ISO_NUDGE * spacing, _ISO_NUDGE_ULPS * ulp)


def case_tables() -> dict:
    """Warp's marching-cubes tables as numpy int32 arrays: ``case_to_tri_range`` (257,), ``tri_local_inds`` (local
    edges of each case's triangles, 3 per triangle), and per local edge ``edge_owner`` / ``edge_upper`` (its lower
    and upper corner) and ``edge_axis`` (12,). Needs Warp's marching-cubes core (``HAS_SHARED_CORNER_CORE``)."""
    from warp._src.geometry import marching_cubes as mc_tables  # the tables the core's device arrays hold

    return {
        "case_to_tri_range": np.asarray(mc_tables.MC_CASE_TO_TRI_RANGE, dtype=np.int32),
        "tri_local_inds": np.asarray(mc_tables.MC_TRI_LOCAL_INDICES, dtype=np.int32),
        "edge_owner": np.asarray(_warp_mc._MC_EDGE_OWNER, dtype=np.int32),
        "edge_upper": np.asarray(_warp_mc._MC_EDGE_UPPER, dtype=np.int32),
        "edge_axis": np.asarray(_warp_mc._MC_EDGE_AXIS, dtype=np.int32),
    }


def patch_tables() -> tuple[np.ndarray, np.ndarray]:
    """Per marching-cubes case: the patch (connected set of triangles sharing local edges) each crossed local edge
    belongs to, (256, 12) int32 with -1 for edges the case does not cross, and the number of patches (256,) int32."""
    tables = case_tables()
    ranges, local = tables["case_to_tri_range"], tables["tri_local_inds"]
    patch = np.full((256, 12), -1, dtype=np.int32)
    count = np.zeros(256, dtype=np.int32)
    for case in range(256):  # a one-off walk over the 256 table entries
        tris = local[ranges[case] : ranges[case + 1]].reshape(-1, 3)
        label = np.arange(12)
        for _ in range(12):  # propagate the smallest label along each triangle until nothing changes
            low = label[tris].min(axis=1)
            new = label.copy()
            np.minimum.at(new, tris.ravel(), np.repeat(low, 3))
            if np.array_equal(new, label):
                break
            label = new
        used = np.unique(tris)
        roots = np.unique(label[used])
        patch[case, used] = np.searchsorted(roots, label[used])
        count[case] = len(roots)
    return patch, count


def patch_masks() -> dict:
    """The patches of :func:`patch_tables` as bit masks, for the dual of the marching cubes (:mod:`.dual`).

    Returns:
        dict of int32 arrays: ``edge_mask`` and ``end_mask`` (256, 4), per case and patch (4 at most) the bits of its
        local edges and of the corners at their ends; ``patch_of_edge`` (256,), per case each crossed local edge's
        patch in 2 bits (bits 2e, 2e + 1 for edge e); ``count`` (256,), the number of patches.
    """
    patch, count = patch_tables()
    tables = case_tables()
    owner, upper = tables["edge_owner"], tables["edge_upper"]
    edge_mask = np.zeros((256, 4), dtype=np.int32)
    end_mask = np.zeros((256, 4), dtype=np.int32)
    patch_of_edge = (np.maximum(patch, 0).astype(np.int64) << (2 * np.arange(12))).sum(axis=1).astype(np.int32)
    for e in range(12):
        rows = np.flatnonzero(patch[:, e] >= 0)
        np.bitwise_or.at(edge_mask, (rows, patch[rows, e]), 1 << e)
        np.bitwise_or.at(end_mask, (rows, patch[rows, e]), (1 << int(owner[e])) | (1 << int(upper[e])))
    return {"edge_mask": edge_mask, "end_mask": end_mask, "patch_of_edge": patch_of_edge, "count": count}


def tunnel_tables() -> tuple[np.ndarray, np.ndarray]:
    """Where the dual of the marching cubes needs a vertex more: faces with four crossed edges (two segments) whose
    cube has one patch through both, so that two cubes doing so across a face meet along two dual edges at once.

    Returns:
        ``spans`` (256,) int32: per case, bit ``2 * axis + side`` set for each face (side 0: the minimum along that
        axis) crossed by one patch in two segments; ``second`` (256, 12, 6) int32: 1 where the local edge lies on that
        face in the segment that does not hold the face's first edge (the one along the face's lower in-plane axis,
        at the minimum of the other).
    """
    tables = case_tables()
    ranges, local, owner, upper, axis = (
        tables[k] for k in ("case_to_tri_range", "tri_local_inds", "edge_owner", "edge_upper", "edge_axis")
    )
    patch, _ = patch_tables()
    off = CORNER_OFFSETS
    faces = np.arange(6)
    # (12, 6) whether each local edge lies on each cube face (side 0: the minimum along the face's axis)
    on = (
        (axis[:, None] != faces // 2)
        & (off[owner][:, faces // 2] == faces % 2)
        & (off[upper][:, faces // 2] == faces % 2)
    )
    spans = np.zeros(256, dtype=np.int32)
    second = np.zeros((256, 12, 6), dtype=np.int32)
    for case in range(256):  # a one-off walk over the 256 table entries
        tris = local[ranges[case] : ranges[case + 1]].reshape(-1, 3)
        sides = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
        keys, uses = np.unique(sides[:, 0] * 12 + sides[:, 1], return_counts=True)
        segments = np.stack([keys[uses == 1] // 12, keys[uses == 1] % 12], axis=1)  # polygon sides: face segments
        crossed = patch[case] >= 0
        for f in np.flatnonzero((on & crossed[:, None]).sum(axis=0) == 4):
            edges = np.flatnonzero(on[:, f] & crossed)
            if len(set(patch[case, edges])) == 1:
                spans[case] |= 1 << int(f)
            u = min(a for a in range(3) if a != f // 2)
            v = 3 - f // 2 - u
            first = next(e for e in edges if axis[e] == u and off[owner[e]][v] == 0)
            mate = next(int(b if a == first else a) for a, b in segments if first in (a, b) and on[a, f] and on[b, f])
            for e in edges:
                second[case, e, f] = int(e not in (first, mate))
    return spans, second


# ---- packed tables for the dual contouring kernels (integer constants: no table reads in inner loops) ----


_EDGES = case_tables() if HAS_SHARED_CORNER_CORE else None


def _pack(entries, bits: int) -> tuple[int, int]:
    """Small non-negative integers packed ``bits`` apiece into two int32 constants (first half, second half)."""
    half = (len(entries) + 1) // 2
    low = sum(int(x) << (bits * k) for k, x in enumerate(entries[:half]))
    high = sum(int(x) << (bits * k) for k, x in enumerate(entries[half:]))
    return low, high


_OWNER_LOW, _OWNER_HIGH = _pack(_EDGES["edge_owner"], 3) if _EDGES else (0, 0)
_UPPER_LOW, _UPPER_HIGH = _pack(_EDGES["edge_upper"], 3) if _EDGES else (0, 0)


@wp.func
def _unpack(low: int, high: int, bits: int, half: int, k: int):
    """Entry ``k`` of a table packed by ``_pack`` (``half`` entries in ``low``)."""
    if k < half:
        return (low >> (bits * k)) & ((1 << bits) - 1)
    return (high >> (bits * (k - half))) & ((1 << bits) - 1)


@wp.func
def edge_ends(e: int):
    """Lower and upper corner of local edge ``e``."""
    return _unpack(_OWNER_LOW, _OWNER_HIGH, 3, 6, e), _unpack(_UPPER_LOW, _UPPER_HIGH, 3, 6, e)


def _quad_tables() -> tuple[list, list, list]:
    """Where each crossed edge's quad comes from.

    A crossed edge along axis a is shared by the four cubes whose minimum corners are its lower end minus
    s_b e_b + s_c e_c (b, c the other axes, s in {0, 1}), numbered counter-clockwise about the axis: (0, 0), (1, 0),
    (1, 1), (0, 1). Its quad is written by the cube at (1, 1), whose corners are the others' minimum corners.

    Returns:
        Per axis and place (12): the writing cube's corner that is that cube's minimum corner, and the edge's index
        in that cube; per axis (6): the writing cube's corners at the edge's two ends.
    """
    owner, axis = _EDGES["edge_owner"], _EDGES["edge_axis"]
    places = ((0, 0), (1, 0), (1, 1), (0, 1))

    def corner_at(off):
        return int(np.flatnonzero((CORNER_OFFSETS == np.asarray(off)).all(1))[0])

    def edge_at(axis_, off):
        return int(next(e for e in range(12) if axis[e] == axis_ and corner_at(off) == owner[e]))

    quad_corner, quad_edge, quad_ends = [], [], []
    for ax in range(3):
        b_, c_ = (ax + 1) % 3, (ax + 2) % 3
        for sb, sc in places:
            off = np.zeros(3, dtype=np.int64)
            off[b_], off[c_] = 1 - sb, 1 - sc
            quad_corner.append(corner_at(off))
            local = np.zeros(3, dtype=np.int64)
            local[b_], local[c_] = sb, sc
            quad_edge.append(edge_at(ax, local))
        end = np.zeros(3, dtype=np.int64)
        end[b_], end[c_] = 1, 1
        quad_ends.append(corner_at(end))
        end[ax] = 1
        quad_ends.append(corner_at(end))
    return quad_corner, quad_edge, quad_ends


_QUADS = _quad_tables() if _EDGES else ([0] * 12, [0] * 12, [0] * 6)
_QCORNER_LOW, _QCORNER_HIGH = _pack(_QUADS[0], 3)
_QEDGE_LOW, _QEDGE_HIGH = _pack(_QUADS[1], 4)
_QENDS_LOW, _QENDS_HIGH = _pack(_QUADS[2], 3)


@wp.func
def quad_corner(k: int):
    return _unpack(_QCORNER_LOW, _QCORNER_HIGH, 3, 6, k)


@wp.func
def quad_edge(k: int):
    return _unpack(_QEDGE_LOW, _QEDGE_HIGH, 4, 6, k)


@wp.func
def quad_ends(a: int):
    """The two corners (lower, upper) of the edge along axis ``a`` whose quad a cube writes."""
    return _unpack(_QENDS_LOW, _QENDS_HIGH, 3, 3, 2 * a), _unpack(_QENDS_LOW, _QENDS_HIGH, 3, 3, 2 * a + 1)


@wp.kernel(enable_backward=False)
def _tunnel_points_kernel(
    cube_of_quad: wp.array[wp.int32],
    axis_of_quad: wp.array[wp.int32],
    cube_corners: wp.array2d[wp.int32],
    values: wp.array[wp.float32],
    codes: wp.array[wp.int64],
    origin: wp.vec3,
    spacing: float,
    points: wp.array[wp.vec3],
):
    """The crossing point of the edge of flagged quad ``tid`` (its cube and axis): where :func:`.dual._quads_kernel`
    flags a tunnel side, :func:`.meshcheck.open_tunnels` puts a vertex between such crossings."""
    t = wp.tid()
    cube = cube_of_quad[t]
    a = axis_of_quad[t]
    ea, eb = quad_ends(a)
    v0 = values[cube_corners[cube, ea]]
    v1 = values[cube_corners[cube, eb]]
    n_a = morton_decode(codes[cube_corners[cube, ea]])
    x_a = origin + (wp.vec3(float(n_a[0]), float(n_a[1]), float(n_a[2])) + wp.vec3(0.5)) * spacing
    x_b = x_a
    x_b[a] = x_b[a] + spacing
    points[t] = x_a + (v0 / (v0 - v1)) * (x_b - x_a)


def tunnel_points(quads, flags, quad_scan, cube_corners, values, codes, origin, spacing) -> np.ndarray:
    """(Q, 3) crossing points of the edges of the dual contouring's flagged ``quads`` (``flags``: their tunnel bits,
    the edge's axis in bits 4-5; ``quad_scan``: each cube's inclusive count of quads), computed for these alone (a
    handful) rather than stored for every quad."""
    device = cube_corners.device
    flags = np.asarray(flags, dtype=np.int64)
    cube_of_quad = np.searchsorted(quad_scan.numpy(), quads, side="right").astype(np.int32)
    points = wp.empty(len(quads), dtype=wp.vec3, device=device)
    wp.launch(
        _tunnel_points_kernel,
        dim=len(quads),
        inputs=[
            wp.array(cube_of_quad, dtype=wp.int32, device=device),
            wp.array((flags >> 4).astype(np.int32), dtype=wp.int32, device=device),
            cube_corners,
            values,
            codes,
            origin,
            float(spacing),
        ],
        outputs=[points],
        device=device,
    )
    return points.numpy()
