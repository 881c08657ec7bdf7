"""Planning a build before any kernel runs: the domain, the node count it will need, and whether memory allows it.

Every field's domain is snapped to multiples of its top-level spacing measured from one world origin (Ren et al.,
Eq. 3), so fields of the same finest spacing are node-aligned. :func:`plan_field` validates a mesh
(:mod:`.meshcheck`), lays out its domain and bounds the finest nodes from above; :func:`check_meshes` refuses a set of
builds that would not fit in memory together, before any of them starts. :func:`plan_grown` lays out the domain of a
surface grown by an offset or a thickness, and refuses one the octree cannot address.
"""

from __future__ import annotations

import ctypes
import math
import numbers
import os
import sys

import numpy as np

from . import octree
from .errors import AasdfError
from .meshcheck import checked_mesh
from .octree import MAX_CELLS_PER_AXIS

# Bytes a finest node costs while building (codes, coords, distances, projections, links, sort buffers).
BUILD_BYTES_PER_NODE = 160


# Surfaces are refused so far from the world origin that float32 resolves less than this fraction of a cell there.
MIN_ULPS_PER_CELL = 32.0

# Voxels smaller than this (world units) are refused: the kernels' float32 products of several lengths underflow
# (a 2e-7 block minus a bore at voxel 6.4e-9 came out open, at 1.6e-8 closed but no quad kept whole; 6.4e-8 as at 1).
MIN_VOXEL_SIZE = 5e-8
# Finest cells kept around the domain's content, as a build keeps them (padding 1 + 2).
MARGIN_CELLS = 3

# A mesh's field gets a level more than asked while its dense top level would have more cells than this: each top
# leaf's closest point is searched (spot at /1024 with 4 levels: 239 k top cells, 0.23 s of a 0.52 s build; with 5,
# 32 k). Below about /700 four levels stay four; the nodes near the surface are the same whatever the levels.
TOP_LEVEL_CELLS = 1 << 16
# (the add-on's most)
MAX_LEVELS = 12


# The thinnest wall (shell, thickness) in voxels: thinner ones leave holes where the surface's two sides share a cell.
MIN_WALL_VOXELS = 2.0


# Blocks from this size up are mapped from the system and given back to it when freed (glibc's M_MMAP_THRESHOLD, set
# fixed). Left alone, glibc raises the threshold to the largest block freed so far (up to 32 MB), after which a stage's
# temporaries stay in its heap, fragmented, beside the next stage's arrays: spot | spot at /1024, a second run in the
# same process, peaked 1,195-1,244 MB, and 1,008-1,031 MB with this; at /512 480-498 -> 414-422 MB. The cost: big
# arrays are mapped and faulted in afresh instead of reused from the heap, a warm /512 pipeline 1.11 -> 1.19 s and
# warm /512 builds 3-11 % slower (none measured at /1024, where glibc maps most arrays anyway; 8 MB kept 459-470 MB
# at /512). Warp's arrays from 1 MB up no longer pay it: they take the pages of freed ones (:mod:`.hostpool`).
MMAP_THRESHOLD = 4 * 2**20
_M_MMAP_THRESHOLD = -3  # mallopt's parameter number (malloc.h)


def tune_allocator() -> bool:
    """Fix the C allocator's mmap threshold at MMAP_THRESHOLD where it is glibc's (Linux; elsewhere nothing changes):
    large arrays go back to the system as soon as they are freed. The environment variable AASDF_MMAP_THRESHOLD_MB
    sets another threshold (0: leave the allocator as it is). Returns whether it was set."""
    threshold = int(float(os.environ.get("AASDF_MMAP_THRESHOLD_MB", MMAP_THRESHOLD / 2**20)) * 2**20)
    if threshold <= 0 or not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt  # the process's C library (Blender's too: it allocates Warp's arrays)
    except (OSError, AttributeError):
        return False
    return bool(mallopt(ctypes.c_int(_M_MMAP_THRESHOLD), ctypes.c_int(threshold)))


