"""Field operations: offset, shell and thickness, each a new field around a level set of an exact distance.

Each operation is a function ``g`` of the signed distance ``S`` to a surface: an offset by ``d`` is ``S - d``, a shell
of thickness ``t`` inside the surface ``max(S, -S - t)`` (outside ``max(-S, S - t)``, centred ``|S| - t/2``), and a
surface that encloses nothing given a thickness ``t`` is ``|U| - t/2`` of its unsigned distance ``U``. ``S`` comes
exact from a BVH over the surface's triangles (a field's ``to_mesh``, or a mesh), its sign from the field the surface
came from (:func:`side_of`), so the new surface can lie anywhere in the domain, not only within a band. The new
finest band is found top-down (:func:`band_octets`): a cell whose centre has ``|g|`` beyond its half diagonal and the
band holds none of the new surface (``g`` is 1-Lipschitz), so only cells near it are split, down to the finest
octets. Every node then takes ``g``, and :func:`.redistancing.redistance` makes the result a signed distance everywhere
(where ``g`` is only a bound: a grown shape's filled creases, a shrunk one's far side).
"""

from __future__ import annotations

import math
import time

import numpy as np
import warp as wp

from .geometry import mesh_closest_point
from .holes import sign_change_octets
from .layout import level_layout
from .octree import add_octets, code_bits, decode_codes, dense_level, morton_decode, node_center, sort_unique
from .ondemand import refined
from .parallel import launch_split
from .plan import check_budget, checked_wall, finite_number, plan_grown
from .redistancing import KEEP_BAND, redistance, surface_mesh
from .sampling import (
    FieldArg,
    closest_stored_point,
    inside_domain,
    level_spacing,
    locate_leaf,
    locate_node,
    node_coords,
    node_source,
    sample_mls,
    stored_proj,
)

KIND_OFFSET, KIND_INSIDE, KIND_OUTSIDE, KIND_CENTER = 0, 1, 2, 3
SIDES = {"inside": KIND_INSIDE, "outside": KIND_OUTSIDE, "center": KIND_CENTER}
# An offset's distances through the field's closest points are held within this many voxels of the distance to its
# surface's triangles (:func:`surface_distance`): those triangles (``to_mesh(sharp=False)``) cut its sharp edges by
# up to about half a voxel, so only a walk that ended farther than that is bounded (a turned box grown, less itself
# blended and grown again: cells read one to three voxels far, and the surface had holes; at a slack of 1, still one).
MESH_SLACK_VOXELS = 0.5


@wp.func
def level_value(kind: int, s: float, a: float) -> float:
    """``g(S)``: offset ``S - a``; shell inside ``max(S, -S - a)``, outside ``max(-S, S - a)``, centred
    ``|S| - a/2``."""
    if kind == 0:
        return s - a
    if kind == 1:
        return wp.max(s, -s - a)
    if kind == 2:
        return wp.max(-s, s - a)
    return wp.abs(s) - 0.5 * a


@wp.func
def level_root(kind: int, s: float, a: float) -> float:
    """The root of ``g`` (a value of ``S`` on the new surface) nearest to ``s``."""
    if kind == 0:
        return a
    if kind == 1:
        return wp.where(s < -0.5 * a, -a, 0.0)
    if kind == 2:
        return wp.where(s > 0.5 * a, a, 0.0)
    return wp.where(s < 0.0, -0.5 * a, 0.5 * a)


@wp.func
def side_of(f: FieldArg, x: wp.vec3) -> float:
    """-1 inside the field, +1 outside: the sign of its node at ``x``, or of the coarse leaf containing ``x`` (coarse
    leaves hold no surface), or of its MLS value between finest nodes; +1 outside its domain."""
    if not inside_domain(f, x):
        return 1.0
    leaf = locate_leaf(f, x)
    v = f.values[leaf[0]]
    if leaf[1] == 0:
        c = node_center(f.origin, f.voxel_size, node_coords(f, leaf[0]))
        if wp.length(x - c) > 0.25 * f.voxel_size:
            v = sample_mls(f, x)[0]
    return wp.where(v < 0.0, -1.0, 1.0)


