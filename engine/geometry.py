"""Geometric primitives as Warp functions, shared by the build's kernels: triangle/box overlap, closest points on
triangles and on a mesh (through Warp's BVH), the fast winding number, segment/triangle tests, and the bound of the
caps over an open mesh's holes. Nothing here launches a kernel.
"""

from __future__ import annotations

import warp as wp

# Distance of a node whose closest point is not known (yet).
UNSET_DISTANCE = 1.0e30


@wp.func
def _axis_test(axis: wp.vec3, v0: wp.vec3, v1: wp.vec3, v2: wp.vec3, half: wp.vec3) -> bool:
    """True when ``axis`` separates the triangle (box-centred) from the box."""
    if wp.length_sq(axis) < 1.0e-30:
        return False
    p0 = wp.dot(v0, axis)
    p1 = wp.dot(v1, axis)
    p2 = wp.dot(v2, axis)
    r = half[0] * wp.abs(axis[0]) + half[1] * wp.abs(axis[1]) + half[2] * wp.abs(axis[2])
    return wp.min(p0, wp.min(p1, p2)) > r or wp.max(p0, wp.max(p1, p2)) < -r


@wp.func
def tri_box_overlap(center: wp.vec3, half: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> bool:
    """Separating-axis triangle/box overlap test (Akenine-Moller); the triangle's AABB is tested by the caller."""
    v0 = a - center
    v1 = b - center
    v2 = c - center
    e0 = v1 - v0
    e1 = v2 - v1
    e2 = v0 - v2
    # the triangle's plane first: it rejects most boxes near a triangle
    if _axis_test(wp.cross(e0, e1), v0, v1, v2, half):
        return False
    for k in range(3):
        unit = wp.vec3(0.0)
        unit[k] = 1.0
        if _axis_test(wp.cross(unit, e0), v0, v1, v2, half):
            return False
        if _axis_test(wp.cross(unit, e1), v0, v1, v2, half):
            return False
        if _axis_test(wp.cross(unit, e2), v0, v1, v2, half):
            return False
    return True


@wp.func
def _closest_on_segment(p: wp.vec3, a: wp.vec3, b: wp.vec3) -> wp.vec3:
    ab = b - a
    t = wp.dot(p - a, ab) / wp.max(wp.dot(ab, ab), 1.0e-30)
    return a + ab * wp.clamp(t, 0.0, 1.0)


@wp.func
def _closest_on_edges(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> wp.vec3:
    """The nearest point to ``p`` on the three edges of triangle (a, b, c)."""
    q = _closest_on_segment(p, a, b)
    r = _closest_on_segment(p, b, c)
    if wp.length_sq(p - r) < wp.length_sq(p - q):
        q = r
    r = _closest_on_segment(p, c, a)
    if wp.length_sq(p - r) < wp.length_sq(p - q):
        q = r
    return q


# A triangle whose largest angle's sine is below this is degenerate: its closest points are its edges' (it is at most
# this fraction of its second-longest edge wide).
DEGENERATE_SINE = 1.0e-5


@wp.func
def triangle_frame(a: wp.vec3, b: wp.vec3, c: wp.vec3):
    """What ``closest_on_triangle`` needs of triangle (a, b, c), once for the many points tested against it.

    Returns (edges, inward, lengths, n): ``edges`` the rows ab = b - a, ac = c - a, bc = c - b; ``lengths`` their
    squared lengths; ``n`` the unit normal (along ab x ac), zero for a degenerate triangle; ``inward`` the rows
    n x ab, ac x n, n x bc, each edge's normal in the triangle's plane pointing inside, as long as the edge. The
    normal is the cross product of the two edges at the largest angle (opposite the longest edge): a long thin
    triangle's two long edges are nearly parallel, and float rounding of theirs would tilt it by up to 1/sine of
    their angle times the rounding."""
    ab = b - a
    ac = c - a
    bc = c - b
    lengths = wp.vec3(wp.dot(ab, ab), wp.dot(ac, ac), wp.dot(bc, bc))
    # the largest angle at a (bc the longest), b (ac) or c (ab): ab x ac = ab x bc = ac x bc
    at_a = lengths[2] >= lengths[0] and lengths[2] >= lengths[1]
    at_b = not at_a and lengths[1] >= lengths[0]
    normal = wp.cross(wp.where(at_a or at_b, ab, ac), wp.where(at_a, ac, bc))
    scale = wp.where(at_a, lengths[0] * lengths[1], wp.where(at_b, lengths[0] * lengths[2], lengths[1] * lengths[2]))
    n = wp.vec3(0.0)
    area2 = wp.dot(normal, normal)
    if area2 > DEGENERATE_SINE * DEGENERATE_SINE * scale:
        n = normal / wp.sqrt(area2)
    inward = wp.matrix_from_rows(wp.cross(n, ab), wp.cross(ac, n), wp.cross(n, bc))
    return wp.matrix_from_rows(ab, ac, bc), inward, lengths, n


@wp.func
def closest_on_triangle(
    p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3, edges: wp.mat33, inward: wp.mat33, lengths: wp.vec3, n: wp.vec3
) -> wp.vec3:
    """Closest point to ``p`` on triangle (a, b, c), given its ``triangle_frame``: its plane's point below ``p`` where
    that lies inside all three edges, else the nearest point of the edges it lies outside. Every quantity is a dot
    product with one of the triangle's own edges or normals, each exact to float rounding of ``p``'s distance to it:
    the barycentric coordinates of the Voronoi-region method (Ericson, Real-Time Collision Detection 5.1.5) are
    differences of products of edge lengths, which on a long thin triangle (a cylinder's side: 0.94 by 0.006 of the
    diagonal) cancel down to 1e-3 of their size, moving the point along the triangle by up to 0.2 voxel at /256. A
    degenerate triangle falls back to its nearest edge."""
    if n[0] == 0.0 and n[1] == 0.0 and n[2] == 0.0:
        return _closest_on_edges(p, a, b, c)
    ap = p - a
    bp = p - b
    in_ab = wp.dot(wp.vec3(inward[0, 0], inward[0, 1], inward[0, 2]), ap)
    in_ac = wp.dot(wp.vec3(inward[1, 0], inward[1, 1], inward[1, 2]), ap)
    in_bc = wp.dot(wp.vec3(inward[2, 0], inward[2, 1], inward[2, 2]), bp)
    if in_ab >= 0.0 and in_ac >= 0.0 and in_bc >= 0.0:
        return p - n * wp.dot(n, ap)
    # outside: the nearest point lies on an edge that p's projection is beyond (a convex polygon's nearest boundary
    # point is seen from outside), one or two of them
    best = float(1.0e30)
    q = p
    if in_ab < 0.0:
        ab = wp.vec3(edges[0, 0], edges[0, 1], edges[0, 2])
        q = a + ab * wp.clamp(wp.dot(ap, ab) / lengths[0], 0.0, 1.0)
        best = wp.length_sq(p - q)
    if in_ac < 0.0:
        ac = wp.vec3(edges[1, 0], edges[1, 1], edges[1, 2])
        r = a + ac * wp.clamp(wp.dot(ap, ac) / lengths[1], 0.0, 1.0)
        d = wp.length_sq(p - r)
        if d < best:
            q = r
            best = d
    if in_bc < 0.0:
        bc = wp.vec3(edges[2, 0], edges[2, 1], edges[2, 2])
        r = b + bc * wp.clamp(wp.dot(bp, bc) / lengths[2], 0.0, 1.0)
        if wp.length_sq(p - r) < best:
            q = r
    return q


@wp.func_native("return wp::mesh_query_winding_number(mesh, x, accuracy);")
def winding_number(mesh: wp.uint64, x: wp.vec3, accuracy: float) -> float:
    """The mesh's fast winding number at ``x`` (Barill et al., Warp's native solid-angle tree): what
    ``wp.mesh_query_point_sign_winding_number`` compares with its threshold, without the closest-point query it runs
    first (a third of its cost; a node's distance is known already)."""
    ...


@wp.func
def near_cap(
    x: wp.vec3, cap_lo: wp.array[wp.vec3], cap_hi: wp.array[wp.vec3], cap_radius: wp.array[wp.float32], margin: float
) -> bool:
    """Whether the cones over an open mesh's holes (see ``hole_caps``; no caps: a closed mesh) may move the winding
    number by 1/4 or more somewhere within ``margin`` of ``x``: sum over caps c of (radius_c / d_c)^2 >= 1, d_c the
    distance from the box c to that ball."""
    total = float(0.0)
    for c in range(cap_radius.shape[0]):
        d = wp.length(wp.max(wp.max(cap_lo[c] - x, x - cap_hi[c]), wp.vec3(0.0))) - margin
        if d <= cap_radius[c]:
            return True
        total += (cap_radius[c] / d) * (cap_radius[c] / d)
    return total >= 1.0


@wp.func
def _may_cross(p: wp.vec3, q: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> bool:
    """Whether segment pq may meet triangle abc: False only when it surely does not (both ends clearly on one side of
    the plane, or the segment's line clearly outside an edge); touching, grazing and degenerate cases count as
    meeting."""
    n = wp.cross(b - a, c - a)
    d = q - p
    reach = wp.max(wp.length(a - p), wp.max(wp.length(b - p), wp.length(c - p))) + wp.length(d)
    # margins 10x above float32 rounding of the products they bound (all lengths cubed)
    tol = 1.0e-5 * wp.length(n) * reach
    sp = wp.dot(p - a, n)
    sq = wp.dot(q - a, n)
    if (sp > tol and sq > tol) or (sp < -tol and sq < -tol):
        return False
    tol = 1.0e-5 * reach * reach * wp.length(d)
    v0 = wp.dot(wp.cross(a - p, b - p), d)
    v1 = wp.dot(wp.cross(b - p, c - p), d)
    v2 = wp.dot(wp.cross(c - p, a - p), d)
    if (v0 > tol or v1 > tol or v2 > tol) and (v0 < -tol or v1 < -tol or v2 < -tol):
        return False
    return True


@wp.func
def segment_clear(mesh: wp.uint64, p: wp.vec3, q: wp.vec3) -> bool:
    """Whether segment pq surely meets no triangle of the mesh."""
    pad = wp.vec3(1.0e-3 * wp.length(q - p))
    candidates = wp.mesh_query_aabb(mesh, wp.min(p, q) - pad, wp.max(p, q) + pad)
    m = wp.mesh_get(mesh)
    f = int(0)
    while wp.mesh_query_aabb_next(candidates, f):
        if _may_cross(p, q, m.points[m.indices[3 * f]], m.points[m.indices[3 * f + 1]], m.points[m.indices[3 * f + 2]]):
            return False
    return True


# What segment_crossings returns when it cannot tell (the segment touches an edge or a vertex, or grazes a face).
CROSSINGS_UNKNOWN = 1 << 20


@wp.func
def _crossing(p: wp.vec3, q: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> int:
    """How segment pq meets triangle abc: 0 surely not at all, +1 or -1 through its interior (from the side its
    normal (b - a) x (c - a) points to, or into it), CROSSINGS_UNKNOWN within float rounding of an edge, a vertex or
    the plane (the margins of ``_may_cross``)."""
    n = wp.cross(b - a, c - a)
    d = q - p
    reach = wp.max(wp.length(a - p), wp.max(wp.length(b - p), wp.length(c - p))) + wp.length(d)
    tol = 1.0e-5 * wp.length(n) * reach
    sp = wp.dot(p - a, n)
    sq = wp.dot(q - a, n)
    if (sp > tol and sq > tol) or (sp < -tol and sq < -tol):
        return 0
    tol = 1.0e-5 * reach * reach * wp.length(d)
    v0 = wp.dot(wp.cross(a - p, b - p), d)
    v1 = wp.dot(wp.cross(b - p, c - p), d)
    v2 = wp.dot(wp.cross(c - p, a - p), d)
    if (v0 > tol or v1 > tol or v2 > tol) and (v0 < -tol or v1 < -tol or v2 < -tol):
        return 0
    through = (v0 > tol and v1 > tol and v2 > tol) or (v0 < -tol and v1 < -tol and v2 < -tol)
    if through and sp > tol and sq < -tol:
        return 1
    if through and sp < -tol and sq > tol:
        return -1
    return CROSSINGS_UNKNOWN


@wp.func
def segment_crossings(mesh: wp.uint64, p: wp.vec3, q: wp.vec3) -> int:
    """The number of times segment pq passes through the mesh's triangles into them (against their normals) minus
    out of them: what the winding number gains from p to q beyond its smooth part, or CROSSINGS_UNKNOWN when a
    triangle is met at an edge, a vertex or a graze."""
    pad = wp.vec3(1.0e-3 * wp.length(q - p))
    candidates = wp.mesh_query_aabb(mesh, wp.min(p, q) - pad, wp.max(p, q) + pad)
    m = wp.mesh_get(mesh)
    f = int(0)
    total = int(0)
    while wp.mesh_query_aabb_next(candidates, f):
        k = _crossing(p, q, m.points[m.indices[3 * f]], m.points[m.indices[3 * f + 1]], m.points[m.indices[3 * f + 2]])
        if k == CROSSINGS_UNKNOWN:
            return CROSSINGS_UNKNOWN
        total += k
    return total


# Warp's BVH closest-point search (``mesh_query_point_no_sign``), returning the point itself: the same traversal
# (nearest child first, boxes farther than the best distance so far skipped), with the closest point on each triangle
# computed as ``closest_on_triangle`` does (Warp's routine is the Voronoi-region method, whose barycentric coordinates
# lose all but a few bits on long thin triangles) and without Warp's per-triangle sliver test: a sliver's points are
# surface points like any other. A triangle whose plane is farther than the best distance so far is passed over after
# one dot product. The closest point of a triangle:
_TRIANGLE_POINT = r"""
            const wp::vec3 ab = q - p;
            const wp::vec3 ac = r - p;
            const wp::vec3 bc = r - q;
            const wp::vec3 ap = x - p;
            const float lab = wp::dot(ab, ab);
            const float lac = wp::dot(ac, ac);
            const float lbc = wp::dot(bc, bc);
            // the normal from the two edges at the largest angle (see triangle_frame), unscaled
            const bool at_a = lbc >= lab && lbc >= lac;
            const bool at_b = !at_a && lac >= lab;
            const wp::vec3 nrm = wp::cross(at_a || at_b ? ab : ac, at_a ? ac : bc);
            const float area2 = wp::dot(nrm, nrm);
            const float scale = at_a ? lab * lac : (at_b ? lab * lbc : lac * lbc);
            const bool flat = area2 > DEGENERATE_SINE_SQ * scale;
            const float plane = wp::dot(nrm, ap);
            if (flat && plane * plane >= best * area2)
                continue;  // its plane is no nearer than the best point so far
            const wp::vec3 bp = x - q;
            wp::vec3 y;
            if (flat) {
                // which side of each edge: signs of N . (edge x (x - its start)), exact to rounding of x's distance
                const float in_ab = wp::dot(nrm, wp::cross(ab, ap));
                const float in_ac = wp::dot(nrm, wp::cross(ap, ac));
                const float in_bc = wp::dot(nrm, wp::cross(bc, bp));
                if (in_ab >= 0.0f && in_ac >= 0.0f && in_bc >= 0.0f) {
                    y = x - nrm * (plane / area2);
                } else {
                    // outside: the nearest point lies on an edge the point's projection is beyond
                    float dy = 1.0e30f;
                    if (in_ab < 0.0f) {
                        y = p + ab * wp::clamp(wp::dot(ap, ab) / lab, 0.0f, 1.0f);
                        dy = wp::length_sq(y - x);
                    }
                    if (in_ac < 0.0f) {
                        const wp::vec3 e = p + ac * wp::clamp(wp::dot(ap, ac) / lac, 0.0f, 1.0f);
                        const float de = wp::length_sq(e - x);
                        if (de < dy) { dy = de; y = e; }
                    }
                    if (in_bc < 0.0f) {
                        const wp::vec3 e = q + bc * wp::clamp(wp::dot(bp, bc) / lbc, 0.0f, 1.0f);
                        if (wp::length_sq(e - x) < dy) y = e;
                    }
                }
            } else {  // degenerate: its nearest edge
                const wp::vec3 e0 = p + ab * wp::clamp(wp::dot(ap, ab) / wp::max(lab, 1.0e-30f), 0.0f, 1.0f);
                const wp::vec3 e1 = p + ac * wp::clamp(wp::dot(ap, ac) / wp::max(lac, 1.0e-30f), 0.0f, 1.0f);
                const wp::vec3 e2 = q + bc * wp::clamp(wp::dot(bp, bc) / wp::max(lbc, 1.0e-30f), 0.0f, 1.0f);
                y = e0;
                if (wp::length_sq(e1 - x) < wp::length_sq(y - x)) y = e1;
                if (wp::length_sq(e2 - x) < wp::length_sq(y - x)) y = e2;
            }
            const float d = wp::length_sq(y - x);
""".replace("DEGENERATE_SINE_SQ", repr(DEGENERATE_SINE * DEGENERATE_SINE) + "f")


_CLOSEST_POINT_SNIPPET = (
    r"""
wp::Mesh m = wp::mesh_get(mesh);
int stack[BVH_QUERY_STACK_SIZE];
stack[0] = *m.bvh.root;
int count = 1;
float best = max_dist * max_dist;
float reach = best * shrink;
wp::vec4 out(x[0], x[1], x[2], -1.0f);
while (count) {
    const int node = stack[--count];
    wp::BVHPackedNodeHalf lower = wp::bvh_load_node(m.bvh.node_lowers, node);
    wp::BVHPackedNodeHalf upper = wp::bvh_load_node(m.bvh.node_uppers, node);
    if (wp::distance_to_aabb_sq(x, wp::vec3(lower.x, lower.y, lower.z), wp::vec3(upper.x, upper.y, upper.z)) > reach)
        continue;
    const int left = lower.i;
    const int right = upper.i;
    if (lower.b) {
        for (int c = left; c < right; c++) {
            const int t = wp::bvh_load_int(m.bvh.primitive_indices, c);
            const wp::vec3 p = m.points[wp::bvh_load_int(m.indices, t * 3 + 0)];
            const wp::vec3 q = m.points[wp::bvh_load_int(m.indices, t * 3 + 1)];
            const wp::vec3 r = m.points[wp::bvh_load_int(m.indices, t * 3 + 2)];
"""
    + _TRIANGLE_POINT
    + r"""
            if (d < best) {
                best = d;
                reach = d * shrink;
                out = wp::vec4(y[0], y[1], y[2], d);
            }
        }
    } else {
        wp::BVHPackedNodeHalf ll = wp::bvh_load_node(m.bvh.node_lowers, left);
        wp::BVHPackedNodeHalf lu = wp::bvh_load_node(m.bvh.node_uppers, left);
        wp::BVHPackedNodeHalf rl = wp::bvh_load_node(m.bvh.node_lowers, right);
        wp::BVHPackedNodeHalf ru = wp::bvh_load_node(m.bvh.node_uppers, right);
        const float dl = wp::distance_to_aabb_sq(x, wp::vec3(ll.x, ll.y, ll.z), wp::vec3(lu.x, lu.y, lu.z));
        const float dr = wp::distance_to_aabb_sq(x, wp::vec3(rl.x, rl.y, rl.z), wp::vec3(ru.x, ru.y, ru.z));
        // the nearer child goes on the stack last, so it is searched first
        const bool left_first = dl < dr;
        const int far_node = left_first ? right : left;
        const int near_node = left_first ? left : right;
        if ((left_first ? dr : dl) < reach)
            stack[count++] = far_node;
        if ((left_first ? dl : dr) < reach)
            stack[count++] = near_node;
    }
}
return out;
"""
)


@wp.func_native(_CLOSEST_POINT_SNIPPET)
def _closest_point_native(mesh: wp.uint64, x: wp.vec3, max_dist: float, shrink: float) -> wp.vec4:
    """(closest point, squared distance) of ``x`` on the mesh within ``max_dist``; squared distance -1: none. Boxes
    farther than sqrt(``shrink``) times the best distance so far are skipped (1: the exact closest point)."""
    ...


# The same search returning the closest triangle's index in place of the squared distance (as a float: exact below
# 2**24 triangles, a neighbouring index above).
_CLOSEST_FACE_SNIPPET = _CLOSEST_POINT_SNIPPET.replace(
    "out = wp::vec4(y[0], y[1], y[2], d);", "out = wp::vec4(y[0], y[1], y[2], (float)t);"
)


@wp.func_native(_CLOSEST_FACE_SNIPPET)
def _closest_face_native(mesh: wp.uint64, x: wp.vec3, max_dist: float, shrink: float) -> wp.vec4:
    """(closest point, index of its triangle) of ``x`` on the mesh within ``max_dist``; index -1: none."""
    ...


@wp.func
def mesh_closest_face(mesh: wp.uint64, x: wp.vec3, max_dist: float):
    """(closest point on the mesh within ``max_dist`` of ``x``, or ``x``; its triangle, or -1). On a mesh of 2**24
    triangles or more the triangle may be one of the few next to it in the index (a triangle of the mesh still)."""
    r = _closest_face_native(mesh, x, max_dist, 1.0)
    return wp.vec3(r[0], r[1], r[2]), wp.min(int(r[3]), wp.mesh_get(mesh).indices.shape[0] / 3 - 1)


@wp.func
def mesh_near_point(mesh: wp.uint64, x: wp.vec3, max_dist: float, tolerance: float):
    """(found, a point of the mesh within ``max_dist`` of ``x`` no more than 1 + ``tolerance`` times as far as its
    closest point, or ``x``): boxes farther than the best distance so far over 1 + ``tolerance`` are skipped, far
    from the surface a fraction of the search."""
    r = _closest_point_native(mesh, x, max_dist, 1.0 / ((1.0 + tolerance) * (1.0 + tolerance)))
    if r[3] < 0.0:
        return False, x
    return True, wp.vec3(r[0], r[1], r[2])


@wp.func
def mesh_closest_point(mesh: wp.uint64, x: wp.vec3, max_dist: float):
    """(found, closest point on the mesh within ``max_dist`` of ``x``, or ``x``): Warp's closest-point query (the same
    result, see ``_CLOSEST_POINT_SNIPPET``)."""
    return mesh_near_point(mesh, x, max_dist, 0.0)
