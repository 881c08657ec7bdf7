"""A field's point queries as kernels: values and gradients at points, the source ids there, the nodes about faces,
and the nodes' closest points decoded (:class:`.field.AdaptiveField` launches them; the interpolation is
:mod:`.sampling`'s)."""

from __future__ import annotations

import numpy as np
import warp as wp

from .octree import morton_decode, node_center
from .parallel import launch_split
from .sampling import (
    FieldArg,
    clamp_to_domain,
    closest_sample,
    coarse_mls,
    leaf_neighbours,
    level_spacing,
    locate_leaf,
    node_proj,
    node_source,
    sample_linear,
    sample_mls,
)


@wp.func
def beyond_domain(f: FieldArg, x: wp.vec3, xc: wp.vec3, out: float, phi: float) -> float:
    """The value at a point ``x`` ``out`` outside the domain box, from ``phi`` read at its clamped point ``xc``. Both
    are upper bounds of the distance and neither is below the distance to the domain box: the bound through the
    clamped point, and the distance to the closest surface point stored at its leaf."""
    through = wp.max(phi, 0.0) + out
    at = locate_leaf(f, xc)
    direct = wp.length(x - node_proj(f, at[0], at[1]))
    return wp.max(wp.min(through, direct), out)


@wp.func
def mls_value(f: FieldArg, x: wp.vec3) -> float:
    """The MLS value at a point of the field's own frame, as :func:`sample_field_kernel` reads it (method 0)."""
    xc = clamp_to_domain(f, x)
    out = wp.length(x - xc)
    leaf = locate_leaf(f, xc)
    if f.exact == 1 and leaf[1] > 0:
        return closest_sample(f, x, leaf)[0]
    phi = sample_mls(f, xc)[0]
    if out > 0.0:
        phi = beyond_domain(f, x, xc, out, phi)
    return phi


@wp.func
def linear_value(f: FieldArg, x: wp.vec3) -> float:
    """The linear value at a point of the field's own frame, as :func:`sample_field_kernel` reads it (method 1)."""
    xc = clamp_to_domain(f, x)
    out = wp.length(x - xc)
    phi = sample_linear(f, xc)
    if out > 0.0:
        phi = beyond_domain(f, x, xc, out, phi)
    return phi


@wp.kernel(enable_backward=False)
def sample_field_kernel(
    f: FieldArg, points: wp.array[wp.vec3], method: int, values: wp.array[wp.float32], grads: wp.array[wp.vec3]
):
    """Signed distance (negative inside) and gradient at each point; outside the domain the value grows with the
    distance to the domain box and is never below it. ``method`` 0: MLS, 1: linear, 2: the unsigned distance of a
    field with no inside (the nearest of the neighbours' closest points, as in a coarse leaf: no fit smooths the kink
    of the distance on the surface). In a coarse leaf of a re-distanced field (``f.exact``), the distance to the
    nearest of its closest points (:func:`closest_sample`): within about h^2 / 4S where the MLS estimate of a coarse
    leaf reads up to a tenth too far."""
    i = wp.tid()
    x = points[i]
    xc = clamp_to_domain(f, x)
    out = wp.length(x - xc)
    if method == 0:
        leaf = locate_leaf(f, xc)
        if f.exact == 1 and leaf[1] > 0:
            # a coarse leaf of a field whose closest points lie on its surface: the nearest of them
            r = closest_sample(f, x, leaf)
            values[i] = r[0]
            grads[i] = wp.vec3(r[1], r[2], r[3])
            return
        r = sample_mls(f, xc)
        phi = r[0]
        g = wp.vec3(r[1], r[2], r[3])
    elif method == 2:
        # a finest leaf's nodes lie half a cell from the surface: their feet on it are a cell apart, and the tangent
        # plane through the nearest is followed a cell along (as a coarse leaf of twice the size would)
        leaf = locate_leaf(f, xc)
        count, ids, levels = leaf_neighbours(f, leaf[0], leaf[1])
        r = coarse_mls(f, count, ids, levels, xc, level_spacing(f, wp.max(leaf[1], 1)), f.values[leaf[0]])
        phi = r[0]
        g = wp.vec3(r[1], r[2], r[3])
    else:
        phi = sample_linear(f, xc)
        g = wp.vec3(0.0)
    if out > 0.0:
        phi = beyond_domain(f, x, xc, out, phi)
        g = (x - xc) / out
    values[i] = phi
    grads[i] = g


