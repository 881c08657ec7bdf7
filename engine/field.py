"""The adaptive field type: a hierarchical sparse octree of signed distances, its queries and its surface.

An :class:`AdaptiveField` is what every build and boolean returns and what every boolean takes: levels stored finest
first in one set of arrays (Morton codes, coordinates, values, closest points, child links, source ids). Queries
descend from the dense top level to a leaf and interpolate by moving least squares (:mod:`.sampling`); ``to_mesh``
extracts the zero surface from the finest band (:mod:`.extract`); ``|``, ``&`` and ``-`` are the booleans
(:mod:`.boolean`).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import boolean, parallel
from .errors import AasdfError
from .extract import extract_octree_level, extract_surface
from .plan import available_memory
from .sampling import FieldArg, sample_field_kernel, source_ids_kernel


class AdaptiveField:
    """A hierarchical sparse octree of signed distances (negative inside), closed under booleans.

    Levels are stored finest first and concatenated; ``level_offsets[k]:level_offsets[k+1]`` is level ``k``.
    Intermediate levels are sorted by Morton code; the top level is dense in x-fastest order.
    """

    def __init__(
        self,
        *,
        voxel_size,
        levels,
        origin,
        top_dims,
        level_offsets,
        codes,
        coords,
        values,
        proj,
        child,
        source,
        field_ids,
        device,
        timings=None,
        stats=None,
    ):
        self.voxel_size = float(voxel_size)
        self.levels = int(levels)
        self.origin = np.asarray(origin, dtype=np.float64)
        self.top_dims = np.asarray(top_dims, dtype=np.int64)
        self.level_offsets = np.asarray(level_offsets, dtype=np.int64)
        self.codes, self.coords, self.values, self.proj = codes, coords, values, proj
        self.child, self.source = child, source
        self.field_ids = tuple(sorted(set(int(i) for i in field_ids)))
        self.device = device
        self.timings = dict(timings or {})
        self.stats = dict(stats or {})

    @classmethod
    def from_layout(
        cls, layout: dict, *, voxel_size, origin, values, proj, source, field_ids, timings=None, stats=None
    ):
        """The field whose nodes are placed by ``layout`` (:func:`.octree.level_layout`: codes, coordinates, level
        offsets, child links, top-level dims) with these (N,) node arrays: ``values`` float32 signed distances,
        ``proj`` vec3 closest surface points, ``source`` int32 ids of the operand each node's value came from."""
        offsets = np.asarray(layout["offsets"], dtype=np.int64)
        return cls(
            voxel_size=voxel_size,
            levels=len(offsets) - 1,
            origin=origin,
            top_dims=layout["top_dims"],
            level_offsets=offsets,
            codes=layout["codes"],
            coords=layout["coords"],
            values=values,
            proj=proj,
            child=layout["child"],
            source=source,
            field_ids=field_ids,
            device=values.device,
            timings=timings,
            stats=stats,
        )

    def relabel(self, field_id: int) -> AdaptiveField:
        """This field with every node's source id ``field_id``: a new field sharing every other array (the field
        itself when it already has that id alone)."""
        field_id = int(field_id)
        if self.field_ids == (field_id,):
            return self
        source = wp.full(self.source.shape[0], field_id, dtype=wp.int32, device=self.source.device)
        relabelled = AdaptiveField.from_layout(
            {
                "offsets": self.level_offsets,
                "top_dims": self.top_dims,
                "codes": self.codes,
                "coords": self.coords,
                "child": self.child,
            },
            voxel_size=self.voxel_size,
            origin=self.origin,
            values=self.values,
            proj=self.proj,
            source=source,
            field_ids=(field_id,),
            timings=self.timings,
            stats=self.stats,
        )
        return relabelled

    # -- geometry of the domain --
    @property
    def top_spacing(self) -> float:
        return self.voxel_size * 2 ** (self.levels - 1)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) corners of the domain, world space."""
        return self.origin.copy(), self.origin + self.top_dims * self.top_spacing

    @property
    def fine_dims(self) -> np.ndarray:
        return self.top_dims * 2 ** (self.levels - 1)

    @property
    def node_count(self) -> int:
        return int(self.level_offsets[-1])

    @property
    def level_counts(self) -> list[int]:
        return [int(n) for n in np.diff(self.level_offsets)]

    @property
    def is_empty(self) -> bool:
        """Whether the field encloses nothing: no node inside (an offset that shrank a shape away; ``to_mesh`` then
        has no triangles)."""
        return not bool((self.values.numpy() < 0.0).any())

    @property
    def field_id(self) -> int:
        return self.field_ids[0]

    def level_slice(self, level: int) -> slice:
        return slice(int(self.level_offsets[level]), int(self.level_offsets[level + 1]))

    def arg(self) -> FieldArg:
        f = FieldArg()
        f.origin = wp.vec3(*self.origin)
        f.voxel_size = self.voxel_size
        f.levels = self.levels
        f.top_dims = wp.vec3i(*(int(d) for d in self.top_dims))
        f.top_offset = int(self.level_offsets[self.levels - 1])
        lo, hi = self.bounds
        f.domain_min = wp.vec3(*lo)
        f.domain_max = wp.vec3(*hi)
        f.coords, f.child, f.values, f.source, f.proj = self.coords, self.child, self.values, self.source, self.proj
        f.codes = self.codes
        f.fine_count = int(self.level_offsets[1])
        f.exact = int(bool(self.stats.get("exact_distance", False)))
        return f

    def __repr__(self) -> str:
        return (
            f"AdaptiveField(voxel_size={self.voxel_size:g}, levels={self.levels}, nodes={self.node_count}, "
            f"level_counts={self.level_counts}, ids={list(self.field_ids)})"
        )

    # -- queries --
    def sample(self, points, method: str = "mls", *, return_gradient: bool = False):
        """Signed distance at world-space points.

        Args:
            points: (N, 3) array-like of world-space points.
            method: ``"mls"`` (moving least squares, Eq. 9-10) or ``"linear"`` (trilinear, for comparison).
            return_gradient: Also return the (N, 3) float32 MLS gradient.
        Returns:
            (N,) float32 signed distances, negative inside; outside the domain never below the distance to it.
        Raises:
            ValueError: If ``points`` is not (N, 3) or ``method`` is unknown.
        """
        pts = _as_points(points)
        if method not in ("mls", "linear"):
            raise ValueError(f"Expected 'method' to be 'mls' or 'linear', but got {method!r}.")
        n = len(pts)
        values = wp.empty(n, dtype=wp.float32, device=self.device)
        grads = wp.empty(n, dtype=wp.vec3, device=self.device)
        if n:
            arg, pts_wp, mode = self.arg(), wp.array(pts, dtype=wp.vec3, device=self.device), int(method != "mls")
            parallel.launch_split(
                sample_field_kernel,
                n,
                lambda lo, k: [arg, pts_wp[lo : lo + k], mode, values[lo : lo + k], grads[lo : lo + k]],
                self.device,
            )
        if return_gradient:
            return values.numpy(), grads.numpy()
        return values.numpy()

    def source_ids(self, points) -> np.ndarray:
        """(N,) int32: the id of the input field whose surface determines the value at each point."""
        pts = _as_points(points)
        ids = wp.empty(len(pts), dtype=wp.int32, device=self.device)
        if len(pts):
            arg, pts_wp = self.arg(), wp.array(pts, dtype=wp.vec3, device=self.device)
            parallel.launch_split(
                source_ids_kernel,
                len(pts),
                lambda lo, n: [arg, pts_wp[lo : lo + n], ids[lo : lo + n]],
                self.device,
            )
        return ids.numpy()

    def level_of_nodes(self) -> np.ndarray:
        return np.repeat(np.arange(self.levels, dtype=np.int32), np.diff(self.level_offsets))

    def node_centers(self) -> np.ndarray:
        """(N, 3) float64 world-space centres of all nodes, finest level first."""
        lv = self.level_of_nodes()
        spacing = self.voxel_size * (2.0**lv)
        return self.origin + (self.coords.numpy().astype(np.float64) + 0.5) * spacing[:, None]

    def debug_cells(self) -> dict:
        """Every stored node: centres (N,3) float32, sizes (N,), levels (N,), sdf (N,), leaf (N,) bool."""
        lv = self.level_of_nodes()
        return {
            "centers": self.node_centers().astype(np.float32),
            "sizes": (self.voxel_size * (2.0**lv)).astype(np.float32),
            "levels": lv,
            "sdf": self.values.numpy().copy(),
            "leaf": self.child.numpy() < 0,
        }

    def to_dense(self, bounds=None, spacing=None, *, max_bytes=None) -> dict:
        """Dense samples for debug volumes.

        Args:
            bounds: ((3,), (3,)) world box; defaults to the domain.
            spacing: Sample spacing; defaults to the finest voxel size.
            max_bytes: Refuse blocks larger than this (default: half the available memory).
        Returns:
            dict with ``values`` (X, Y, Z) float32 (x-major, index [i, j, k]), ``origin`` (3,) world position of
            sample [0, 0, 0], and ``spacing``.
        Raises:
            AasdfError: If the block would not fit in memory.
        """
        lo, hi = self.bounds if bounds is None else (np.asarray(bounds[0], float), np.asarray(bounds[1], float))
        spacing = self.voxel_size if spacing is None else float(spacing)
        if not spacing > 0:
            raise ValueError(f"Expected a positive 'spacing', but got {spacing}.")
        shape = np.maximum(np.ceil((hi - lo) / spacing).astype(np.int64), 1)
        budget = available_memory() // 2 if max_bytes is None else int(max_bytes)
        need = int(np.prod(shape)) * 4 * 8
        if need > budget:
            raise AasdfError(
                f"A dense block of {shape[0]}x{shape[1]}x{shape[2]} samples needs {need / 2**30:.1f} GiB,"
                f" more than the {budget / 2**30:.1f} GiB available; use a coarser spacing."
            )
        axes = [lo[a] + (np.arange(shape[a]) + 0.5) * spacing for a in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        values = self.sample(grid).reshape(tuple(shape))
        return {"values": values, "origin": lo + 0.5 * spacing, "spacing": spacing}

    def to_mesh(self, iso: float = 0.0):
        """Marching cubes over the finest level's narrow band: (V,3) float32 vertices, (F,3) int32 triangles."""
        n0 = self.level_counts[0]
        if self.levels == 1:  # the dense top level is the finest: no octets to walk
            return extract_surface(
                self.coords.numpy(), self.values.numpy(), origin=self.origin, spacing=self.voxel_size, iso=float(iso)
            )
        return extract_octree_level(
            self.coords[:n0],
            self.values[:n0],
            (self.child, self.level_offsets[self.levels - 1], self.top_dims, self.levels),
            origin=self.origin,
            spacing=self.voxel_size,
            iso=float(iso),
        )

    # -- booleans as operators --
    def __or__(self, other):
        return boolean.union(self, other)

    def __and__(self, other):
        return boolean.intersection(self, other)

    def __sub__(self, other):
        return boolean.difference(self, other)


def _as_points(points) -> np.ndarray:
    pts = np.ascontiguousarray(points, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"Expected 'points' of shape (N, 3), but got {pts.shape}.")
    return pts