def available_memory() -> int:
    """Bytes of memory available to this process (best effort, 8 GiB when the platform does not say)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return 8 * 2**30


def plan_domain(lo, hi, voxel_size: float, levels: int, margin_cells: float):
    """Domain origin (snapped to the shared world origin at the top spacing, Eq. 3) and top-level dims."""
    top = voxel_size * 2 ** (levels - 1)
    margin = margin_cells * voxel_size
    origin = np.floor((np.asarray(lo, np.float64) - margin) / top) * top
    dims = np.maximum(np.ceil((np.asarray(hi, np.float64) + margin - origin) / top).astype(np.int64), 1)
    return origin, dims


def check_voxel_size(spacing: float) -> None:
    """Refuse (AasdfError) a finest spacing below MIN_VOXEL_SIZE world units."""
    if spacing < MIN_VOXEL_SIZE:
        raise AasdfError(
            f"The voxel size {spacing:.3g} is below {MIN_VOXEL_SIZE:g}, where float32 products of lengths underflow "
            "and surfaces come out open. Scale the objects up (Scene Units' Unit Scale keeps their displayed size) "
            "or use a coarser resolution (a larger voxel size)."
        )


def check_resolvable(lo, hi, spacing: float) -> float:
    """The float32 resolution (ulp) of world positions in the box ``lo``..``hi``; refused (AasdfError) where it is
    coarser than 1/MIN_ULPS_PER_CELL of ``spacing``: surfaces there would fall onto float32's grid."""
    extent = float(np.abs([np.asarray(lo, np.float64), np.asarray(hi, np.float64)]).max())
    ulp = float(np.spacing(np.float32(extent)))
    if not np.isfinite(extent) or ulp * MIN_ULPS_PER_CELL > spacing:
        raise AasdfError(
            f"The surface lies too far from the world origin for its voxel size: float32 positions {extent:.4g} "
            f"away resolve only {ulp:.3g}, more than 1/{MIN_ULPS_PER_CELL:g} of the voxel size {spacing:.3g}. "
            "Move the objects closer to the origin or use a coarser resolution (a larger voxel size)."
        )
    return ulp


def check_budget(fine_dims, top_count, fine_nodes_estimate, pairs=0):
    """Refuse domains the Morton codes cannot address and node counts that would not fit in memory (``pairs``:
    (triangle, octet) codes to sort before de-duplication, about 32 bytes each with the sort buffers)."""
    if np.any(np.asarray(fine_dims) >= MAX_CELLS_PER_AXIS):
        raise AasdfError(
            f"The domain spans {int(np.max(fine_dims))} finest cells along an axis, more than the "
            f"{MAX_CELLS_PER_AXIS - 1} the octree can address; use a larger voxel size."
        )
    need = max((int(fine_nodes_estimate) + int(top_count)) * BUILD_BYTES_PER_NODE, 32 * int(pairs))
    budget = available_memory() // 2
    if need > budget:
        raise AasdfError(
            f"This voxel size needs about {need / 2**30:.1f} GiB ({int(fine_nodes_estimate):,} finest "
            f"nodes), more than the {budget / 2**30:.1f} GiB that can be used; use a larger voxel size."
        )


