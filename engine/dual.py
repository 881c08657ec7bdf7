"""Feature-preserving surface extraction: dual marching cubes whose vertices minimise a quadric of exact tangent planes.

Marching cubes puts its vertices on the lattice edges and so cuts every crease and corner of the surface. This module
contours the same active cubes dually (Nielson's dual marching cubes, the uniform-grid case of Schaefer et al.'s
manifold dual contouring): one vertex per marching-cubes patch of a cube (a cube's triangles that share edges), one
quad per crossed lattice edge joining the patches of the four cubes around it. The mesh is the dual of the marching
cubes mesh, so it is closed and oriented where that one is, with as many quads as marching cubes has vertices.

Each vertex is placed as in dual contouring (Ju et al. 2002): the minimiser of the squared distances to tangent planes
(a quadric error function), taken relative to the mass point of the patch's edge crossings, with small eigenvalues
truncated. The tangent planes are Hermite data the field already holds: every finest node stores the exact closest
point ``proj`` of its source surface (for a boolean, of the operand that decides there), so the plane through
``proj`` with normal ``(x - proj) / |x - proj|`` times the sign of the value is exact, and at a node whose closest
point lies on a crease it contains the crease line. Where a node's value is not its distance to ``proj`` (blended
booleans, where the value is a smooth minimum) the plane is taken at the edge crossing with the gradient of the cube's
trilinear interpolant instead, so smooth blends get no crease. Vertices stay in their cube: a crease line found
outside it is clipped to the cube, a corner outside it gives way to the crease through the cube, and anything left
outside is clamped. A node's plane that misses the cube bounds the surface near that node only (a face that ends
before the cube, beside a concave seam): the crease or corner of the planes through the cube is taken if in it.
Where a part thinner than the lattice resolves passes (a cube with two patches, both its sides; or a patch whose
corners' planes face each other, :data:`OPPOSED_COS`), the vertex is its patch's mass point, where marching cubes'
surface lies: placed by the planes of both sides, neighbouring vertices land on either side and their faces pass
through each other (the beetle united with a ball: 55 crossing pairs, none so; a part thinner than a voxel loses no
more than it does to the lattice's signs).

Each quad is split along the diagonal whose midpoint fits its two vertices' planes best, which keeps crease lines
(both ends on the crease) as mesh edges. Vertices whose quadric has two or more significant eigenvalues lie on a
crease or corner; :func:`.quadric.crease_edges` returns the mesh edges between two of them where the surface
folds. ``AdaptiveField.to_mesh(sharp=True)`` runs it on the field's active cubes.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .marching import (
    edge_ends,
    patch_masks,
    quad_corner,
    quad_edge,
    quad_ends,
    tunnel_points,
    tunnel_tables,
)
from .meshcheck import open_tunnels
from .octree import morton_decode
from .parallel import EMIT_SPLIT_MIN_DIM, launch_split
from .quadric import (
    clamp_box,
    corner_plane,
    cube_corner,
    fold_cos,
    is_smooth,
    opposed_planes,
    pack_quadric,
    plane_terms,
    quadric_at,
    solve_in_cube,
    solve_smooth,
    through_cube,
    trilinear,
    unpack_terms,
    vec8,
    vec10,
    wide_box,
)
from .quads import QUAD_ANGLE

# A vertex's plane quadric as the quads need it (which diagonal to split along): half floats, 20 bytes a vertex.
vec10h = wp.types.vector(length=10, dtype=wp.float16)

# Eigenvalues of a patch's plane quadric below this fraction of the largest are dropped (Ju et al. truncate singular
# values below 0.1; the eigenvalues of A^T A are their squares): normals less than about 16 degrees apart make no
# crease.
EIGEN_CUTOFF = 0.02

# A patch whose normals all lie within this cosine of its first one is smooth: solved along their mean normal
# without an eigen decomposition (8 degrees, well inside EIGEN_CUTOFF's).
SMOOTH_COS = 0.99

# A node's plane is used when its value is its distance to its closest point within this fraction of a voxel.
HERMITE_TOLERANCE = 0.02

# A crossed edge whose values differ by more than this many edge lengths is a sign jump, not a surface (a distance
# field changes by at most its edge length): the patch takes no node planes (their closest points lie on a hole's
# rim), only the interpolant's.
JUMP_RATIO = 1.5

# Below this distance (voxels) from its closest point a node's plane is damped, to (distance / this)^2 of its weight,
# where the direction to that point turns to noise: only in a patch whose crease or corner misses its cube otherwise.
HERMITE_NEAR = 0.12

# A patch two of whose corners' planes face each other within about 18 degrees (the cosine between their normals below
# this) sees both sides of a thin part: its vertex is the mass point (module docstring). Slabs 0.4-0.8 voxel thick at 4
# turns: 25,398 crossing pairs, 38 so. At -0.5 a wedge sharper than 60 degrees went too (three balls' difference,
# whose ring has a 52-degree edge: Hausdorff p95 0.079 -> 0.388 voxel, 0.084 now), and a gap narrower than a voxel
# between kept faces (the teapot's lid and rim) had its voxel surface moved off them (crossing pairs left in its kept
# surface 1 -> 10; 0 now).
OPPOSED_COS = -0.95
# Planes within this cosine of one are never OPPOSED_COS apart: a patch all of whose planes are is not compared.
TURNED_COS = float(np.sqrt((1.0 + OPPOSED_COS) / 2.0)) + 1e-3


# A crease or corner vertex whose planes meet outside its cube may go this many voxels past a face whose neighbouring
# cube the surface does not cross (the tip of a wedge more acute than the lattice resolves lies there).
EMPTY_REACH = 1.0


# A quad is split along the diagonal its vertices' planes fit best unless that gives a triangle of less than this
# twice-area (voxels^2) seen along the quad's edge and the other diagonal does better: so no triangle folds back or
# lies along a crease line through three of its vertices.
MIN_SPLIT_AREA = 0.1


# Vertices keep this fraction of a voxel from their cube's faces, so vertices of neighbouring cubes never coincide.
CELL_MARGIN = 1.0e-3


# ---- tables ----


_TABLE_CACHE: dict = {}


def lookup_tables(device) -> dict:
    """Warp arrays of the dual tables on ``device`` (built once per device)."""
    key = str(device)
    if key not in _TABLE_CACHE:
        tables = patch_masks()
        tables["spans"], tables["second"] = tunnel_tables()
        _TABLE_CACHE[key] = {k: wp.array(v.ravel(), dtype=wp.int32, device=device) for k, v in tables.items()}
    return _TABLE_CACHE[key]


# ---- patches and their vertices ----


@wp.func
def _case(cube_corners: wp.array2d[wp.int32], values: wp.array[wp.float32], cube: int):
    """Marching-cubes case of a cube: bit c set when corner c is at or above the level (as ``marching``)."""
    case = int(0)
    for c in range(8):
        if values[cube_corners[cube, c]] >= 0.0:
            case = case | (1 << c)
    return case


@wp.kernel(enable_backward=False)
def _count_patches_kernel(
    first: int,
    cube_corners: wp.array2d[wp.int32],
    values: wp.array[wp.float32],
    patch_count: wp.array[wp.int32],
    counts: wp.array[wp.int32],
    quad_counts: wp.array[wp.int32],
    cube_of_node: wp.array[wp.int32],
    below: wp.array[wp.uint8],
    crossed: wp.array[wp.uint8],
):
    """Patches of cube ``first + tid``, and the crossed edges whose quads it writes (see ``_quads_kernel``); the
    cube's index at its minimum corner's node, and at the nodes that are the minimum corners of its face neighbours
    towards +x, +y, +z a flag that the neighbour below them along that axis is active (``below`` (N, 3), zeroed);
    how many of its edges it crosses in ``crossed`` (per cube: CPU launches of parallel parts add unguarded)."""
    cube = first + wp.tid()
    case = _case(cube_corners, values, cube)
    counts[cube] = patch_count[case]
    edges = int(0)
    for e in range(12):
        ca, cb = edge_ends(e)
        edges += wp.where(((case >> ca) & 1) != ((case >> cb) & 1), 1, 0)
    crossed[cube] = wp.uint8(edges)
    cube_of_node[cube_corners[cube, 0]] = cube
    quads = int(0)
    for a in range(3):
        ea, eb = quad_ends(a)
        if ((case >> ea) & 1) != ((case >> eb) & 1):
            quads += 1
        below[cube_corners[cube, wp.where(a == 0, 1, wp.where(a == 1, 3, 4))] * 3 + a] = wp.uint8(1)
    quad_counts[cube] = quads


@wp.kernel(enable_backward=False)
def _place_vertices_kernel(
    first: int,
    cube_corners: wp.array2d[wp.int32],
    values: wp.array[wp.float32],
    codes: wp.array[wp.int64],
    proj: wp.array[wp.vec3h],
    origin: wp.vec3,
    spacing: float,
    iso: float,
    edge_mask: wp.array[wp.int32],
    end_mask: wp.array[wp.int32],
    spans: wp.array[wp.int32],
    vertex_start: wp.array[wp.int32],
    cube_of_node: wp.array[wp.int32],
    below: wp.array[wp.uint8],
    reach: float,
    cutoff: float,
    smooth_cos: float,
    tolerance: float,
    near: float,
    margin: float,
    verts: wp.array[wp.vec3],
    ranks: wp.array[wp.int32],
    cells: wp.array[wp.int32],
    quadrics: wp.array[vec10h],
    cube_info: wp.array[wp.vec2i],
):
    """One vertex per patch of cube ``first + tid``: its plane quadric (node planes, or crossing planes where a
    node's Hermite data does not hold), solved in the cube. The cube's first vertex, case and tunnel faces go to
    ``cube_info`` (its patches' vertices follow in patch order)."""
    cube = first + wp.tid()
    base_vertex = int(0)
    if cube > 0:
        base_vertex = vertex_start[cube - 1]
    n_patches = vertex_start[cube] - base_vertex
    ids = wp.vector(0, 0, 0, 0, 0, 0, 0, 0, length=8, dtype=int)
    vals = vec8()
    case = int(0)
    for c in range(8):
        ids[c] = cube_corners[cube, c]
        vals[c] = values[ids[c]]
        if vals[c] >= 0.0:
            case = case | (1 << c)
    cube_info[cube] = wp.vec2i(base_vertex, case | (spans[case] << 8))
    c0 = morton_decode(codes[ids[0]])
    corner = origin + spacing * wp.vec3(float(c0[0]) + 0.5, float(c0[1]) + 0.5, float(c0[2]) + 0.5)
    inv = 1.0 / spacing
    lo = margin
    hi = 1.0 - margin
    normals = wp.matrix(0.0, shape=(8, 3), dtype=float)  # each corner's plane, shared by the cube's patches
    offsets = vec8()
    weights = vec8()
    state = wp.vector(0, 0, 0, 0, 0, 0, 0, 0, length=8, dtype=int)
    for c in range(8):
        n, offset, weight, s = corner_plane(-wp.vec3(proj[ids[c]]), cube_corner(c), vals[c], iso, inv, tolerance, near)
        normals[c] = n
        offsets[c] = offset
        weights[c] = weight
        state[c] = s
    for p in range(n_patches):
        # the mass point of the patch's edge crossings and the interpolant's value and gradient there
        mass = wp.vec3(0.0)
        crossings = float(0.0)
        edges = edge_mask[case * 4 + p]
        ends = end_mask[case * 4 + p]
        jump = int(0)  # values across a crossed edge further apart than its length: a sign jump (a hole's span)
        bits = edges
        while bits != 0:
            low = bits & (-bits)
            e = wp.bit_count(low - 1)
            bits = bits ^ low
            ca, cb = edge_ends(e)
            t = vals[ca] / (vals[ca] - vals[cb])
            mass += cube_corner(ca) + t * (cube_corner(cb) - cube_corner(ca))
            crossings += 1.0
            if wp.abs(vals[ca] - vals[cb]) > JUMP_RATIO * spacing:
                jump = 1
        mass = mass / crossings
        f_mass, g_mass = trilinear(vals, mass)
        # the planes of the patch's corners, summed (plane_terms), and the part of that which planes of nodes near
        # the surface lose when damped (see HERMITE_NEAR)
        sums = vec10()
        planes = float(0.0)
        normal_sum = wp.vec3(0.0)
        near_sums = vec10()
        near_planes = float(0.0)
        near_normals = wp.vec3(0.0)
        first_normal = wp.vec3(0.0)
        first_heavy = wp.vec3(0.0)
        min_cos = float(1.0)  # of all planes
        min_cos_heavy = float(1.0)  # of the planes that keep at least half their weight when damped
        fallback = float(0.0)
        skipped = float(0.0)
        heavy = int(0)
        through_sums = vec10()
        through_planes = float(0.0)
        missing = int(0)
        bits = ends
        while bits != 0:
            low = bits & (-bits)
            c = wp.bit_count(low - 1)
            bits = bits ^ low
            if state[c] != 1 or jump == 1:  # no plane, or the closest points lie on a hole's rim (a sign jump)
                if state[c] == 0 or jump == 1:
                    fallback += 1.0
                else:
                    skipped += 1.0
                continue
            n = wp.vec3(normals[c, 0], normals[c, 1], normals[c, 2])
            if wp.dot(n, g_mass) <= 0.0:  # the far side of a plate thinner than a cell
                fallback += 1.0
                continue
            terms = plane_terms(n, offsets[c])
            sums += terms
            if planes == 0.0:
                first_normal = n
            planes += 1.0
            normal_sum += n
            min_cos = wp.min(min_cos, wp.dot(n, first_normal))
            if wp.abs(wp.dot(n, wp.vec3(0.5)) - offsets[c]) <= 0.5 * (wp.abs(n[0]) + wp.abs(n[1]) + wp.abs(n[2])):
                through_sums += terms
                through_planes += 1.0
            else:
                missing += 1
            lost = 1.0 - weights[c]
            if lost > 0.0:
                near_sums += lost * terms
                near_planes += lost
                near_normals += lost * n
            if lost <= 0.5:
                if heavy == 0:
                    first_heavy = n
                    heavy = 1
                min_cos_heavy = wp.min(min_cos_heavy, wp.dot(n, first_heavy))
        if planes == 0.0:
            fallback += skipped
        gl = wp.length(g_mass)
        if fallback > 0.0 and gl > 0.0:
            # corners whose Hermite data does not hold: the interpolant's tangent plane at the mass point moved onto
            # its zero set (one Newton step; values are in world units, positions in voxels)
            n = g_mass / gl
            sums += fallback * plane_terms(n, wp.dot(n, mass) - f_mass / gl)
            through_sums += fallback * plane_terms(n, wp.dot(n, mass) - f_mass / gl)
            through_planes += fallback
            if planes == 0.0:
                first_normal = n
            if heavy == 0:
                first_heavy = n
            planes += fallback
            normal_sum += fallback * n
            min_cos = wp.min(min_cos, wp.dot(n, first_normal))
            min_cos_heavy = wp.min(min_cos_heavy, wp.dot(n, first_heavy))
        ata, atb, btb = unpack_terms(sums)
        vid = base_vertex + p
        x = mass
        rank = int(0)
        if planes > 0.0:
            if is_smooth(ata, normal_sum, min_cos, smooth_cos, cutoff):
                x = clamp_box(solve_smooth(ata, atb - ata * mass, mass, normal_sum), lo, hi)
                rank = 1
            else:
                wide_lo, wide_hi = wide_box(below, cube_of_node, ids, lo, hi, reach)
                x, rank, own = solve_in_cube(ata, atb - ata * mass, mass, cutoff, lo, hi, wide_lo, wide_hi)
                if missing > 0 and through_planes > 0.0:  # (planes missing the cube: see the module docstring)
                    t_x, t_rank = through_cube(through_sums, mass, cutoff, lo, hi, wide_lo, wide_hi)
                    if t_rank >= 2:
                        x, rank, own = t_x, t_rank, 1
                        ata, atb, btb = unpack_terms(through_sums)
                        planes = through_planes
                if own == 0 and near_planes > 0.0 and planes - near_planes > 0.0:
                    # the crease or corner that planes of nodes near the surface make misses the cube (a crease just
                    # past it, seen from a node within a fraction of a voxel of its other face): solved with those
                    # planes damped
                    ata, atb, btb = unpack_terms(sums - near_sums)
                    planes = planes - near_planes
                    normal_sum = normal_sum - near_normals
                    if is_smooth(ata, normal_sum, min_cos_heavy, smooth_cos, cutoff):
                        x = clamp_box(solve_smooth(ata, atb - ata * mass, mass, normal_sum), lo, hi)
                        rank = 1
                    else:
                        x, rank, own = solve_in_cube(ata, atb - ata * mass, mass, cutoff, lo, hi, wide_lo, wide_hi)
            thin = n_patches > 1  # a thin part: see the module docstring
            if not thin and (fallback > 0.0 or min_cos < TURNED_COS):  # (else no two corners' planes face apart)
                thin = opposed_planes(normals, state, ends) < OPPOSED_COS
            if thin:
                x = mass
                rank = 1
            quadrics[vid] = vec10h(pack_quadric(ata, atb, btb, x, 1.0 / planes))
        else:
            quadrics[vid] = vec10h()
        verts[vid] = corner + spacing * x
        ranks[vid] = rank
        cells[vid] = cube


# ---- quads ----


@wp.kernel(enable_backward=False)
def _quads_kernel(
    first: int,
    cube_corners: wp.array2d[wp.int32],
    cube_of_node: wp.array[wp.int32],
    cube_info: wp.array[wp.vec2i],
    patch_of_edge: wp.array[wp.int32],
    quad_scan: wp.array[wp.int32],
    verts: wp.array[wp.vec3],
    quadrics: wp.array[vec10h],
    inv: float,
    min_area: float,
    quad_cos: float,
    second: wp.array[wp.int32],
    tris: wp.array2d[wp.int32],
    tunnel: wp.array[wp.uint8],
    whole: wp.array[wp.uint8],
):
    """The quads of the crossed edges whose four cubes cube ``first + tid`` completes as the one below both other
    axes (each crossed edge has exactly one such cube), as two triangles, outward, split along the diagonal whose
    midpoint its two vertices' planes fit best; -1 rows where one of the four cubes is missing (the band's edge).
    Where two of its cubes meet across a face that each crosses with one patch in two segments and its edge lies in
    the second segment (``tunnel_tables``), the quad's ``tunnel`` entry has that side's bit (its sides numbered from
    its first vertex as written; bits 4-5: the edge's axis, for :func:`_tunnel_points_kernel`): such sides get a
    vertex of their own (see :func:`.meshcheck.open_tunnels`). A quad whose two triangles lie within ``quad_cos``
    of each other's plane along both diagonals (planar and convex) is flagged ``whole``: 1 split along q0-q2, 2
    along q1-q3 (see :func:`.quads.merge_pairs`)."""
    cube = first + wp.tid()
    out = int(0)
    if cube > 0:
        out = quad_scan[cube - 1]
    case = cube_info[cube][1] & 255
    count = int(0)
    for a in range(3):
        ea, eb = quad_ends(a)
        if ((case >> ea) & 1) == ((case >> eb) & 1):
            continue
        q = wp.vector(-1, -1, -1, -1, length=4, dtype=int)
        info = wp.vector(0, 0, 0, 0, length=4, dtype=int)  # case and tunnel faces of each of the four cubes
        complete = int(1)
        for k in range(4):
            other = cube_of_node[cube_corners[cube, quad_corner(4 * a + k)]]
            if other < 0:
                complete = 0
            else:
                o = cube_info[other]
                info[k] = o[1]
                q[k] = o[0] + ((patch_of_edge[o[1] & 255] >> (2 * quad_edge(4 * a + k))) & 3)
        quad = out + count
        row = 2 * quad
        count += 1
        tunnel[quad] = wp.uint8(0)
        whole[quad] = wp.uint8(0)
        if complete == 0:
            for k in range(3):
                tris[row, k] = -1
                tris[row + 1, k] = -1
            continue
        # sides across a face both their cubes cross with one patch in two segments, this edge in the second
        sides = int(0)
        if (info[0] | info[1] | info[2] | info[3]) >> 8 != 0:
            for k in range(4):
                face = 2 * ((a + 1 + k % 2) % 3) + wp.where(k < 2, 0, 1)
                mate = face + 1 - 2 * (face % 2)  # the same face seen from the next cube
                if (info[k] >> (8 + face)) & 1 == 1 and (info[(k + 1) % 4] >> (8 + mate)) & 1 == 1:
                    if second[((info[k] & 255) * 12 + quad_edge(4 * a + k)) * 6 + face] == 1:
                        sides = sides | (1 << k)
        q0 = q[0]
        q1 = q[1]
        q2 = q[2]
        q3 = q[3]
        inside_above = (case >> ea) & 1 == 1
        if inside_above:  # inside above: the outward normal is -axis, so turn the other way round
            q1 = q[3]
            q3 = q[1]
            # side k (q[k], q[k + 1]) is now side (3 - k) % 4
            sides = ((sides & 1) << 3) | ((sides & 2) << 1) | ((sides & 4) >> 1) | ((sides & 8) >> 3)
        if sides != 0:
            # written in order and split along q0-q2, for _open_tunnels to rebuild around the sides' new vertices
            tunnel[quad] = wp.uint8(sides | (a << 4))
            tris[row, 0] = q0
            tris[row, 1] = q1
            tris[row, 2] = q2
            tris[row + 1, 0] = q0
            tris[row + 1, 1] = q2
            tris[row + 1, 2] = q3
            continue
        p0 = verts[q0]
        p1 = verts[q1]
        p2 = verts[q2]
        p3 = verts[q3]
        # each split's smaller triangle area seen along the edge (outward), in voxels^2 (twice the area)
        axis = wp.vec3(0.0)
        axis[a] = wp.where(inside_above, -inv * inv, inv * inv)
        area02 = wp.min(wp.dot(wp.cross(p1 - p0, p2 - p0), axis), wp.dot(wp.cross(p2 - p0, p3 - p0), axis))
        area13 = wp.min(wp.dot(wp.cross(p1 - p0, p3 - p0), axis), wp.dot(wp.cross(p2 - p1, p3 - p1), axis))
        # the diagonal whose midpoint its two vertices' planes fit best, unless that folds a triangle the other does not
        m02 = 0.5 * (p0 + p2)
        m13 = 0.5 * (p1 + p3)
        e02 = quadric_at(vec10(quadrics[q0]), (m02 - p0) * inv) + quadric_at(vec10(quadrics[q2]), (m02 - p2) * inv)
        e13 = quadric_at(vec10(quadrics[q1]), (m13 - p1) * inv) + quadric_at(vec10(quadrics[q3]), (m13 - p3) * inv)
        split02 = e02 <= e13
        if split02 and area02 < min_area and area13 > area02:
            split02 = False
        elif not split02 and area13 < min_area and area02 > area13:
            split02 = True
        # planar and convex: both splits' triangles within quad_cos of each other (a quad of its own)
        if fold_cos(p0, p1, p2, p3) >= quad_cos and fold_cos(p1, p2, p3, p0) >= quad_cos:
            whole[quad] = wp.where(split02, wp.uint8(1), wp.uint8(2))
        if split02:
            tris[row, 0] = q0
            tris[row, 1] = q1
            tris[row, 2] = q2
            tris[row + 1, 0] = q0
            tris[row + 1, 1] = q2
            tris[row + 1, 2] = q3
        else:
            tris[row, 0] = q0
            tris[row, 1] = q1
            tris[row, 2] = q3
            tris[row + 1, 0] = q1
            tris[row + 1, 1] = q2
            tris[row + 1, 2] = q3


def contour_dual(cube_corners, values, codes, proj, *, origin, spacing, iso=0.0):
    """Dual marching cubes over active cubes, each vertex at its patch's plane-quadric minimiser within its cube.

    Args:
        cube_corners: (M, 8) int32 Warp array: node indices of each active cube's corners (``CORNER_OFFSETS`` order).
        values: (N,) float32 Warp array of node values minus ``iso``, none exactly 0 (the nudged values marching
            cubes uses, so both agree on every cube's case; a node's Hermite data holds where its value plus ``iso``
            is its distance to its closest point).
        codes: (N,) int64 Warp array of the nodes' Morton codes (node at ``origin + (c + 0.5) * spacing``, c its
            lattice coordinates).
        proj: (N,) vec3h Warp array of each node's closest point on the surface its value came from, as a field keeps
            it (the offset from the node in voxels, :func:`.sampling.stored_proj`).
        origin: (3,) world position of lattice point (0, 0, 0)'s cell minimum.
        spacing: Lattice spacing.
        iso: Level extracted (planes are moved by it along their normals).
    Returns:
        dict: ``verts`` (V, 3) float32, ``tris`` (T, 3) int32 (outward, counter-clockwise), ``ranks`` (V,) int32
        (significant eigenvalues of each vertex's quadric: 1 smooth, 2 crease, 3 corner; 0 without planes) and
        ``cells`` (V,) int32 (the active cube each vertex belongs to, a row of ``cube_corners``), ``tunnels``: how
        many of the vertices were added between two cubes meeting along two dual edges (``meshcheck.open_tunnels``),
        ``whole`` (Q,) uint8: per pair of rows 2q, 2q + 1 (first in ``tris``; a tunnel's fans follow them),
        whether their quad is planar and convex enough to stay one polygon, and its split (:func:`.quads.merge_pairs`),
        ``closed``: whether every crossed lattice edge of an active cube has its quad (no hole at a missing cube).
    """
    device = cube_corners.device
    tables = lookup_tables(device)
    m, n = cube_corners.shape[0], values.shape[0]
    counts = wp.empty(m, dtype=wp.int32, device=device)
    quad_counts = wp.empty(m, dtype=wp.int32, device=device)
    cube_of_node = wp.full(n, -1, dtype=wp.int32, device=device)
    below = wp.zeros(3 * n, dtype=wp.uint8, device=device)
    crossed = wp.empty(m, dtype=wp.uint8, device=device)
    patches = [cube_corners, values, tables["count"], counts, quad_counts, cube_of_node, below, crossed]
    launch_split(_count_patches_kernel, m, lambda s, c: [s, *patches], device, min_dim=EMIT_SPLIT_MIN_DIM)
    vertex_start = wp.empty(m, dtype=wp.int32, device=device)
    wp.utils.array_scan(counts, vertex_start, inclusive=True)
    quad_scan = counts  # reused
    wp.utils.array_scan(quad_counts, quad_scan, inclusive=True)
    n_verts = int(vertex_start[-1:].numpy()[0])
    n_quads = int(quad_scan[-1:].numpy()[0])
    quad_counts = None  # (arrays are let go as soon as they are used: the peak of a large extraction is here)
    origin_wp = wp.vec3(*(float(x) for x in origin))
    nodes = (cube_corners, values, codes, proj, cube_of_node)
    starts = (vertex_start, below, n_verts)
    verts, ranks, cells, quadrics, cube_info = _placed_vertices(nodes, starts, tables, origin_wp, spacing, iso)
    vertex_start = below = None
    tris = wp.empty((2 * n_quads, 3), dtype=wp.int32, device=device)
    tunnel = wp.empty(n_quads, dtype=wp.uint8, device=device)
    whole = wp.empty(n_quads, dtype=wp.uint8, device=device)
    launch_split(
        _quads_kernel,
        m,
        lambda s, c: [
            s,
            cube_corners,
            cube_of_node,
            cube_info,
            tables["patch_of_edge"],
            quad_scan,
            verts,
            quadrics,
            1.0 / float(spacing),
            MIN_SPLIT_AREA,
            float(np.cos(np.radians(QUAD_ANGLE))),
            tables["second"],
            tris,
            tunnel,
            whole,
        ],
        device,
        min_dim=EMIT_SPLIT_MIN_DIM,  # (a cube's quads and their splits each)
    )
    surface = {"verts": verts.numpy().reshape(-1, 3), "tris": tris.numpy(), "ranks": ranks.numpy()}
    surface.update(cells=cells.numpy(), tunnels=0, whole=whole.numpy())
    quadrics = cube_info = None
    tunnel_np = tunnel.numpy()
    flagged = np.flatnonzero(tunnel_np)
    if len(flagged):
        points = tunnel_points(flagged, tunnel_np[flagged], quad_scan, cube_corners, values, codes, origin_wp, spacing)
        open_tunnels(surface, flagged, tunnel_np[flagged] & 15, points)
    return _without_missing_quads(surface, n_quads, crossed)


def _placed_vertices(nodes, starts, tables, origin, spacing: float, iso: float) -> tuple:
    """``_place_vertices_kernel`` over the active cubes (``nodes``: their corners, the nodes' values, codes, closest
    points and each node's cube; ``starts``: each cube's first vertex, the below flags, the vertex count): the
    vertices, their ranks, cells, half-float quadrics and each cube's (first vertex, case)."""
    (cube_corners, values, codes, proj, cube_of_node), (vertex_start, below, n) = nodes, starts
    device, m = cube_corners.device, cube_corners.shape[0]
    out = [wp.empty(n, dtype=t, device=device) for t in (wp.vec3, wp.int32, wp.int32, vec10h)]
    out.append(wp.empty(m, dtype=wp.vec2i, device=device))  # (quadrics only to choose each quad's diagonal)
    fixed = [tables["edge_mask"], tables["end_mask"], tables["spans"], vertex_start, cube_of_node, below]
    fixed += [EMPTY_REACH, EIGEN_CUTOFF, SMOOTH_COS, HERMITE_TOLERANCE, HERMITE_NEAR, CELL_MARGIN]
    head = [cube_corners, values, codes, proj, origin, float(spacing), float(iso)]
    args = lambda s, c: [s, *head, *fixed, *out]  # noqa: E731 (a minimiser each: worth two cores from a few thousand)
    launch_split(_place_vertices_kernel, m, args, device, balance=True, min_dim=EMIT_SPLIT_MIN_DIM)
    return tuple(out)


def _without_missing_quads(surface: dict, n_quads: int, crossed) -> dict:
    """``surface`` without the -1 rows of quads at a missing cube, and ``closed``: every crossed edge of an active
    cube (``crossed``: (M,) how many each has) in a quad of four active cubes (an edge with a cube missing has no
    quad, or a -1 row where the cube writing it is there)."""
    tris = surface["tris"]
    complete = tris[: 2 * n_quads : 2, 0] >= 0
    surface["closed"] = bool(int(crossed.numpy().sum(dtype=np.int64)) == 4 * int(np.count_nonzero(complete)))
    if not complete.all():  # quads at the band's edge, where a cube is missing (open surface)
        complete = tris[:, 0] >= 0
        surface["tris"] = tris[complete]
        surface["whole"] = surface["whole"][complete[: 2 * len(surface["whole"]) : 2]]  # (a tunnel's fans: last)
    return surface
