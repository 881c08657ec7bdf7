"""Planning a build before any kernel runs: the domain, the node count it will need, and whether memory allows it.

Every field's domain is snapped to multiples of its top-level spacing measured from one world origin (Ren et al.,
Eq. 3), so fields of the same finest spacing are node-aligned. :func:`plan_field` validates a mesh
(:mod:`.meshcheck`), lays out its domain and bounds the finest nodes from above; :func:`check_meshes` refuses a set of
builds that would not fit in memory together, before any of them starts.
"""

from __future__ import annotations

import os

import numpy as np

from . import octree
from .errors import AasdfError
from .meshcheck import checked_mesh
from .octree import MAX_CELLS_PER_AXIS

# Bytes a finest node costs while building (codes, coords, distances, projections, links, sort buffers).
BUILD_BYTES_PER_NODE = 160


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
    """Validate a build and estimate what it needs, without running any kernel.

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
    if int(levels) != levels or levels < 1:
        raise AasdfError(f"The number of levels must be an integer of at least 1, but got {levels}.")
    if int(padding) != padding or padding < 0:
        raise AasdfError(f"The padding must be a non-negative integer, but got {padding}.")
    levels, padding = int(levels), int(padding)
    verts, tris, area, kept = checked_mesh(vertices, triangles)
    lo = np.array([verts[:, k].min() for k in range(3)])
    hi = np.array([verts[:, k].max() for k in range(3)])
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


def check_meshes(meshes, *, voxel_size, levels=4, padding=1) -> int:
    """Refuse, before any work, a set of builds that is invalid or would not fit in memory together.

    Args:
        meshes: Iterable of (vertices, triangles) pairs.
        voxel_size, levels, padding: As for :func:`build_field`.
    Returns:
        The estimated bytes of all the builds.
    Raises:
        AasdfError: The first invalid mesh (its index in the message), or the total being too large.
    """
    return sum(plan["bytes"] for plan in checked_plans(meshes, voxel_size=voxel_size, levels=levels, padding=padding))


def checked_plans(meshes, *, voxel_size, levels, padding) -> list[dict]:
    """:func:`check_meshes`, returning each mesh's :func:`plan_field`."""
    plans = []
    for k, (verts, tris) in enumerate(meshes):
        try:
            plan = plan_field(verts, tris, voxel_size=voxel_size, levels=levels, padding=padding)
            check_budget(plan["fine_dims"], plan["top_count"], plan["fine_nodes"])
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