def byte_grid_fits(dims) -> bool:
    """Whether a dense grid of one byte per cell over ``dims`` is small enough to use (``octree.MASK_MAX_CELLS``, and
    an eighth of the memory available)."""
    cells = int(np.prod(np.asarray(dims, dtype=np.int64)))
    return cells <= min(octree.MASK_MAX_CELLS, available_memory() // 8)


def plan_field(vertices, triangles, *, voxel_size, levels=4, padding=1) -> dict:
    """Validate a build and estimate what it needs, without running any kernel. ``levels`` (2 or more) is raised
    until the dense top level has at most ``TOP_LEVEL_CELLS`` cells.

    Returns:
        dict with the cleaned ``vertices``/``triangles``, the domain (``origin``, ``top_dims``, ``fine_dims``,
        ``top_count``), an upper bound of the finest nodes (``fine_nodes``) and of the bytes the build needs
        (``bytes``), and the triangles' ``areas``.
    Raises:
        ValueError, AasdfError: As :func:`build_field` does for bad input.
    """
    voxel_size = float(voxel_size)
    if not np.isfinite(voxel_size) or voxel_size <= 0.0:
        raise AasdfError(f"The voxel size must be a positive number, but got {voxel_size}.")
    check_voxel_size(voxel_size)
    if int(levels) != levels or levels < 1:
        raise AasdfError(f"The number of levels must be an integer of at least 1, but got {levels}.")
    if int(padding) != padding or padding < 1:  # (with none, cubes the surface crosses lack nodes: it comes out open)
        raise AasdfError(f"The padding must be an integer of at least 1, but got {padding}.")
    levels, padding = int(levels), int(padding)
    verts, tris, area, kept = checked_mesh(vertices, triangles)
    lo = np.array([verts[:, k].min() for k in range(3)])
    hi = np.array([verts[:, k].max() for k in range(3)])
    origin, top_dims = plan_domain(lo, hi, voxel_size, levels, padding + 2)
    while levels > 1 and levels < MAX_LEVELS and int(np.prod(top_dims)) > TOP_LEVEL_CELLS:
        levels += 1  # a level more than asked where the dense top would be large (fine voxels): nothing near changes
        origin, top_dims = plan_domain(lo, hi, voxel_size, levels, padding + 2)
    fine_dims = top_dims * 2 ** (levels - 1)
    # Upper bound of finest nodes: every triangle's padded AABB in octets, capped by a surface-area estimate for
    # large triangles.
    octet = 2.0 * voxel_size
    v64 = verts.astype(np.float64)
    box_count = np.ones(len(tris))
    for k in range(3):
        a, b, c = (v64[tris[:, m], k] for m in range(3))
        ext = (np.maximum(np.maximum(a, b), c) - np.minimum(np.minimum(a, b), c) + 2.0 * padding * voxel_size) / octet
        box_count *= np.ceil(ext + 1.0) + 1.0
    area_count = (np.sqrt(area) / octet + 2.0 + padding) ** 2 * (3.0 + padding)
    per_triangle = 8.0 * float(np.minimum(box_count, area_count).sum())
    # Many small triangles share their octets: the band around the whole surface (both sides, padding plus octet
    # rounding, a 1.5x margin) and the dense domain bound it too.
    band = 1.5 * 2.0 * (padding + 2) * float(area.sum()) / voxel_size**2
    fine_nodes = min(per_triangle, band, float(np.prod(fine_dims))) if levels > 1 else float(np.prod(fine_dims))
    top_count = int(np.prod(top_dims))
    return {
        "vertices": verts,
        "triangles": tris,
        "voxel_size": voxel_size,
        "levels": levels,
        "padding": padding,
        "origin": origin,
        "top_dims": top_dims,
        "fine_dims": fine_dims,
        "top_count": top_count,
        "fine_nodes": fine_nodes,
        "bytes": int((fine_nodes + top_count) * BUILD_BYTES_PER_NODE),
        "areas": area,
        "triangle_ids": kept,
    }


def grown_domain(plan: dict, sides: np.ndarray, reach: float) -> dict | None:
    """``plan`` with its domain grown by ``reach`` on the ``sides`` (6,) bool (low x, y, z, then high x, y, z) that
    an open mesh's inside reaches (:func:`.build.inside_at_edges`), snapped as :func:`plan_domain` snaps it; None where
    the grown domain is more than the octree can address or than memory allows (the plan as it was stands)."""
    top = plan["voxel_size"] * 2 ** (plan["levels"] - 1)
    lo = np.asarray(plan["origin"], np.float64)
    hi = lo + np.asarray(plan["top_dims"], np.float64) * top
    lo, hi = lo - np.where(sides[:3], reach, 0.0), hi + np.where(sides[3:], reach, 0.0)
    origin = np.floor(lo / top) * top  # (already a margin past the mesh on every side: none added)
    top_dims = np.maximum(np.ceil((hi - origin) / top - 1e-9).astype(np.int64), 1)
    fine_dims = top_dims * 2 ** (plan["levels"] - 1)
    try:
        check_budget(fine_dims, int(np.prod(top_dims)), plan["fine_nodes"])
    except AasdfError:
        return None
    return {**plan, "origin": origin, "top_dims": top_dims, "fine_dims": fine_dims, "top_count": int(np.prod(top_dims))}


def finite_number(name: str, value) -> float:
    """``value`` as a float: a number (TypeError) and finite (ValueError)."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"Expected a number for '{name}', but got {type(value).__name__}.") from None
    if not math.isfinite(value):
        raise ValueError(f"Expected a finite '{name}', but got {value}.")
    return value


def checked_wall(name: str, value, voxel_size: float) -> float:
    """A thickness: positive and finite (ValueError), at least ``MIN_WALL_VOXELS`` voxels (AasdfError)."""
    value = finite_number(name, value)
    if value <= 0.0:
        raise ValueError(f"Expected a positive '{name}', but got {value}.")
    if value < MIN_WALL_VOXELS * voxel_size:
        raise AasdfError(
            f"A {name} of {value:g} is thinner than two voxels ({MIN_WALL_VOXELS * voxel_size:g}) and would leave "
            f"holes; use a {name} of at least {MIN_WALL_VOXELS * voxel_size:g}, or a smaller voxel size."
        )
    return value


def plan_grown(lo, hi, grow: float, *, voxel_size: float, levels: int, nodes: float, what: str):
    """(origin, top_dims, levels) of a domain around the box ``lo``-``hi`` grown by ``grow`` on every side, refused
    (AasdfError) when the octree cannot address it or its ``nodes`` finest nodes would not fit in memory. More levels
    keep the dense top level about as large as the box's when the domain grows much."""
    lo = np.asarray(lo, np.float64) - grow
    hi = np.asarray(hi, np.float64) + grow
    span = float(np.max(hi - lo)) / voxel_size + 2 * MARGIN_CELLS
    if not span < MAX_CELLS_PER_AXIS - 1:
        raise AasdfError(
            f"{what} needs a domain of {span:.0f} finest cells along an axis, more than the {MAX_CELLS_PER_AXIS - 1} "
            "the octree can address; use a smaller distance or a larger voxel size."
        )
    base = float(np.max(hi - lo - 2.0 * grow)) / voxel_size + 2 * MARGIN_CELLS
    levels = int(levels) + max(0, int(math.floor(math.log2(max(span / max(base, 1.0), 1.0)))))
    while levels > 1 and 2 ** (levels - 1) > span:  # a top cell no larger than the domain
        levels -= 1
    origin, top_dims = plan_domain(lo, hi, voxel_size, levels, MARGIN_CELLS)
    check_budget(top_dims * 2 ** (levels - 1), int(np.prod(top_dims)), nodes)
    return origin, top_dims, levels


def check_meshes(meshes, *, voxel_size, levels=4, padding=1, thickness=None) -> int:
    """Refuse, before any work, a set of builds that is invalid or would not fit in memory together.

    Args:
        meshes: Iterable of (vertices, triangles) pairs.
        voxel_size, levels, padding, thickness: As for :func:`build_fields`.
    Returns:
        The estimated bytes of all the builds.
    Raises:
        ValueError: If ``thickness`` is not None, a number or one per mesh, or not positive and finite.
        AasdfError: The first invalid mesh (its index in the message), or the total being too large.
    """
    plans = checked_plans(meshes, voxel_size=voxel_size, levels=levels, padding=padding, thickness=thickness)
    return sum(plan["bytes"] for plan in plans)


def thicknesses(thickness, count: int, voxel_size) -> list:
    """One thickness (or None) per mesh from ``thickness``: None, a number for every mesh, or one per mesh
    (:func:`checked_wall` each)."""
    if thickness is None or np.ndim(thickness) == 0:
        thickness = [thickness] * count
    thickness = list(thickness)
    if len(thickness) != count:
        raise ValueError(f"Expected one thickness per mesh ({count}), but got {len(thickness)}.")
    return [None if t is None else checked_wall("thickness", t, float(voxel_size)) for t in thickness]


def thick_plan(plan: dict, thickness) -> dict:
    """``plan`` for the shell of ``thickness`` around its mesh's triangles: the domain grown by half the thickness,
    refused (AasdfError) when the octree cannot address it or it would not fit in memory; ``plan`` itself for None."""
    if thickness is None:
        return plan
    verts = plan["vertices"]
    nodes = 2.0 * plan["fine_nodes"]  # the band runs along both sides of the surface
    origin, top_dims, levels = plan_grown(
        verts.min(axis=0),
        verts.max(axis=0),
        0.5 * thickness,
        voxel_size=plan["voxel_size"],
        levels=plan["levels"],
        nodes=nodes,
        what=f"A thickness of {thickness:g}",
    )
    top_count = int(np.prod(top_dims))
    return {
        **plan,
        "thickness": thickness,
        "origin": origin,
        "top_dims": top_dims,
        "levels": levels,
        "fine_dims": top_dims * 2 ** (levels - 1),
        "top_count": top_count,
        "fine_nodes": nodes,
        "bytes": int((nodes + top_count) * BUILD_BYTES_PER_NODE),
    }


def checked_plans(meshes, *, voxel_size, levels, padding, thickness=None) -> list[dict]:
    """:func:`check_meshes`, returning each mesh's :func:`plan_field` (:func:`thick_plan` where it has a thickness)."""
    meshes = list(meshes)
    if isinstance(voxel_size, numbers.Real) and voxel_size > 0.0:  # (the voxel's fault: said before a mesh is named)
        check_voxel_size(float(voxel_size))
    walls = thicknesses(thickness, len(meshes), voxel_size)
    plans = []
    for k, (verts, tris) in enumerate(meshes):
        try:
            plan = plan_field(verts, tris, voxel_size=voxel_size, levels=levels, padding=padding)
            check_budget(plan["fine_dims"], plan["top_count"], plan["fine_nodes"])
            plan = thick_plan(plan, walls[k])
        except AasdfError as err:
            raise AasdfError(f"Mesh {k}: {err}") from err
        plans.append(plan)
    total = sum(plan["bytes"] for plan in plans)
    budget = available_memory() // 2
    if total > budget:
        raise AasdfError(
            f"These fields need about {total / 2**30:.1f} GiB together, more than the {budget / 2**30:.1f} GiB "
            "that can be used; use a larger voxel size."
        )
    return plans
