"""The algebraic adaptive signed distance field of a triangle mesh (Ren et al., Sec. 4), built bottom-up in Warp.

Pipeline of :func:`build_field`:

1. finest level: one thread per triangle lists the octets (parents of finest cells) that a triangle-box test says
   lie within ``padding`` cells of it (Eq. 4-5: whole octets, so every parent gets exactly 8 children), marked in a
   byte per octet (or, for very large grids, all (triangle, octet) pairs radix-sorted), gathered, radix-sorted into
   Morton order, expanded to cells; exact closest points octet by octet (:mod:`.distance`);
2. coarser levels: placed by :func:`.layout.level_layout`, their distances solved bottom-up (:mod:`.distance`);
3. signs, top-down (:mod:`.signs`): inside means |w| >= 1/2, w the generalised winding number, decided exactly where
   the fast one is not sure (:mod:`.winding`);
4. open meshes: the surface across their holes (:mod:`.holes`), before the first build and in refinement rounds.

Sign convention: negative inside, positive outside (Blender/OpenVDB); the paper uses the opposite.
"""

from __future__ import annotations

import sys
import threading
import time

import numpy as np
import warp as wp

from . import distance, fieldops, fim, holes, octree, parallel, redistancing, search, signs, sweeping, winding
from .errors import AasdfError
from .field import AdaptiveField
from .geometry import tri_box_overlap
from .holes import cap_lattices
from .levels import LevelBuilder, finished, refined_across_holes
from .meshcheck import edge_table, encloses_nothing, hole_boundary, problem_faces, weld_positions
from .octree import add_octets, code_bits, in_sorted, morton_decode, morton_encode
from .ondemand import partial_build
from .plan import byte_grid_fits, check_budget, checked_plans, grown_domain, plan_field, thick_plan, thicknesses
from .selfcross import crossing_pairs
from .winding import winding_arg

# Finest octets search their candidate triangles in a box (instead of 8 BVH queries) when the mean triangle area is
# at least this many cell faces (measured break-even about 0.15 on this CPU: the bunny's finest distances take 0.075 s
# node by node against 0.083 s by boxes at 0.10 cell faces per triangle, 0.19 s against 0.145 s at 0.41).
OCTET_SEARCH_MIN_AREA = 0.15

# ``refine="auto"`` builds a field on demand from this many finest nodes per triangle of its band on: kept faces of
# booleans along their seams took 0.7x the full builds' time at 54 (the cow at /256; a fifth of its finest octets
# built), 1.1-1.3x at 10-16 (the rocker arm, the fandisk), where the triangles' sides off the mesh (2 winding numbers
# each, about 2 us) cost more than the finest nodes not built save (about 0.2 us each).
ON_DEMAND_NODES_PER_TRIANGLE = 24

# Triangles of all meshes above which build_fields builds one mesh after the other (see there).
SEQUENTIAL_TRIANGLES = 1_000_000