@wp.func
def surface_distance(
    mesh: wp.uint64, f: FieldArg, signs: int, x: wp.vec3, reach: float, level: int, kind: int, a: float, near: float
):
    """(S, closest point, found): with ``signs`` 1 the distance from ``x`` to the field ``f``'s surface through its
    closest points (:func:`.sampling.closest_stored_point`), signed by :func:`side_of`; where that puts ``x`` within
    ``near`` of the new surface (``g`` of ``kind`` and ``a``) through a walk (not a node's own closest point), at most
    MESH_SLACK_VOXELS more than the distance to the field's surface's triangles (``mesh``, where given: a walk can
    end a voxel or two far in a concave blend, and a band cell the new surface passes be culled). Else the unsigned
    distance to the mesh's triangles within ``reach`` (``reach`` and ``x`` itself when none is nearer)."""
    if signs == 2:  # ``mesh`` is the field's own closed mesh: its distance is the field's, exact
        found, p = mesh_closest_point(mesh, x, reach)
        d = reach
        if found:
            d = wp.length(x - p)
        return d * side_of(f, x), p, found
    if signs == 1:
        d, p, exact = _stored_distance(f, x, level)
        side = side_of(f, x)
        if mesh != wp.uint64(0) and not exact and wp.abs(level_value(kind, d * side, a)) <= near:
            slack = MESH_SLACK_VOXELS * f.voxel_size
            found, q = mesh_closest_point(mesh, x, wp.min(reach, d - slack))
            if found and wp.length(x - q) + slack < d:
                d = wp.length(x - q) + slack
                p = q
        return d * side, p, True
    found, p = mesh_closest_point(mesh, x, reach)
    d = reach
    if found:
        d = wp.length(x - p)
    return d, p, found


@wp.func
def _mesh_near(f: FieldArg) -> float:
    """How near the new surface a node's or cell's ``g`` read through closest points must be to be bounded by the
    mesh: the band, and how far a walk may end beyond that (2 voxels seen) and the slack."""
    return (KEEP_BAND + 2.0 + MESH_SLACK_VOXELS) * f.voxel_size


@wp.func
def _stored_distance(f: FieldArg, x: wp.vec3, level: int):
    """(distance, point, exact): the nearest of the field's stored closest points to ``x`` (:func:`surface_distance`);
    at a node of the field's own below its top level (whose closest points may be 5 % off), its closest point
    (``exact``)."""
    node = locate_node(f, x, level)
    if node[1] == level and level < f.levels - 1 and inside_domain(f, x):
        s = level_spacing(f, level)
        centre = node_center(f.origin, s, node_coords(f, node[0]))
        if wp.length(centre - x) < 0.25 * s:
            p = stored_proj(f, node[0], centre, s)
            return wp.length(x - p), p, True
    d, p = closest_stored_point(f, x)
    return d, p, False


@wp.kernel(enable_backward=False)
def _band_cells_kernel(
    first: int,
    mesh: wp.uint64,
    f: FieldArg,
    signs: int,
    kind: int,
    a: float,
    codes: wp.array[wp.int64],
    origin: wp.vec3,
    spacing: float,
    level: int,
    radius: float,
    reach: float,
    keep: wp.array[wp.int32],
):
    """Whether cell ``first + tid`` (Morton code ``codes[...]`` on a level of ``spacing``) may hold a node within the
    band of the new surface: ``|g|`` at its centre within ``radius``."""
    t = first + wp.tid()
    x = node_center(origin, spacing, morton_decode(codes[t]))
    s, p, found = surface_distance(mesh, f, signs, x, reach, level, kind, a, radius + _mesh_near(f))
    keep[t] = wp.where(wp.abs(level_value(kind, s, a)) <= radius, 1, 0)


