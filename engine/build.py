"""The algebraic adaptive signed distance field of a triangle mesh (Ren et al., Sec. 4), built bottom-up in Warp.

Pipeline of :func:`build_field`:

1. finest level: one thread per triangle lists the octets (parents of finest cells) that a triangle-box test says
   lie within ``padding`` cells of it (Eq. 4-5: whole octets, so every parent gets exactly 8 children), marked in a
   byte per octet (or, for very large grids, all (triangle, octet) pairs radix-sorted), gathered, radix-sorted into
   Morton order, expanded to cells; exact closest points octet by octet (:mod:`.distance`);
2. coarser levels: placed by :func:`.octree.level_layout`, their distances solved bottom-up (:mod:`.distance`);
3. signs, top-down (:mod:`.signs`): inside means generalised winding number >= 0.5;
4. open meshes: the surface across their holes (:mod:`.holes`), before the first build and in refinement rounds.

Sign convention: negative inside, positive outside (Blender/OpenVDB); the paper uses the opposite.
"""

from __future__ import annotations

import os
import sys
import threading
import time

import numpy as np
import warp as wp

from . import distance, geometry, holes, octree, parallel, signs
from .distance import finest_distance_kernel, finest_octet_distance_kernel, take_known_kernel
from .errors import AasdfError
from .field import AdaptiveField
from .geometry import tri_box_overlap
from .holes import cap_lattices, cap_sign_presets, changed_top_cells, sign_change_octets
from .meshcheck import edge_table, hole_caps, problem_faces, weld_positions
from .octree import add_octets, code_bits, in_sorted, level_layout, match_levels, morton_encode
from .plan import byte_grid_fits, check_budget, checked_plans, plan_field
from .signs import (
    MAX_SIGN_SWEEPS,
    NO_BOXES,
    SIGN_SAFETY,
    SIGN_SWEEP_SETTLED,
    TOP_SEED_STRIDE,
    apply_sign_kernel,
    box_arrays,
    mesh_sign_kernel,
    propagate_sign_kernel,
    propagate_sign_octet_kernel,
    take_known_sign_kernel,
)

# Rounds of refining coarse leaves the zero set crosses (open meshes: the surface across a hole).
MAX_SIGN_REFINEMENTS = 4


# Relative error allowed to the closest points of the top level's leaves (0: exact). Far from the surface it is the
# bulk of a query's work (bunny /512: 0.32 s of thread time at 1 %, 0.15 s at 5 %), while the far field's error stays
# the interpolation's (p95 2.79 % exact, 2.85 % at 5 %). A value up to this share above the distance must keep the
# empty balls of the signs within SIGN_SAFETY (a test checks) and widens the booleans' brackets (``LEAF_SLACK``).
TOP_LEVEL_TOLERANCE = 0.05


# Finest octets search their candidate triangles in a box (instead of 8 BVH queries) when the mean triangle area is
# at least this many cell faces (measured break-even about 0.15 on this CPU: the bunny's finest distances take 0.075 s
# node by node against 0.083 s by boxes at 0.10 cell faces per triangle, 0.19 s against 0.145 s at 0.41).
OCTET_SEARCH_MIN_AREA = 0.15


@wp.kernel(enable_backward=False)
def _octets_per_triangle_kernel(
    first: int,
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    origin: wp.vec3,
    octet_size: float,
    pad: float,
    dims: wp.vec3i,
    mask: wp.array[wp.uint8],
    offsets: wp.array[wp.int32],
    emit: int,
    counts: wp.array[wp.int32],
    codes: wp.array[wp.int64],
):
    """Count (emit=0), write (emit=1) or mark in ``mask`` (emit=2, see ``octree.mark_then_compact``) the octets
    within ``pad`` of triangle ``t``."""
    t = first + wp.tid()
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    lo = wp.min(a, wp.min(b, c)) - wp.vec3(pad)
    hi = wp.max(a, wp.max(b, c)) + wp.vec3(pad)
    i0 = wp.vec3i(0)
    i1 = wp.vec3i(0)
    for k in range(3):
        i0[k] = wp.clamp(int(wp.floor((lo[k] - origin[k]) / octet_size)), 0, dims[k] - 1)
        i1[k] = wp.clamp(int(wp.floor((hi[k] - origin[k]) / octet_size)), 0, dims[k] - 1)
    half = wp.vec3(0.5 * octet_size + pad)
    n = int(0)
    base = int(0)
    if emit == 1:
        base = offsets[t]
    for z in range(i0[2], i1[2] + 1):
        for y in range(i0[1], i1[1] + 1):
            for x in range(i0[0], i1[0] + 1):
                cell = wp.vec3i(x, y, z)
                center = origin + octet_size * wp.vec3(float(x) + 0.5, float(y) + 0.5, float(z) + 0.5)
                if emit == 2:
                    # an octet a neighbouring triangle marked already needs no test (races only write 1 twice)
                    m = x + dims[0] * (y + dims[1] * z)
                    if mask[m] == wp.uint8(0):
                        if tri_box_overlap(center, half, a, b, c):
                            mask[m] = wp.uint8(1)
                elif tri_box_overlap(center, half, a, b, c):
                    if emit == 1:
                        codes[base + n] = morton_encode(cell)
                    n += 1
    if emit == 0:
        counts[t] = n