@wp.func
def _slab_extent(a: wp.vec3, b: wp.vec3, c: wp.vec3, u: int, v: int, v_lo: float, v_hi: float):
    """(lowest, highest) coordinate ``u`` of triangle (a, b, c) where its coordinate ``v`` lies in [v_lo, v_hi]: over
    its corners inside that slab and its edges' crossings of the slab's two sides ((1e30, -1e30) where it misses the
    slab)."""
    u_lo = float(1.0e30)
    u_hi = float(-1.0e30)
    for e in range(3):
        p = a
        q = b
        if e == 1:
            p = b
            q = c
        elif e == 2:
            p = c
            q = a
        if p[v] >= v_lo and p[v] <= v_hi:
            u_lo = wp.min(u_lo, p[u])
            u_hi = wp.max(u_hi, p[u])
        for side in range(2):
            line = wp.where(side == 0, v_lo, v_hi)
            if (p[v] - line) * (q[v] - line) < 0.0:
                at = p[u] + (line - p[v]) / (q[v] - p[v]) * (q[u] - p[u])
                u_lo = wp.min(u_lo, at)
                u_hi = wp.max(u_hi, at)
    return u_lo, u_hi


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
    # Columns along the axis the triangle's normal leans on most: a column meets the slab of boxes that can touch
    # the triangle's plane in a few cells, where the whole box of a large or slanted triangle holds tens of thousands
    # (a superset of what the plane test below keeps, so the octets found are the same).
    normal = wp.cross(b - a, c - a)
    k = int(0)
    if wp.abs(normal[1]) > wp.abs(normal[k]):
        k = 1
    if wp.abs(normal[2]) > wp.abs(normal[k]):
        k = 2
    u = (k + 1) % 3
    v = (k + 2) % 3
    # (a box of a few cells along k, as most triangles of a fine mesh have, or a degenerate triangle: the whole box)
    columns = i1[k] - i0[k] >= 2 and wp.abs(normal[k]) > 1.0e-6 * wp.length(normal)
    plane = wp.dot(normal, a)
    # within a column the plane's k moves by at most this across a box's extent in u and v, and the box spans half
    # more; a thousandth of a cell more for rounding
    reach = float(0.0)
    if columns:
        reach = (wp.abs(normal[u]) + wp.abs(normal[v])) * half[0] / wp.abs(normal[k]) + half[0] + 1.0e-3 * octet_size
    n = int(0)
    base = int(0)
    if emit == 1:
        base = offsets[t]
    slack = 1.0e-3 * octet_size  # a thousandth of a cell more for rounding
    for iv in range(i0[v], i1[v] + 1):
        # the row's boxes meet the triangle only where the slab of v they span (grown by ``half``) does: its u-extent
        # there bounds the row (a long slanted triangle crosses a few boxes of each row of its bounding box)
        cv = origin[v] + octet_size * (float(iv) + 0.5)
        u_lo, u_hi = _slab_extent(a, b, c, u, v, cv - half[0] - slack, cv + half[0] + slack)
        iu0 = wp.max(i0[u], int(wp.ceil((u_lo - half[0] - slack - origin[u]) / octet_size - 0.5)))
        iu1 = wp.min(i1[u], int(wp.floor((u_hi + half[0] + slack - origin[u]) / octet_size - 0.5)))
        for iu in range(iu0, iu1 + 1):
            k0 = i0[k]
            k1 = i1[k]
            if columns:
                cu = origin[u] + octet_size * (float(iu) + 0.5)
                cv = origin[v] + octet_size * (float(iv) + 0.5)
                at = (plane - normal[u] * cu - normal[v] * cv) / normal[k]
                k0 = wp.max(k0, int(wp.ceil((at - reach - origin[k]) / octet_size - 0.5)))
                k1 = wp.min(k1, int(wp.floor((at + reach - origin[k]) / octet_size - 0.5)))
            for ik in range(k0, k1 + 1):
                cell = wp.vec3i(0)
                cell[k] = ik
                cell[u] = iu
                cell[v] = iv
                x = cell[0]
                y = cell[1]
                z = cell[2]
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


def build_fields(
    meshes, *, voxel_size, levels=4, padding=1, device=None, field_ids=None, thickness=None, refine="all"
) -> list[AdaptiveField]:
    """Build the fields of several meshes at one voxel size, checked together first (:func:`check_meshes`), so an
    impossible request builds none.

    On the CPU the builds run at the same time, one Python thread each (up to the core count): every build has
    stretches that keep one core busy (sorts, in-place sweeps, small launches), which the other build fills. On
    CUDA, and for meshes of more than ``SEQUENTIAL_TRIANGLES`` triangles in all, they run one after the other (each
    on every core): a build's peak memory grows with its triangles (Warp's BVH with its winding-number data, about
    130 bytes a triangle, the mesh checks), and two such peaks at once would add up.

    Args:
        meshes: Sequence of (vertices, triangles) pairs, as for :func:`build_field`.
        voxel_size, levels, padding, device: As for :func:`build_field`.
        refine: As for :func:`build_field`: one value for every mesh, or one per mesh.
        field_ids: One id per mesh (default 0, 1, 2, ...).
        thickness: As for :func:`build_field`: one value for every mesh, or one per mesh (None: none).
    Returns:
        One AdaptiveField per mesh, in order.
    Raises:
        ValueError, AasdfError: As :func:`check_meshes` and :func:`build_field`; messages about one mesh start with
            "Mesh <k>: ".
    """
    meshes = list(meshes)
    refine = list(refine) if isinstance(refine, list | tuple) else [refine] * len(meshes)
    refine = [_checked_refine(r) for r in refine]
    field_ids = list(range(len(meshes))) if field_ids is None else [int(k) for k in field_ids]
    if len(field_ids) != len(meshes):
        raise ValueError(f"build_fields got {len(field_ids)} field ids for {len(meshes)} meshes")
    if len(refine) != len(meshes):
        raise ValueError(f"build_fields got {len(refine)} refine values for {len(meshes)} meshes")
    plans = checked_plans(meshes, voxel_size=voxel_size, levels=levels, padding=padding, thickness=thickness)
    device, fields = _device(device), [None] * len(meshes)
    errors: dict = {}

    def build(k):
        try:
            fields[k] = _build_planned(plans[k], device=device, field_id=field_ids[k], refine=refine[k])
        except AasdfError as err:
            errors[k] = AasdfError(f"Mesh {k}: {err}")
            errors[k].__cause__ = err
        except Exception as err:  # noqa: BLE001 (re-raised below, in the caller's thread)
            errors[k] = err

    triangles = sum(len(plan["triangles"]) for plan in plans)
    if device.is_cuda or len(meshes) < 2 or triangles > SEQUENTIAL_TRIANGLES:
        for k in range(len(meshes)):
            build(k)
            if k in errors:
                raise errors[k]
        return fields
    # the modules a build launches (a thick one: those of the field operations too), compiled or loaded once,
    # before the threads
    launched = (octree, distance, fim, winding, signs, holes, sys.modules[__name__])
    if any(plan.get("thickness") is not None for plan in plans):  # loading hashes a module's kernels: only if needed
        launched += (fieldops, sweeping, redistancing)
    parallel.load_modules(launched, device)
    workers = min(len(meshes), parallel.cores())
    # worker w builds meshes w, w + workers, ...
    parallel.run_tasks([lambda w=w: [build(k) for k in range(w, len(meshes), workers)] for w in range(workers)], device)
    if errors:
        raise errors[min(errors)]
    return fields