@wp.kernel(enable_backward=False)
def _level_values_kernel(
    first: int,
    mesh: wp.uint64,
    f: FieldArg,
    signs: int,
    kind: int,
    a: float,
    coords: wp.array[wp.vec3i],
    origin: wp.vec3,
    spacing: float,
    level: int,
    reach: float,
    source_id: int,
    values: wp.array[wp.float32],
    proj: wp.array[wp.vec3],
    source: wp.array[wp.int32],
):
    """``g`` at node ``first + tid`` of a level of ``spacing``, a point of the new surface (its distance from the
    node, along the old closest point's normal) and the source id of the old surface there."""
    i = first + wp.tid()
    x = node_center(origin, spacing, coords[i])
    s, p, found = surface_distance(mesh, f, signs, x, reach, level, kind, a, _mesh_near(f))
    values[i] = level_value(kind, s, a)
    n = x - p
    ln = wp.length(n)
    n = wp.where(ln > 0.0, n / wp.max(ln, 1.0e-30), wp.vec3(0.0))
    if s < 0.0:
        n = -n
    proj[i] = p + level_root(kind, s, a) * n
    source[i] = source_id
    if signs >= 1 and found:
        if inside_domain(f, p):
            source[i] = node_source(f, locate_leaf(f, p)[0])


def level_reach(kind: int, a: float) -> float:
    """How far from the old surface the new one may lie."""
    return abs(a) if kind == KIND_OFFSET else (0.5 * a if kind == KIND_CENTER else a)


def band_octets(mesh_id, f_arg, signs, kind, a, *, origin, top_dims, levels, voxel_size, device) -> wp.array:
    """Codes (unsorted) of the finest octets with a node within ``KEEP_BAND`` voxels of the new surface, found
    top-down: every top cell, then the children of the cells kept on each level (a level-``k`` cell is kept when
    ``|g|`` at its centre is within the band plus the reach of its octets: ``g`` is 1-Lipschitz)."""
    h = float(voxel_size)
    top_n = int(np.prod(top_dims))
    codes = wp.empty(top_n, dtype=wp.int64, device=device)
    dense_level(top_dims, codes, wp.empty(top_n, dtype=wp.vec3i, device=device))
    reach0 = level_reach(kind, a)
    origin_v = wp.vec3(*origin)
    for k in range(levels - 1, 0, -1):
        n = codes.shape[0]
        if n == 0:
            break
        spacing = h * 2**k
        # the band around the new surface, widened by how far this cell's octet centres lie from its centre
        radius = (KEEP_BAND + 0.5 * math.sqrt(3.0)) * h + math.sqrt(3.0) * (0.5 * spacing - h)
        keep = wp.empty(n, dtype=wp.int32, device=device)
        launch_split(
            _band_cells_kernel,
            n,
            lambda s, _n, k=k, spacing=spacing, radius=radius, codes=codes, keep=keep: [
                s,
                wp.uint64(mesh_id),
                f_arg,
                int(signs),
                int(kind),
                float(a),
                codes,
                origin_v,
                float(spacing),
                k,
                float(radius),
                float(reach0 + radius + spacing),
                keep,
            ],
            device,
            balance=True,
        )
        kept = codes.numpy()[keep.numpy().astype(bool)]
        if k == 1:
            return wp.array(kept, dtype=wp.int64, device=device)
        check_budget(np.asarray(top_dims) * 2 ** (levels - 1), top_n, 8 * 8 * len(kept))
        codes = wp.array((kept[:, None] << 3 | np.arange(8)[None, :]).reshape(-1), dtype=wp.int64, device=device)
    return wp.empty(0, dtype=wp.int64, device=device)


# Rounds of octets added where the new surface leaves the band found top-down (:func:`.holes.sign_change_octets`): a
# band cell's bound can miss it where the old surface's sides disagree about a cell (two open tubes overlapping, offset
# by 0.05 at /128: 3 octets, the surface open there).
BAND_ROUNDS = 2


def octets_end_bit(top_dims, levels: int) -> int:
    """The bits of the octet codes of a domain of ``top_dims`` top cells and ``levels`` levels."""
    return 3 * code_bits(np.asarray(top_dims) * 2 ** (levels - 2))