def _device(device):
    return wp.get_device(device)


def build_fields(meshes, *, voxel_size, levels=4, padding=1, device=None, field_ids=None) -> list[AdaptiveField]:
    """Build the fields of several meshes at one voxel size, checked together first (:func:`check_meshes`), so an
    impossible request builds none.

    On the CPU the builds run at the same time, one Python thread each (up to the core count): every build has
    stretches that keep one core busy (sorts, in-place sweeps, small launches), which the other build fills. On
    CUDA they run one after the other.

    Args:
        meshes: Sequence of (vertices, triangles) pairs, as for :func:`build_field`.
        voxel_size, levels, padding, device: As for :func:`build_field`.
        field_ids: One id per mesh (default 0, 1, 2, ...).
    Returns:
        One AdaptiveField per mesh, in order.
    Raises:
        ValueError, AasdfError: As :func:`check_meshes` and :func:`build_field`; messages about one mesh start with
            "Mesh <k>: ".
    """
    meshes = list(meshes)
    field_ids = list(range(len(meshes))) if field_ids is None else [int(k) for k in field_ids]
    if len(field_ids) != len(meshes):
        raise ValueError(f"build_fields got {len(field_ids)} field ids for {len(meshes)} meshes")
    plans = checked_plans(meshes, voxel_size=voxel_size, levels=levels, padding=padding)
    device = _device(device)
    fields: list = [None] * len(meshes)
    errors: dict = {}

    def build(k):
        try:
            fields[k] = _build_planned(plans[k], device=device, field_id=field_ids[k])
        except AasdfError as err:
            errors[k] = AasdfError(f"Mesh {k}: {err}")
            errors[k].__cause__ = err
        except Exception as err:  # noqa: BLE001 (re-raised below, in the caller's thread)
            errors[k] = err

    if device.is_cuda or len(meshes) < 2:
        for k in range(len(meshes)):
            build(k)
            if k in errors:
                raise errors[k]
        return fields
    for module in (octree, distance, signs, holes, sys.modules[__name__]):  # the modules a build launches
        wp.load_module(module, device=device)  # compiled or loaded once, before the threads
    workers = min(len(meshes), os.cpu_count() or 1)
    # worker w builds meshes w, w + workers, ...
    parallel.run_tasks([lambda w=w: [build(k) for k in range(w, len(meshes), workers)] for w in range(workers)], device)
    if errors:
        raise errors[min(errors)]
    return fields


def build_field(vertices, triangles, *, voxel_size, levels=4, padding=1, device=None, field_id=0) -> AdaptiveField:
    """Build the adaptive signed distance field of a triangle mesh.

    Args:
        vertices: (V, 3) world-space vertex positions.
        triangles: (T, 3) integer vertex indices. Open, multi-shell, flipped or duplicated faces are handled:
            inside means generalised winding number >= 0.5.
        voxel_size: Edge length of the finest cells.
        levels: Number of levels, finest to dense top (>= 1).
        padding: Finest cells kept around each triangle (>= 0; 1 or more gives watertight surfaces).
        device: Warp device (``None``: Warp's default).
        field_id: Integer id carried per node through booleans (see ``source_ids``).
    Returns:
        AdaptiveField, negative inside.
    Raises:
        ValueError: On wrongly shaped or typed arguments.
        AasdfError: On empty, non-finite or fully degenerate meshes, out-of-range indices, non-positive voxel
            size, ``levels < 1``, ``padding < 0``, or a resolution that would not fit in memory.
    """
    plan = plan_field(vertices, triangles, voxel_size=voxel_size, levels=levels, padding=padding)
    check_budget(plan["fine_dims"], plan["top_count"], plan["fine_nodes"])
    return _build_planned(plan, device=device, field_id=field_id)