def build_field(
    vertices, triangles, *, voxel_size, levels=4, padding=1, device=None, field_id=0, thickness=None, refine="all"
) -> AdaptiveField:
    """Build the adaptive signed distance field of a triangle mesh.

    Args:
        vertices: (V, 3) world-space vertex positions.
        triangles: (T, 3) integer vertex indices. Open, multi-shell, flipped or duplicated faces are handled:
            inside means |w| >= 1/2, w the generalised winding number, whatever the orientation (an inside-out
            closed mesh is the same solid; a shell facing inward inside another is a cavity). A flat surface
            that encloses nothing (a plane, a single triangle, a flat sheet) gives a field with no inside
            (``encloses_volume`` False, ``to_mesh()`` empty) and ``stats["flat"]`` True.
        voxel_size: Edge length of the finest cells.
        levels: Number of levels, finest to dense top (>= 1; from 2, raised while the dense top level would have
            more than ``plan.TOP_LEVEL_CELLS`` cells).
        padding: Finest cells kept around each triangle (1 or more: the surface's cubes need their nodes).
        device: Warp device (``None``: Warp's default).
        field_id: Integer id carried per node through booleans (see ``source_ids``).
        thickness: Give the surface this thickness (world units, at least two voxels): the field is the solid
            shell of half-width ``thickness / 2`` around the triangles (their unsigned distance minus half the
            thickness), so surfaces that enclose nothing (planes, cloth, single-sided scans) become solids; a closed
            mesh becomes a hollow shell centred on its surface. None: the mesh's own inside.
        refine: ``"all"``: the finest level about every triangle; ``"none"``: every level above it, the finest
            octets built when a query, a surface or a boolean needs them (:mod:`.ondemand`; a mesh that encloses a
            volume, of three levels or more: others are built whole); ``"auto"``: on demand where the band is large
            for the triangles (ON_DEMAND_NODES_PER_TRIANGLE) and the mesh does not pass through itself.
    Returns:
        AdaptiveField, negative inside.
    Raises:
        ValueError: On wrongly shaped or typed arguments, or an unknown ``refine``.
        AasdfError: On empty, non-finite or fully degenerate meshes, out-of-range indices, non-positive voxel
            size, ``levels < 1``, ``padding < 0``, a resolution that would not fit in memory, or a thickness under
            two voxels.
    """
    wall = thicknesses(thickness, 1, voxel_size)[0]
    plan = plan_field(vertices, triangles, voxel_size=voxel_size, levels=levels, padding=padding)
    check_budget(plan["fine_dims"], plan["top_count"], plan["fine_nodes"])
    return _build_planned(thick_plan(plan, wall), device=device, field_id=field_id, refine=_checked_refine(refine))


def _checked_refine(refine) -> str:
    if refine not in ("all", "none", "auto"):
        raise ValueError(f"Expected 'refine' to be 'all', 'none' or 'auto', but got {refine!r}.")
    return refine