def levelset_field(
    mesh_id,
    base,
    kind: int,
    a: float,
    *,
    voxel_size: float,
    levels: int,
    origin,
    top_dims,
    field_ids,
    device,
    cls,
    exact: bool = False,
):
    """The field of ``g(S)``, re-distanced: the new surface's band found top-down (:func:`band_octets`), every node
    given ``g`` (a point of the new surface as its closest point), then :func:`.redistancing.redistance`.

    Args:
        mesh_id: ``wp.Mesh.id`` of the surface's triangles (``S`` their unsigned distance when ``base`` is None, a
            bound on it through ``base``'s closest points otherwise: :func:`surface_distance`; 0: none; with ``exact``
            ``base``'s own closed mesh, ``S`` its distance signed by ``base``).
        base: The field whose surface is offset or hollowed (``S`` signed by its values).
        kind, a: Which ``g`` (KIND_OFFSET, KIND_INSIDE, KIND_OUTSIDE, KIND_CENTER) and its distance or thickness.
        voxel_size, levels, origin, top_dims: The new field's lattice and domain (see :func:`plan_grown`).
        field_ids: Ids of the new field (its nodes' sources come from ``base`` where it has them, else the first).
        device: Warp device.
        cls: The field class (``AdaptiveField``: passed in, so that the field's own module can call this one).
    Returns:
        AdaptiveField, ``stats["exact_distance"]`` True.
    """
    timings = {}
    t0 = time.perf_counter()
    signs = 2 if exact else int(base is not None)
    f_arg = base.arg() if signs else _empty_field_arg(device)
    octets = None
    if levels > 1:
        grid = {"origin": origin, "top_dims": top_dims, "levels": levels, "voxel_size": voxel_size, "device": device}
        octets = band_octets(mesh_id, f_arg, signs, kind, a, **grid)
        octets = sort_unique(octets, end_bit=octets_end_bit(top_dims, levels))
    timings["band"] = time.perf_counter() - t0
    lattice = {"voxel_size": voxel_size, "origin": origin, "field_ids": field_ids, "timings": timings}
    for round_ in range(BAND_ROUNDS + 1):
        t0 = time.perf_counter()
        layout = level_layout(octets, top_dims, levels, device, timings)
        values, proj, source = _level_values(layout, (mesh_id, f_arg, signs), kind, a, voxel_size, origin, field_ids[0])
        timings["values"] = timings.get("values", 0.0) + time.perf_counter() - t0
        field = cls.from_layout(layout, values=values, proj=proj, source=source, **lattice)
        extra = sign_change_octets(field) if levels > 1 and round_ < BAND_ROUNDS else ()
        if not len(extra):
            break
        octets = add_octets(
            octets, extra, np.asarray(top_dims) * 2 ** (levels - 2), end_bit=octets_end_bit(top_dims, levels)
        )
    result = redistance(field)
    result.timings = {**timings, **{f"redistance_{k}": v for k, v in result.timings.items()}}
    return result


def _level_values(layout, surface, kind: int, a: float, voxel_size: float, origin, field_id: int) -> tuple:
    """Every node of ``layout`` given ``g`` of the surface (``surface``: mesh id, field arg, whether signed; see
    :func:`levelset_field`): (N,) values, closest points and sources, level by level."""
    mesh_id, f_arg, signs = surface
    offsets, levels, device = layout["offsets"], len(layout["offsets"]) - 1, layout["codes"].device
    n = int(offsets[-1])
    values = wp.empty(n, dtype=wp.float32, device=device)
    proj = wp.empty(n, dtype=wp.vec3, device=device)
    source = wp.empty(n, dtype=wp.int32, device=device)
    origin_v = wp.vec3(*origin)
    diag = float(np.linalg.norm(np.asarray(layout["top_dims"]) * voxel_size * 2 ** (levels - 1)))
    reach0 = level_reach(kind, a)
    for k in range(levels):
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        spacing = voxel_size * 2**k
        reach = diag if levels == 1 else reach0 + (KEEP_BAND + 3.0) * voxel_size + 2.0 * spacing
        launch_split(
            _level_values_kernel,
            hi - lo,
            lambda s, _n, lo=lo, k=k, spacing=spacing, reach=reach: [
                lo + s,
                wp.uint64(mesh_id),
                f_arg,
                int(signs),
                int(kind),
                float(a),
                layout["coords"],
                origin_v,
                float(spacing),
                k,
                float(reach),
                int(field_id),
                values,
                proj,
                source,
            ],
            device,
            balance=True,
        )
    return values, proj, source