@wp.kernel(enable_backward=False)
def source_ids_kernel(f: FieldArg, points: wp.array[wp.vec3], ids: wp.array[wp.int32]):
    i = wp.tid()
    leaf = locate_leaf(f, clamp_to_domain(f, points[i]))
    ids[i] = node_source(f, leaf[0])


@wp.kernel(enable_backward=False)
def face_nodes_kernel(
    f: FieldArg,
    first: int,
    verts: wp.array[wp.vec3],
    tris: wp.array[wp.int32],
    source: wp.array[wp.int32],
    tri: wp.array[wp.int32],
):
    """For face ``i = first + tid`` of a surface (corners ``verts[tris[3 i .. 3 i + 2]]``): the source id of the leaf
    holding its centre, and that leaf's closest triangle when it is a finest node whose triangle the field knows (else
    -1)."""
    i = first + wp.tid()
    centre = (verts[tris[3 * i]] + verts[tris[3 * i + 1]] + verts[tris[3 * i + 2]]) / 3.0
    leaf = locate_leaf(f, clamp_to_domain(f, centre))
    source[i] = node_source(f, leaf[0])
    tri[i] = -1
    if leaf[1] == 0 and f.tri.shape[0] > 0:
        tri[i] = f.tri[leaf[0]]


@wp.kernel(enable_backward=False)
def _code_proj_kernel(
    first: int,
    codes: wp.array[wp.int64],
    coords: wp.array[wp.vec3i],
    offsets: wp.array[wp.int32],
    origin: wp.vec3,
    voxel_size: float,
    encode: int,
    points: wp.array[wp.vec3],
    stored: wp.array[wp.vec3h],
):
    """Node ``first + tid``'s closest point between a point (``points``) and the half-float offset from its centre
    in its level's spacings (``stored``): ``encode`` 1 from the first to the second, 0 back. The node's coordinates
    from ``coords`` where given (a layout's: half the time of decoding its code), else from its code."""
    i = first + wp.tid()
    k = int(0)
    while i >= offsets[k + 1]:
        k += 1
    s = voxel_size * float(1 << k)
    c = wp.vec3i()
    if coords.shape[0] > 0:
        c = coords[i]
    else:
        c = morton_decode(codes[i])
    centre = node_center(origin, s, c)
    if encode == 1:
        stored[i] = wp.vec3h((points[i] - centre) / s)
    else:
        points[i] = centre + s * wp.vec3(stored[i])


def code_proj(codes, level_offsets, origin, voxel_size, *, points=None, stored=None, coords=None):
    """Closest points between world points and how a field keeps them (:func:`stored_proj`): given ``points`` (N,)
    vec3, their (N,) vec3h offsets; given ``stored``, the (N,) vec3 points. ``codes``/``level_offsets``: the nodes'
    Morton codes and the levels' offsets (finest first), ``origin``/``voxel_size`` the finest lattice; ``coords``:
    the nodes' (N,) vec3i lattice coordinates where at hand (else decoded from the codes)."""
    source = points if points is not None else stored
    device = source.device
    n = source.shape[0]
    encode = int(points is not None)
    if encode:
        stored = wp.empty(n, dtype=wp.vec3h, device=device)
    else:
        points = wp.empty(n, dtype=wp.vec3, device=device)
    if coords is None:
        coords = wp.empty(0, dtype=wp.vec3i, device=device)
    offsets = wp.array(np.asarray(level_offsets, dtype=np.int32), dtype=wp.int32, device=device)
    origin_v = wp.vec3(*(float(v) for v in origin))
    launch_split(
        _code_proj_kernel,
        n,
        lambda lo, _n: [lo, codes, coords, offsets, origin_v, float(voxel_size), encode, points, stored],
        device,
    )
    return stored if encode else points