def _on_demand(refine: str, band, plan: dict, mesh, device) -> bool:
    """Whether a mesh's field is built on demand: asked (``"none"``), or ``"auto"`` where its band holds at least
    ON_DEMAND_NODES_PER_TRIANGLE finest nodes per triangle (what it saves grows with the nodes, what it costs a kept
    surface with the triangles: their sides off the mesh's winding number) and the mesh does not pass through itself
    (a boolean that keeps faces reads such a mesh's own field everywhere: built whole at once, not refined whole
    later; its crossing pairs, searched on the build's BVH, cost under 1 us a triangle)."""
    if refine != "auto":
        return refine == "none"
    if 8 * band.shape[0] < ON_DEMAND_NODES_PER_TRIANGLE * len(plan["triangles"]):
        return False
    return not len(crossing_pairs(plan["vertices"], plan["triangles"], device, mesh=mesh))


def _build_thick(plan: dict, *, device, field_id: int) -> AdaptiveField:
    """The shell of ``plan["thickness"]`` around a mesh's triangles (:func:`.fieldops.levelset_field` of their
    unsigned distance)."""
    t0 = time.perf_counter()
    mesh = wp.Mesh(
        points=wp.array(plan["vertices"], dtype=wp.vec3, device=device),
        indices=wp.array(plan["triangles"].reshape(-1), dtype=wp.int32, device=device),
    )
    seconds = time.perf_counter() - t0
    field = fieldops.levelset_field(
        mesh.id,
        None,
        fieldops.KIND_CENTER,
        plan["thickness"],
        voxel_size=plan["voxel_size"],
        levels=plan["levels"],
        origin=plan["origin"],
        top_dims=plan["top_dims"],
        field_ids=(field_id,),
        device=device,
        cls=AdaptiveField,
    )
    field.timings["mesh_bvh"] = seconds
    field.stats["thickness"] = plan["thickness"]
    return field


def _build_planned(plan: dict, *, device, field_id: int, refine: str = "all") -> AdaptiveField:
    """:func:`build_field` of a checked :func:`plan_field`: the steps of the module docstring; an open mesh's built
    again on a grown domain where its inside reaches the domain's edge (:data:`DOMAIN_GROWTH_ROUNDS`)."""
    device = _device(device)
    if plan.get("thickness") is not None:
        return _build_thick(plan, device=device, field_id=field_id)
    field = _build_mesh(plan, device=device, field_id=field_id, refine=refine)
    for _ in range(DOMAIN_GROWTH_ROUNDS):
        caps = field.stats.get("hole_caps")
        sides = None if caps is None else inside_at_edges(field)
        grown = None if sides is None or not sides.any() else grown_domain(plan, sides, _growth(plan, caps))
        if grown is None:
            break
        plan, field = grown, _build_mesh(grown, device=device, field_id=field_id, refine=refine)
    return field


# An open mesh's inside (where its winding number passes 1/2) can reach past its bounding box across its holes: two
# open tubes side by side, overlapping, add their winding numbers past their ends, where the inside bulged 8 voxels
# out of the domain (/128: cut there, the surface came out open). Its domain is grown on the sides reached, by the
# largest hole's radius (at least a top cell), this many times at most.
DOMAIN_GROWTH_ROUNDS = 3


def _growth(plan: dict, caps) -> float:
    """How far a domain is grown on a side an open mesh's inside reaches: its largest hole's radius, at least a top
    cell."""
    return max(float(np.max(caps[2])) if len(caps[2]) else 0.0, plan["voxel_size"] * 2 ** (plan["levels"] - 1))


@wp.kernel(enable_backward=False)
def _edge_sides_kernel(
    codes: wp.array[wp.int64],
    values: wp.array[wp.float32],
    first: int,
    dims: wp.vec3i,
    below: float,
    sides: wp.array[wp.uint8],
):
    """Per node ``first + tid`` of a level of ``dims``: the sides of the domain (bits: low x, y, z, high x, y, z) on
    whose outer layer it lies where its value is under ``below``, else 0."""
    i = first + wp.tid()
    out = int(0)
    if values[i] < below:
        c = morton_decode(codes[i])
        for a in range(3):
            if c[a] == 0:
                out = out | (1 << a)
            if c[a] == dims[a] - 1:
                out = out | (8 << a)
    sides[wp.tid()] = wp.uint8(out)