def _empty_field_arg(device) -> FieldArg:
    f = FieldArg()
    f.child = wp.empty(0, dtype=wp.int32, device=device)
    f.values = wp.empty(0, dtype=wp.float32, device=device)
    f.proj = wp.empty(0, dtype=wp.vec3h, device=device)
    f.source = wp.empty(0, dtype=wp.int32, device=device)
    f.single_source = -1
    f.codes = wp.empty(0, dtype=wp.int64, device=device)
    f.tri = wp.empty(0, dtype=wp.int32, device=device)
    f.exact = 0
    f.inner_points = 0
    f.lipschitz = 1.0
    f.no_inside = 0
    f.moved = 0
    return f


# ---- public operations ----


def _check_field(field):
    if not callable(getattr(field, "arg", None)) or not hasattr(field, "level_offsets"):
        raise TypeError(f"Expected 'field' to be an AdaptiveField, but got {type(field).__name__}.")


def _grown_nodes(field, grow: float) -> float:
    """Finest nodes of a band like ``field``'s around a surface grown by ``grow`` (areas scale with the box's)."""
    lo, hi = field.bounds
    ext = np.maximum(hi - lo, field.voxel_size)
    area = lambda e: e[0] * e[1] + e[1] * e[2] + e[2] * e[0]  # noqa: E731
    return field.level_counts[0] * area(ext + 2.0 * max(grow, 0.0)) / area(ext)


def _operate(field, kind: int, a: float, grow: float, what: str):
    field = refined(field, view=True)  # built on demand: its whole band (:mod:`.ondemand`)
    if field.placement is not None:  # built in the field's own frame (distances scale with it), then placed
        scale = field.placement.scale
        frame = _operate(field.in_frame(), kind, a / scale, grow / scale, what)
        return frame.transformed(field.placement.matrix)
    h = field.voxel_size
    lo, hi = field.bounds
    # refused before any work: the field's domain holds its surface
    plan_grown(lo, hi, grow, voxel_size=h, levels=field.levels, nodes=_grown_nodes(field, grow), what=what)
    # a closed, clean mesh's field is that mesh's signed distance: read from its triangles (its BVH, kept with it);
    # any other's from the closest points on its own surface, walked (an axis-aligned box grown by 10 voxels: 12 s of
    # walks against 0.4 s)
    exact = field.distance_mesh
    surface = (exact, None, None) if exact is not None else surface_mesh(field)  # (the same after redistancing)
    if surface[0] is None:  # nothing to offset or hollow: nothing comes out
        return _without_surface(field)
    if exact is None and not field.stats.get("surface_points", False):
        field = redistance(field, surface=surface)  # closest points on its own surface
    verts_lo, verts_hi = _surface_box(field)
    origin, top_dims, levels = plan_grown(
        verts_lo, verts_hi, grow, voxel_size=h, levels=field.levels, nodes=_grown_nodes(field, grow), what=what
    )
    mesh = surface[0]  # its surface's triangles bound the distances its closest points give (:func:`surface_distance`)
    grid = {"voxel_size": h, "levels": levels, "origin": origin, "top_dims": top_dims}
    return levelset_field(
        mesh.id, field, kind, a, **grid, field_ids=field.field_ids, device=field.device, cls=type(field),
        exact=exact is not None,
    )  # fmt: skip