def _build_planned(plan: dict, *, device, field_id: int) -> AdaptiveField:
    """:func:`build_field` of a checked :func:`plan_field`."""
    verts, tris, origin, top_dims = plan["vertices"], plan["triangles"], plan["origin"], plan["top_dims"]
    fine_dims, top_count = plan["fine_dims"], plan["top_count"]
    voxel_size, levels, padding = plan["voxel_size"], plan["levels"], plan["padding"]
    octet = 2.0 * voxel_size
    device = _device(device)

    timings = {}
    t0 = time.perf_counter()
    # the BVH builds while the mesh checks and the cell enumeration run: on the CPU on a thread of its own (Warp's
    # native build releases the GIL)
    made = {}

    def make_mesh():
        try:
            made["mesh"] = wp.Mesh(
                points=wp.array(verts, dtype=wp.vec3, device=device),
                indices=wp.array(tris.reshape(-1), dtype=wp.int32, device=device),
                support_winding_number=True,
            )
        except Exception as err:  # noqa: BLE001 (re-raised in the caller's thread)
            made["error"] = err

    builder = threading.Thread(target=make_mesh) if device.is_cpu else None
    if builder is not None:
        builder.start()
    else:
        make_mesh()
    edges = edge_table(tris, len(verts))
    problem = problem_faces(tris, len(verts), edges)
    clean = not bool(problem.any())
    caps = None
    if not clean:
        # the checks are about the surface, not its indexing: seams that repeat a vertex at one position (UV or patch
        # seams) open edges only in the index, so they are judged on the mesh with those vertices merged
        seam_verts, seam_tris = weld_positions(verts, tris)
        if len(seam_verts) == len(verts):
            seam_verts, seam_tris = verts, tris  # nothing merged: keep the indexing the edge table has
        else:
            edges = edge_table(seam_tris, len(seam_verts))
            problem = problem_faces(seam_tris, len(seam_verts), edges)
            clean = not bool(problem.any())
        caps = None if clean else hole_caps(seam_verts, seam_tris, edges)
    diag = float(np.linalg.norm(fine_dims * voxel_size))
    # candidate triangles per octet grow as cell area / triangle area: search boxes only where that stays small
    box_search = int(float(plan["areas"].mean()) >= OCTET_SEARCH_MIN_AREA * voxel_size**2)
    timings["mesh_checks"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if levels == 1:
        base_octets = None  # the dense top level is the finest
    else:
        oct_dims = wp.vec3i(*(int(d) for d in fine_dims // 2))
        verts_wp = wp.array(verts, dtype=wp.vec3, device=device)
        tris_wp = wp.array(tris, dtype=wp.int32, device=device)
        args = [verts_wp, tris_wp, wp.vec3(*origin), octet, padding * voxel_size, oct_dims]
        end_bit = 3 * code_bits(fine_dims // 2)
        if byte_grid_fits(fine_dims // 2):
            base_octets = octree.mark_then_compact(
                _octets_per_triangle_kernel,
                len(tris),
                args,
                fine_dims // 2,
                device,
                end_bit=end_bit,
                check=lambda total: check_budget(fine_dims, top_count, 8 * total),
            )
        else:
            octet_codes = octree.count_then_emit(
                _octets_per_triangle_kernel,
                len(tris),
                [*args, wp.empty(0, dtype=wp.uint8, device=device)],  # no mask
                device,
                check=lambda total: check_budget(fine_dims, top_count, min(8 * total, plan["fine_nodes"]), pairs=total),
            )
            base_octets = octree.sort_unique(octet_codes, end_bit=end_bit)
    timings["finest_cells"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if builder is not None:
        builder.join()
    timings["mesh_bvh"] = time.perf_counter() - t0  # what is left of the BVH build once the cells are found
    if "error" in made:
        raise made["error"]
    mesh = made["mesh"]
    lattices = None
    if caps is not None and levels > 1:
        # the surface across the holes, found before the first build instead of by a refinement round after it
        t0 = time.perf_counter()
        lattices = cap_lattices(mesh.id, caps, origin, fine_dims // 2, octet, base_octets.shape[0], device)
        if lattices is not None:
            band = base_octets.numpy()
            sheet = lattices["sheet"][~in_sorted(band, lattices["sheet"])]  # where the band does not hold it already
            if len(sheet):
                check_budget(fine_dims, top_count, 8 * len(band) + 8 * 27 * len(sheet))
                base_octets = add_octets(base_octets, sheet, fine_dims // 2, end_bit=3 * code_bits(fine_dims // 2))
        timings["cap_lattices"] = time.perf_counter() - t0

    def oracle(coords, nodes_np, spacing, sign):
        if len(nodes_np) == 0:
            return
        nodes = wp.array(nodes_np.astype(np.int32), dtype=wp.int32, device=device)
        origin_v = wp.vec3(*origin)
        parallel.launch_split(
            mesh_sign_kernel,
            len(nodes_np),
            lambda lo, n: [mesh.id, coords, nodes[lo : lo + n], origin_v, float(spacing), sign],
            device,
            min_dim=parallel.EMIT_SPLIT_MIN_DIM,  # a winding number costs microseconds: split from a few thousand
            balance=True,  # winding numbers cost most near holes, which a Morton-ordered list bunches
        )

    def finest_signs(coords, sign, lo0, hi0):
        # Undecided finest nodes lie within about half a voxel of the surface, where the pseudo-normal sign is wrong
        # near open edges and where shells intersect or touch: they pay the winding number.
        idx = lo0 + np.flatnonzero(sign.numpy()[lo0:hi0] == 0.0)
        oracle(coords, idx, voxel_size, sign)
        return len(idx)

    def build(octets, query_radius, previous=None):
        # every node's place first, so each level's values are computed where they are kept
        layout = level_layout(octets, top_dims, levels, device, timings)
        t0 = time.perf_counter()
        n, n0 = int(layout["offsets"][-1]), int(layout["offsets"][1])
        fine_codes, fine_coords = layout["codes"][:n0], layout["coords"][:n0]
        dist = wp.empty(n, dtype=wp.float32, device=device)
        proj = wp.empty(n, dtype=wp.vec3, device=device)
        source = wp.empty(n, dtype=wp.int32, device=device)
        dist0, proj0, src0 = dist[:n0], proj[:n0], source[:n0]
        # Octets an earlier build of this mesh already has keep their closest points; only new ones are queried.
        first_nodes = np.arange(0, n0, 8)
        if previous is not None:
            where = match_levels(fine_codes, [0, n0], previous)
            no_known = wp.empty(0, dtype=wp.int32, device=device)
            parallel.launch_split(
                take_known_kernel,
                n0,
                lambda s, _n: [s, where, previous.values, previous.proj, previous.source, no_known, dist0, proj0, src0],
                device,
            )
            first_nodes = 8 * np.flatnonzero(where.numpy()[::8] < 0)  # matched octet by octet
        src0.fill_(int(field_id))
        origin_v = wp.vec3(*origin)
        if octets is not None:
            # octet by octet, in place
            octet_nodes = wp.array(first_nodes.astype(np.int32), dtype=wp.int32, device=device)
            octet_dist = wp.full(n0 // 8, geometry.UNSET_DISTANCE, dtype=wp.float32, device=device)
            octet_proj = wp.empty(n0 // 8, dtype=wp.vec3, device=device)
            octet_points = (octet_dist, octet_proj)
            parallel.launch_split(
                finest_octet_distance_kernel,
                len(first_nodes),
                lambda lo, n: [
                    lo,
                    mesh.id,
                    fine_coords,
                    octet_nodes,
                    origin_v,
                    voxel_size,
                    float(query_radius),
                    diag,
                    dist0,
                    proj0,
                    octet_dist,
                    octet_proj,
                    box_search,
                ],
                device,
                min_dim=parallel.EMIT_SPLIT_MIN_DIM,
                balance=True,  # octets near an open mesh's holes, or far from it, cost more
            )
        else:  # a single dense level: node by node
            octet_points = None
            parallel.launch_split(
                finest_distance_kernel,
                n0,
                lambda lo, n: [
                    mesh.id,
                    fine_coords[lo : lo + n],
                    origin_v,
                    voxel_size,
                    float(query_radius),
                    diag,
                    int(field_id),
                    dist0[lo : lo + n],
                    proj0[lo : lo + n],
                    src0[lo : lo + n],
                ],
                device,
            )
        timings["finest_distance"] = timings.get("finest_distance", 0.0) + time.perf_counter() - t0
        return assemble_field(
            origin=origin,
            top_dims=top_dims,
            voxel_size=voxel_size,
            levels=levels,
            layout=layout,
            dist=dist,
            proj=proj,
            source=source,
            known_signs=previous,
            oracle=oracle,
            finest_signs=finest_signs,
            device=device,
            field_ids=(field_id,),
            timings=timings,
            mesh_id=mesh.id,
            octet_points=octet_points,
            hole_caps=caps,
            sign_presets=None if lattices is None else lambda layout: cap_sign_presets(lattices, layout, levels),
        )

    # a band node lies within (padding + 1) cells (L-inf) of a triangle; misses fall back to the domain diagonal
    near_radius = diag if levels == 1 else (padding + 2) * voxel_size * 1.75
    field = build(base_octets, near_radius)
    # Across a hole of an open mesh the inside/outside boundary (winding number 0.5) runs away from any triangle,
    # through coarse leaves. Refine those leaves to the finest level so the surface there can be extracted too. A
    # closed, consistently oriented mesh (even a self-intersecting one) changes its winding number only across its
    # triangles, which the finest level covers: nothing to check.
    rounds = 0
    refine_seconds = 0.0
    region = None
    while levels > 1 and not clean and rounds < MAX_SIGN_REFINEMENTS:
        t_refine = time.perf_counter()
        # off the caps over the holes the winding number stays near an integer (see hole_caps): the zero set can
        # only leave the band near them (no caps: the edges cancel, it never does)
        extra = sign_change_octets(field, caps if caps is not None else NO_BOXES, region)
        refine_seconds += time.perf_counter() - t_refine
        if len(extra) == 0:
            break
        rounds += 1
        region = changed_top_cells(extra, top_dims, levels)
        check_budget(fine_dims, top_count, field.level_counts[0] + 8 * 27 * len(extra))
        t0 = time.perf_counter()
        base_octets = add_octets(base_octets, extra, fine_dims // 2, end_bit=3 * code_bits(fine_dims // 2))
        timings["finest_cells"] += time.perf_counter() - t0
        queries = field.stats["sign_queries"]
        field = build(base_octets, near_radius, previous=field)
        field.stats["sign_queries"] = {k: v + queries.get(k, 0) for k, v in field.stats["sign_queries"].items()}
    field.stats["sign_refinements"] = rounds
    field.timings["sign_check"] = refine_seconds
    field.stats["clean_mesh"] = clean
    field.stats["problem_faces"] = int(problem.sum())
    field._mesh = mesh  # keeps the BVH alive for callers that want exact queries
    return field


def assemble_field(
    *,
    origin,
    top_dims,
    voxel_size,
    levels,
    layout,
    dist,
    proj,
    source,
    oracle,
    finest_signs,
    device,
    field_ids,
    timings,
    mesh_id=0,
    level_values=None,
    spread_signs=True,
    known_signs=None,
    hole_caps=None,
    octet_points=None,
    fine_values=None,
    sign_presets=None,
):
    """Solve the intermediate and top levels above a finest level and sign every node (shared by construction
    and booleans).

    ``layout``: every node's place (:func:`level_layout`); ``dist``/``proj`` (unsigned distances and projection
    points) and ``source``: one entry per node, the finest level's filled in. Signs are assigned top-down:
    ``oracle(coords, nodes, spacing, sign)`` writes the sign of the given nodes of one level; ``finest_signs(coords,
    sign, lo, hi)`` decides the finest nodes the parent left undecided. When ``fine_values`` (one entry per node, the
    finest level's signed values filled in) is given the finest level keeps those values (and the array becomes the
    field's values). When ``level_values(coords, lo,
    hi, spacing, dist, proj, source, sign)`` is given (booleans: the operands are sampled), it sets every coarse
    node's distance, projection, source and sign directly, in place of the FIM solve and the sign oracles.
    ``spread_signs`` lets signs spread between same-level neighbours; ``hole_caps`` (boxes lo, boxes hi, radii, from
    :func:`hole_caps`) keeps them from spreading near an open mesh's holes. ``octet_points`` (distances, closest
    points) of the finest octets' centres, where the finest level's computation found them: the level-1 nodes there.
    ``known_signs``: an earlier field of the same mesh and domain whose nodes' signs are reused where nodes match.
    ``sign_presets(layout)``: (signs (N,) float32, 0 where undecided; no_inherit (N,) uint8, nodes that must not take
    their parent's sign) set before the top-down pass (see :func:`cap_sign_presets`).
    """
    top_dims = np.asarray(top_dims, dtype=np.int64)
    fine_dims = top_dims * 2 ** (levels - 1)
    codes, coords, offsets = layout["codes"], layout["coords"], layout["offsets"]
    child, parent = layout["child"], layout["parent"]
    n, n0 = int(offsets[-1]), int(offsets[1])
    # same-level neighbours of the coarse nodes (node i in row i - n0): the finest level finds its own by octet, and
    # booleans sample their operands instead of solving
    neighbours = wp.full((n - n0 if level_values is None else 0, 6), -1, dtype=wp.int32, device=device)
    # Coarse nodes an earlier build of the same mesh and domain has keep their distances (refinement rounds).
    known = wp.zeros(n, dtype=wp.int32, device=device)
    # each node's index in the earlier build (-1: new), shared by distances and signs
    prev_index = match_levels(codes, offsets, known_signs) if known_signs is not None else None
    if known_signs is not None and level_values is None:
        parallel.launch_split(
            take_known_kernel,
            n - n0,
            lambda s, _n: [
                n0 + s,
                prev_index,
                known_signs.values,
                known_signs.proj,
                known_signs.source,
                known,
                dist,
                proj,
                source,
            ],
            device,
        )
    sweeps = {}
    origin_t = tuple(float(x) for x in origin)
    sign = wp.zeros(n, dtype=wp.float32, device=device)
    no_inherit = wp.empty(0, dtype=wp.uint8, device=device)
    if sign_presets is not None:
        preset, flags = sign_presets(layout)
        sign = wp.array(preset, dtype=wp.float32, device=device)
        no_inherit = wp.array(flags, dtype=wp.uint8, device=device)
    for k in range(1, levels):
        tk = time.perf_counter()
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        name = "top_level" if k == levels - 1 else f"level_{k}"
        if level_values is not None:
            level_values(coords, lo, hi, voxel_size * 2**k, dist, proj, source, sign)
            timings[name] = timings.get(name, 0.0) + time.perf_counter() - tk
            continue
        octree.level_neighbours(coords, lo, hi, fine_dims >> k, neighbours, row0=n0)
        tn = time.perf_counter()
        sweeps[k] = distance.solve_level(
            coords,
            child,
            neighbours,
            lo,
            hi,
            origin_t,
            voxel_size * 2**k,
            dist,
            proj,
            source,
            mesh_id=mesh_id,
            known=known,
            octet_points=octet_points if k == 1 else None,
            row0=n0,
            ordered_sweeps=k == levels - 1,  # the dense top level: far from the surface, information travels far
            tolerance=TOP_LEVEL_TOLERANCE if k == levels - 1 else 0.0,
        )
        timings[f"{name}_neighbours"] = timings.get(f"{name}_neighbours", 0.0) + tn - tk
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - tk

    # Signs, top-down: the top level from a sparse set of oracle seeds, every lower level from its parents; then
    # within each level from already signed neighbours (empty balls again); the oracle only for what is left.
    t0 = time.perf_counter()
    if known_signs is not None:
        parallel.launch_split(
            take_known_sign_kernel, n, lambda s, _n: [s, prev_index, known_signs.values, sign], device
        )
    top_lo, top_hi = int(offsets[levels - 1]), int(offsets[levels])
    oracle_counts = {}
    sign_sweeps = {}
    origin_v = wp.vec3(*origin_t)

    cap_args = box_arrays(hole_caps, device)

    def spread(k, lo, hi):
        if not spread_signs:
            return lo + np.flatnonzero(sign.numpy()[lo:hi] == 0.0)
        changed = wp.zeros(1, dtype=wp.int32, device=device)
        # the finest level first spreads by empty balls alone, then (with a mesh) across segments that cross no
        # triangle, which costs a box query each and so runs only once the cheap test is exhausted
        phases = [0, int(mesh_id)] if mesh_id else [0]
        sweeps = {}
        for phase_mesh in phases:
            for sweep in range(MAX_SIGN_SWEEPS):  # noqa: B007 (the count is kept)
                changed.zero_()
                if k == 0:
                    # in place from two threads: a sign only ever goes from unset to final, so races are harmless
                    parallel.launch_split(
                        propagate_sign_octet_kernel,
                        (hi - lo) // 8,
                        lambda start, span, phase_mesh=phase_mesh, sweep=sweep: [
                            start,
                            codes,
                            parent,
                            child,
                            neighbours,
                            n0,
                            dist,
                            sign,
                            SIGN_SAFETY * 1.0,
                            float(voxel_size),
                            origin_v,
                            *cap_args,
                            wp.uint64(phase_mesh),
                            changed,
                            span,
                            sweep % 2,
                        ],
                        device,
                    )
                else:
                    # split the same way (racing increments from two threads still leave ``changed`` nonzero)
                    parallel.launch_split(
                        propagate_sign_kernel,
                        hi - lo,
                        lambda start, span, phase_mesh=phase_mesh, sweep=sweep: [
                            neighbours,
                            n0,
                            lo + start,
                            dist,
                            sign,
                            SIGN_SAFETY,
                            float(voxel_size * 2**k),
                            coords,
                            origin_v,
                            *cap_args,
                            wp.uint64(phase_mesh),
                            changed,
                            span,
                            sweep % 2,
                        ],
                        device,
                    )
                got = int(changed.numpy()[0])
                if got == 0:
                    break
                if phase_mesh != phases[-1] and (k == 0 or got < SIGN_SWEEP_SETTLED * (hi - lo)):
                    # the empty balls have settled (on the finest level one in-place sweep leaves a handful): the
                    # segments' phase signs the few nodes another sweep over the whole level would
                    break
            sweeps[phase_mesh] = sweep + 1
        sign_sweeps[k] = (sweeps[0], sweeps.get(int(mesh_id), 0))
        return lo + np.flatnonzero(sign.numpy()[lo:hi] == 0.0)

    if level_values is None and levels > 1:
        # Across a hole of an open mesh the sign changes where no triangle is near, so empty balls prove nothing
        # near it: signs spread only away from the holes' caps (``hole_caps``), the oracle decides the rest.
        stride = TOP_SEED_STRIDE if spread_signs else 1
        nx, ny, nz = (int(d) for d in top_dims)
        ix, iy, iz = (np.arange(min(stride // 2, n_axis - 1), n_axis, stride) for n_axis in (nx, ny, nz))
        seeds = top_lo + (ix[None, None, :] + nx * (iy[None, :, None] + ny * iz[:, None, None])).ravel()
        seeds = seeds[sign.numpy()[seeds] == 0.0]
        oracle(coords, seeds, voxel_size * 2 ** (levels - 1), sign)
        rest = spread(levels - 1, top_lo, top_hi)
        oracle(coords, rest, voxel_size * 2 ** (levels - 1), sign)
        oracle_counts[levels - 1] = len(seeds) + len(rest)
    for k in range(levels - 2, -1, -1) if level_values is None else ():
        lo, hi = int(offsets[k]), int(offsets[k + 1])
        parallel.launch_split(
            signs.inherit_sign_kernel,
            hi - lo,
            lambda start, _n, k=k, lo=lo: [
                coords,
                parent,
                lo + start,
                origin_v,
                voxel_size * 2**k,
                dist,
                sign,
                SIGN_SAFETY,
                no_inherit,
            ],
            device,
        )
        if k > 0:
            idx = spread(k, lo, hi)
            oracle(coords, idx, voxel_size * 2**k, sign)
            oracle_counts[k] = len(idx)
    if fine_values is None:
        if levels > 1:
            spread(0, 0, n0)
        oracle_counts[0] = finest_signs(coords, sign, 0, n0)
    if fine_values is None:
        values = wp.empty(n, dtype=wp.float32, device=device)
        parallel.launch_split(apply_sign_kernel, n, lambda start, _n: [start, dist, sign, values], device)
    else:  # the finest values are in place already
        values = fine_values
        parallel.launch_split(apply_sign_kernel, n - n0, lambda start, _n: [n0 + start, dist, sign, values], device)
    timings["signs"] = timings.get("signs", 0.0) + time.perf_counter() - t0

    return AdaptiveField(
        voxel_size=voxel_size,
        levels=levels,
        origin=origin,
        top_dims=top_dims,
        level_offsets=offsets,
        codes=codes,
        coords=coords,
        values=values,
        proj=proj,
        child=child,
        source=source,
        field_ids=field_ids,
        device=device,
        timings=timings,
        stats={"fim_sweeps": sweeps, "sign_queries": oracle_counts, "sign_sweeps": sign_sweeps},
    )