def inside_at_edges(field) -> np.ndarray:
    """(6,) bool: the sides of ``field``'s domain (low x, y, z, then high x, y, z) its inside reaches, where the
    surface would run out of the domain (which counts as outside): a finest node of the outer layer inside, or a
    coarser one deeper inside than its centre lies from the domain's edge (a coarse node's value a little under 0 says
    the surface passes near it: the bunny's and the beetle's top levels at /64-/256, 0.09-0.71 voxel, surfaces
    closed)."""
    offsets, found = np.asarray(field.level_offsets), 0
    for level in range(field.levels):
        n = int(offsets[level + 1] - offsets[level])
        dims = np.asarray(field.top_dims, dtype=np.int64) * 2 ** (field.levels - 1 - level)
        below = 0.0 if level == 0 else -float(field.voxel_size) * 2 ** (level - 1)
        sides = wp.empty(n, dtype=wp.uint8, device=field.device)
        args = [field.codes, field.values, int(offsets[level]), wp.vec3i(*(int(d) for d in dims)), below, sides]
        wp.launch(_edge_sides_kernel, dim=n, inputs=args, device=field.device)
        found |= int(np.bitwise_or.reduce(sides.numpy())) if n else 0
    return (found >> np.arange(6)) & 1 == 1


def _build_mesh(plan: dict, *, device, field_id: int, refine: str = "all") -> AdaptiveField:
    """A mesh's field on the domain ``plan`` gives (no wall)."""
    timings = {}
    t0 = time.perf_counter()
    bvh = _MeshBuild(plan["vertices"], plan["triangles"], device)  # on a thread of its own while the checks run
    facts = _mesh_facts(plan, device)
    timings["mesh_checks"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    base_octets = _finest_octets(plan, device)
    timings["finest_cells"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    mesh = bvh.result()
    timings["mesh_bvh"] = time.perf_counter() - t0  # what is left of the BVH build once the cells are found
    search_mesh = _search_mesh(plan, facts["frame"], mesh, device, timings)
    winding = winding_arg(mesh, facts["boundary"], device, encloses=facts["encloses"])
    base_octets = _with_cap_sheets(plan, facts["caps"], winding, base_octets, device, timings)
    levels = LevelBuilder(plan, facts, mesh, search_mesh, winding, device, field_id, timings)
    if facts["encloses"] and plan["levels"] > 2 and _on_demand(refine, base_octets, plan, mesh, device):
        finish = lambda f, band: finished(f, plan, facts, mesh, field_id, band)  # noqa: E731
        across = (
            None if facts["clean"] else lambda f, octets: refined_across_holes(levels, f, octets, plan, facts, winding)
        )  # noqa: E731
        return partial_build(levels, base_octets, finish, across)
    field = levels.build(base_octets)
    field = refined_across_holes(levels, field, base_octets, plan, facts, winding)
    return finished(field, plan, facts, mesh, field_id)


class _MeshBuild:
    """The mesh's BVH (with winding-number data), built on a thread of its own on the CPU (Warp's native build
    releases the GIL) while the mesh checks and the cell enumeration run; :meth:`result` waits for it."""

    def __init__(self, verts, tris, device):
        self.verts, self.tris, self.device, self.made = verts, tris, device, {}
        self.thread = threading.Thread(target=self.make) if device.is_cpu else None
        if self.thread is not None:
            self.thread.start()
        else:
            self.make()

    def make(self):
        try:
            self.made["mesh"] = wp.Mesh(
                points=wp.array(self.verts, dtype=wp.vec3, device=self.device),
                indices=wp.array(self.tris.reshape(-1), dtype=wp.int32, device=self.device),
                support_winding_number=True,
            )
        except Exception as err:  # noqa: BLE001 (re-raised in the caller's thread)
            self.made["error"] = err

    def result(self) -> wp.Mesh:
        if self.thread is not None:
            self.thread.join()
        if "error" in self.made:
            raise self.made["error"]
        return self.made["mesh"]


def _mesh_facts(plan: dict, device) -> dict:
    """What the build needs to know of the mesh: ``clean`` (closed, consistently oriented, manifold), ``problem``
    (T,) its problem faces, ``boundary`` (its holes, None when clean), ``encloses`` (False for a flat sheet),
    ``caps`` (the surfaces across its holes, or None), ``diag``, ``mean_area``, and how the octets search it
    (``box_search``, ``frame``, ``thin``: :mod:`.search`)."""
    verts, tris, voxel_size = plan["vertices"], plan["triangles"], plan["voxel_size"]
    edges = edge_table(tris, len(verts))
    problem = problem_faces(tris, len(verts), edges)
    clean = not bool(problem.any())
    boundary = None
    encloses = True
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
        boundary = None if clean else hole_boundary(seam_verts, seam_tris, edges)
        # a flat sheet (a plane, a triangle) encloses nothing: no winding number needed, no surface across its holes
        encloses = not encloses_nothing(seam_verts, boundary)
    # candidate triangles per octet grow as cell area / triangle area: search boxes only where that stays small
    mean_area = float(plan["areas"].mean())
    box_search = mean_area >= OCTET_SEARCH_MIN_AREA * voxel_size**2
    octet = 2.0 * voxel_size
    return {
        "clean": clean,
        "problem": problem,
        "boundary": boundary,
        "encloses": encloses,
        "caps": None if boundary is None or not encloses else boundary["caps"],
        "diag": float(np.linalg.norm(plan["fine_dims"] * voxel_size)),
        "mean_area": mean_area,
        "box_search": box_search,
        # the octets search a turned copy of a mesh whose slanted parts have loose bounding boxes (a turned cylinder)
        "frame": search.search_frame(verts, tris, octet, device) if box_search and plan["levels"] > 1 else None,
        # the triangles the octets' capsule test is for
        "thin": search.slivers(verts, tris, voxel_size, device) if box_search else None,
    }


def _finest_octets(plan: dict, device):
    """The sorted Morton codes of the finest level's octets (None for a single dense level: it is the finest), by
    :func:`_octets_per_triangle_kernel`: marked in a byte grid where one fits, else listed and sorted."""
    if plan["levels"] == 1:
        return None
    verts, tris, fine_dims, top_count = plan["vertices"], plan["triangles"], plan["fine_dims"], plan["top_count"]
    voxel_size = plan["voxel_size"]
    oct_dims = wp.vec3i(*(int(d) for d in fine_dims // 2))
    verts_wp = wp.array(verts, dtype=wp.vec3, device=device)
    tris_wp = wp.array(tris, dtype=wp.int32, device=device)
    args = [verts_wp, tris_wp, wp.vec3(*plan["origin"]), 2.0 * voxel_size, plan["padding"] * voxel_size, oct_dims]
    end_bit = 3 * code_bits(fine_dims // 2)
    if byte_grid_fits(fine_dims // 2):
        return octree.mark_then_compact(
            _octets_per_triangle_kernel,
            len(tris),
            args,
            fine_dims // 2,
            device,
            end_bit=end_bit,
            check=lambda total: check_budget(fine_dims, top_count, 8 * total),
        )
    octet_codes = octree.count_then_emit(
        _octets_per_triangle_kernel,
        len(tris),
        [*args, wp.empty(0, dtype=wp.uint8, device=device)],  # no mask
        device,
        check=lambda total: check_budget(fine_dims, top_count, min(8 * total, plan["fine_nodes"]), pairs=total),
    )
    return octree.sort_unique(octet_codes, end_bit=end_bit)


def _search_mesh(plan: dict, frame, mesh, device, timings: dict):
    """The mesh the octets search: ``mesh`` itself, or its copy turned by ``frame``."""
    if frame is None:
        return mesh
    t0 = time.perf_counter()
    turned = wp.Mesh(
        points=wp.array((plan["vertices"] @ frame.T).astype(np.float32), dtype=wp.vec3, device=device),
        indices=wp.array(plan["triangles"].reshape(-1), dtype=wp.int32, device=device),
    )
    timings["search_frame"] = time.perf_counter() - t0
    return turned


def _with_cap_sheets(plan: dict, caps, winding, base_octets, device, timings: dict):
    """``base_octets`` with the octets of the surface across an open mesh's holes (``caps``), found before the first
    build instead of by a refinement round after it."""
    if caps is None or plan["levels"] == 1:
        return base_octets
    t0 = time.perf_counter()
    fine_dims = plan["fine_dims"]
    octet = 2.0 * plan["voxel_size"]
    lattices = cap_lattices(winding, caps, plan["origin"], fine_dims // 2, octet, base_octets.shape[0], device)
    if lattices is not None:
        band = base_octets.numpy()
        sheet = lattices["sheet"][~in_sorted(band, lattices["sheet"])]  # where the band does not hold it already
        if len(sheet):
            check_budget(fine_dims, plan["top_count"], 8 * len(band) + 8 * 27 * len(sheet))
            base_octets = add_octets(base_octets, sheet, fine_dims // 2, end_bit=3 * code_bits(fine_dims // 2))
    timings["cap_lattices"] = time.perf_counter() - t0
    return base_octets