def _without_surface(field):
    """What an offset or a shell makes of a field without a surface: the field itself where its finest nodes lie
    inside (all of its domain), else nothing: every node as far out as the domain is across, so that no blend over it
    makes anything either. A boolean of surfaces that do not meet can leave nodes a little below 0 where its finest
    nodes are all above (a closed mesh intersected with a sheet that encloses nothing, chamfered: down to -1.8 voxels,
    the sheet's resampled values); grown, they became a surface with holes."""
    values = field.values.numpy()
    n0 = field.level_counts[0] if field.levels > 1 else len(values)
    if n0 and (values[:n0] < 0.0).all():
        return field
    far = float(np.linalg.norm(field.fine_dims * field.voxel_size))
    return type(field)(
        voxel_size=field.voxel_size, levels=field.levels, origin=field.origin, top_dims=field.top_dims,
        level_offsets=field.level_offsets, codes=field.codes, proj=field.proj, child=field.child, source=field.source,
        values=wp.full(len(values), far, dtype=wp.float32, device=field.device), field_ids=field.field_ids,
        device=field.device, stats=field.stats, sources=field.sources, triangles=field.tri, placement=field.placement,
    )  # fmt: skip


def _surface_box(field):
    """(lo, hi) world box of the finest band (which holds the surface)."""
    n0 = field.level_counts[0]
    if field.levels == 1 or n0 == 0:
        return field.bounds
    c = decode_codes(field.codes[:n0], step=8).numpy()  # each octet: its first node's coordinates plus 0 or 1
    lo = np.array([c[:, k].min() for k in range(3)], dtype=np.float64)
    hi = np.array([c[:, k].max() + 2 for k in range(3)], dtype=np.float64)
    return field.origin + lo * field.voxel_size, field.origin + hi * field.voxel_size


def offset(field, distance):
    """The field grown (``distance > 0``) or shrunk (``< 0``) by ``distance``: the surface of ``S - distance``.

    Any distance the octree can address works, not only one within the finest band: the new band is built around
    the new surface from exact distances to the old one, and the domain grows with an outward offset. Outward,
    edges and corners round with radius ``distance``; inward they stay sharp.

    Args:
        field: AdaptiveField.
        distance: World units; negative shrinks.
    Returns:
        A new AdaptiveField of the same voxel size, a signed distance to its own surface (re-distanced). Shrinking a
        shape away leaves an empty field (``is_empty``, ``to_mesh`` without triangles): not an error.
    Raises:
        TypeError: If ``field`` is not an AdaptiveField or ``distance`` not a number.
        ValueError: If ``distance`` is NaN or infinite.
        AasdfError: If the grown domain is more than the octree can address or would not fit in memory (checked
            before any work).
    """
    _check_field(field)
    d = finite_number("distance", distance)
    return _operate(field, KIND_OFFSET, d, max(d, 0.0), f"An offset of {d:g}")


def shell(field, thickness, *, side: str = "inside"):
    """A hollow version of the field: the solid between its surface and that surface offset by ``thickness``.

    Args:
        field: AdaptiveField.
        thickness: Wall thickness, world units, at least two voxels.
        side: ``"inside"`` (the wall inside the surface, the outside unchanged), ``"outside"`` (around it, the inside
            unchanged) or ``"center"`` (half on each side).
    Returns:
        A new AdaptiveField (re-distanced); for ``"inside"`` of volume V(surface) - V(surface offset by -thickness).
    Raises:
        TypeError: If ``field`` is not an AdaptiveField or ``thickness`` not a number.
        ValueError: If ``thickness`` is not positive and finite, or ``side`` is unknown.
        AasdfError: If the wall would be thinner than two voxels (it would have holes), or the domain too large.
    """
    _check_field(field)
    if side not in SIDES:
        raise ValueError(f"Expected 'side' to be one of {sorted(SIDES)}, but got {side!r}.")
    t = checked_wall("thickness", thickness, field.world_voxel_size)
    kind = SIDES[side]
    grow = t if kind == KIND_OUTSIDE else (0.5 * t if kind == KIND_CENTER else 0.0)
    return _operate(field, kind, t, grow, f"A shell of {t:g}")
