"""The adaptive field type: a hierarchical sparse octree of signed distances, its queries and its surface.

An :class:`AdaptiveField` is what every build and boolean returns and what every boolean takes: levels stored finest
first in one set of arrays (Morton codes, values, closest points, child links, source ids). Queries
descend from the dense top level to a leaf and interpolate by moving least squares (:mod:`.sampling`); ``to_mesh``
extracts the zero surface from the finest band (:mod:`.extract`); ``|``, ``&`` and ``-`` are the booleans
(:mod:`.boolean`).
"""

from __future__ import annotations

import copy

import numpy as np
import warp as wp

from . import boolean, parallel, sources
from .errors import AasdfError
from .hybrid import kept_surface
from .meshing import field_mesh
from .octree import decode_codes
from .ondemand import refined
from .placement import Placement
from .plan import available_memory, check_resolvable, check_voxel_size
from .queries import code_proj, sample_field_kernel, source_ids_kernel
from .sampling import FieldArg
from .seams import kept_along_seams


@wp.kernel(enable_backward=False)
def _find_inside_kernel(values: wp.array[wp.float32], found: wp.array[wp.int32]):
    """``found[0]`` becomes 1 when some node is inside (every such thread writes the same 1: races are harmless)."""
    if values[wp.tid()] < 0.0:
        found[0] = 1


class AdaptiveField:
    """A hierarchical sparse octree of signed distances (negative inside), closed under booleans.

    Levels are stored finest first and concatenated; ``level_offsets[k]:level_offsets[k+1]`` is level ``k``.
    Intermediate levels are sorted by Morton code; the top level is dense in x-fastest order. ``encloses_volume``
    says whether it has an inside at all. A node keeps its Morton code (8 bytes), value (4), closest point (``proj``,
    6: a half-float offset from the node; ``closest_points`` decodes them) and source id (4; a field of one operand
    keeps its id once, ``single_source``); a coarse node its first child (4), a finest node its closest triangle (4).
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
        values,
        proj,
        child,
        source,
        field_ids,
        device,
        timings=None,
        stats=None,
        sources=None,
        triangles=None,
        placement=None,
    ):
        self.voxel_size, self.levels = float(voxel_size), int(levels)
        self.origin = np.asarray(origin, dtype=np.float64)
        self.top_dims = np.asarray(top_dims, dtype=np.int64)
        self.level_offsets = np.asarray(level_offsets, dtype=np.int64)
        self.codes, self.values, self.proj = codes, values, proj
        self.field_ids = tuple(sorted(set(int(i) for i in field_ids)))
        # (N,) int32 source id of every node; a field of one operand keeps its id alone (4 bytes a node less)
        self.single_source = self.field_ids[0] if len(self.field_ids) == 1 else -1
        if len(self.field_ids) == 1:
            source = wp.empty(0, dtype=wp.int32, device=device)
        self.child, self.source = child, source
        self.device = device
        self.timings = dict(timings or {})
        self.stats = dict(stats or {})
        self.sources = dict(sources or {})  # field id -> the SourceMesh it was built from (see closest_sources)
        # (N0,) int32: each finest node's closest triangle in its source's mesh (-1, None: unknown)
        self.tri = triangles
        # where the field's own frame sits in the world (None: it is the world; see ``transformed``)
        self.placement = placement
        # a boolean's operation tree over its operand fields (:mod:`.expression`); None: the field is a leaf
        self.expression = None
        # what adds the finest octets of a field built on demand (:mod:`.ondemand`; a copy read as built: built_by)
        self.refiner = self.built_by = None
        self._encloses_volume = None

    @classmethod
    def from_layout(
        cls,
        layout: dict,
        *,
        voxel_size,
        origin,
        values,
        proj,
        source,
        field_ids,
        timings=None,
        stats=None,
        sources=None,
        triangles=None,
    ):
        """The field whose nodes are placed by ``layout`` (:func:`.layout.level_layout`: codes, coordinates, level
        offsets, child links, top-level dims) with these (N,) node arrays: ``values`` float32 signed distances,
        ``proj`` vec3 closest surface points (or vec3h offsets, as the field keeps them: see ``closest_points``),
        ``source`` int32 ids of the operand each node's value came from; ``sources`` maps field ids to the
        :class:`.sources.SourceMesh` each was built from, ``triangles`` (N0,) int32 gives each finest node's closest
        triangle there (None: not known)."""
        offsets = np.asarray(layout["offsets"], dtype=np.int64)
        child = layout["child"]
        n0 = int(offsets[1])
        if child.shape[0] == offsets[-1]:  # a layout's links of every node: the finest level has none to keep
            child = wp.clone(child[n0:]) if n0 < child.shape[0] else wp.empty(0, dtype=wp.int32, device=child.device)
        if proj.dtype == wp.vec3:  # points: kept as offsets from their nodes
            proj = code_proj(layout["codes"], offsets, origin, voxel_size, points=proj, coords=layout.get("coords"))
        return cls(
            voxel_size=voxel_size,
            levels=len(offsets) - 1,
            origin=origin,
            top_dims=layout["top_dims"],
            level_offsets=offsets,
            codes=layout["codes"],
            values=values,
            proj=proj,
            child=child,
            source=source,
            field_ids=field_ids,
            device=values.device,
            timings=timings,
            stats=stats,
            sources=sources,
            triangles=triangles,
        )

    def relabel(self, field_id: int) -> AdaptiveField:
        """This field with every node's source id ``field_id``: a new field sharing every other array (the field
        itself when it already has that id alone)."""
        field_id = int(field_id)
        if self.field_ids == (field_id,):
            return self
        relabelled = copy.copy(self)
        relabelled.field_ids, relabelled.single_source = (field_id,), field_id
        relabelled.source = wp.empty(0, dtype=wp.int32, device=self.device)  # one id: none kept per node
        relabelled.sources = {field_id: next(iter(self.sources.values()))} if len(self.sources) == 1 else {}
        relabelled.timings, relabelled.stats = dict(self.timings), dict(self.stats)
        return relabelled

    def transformed(self, matrix) -> AdaptiveField:
        """This field moved by a similarity (rotation or reflection, uniform scale, translation): a new field sharing
        every array, nothing rebuilt. Queries, ``to_mesh`` and booleans see it in its new place; a boolean resamples
        it onto the result's lattice from its own cells.

        ``matrix``: (4, 4) array-like, applied after the field's current placement. Returns the placed field (the field
        itself for the identity). Raises ValueError if ``matrix`` is not a finite (4, 4) similarity (uneven scales and
        shears need a new field), AasdfError if float32 positions where it lands cannot resolve its voxels
        (:func:`.plan.check_resolvable`) or it scales them below :data:`.plan.MIN_VOXEL_SIZE`.
        """
        matrix = np.asarray(matrix, dtype=np.float64)
        placement = Placement(matrix) if self.placement is None else self.placement.then(matrix)
        if placement.is_identity and self.placement is None:
            return self
        moved = copy.copy(self)
        moved.placement = None if placement.is_identity else placement
        check_voxel_size(moved.world_voxel_size)
        check_resolvable(*moved.bounds, moved.world_voxel_size)
        return moved

    @property
    def world_voxel_size(self) -> float:
        """The finest spacing where the field is placed (``voxel_size`` times the placement's scale)."""
        return self.voxel_size * (self.placement.scale if self.placement is not None else 1.0)

    def world_sources(self) -> dict:
        """``sources`` with their vertices where the field is placed (the same objects when it is not); a placed
        field's are made once for its placement, so what is built on them (a BVH) is shared by every reader."""
        return dict(self.sources) if self.placement is None else sources.placed_sources(self.sources, self.placement)

    # -- geometry of the domain --
    @property
    def top_spacing(self) -> float:
        return self.voxel_size * 2 ** (self.levels - 1)

    @property
    def frame_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) corners of the domain in the field's own frame."""
        return self.origin.copy(), self.origin + self.top_dims * self.top_spacing

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) world corners of the box around the domain (the domain itself unless the field is placed; a
        placed field of one mesh: around its placed vertices, see ``Placement.content_box``)."""
        lo, hi = self.frame_bounds
        if self.placement is None:
            return lo, hi
        if len(self.sources) == 1 and len(verts := next(iter(self.sources.values())).verts):
            return self.placement.content_box(lo, hi, verts)
        return self.placement.box(lo, hi)

    @property
    def fine_dims(self) -> np.ndarray:
        return self.top_dims * 2 ** (self.levels - 1)

    @property
    def node_count(self) -> int:
        return int(self.level_offsets[-1])

    @property
    def tree(self) -> tuple:
        """(coarse nodes' child links, finest node count, first top node, top dims, levels): what the extraction
        walks the octree by."""
        return (self.child, self.level_counts[0], int(self.level_offsets[self.levels - 1]), self.top_dims, self.levels)

    def child_links(self) -> wp.array:
        """(N,) int32 first child of every node (-1: a leaf; ``child`` keeps the coarse nodes' only)."""
        links = wp.full(self.node_count, -1, dtype=wp.int32, device=self.device)
        wp.copy(links, self.child, dest_offset=self.level_counts[0], count=self.child.shape[0])
        return links

    @property
    def coords(self) -> wp.array:
        """(N,) vec3i lattice coordinates of every node on its level, decoded from the codes (not kept)."""
        return decode_codes(self.codes)

    def node_sources(self) -> wp.array:
        """(N,) int32 source id of every node (made for a field of one operand, which keeps its id alone)."""
        if self.source.shape[0] == 0:
            return wp.full(self.node_count, self.single_source, dtype=wp.int32, device=self.device)
        return self.source

    @property
    def closest_points(self) -> wp.array:
        """(N,) vec3 closest surface point of every node (the field's frame), decoded from ``proj`` (not kept)."""
        return code_proj(self.codes, self.level_offsets, self.origin, self.voxel_size, stored=self.proj)

    @property
    def encloses_volume(self) -> bool:
        """Whether the field has an inside: some node's value is negative.

        False for a mesh that encloses nothing (a plane, a flat sheet: |w| < 1/2 everywhere, see
        :func:`.build.build_field`) and for an empty boolean (disjoint solids intersected); ``to_mesh()`` then returns
        empty arrays. Computed once.
        """
        if self._encloses_volume is None:
            found = wp.zeros(1, dtype=wp.int32, device=self.device)
            if self.node_count:
                parallel.load_modules([_find_inside_kernel.module], self.device)
                wp.launch(_find_inside_kernel, dim=self.node_count, inputs=[self.values, found], device=self.device)
            self._encloses_volume = bool(found.numpy()[0])
        return self._encloses_volume

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
        lo, hi = self.frame_bounds
        f.domain_min = wp.vec3(*lo)
        f.domain_max = wp.vec3(*hi)
        placed = self.placement
        f.moved = int(placed is not None)
        f.rotation = wp.mat33(*(placed.rotation.ravel() if placed is not None else np.eye(3).ravel()))
        f.translation = wp.vec3(*(placed.translation if placed is not None else np.zeros(3)))
        f.scale = float(placed.scale if placed is not None else 1.0)
        f.child, f.values, f.source, f.proj = self.child, self.values, self.source, self.proj
        f.single_source = self.single_source
        f.codes = self.codes
        f.fine_count = int(self.level_offsets[1])
        f.tri = self.tri if self.tri is not None else wp.empty(0, dtype=wp.int32, device=self.device)
        f.exact = int(bool(self.stats.get("exact_distance", False)))
        f.inner_points = int(getattr(self, "expression", None) is not None)
        if f.inner_points and self.stats.get("lipschitz", 1.0) > 1.0:  # a chamfer's (:func:`.sampling.coarse_mls`)
            f.inner_points = 2
        f.lipschitz = float(self.stats.get("lipschitz", 1.0))
        f.no_inside = int(self._no_inside())
        f.mesh = wp.uint64(getattr(self.distance_mesh, "id", 0))
        return f

    def _no_inside(self) -> bool:
        """Whether the field has no inside anywhere (read as an unsigned distance): a mesh that encloses nothing, or a
        boolean result made whole with no node inside (one built on demand may yet refine nodes inside)."""
        whole_result = getattr(self, "expression", None) is not None and self.refiner is None
        return bool(self.stats.get("flat", False)) or (whole_result and not self.encloses_volume)

    @property
    def distance_mesh(self):
        """Warp's mesh (the field's own frame) whose signed distance this field is, kept by its build: a closed mesh's
        (``stats["mesh_distance"]``); None for booleans, field operations and open meshes."""
        if self.stats.get("mesh_distance", False) and len(self.sources) == 1:
            return next(iter(self.sources.values())).kept_bvh(self.device)
        return None

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
            (N,) float32 signed distances, negative inside; outside the domain never below the distance to it. A field
            that encloses no volume (``encloses_volume`` False) is an unsigned distance, kinked on its surface: "mls"
            there takes the nearest closest point of the neighbouring nodes instead of a fit.
        Raises:
            ValueError: If ``points`` is not (N, 3) of finite numbers or ``method`` is unknown.
        """
        if self.refiner is not None:  # the finest octets it reads built first (:mod:`.ondemand`)
            return self._asked(points).sample(points, method, return_gradient=return_gradient)
        pts = self._frame_points(points)
        if method not in ("mls", "linear"):
            raise ValueError(f"Expected 'method' to be 'mls' or 'linear', but got {method!r}.")
        n = len(pts)
        values = wp.empty(n, dtype=wp.float32, device=self.device)
        grads = wp.empty(n, dtype=wp.vec3, device=self.device)
        if n:
            arg, pts_wp = self.arg(), wp.array(pts, dtype=wp.vec3, device=self.device)
            mode = 1 if method == "linear" else (0 if self.encloses_volume else 2)
            parallel.launch_split(
                sample_field_kernel,
                n,
                lambda lo, k: [arg, pts_wp[lo : lo + k], mode, values[lo : lo + k], grads[lo : lo + k]],
                self.device,
                min_dim=parallel.EMIT_SPLIT_MIN_DIM,  # a descent of the tree each: worth two threads from a thousand
            )
        values = values.numpy()
        if self.placement is not None:
            values = values * np.float32(self.placement.scale)
        if return_gradient:
            grads = grads.numpy()
            if self.placement is not None:
                grads = (grads @ self.placement.rotation.T).astype(np.float32)
            return values, grads
        return values

    def source_ids(self, points) -> np.ndarray:
        """(N,) int32: the id of the input field whose surface determines the value at each point."""
        if self.refiner is not None:
            return self._asked(points).source_ids(points)
        pts = self._frame_points(points)
        ids = wp.empty(len(pts), dtype=wp.int32, device=self.device)
        if len(pts):
            arg, pts_wp = self.arg(), wp.array(pts, dtype=wp.vec3, device=self.device)
            args = lambda lo, n: [arg, pts_wp[lo : lo + n], ids[lo : lo + n]]  # noqa: E731
            parallel.launch_split(source_ids_kernel, len(pts), args, self.device, min_dim=parallel.EMIT_SPLIT_MIN_DIM)
        return ids.numpy()

    def closest_sources(self, points):
        """Where the surface near each point came from: the operand whose value decides there (``source_ids``), the
        closest triangle of the mesh that operand was built from, and the barycentric coordinates of the closest
        point on it.

        Args:
            points: (N, 3) array-like of world-space points on or near the surface.
        Returns:
            ``(field_ids, triangle_ids, barycentrics)``: (N,) int32 field ids, (N,) int32 triangle indices among the
            triangles that operand's field was built from (-1 where the field keeps no source mesh for that id), and
            (N, 3) float32 weights of the triangle's corners.
        Raises:
            ValueError: If ``points`` is not (N, 3).
        """
        ids = self.source_ids(points)
        pts = self._frame_points(points)  # the sources are kept in the field's own frame
        tris = np.full(len(pts), -1, dtype=np.int32)
        bary = np.zeros((len(pts), 3), dtype=np.float32)
        for field_id in np.unique(ids):
            source = self.sources.get(int(field_id))
            if source is not None:
                rows = np.flatnonzero(ids == field_id)
                tris[rows], bary[rows] = sources.closest_triangles(source, pts[rows], self.device)
        return ids, tris, bary

    def face_sources(self, verts, tris):
        """Where each face of a surface of this field came from, and where each of its corners lies on that one source
        triangle, so that what corners read off it (UVs, colours) keeps the source's seams. The source is the
        operand of the leaf holding the face's centre (``source_ids``) and, where that leaf is a finest node, the
        triangle of its closest point (found by the build; for a boolean, the operand's node the value came from),
        else the triangle closest to the centre (``closest_sources``).

        Args:
            verts: (V, 3) float32 vertices, e.g. from ``to_mesh``.
            tris: (F, 3) int triangles.
        Returns:
            ``(field_ids, triangle_ids, corner_barycentrics)``: (F,) int32, (F,) int32 (-1 where the field keeps no
            source mesh for that id) and (F, 3, 3) float32 (per corner, the weights of the triangle's corners,
            projected onto its plane and not clamped).
        """
        field = self if self.refiner is None else self._asked(verts)
        return sources.face_sources_of(field, field._frame_points(verts), tris)

    def source_barycentrics(self, field_ids, triangle_ids, points) -> np.ndarray:
        """(N, 3) float32 barycentric coordinates of each point projected onto a given source triangle (the plane of
        triangle ``triangle_ids[i]`` of operand ``field_ids[i]``, not clamped: see :func:`.sources.barycentrics`);
        zeros where the field keeps no such source."""
        pts = _as_points(points)
        field_ids = np.asarray(field_ids).reshape(-1)
        triangle_ids = np.asarray(triangle_ids).reshape(-1)
        if len(field_ids) != len(pts) or len(triangle_ids) != len(pts):
            raise ValueError(
                f"Expected one field id and one triangle id per point ({len(pts)}), but got {len(field_ids)} and "
                f"{len(triangle_ids)}."
            )
        out = np.zeros((len(pts), 3), dtype=np.float32)
        for field_id in np.unique(field_ids):
            source = self.sources.get(int(field_id))
            if source is not None:
                rows = np.flatnonzero(field_ids == field_id)
                out[rows] = sources.barycentrics(source, triangle_ids[rows], pts[rows])
        return out

    def level_of_nodes(self) -> np.ndarray:
        return np.repeat(np.arange(self.levels, dtype=np.int32), np.diff(self.level_offsets))

    def node_centers(self) -> np.ndarray:
        """(N, 3) float64 world-space centres of all nodes, finest level first."""
        lv = self.level_of_nodes()
        spacing = self.voxel_size * (2.0**lv)
        centres = self.origin + (self.coords.numpy().astype(np.float64) + 0.5) * spacing[:, None]
        return centres if self.placement is None else self.placement.to_world(centres)

    def debug_cells(self) -> dict:
        """Every stored node: centres (N,3) float32, sizes (N,), levels (N,), sdf (N,), leaf (N,) bool."""
        lv = self.level_of_nodes()
        return {
            "centers": self.node_centers().astype(np.float32),
            "sizes": (self.world_voxel_size * (2.0**lv)).astype(np.float32),
            "levels": lv,
            "sdf": self.values.numpy() * np.float32(self.placement.scale if self.placement is not None else 1.0),
            "leaf": self.child_links().numpy() < 0,
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

    def kept_surface(self, *, sharp: bool | None = None, adaptivity: float = 0.0, regions: dict | None = None) -> dict:
        """The zero surface keeping the operands' own faces wherever it is theirs, new (voxel) surface only along the
        seams, merged where flat (more with an ``adaptivity``, within ``regions``): see :func:`.hybrid.kept_surface`
        (a field that is no boolean of meshes keeps nothing). A boolean made along its seams (``seams=True``) is
        joined there, and gives ``new_sources``: the new faces' rows and their ``face_sources`` (read there)."""
        if self.refiner is not None and self.expression is not None:  # made along its seams (:mod:`.seams`)
            return kept_along_seams(self, sharp=sharp, adaptivity=adaptivity, regions=regions)
        return kept_surface(refined(self, view=True), sharp=sharp, adaptivity=adaptivity, regions=regions)

    def to_mesh(
        self,
        iso: float = 0.0,
        *,
        sharp: bool | None = None,
        return_creases: bool = False,
        keep_faces: bool = False,
        quads: bool = False,
        adaptivity: float = 0.0,
        regions: dict | None = None,
    ):
        """The ``iso`` surface of the finest level's narrow band.

        Args:
            iso: Level to extract (world units; 0 is the surface, positive values offset it outwards). Farther than
                ISO_REACH voxels, or where the level leaves the finest band (its surface there is open), it is the
                zero surface of :func:`.fieldops.offset` (``regions`` are not read there: the offset has no sources).
            sharp: Keep creases and corners (dual marching cubes placing each vertex at the minimiser of the exact
                tangent planes of its cube, :mod:`.dual`); ``False`` gives marching cubes. Default: sharp, but for a
                re-distanced field (offsets, shells: its closest points lie on a marching-cubes surface, no crease to
                recover) marching cubes unless ``quads`` or an ``adaptivity`` (the dual surface's) are asked.
            return_creases: Also return the crease edges the sharp extraction reconstructed.
            keep_faces: Keep the operands' own triangles wherever the surface is theirs, away from the seams
                (:meth:`kept_surface`; ``iso`` 0 only; no crease edges are returned with them); an ``adaptivity``
                merges the seams' new faces where flat within it.
            quads: Return polygons: the dual quads kept whole where they are planar and convex (:mod:`.quads`),
                the rest triangles (sharp surfaces only; marching cubes stays triangles).
            adaptivity: 0 to 1: merge cells where the surface is flat within a bound that grows with it
                (:mod:`.adaptive`; 0 is the surface of every cell; sharp surfaces only).
            regions: Optional {field id: (T,) int label of each source triangle}: cells merge only within a label
                (materials, UV islands: no merged polygon spans a seam); default: within an operand.
        Returns:
            ``verts`` (V, 3) float32 and ``tris`` (T, 3) int32, counter-clockwise seen from outside; with ``quads``
            ``verts``, ``faces`` (C,) int32 corner vertices face after face and ``sizes`` (P,) int32 corners per face
            (quads first); with ``return_creases`` also ``creases`` (E, 2) int32 vertex index pairs, each edge of
            the mesh along which the surface folds at a crease (empty when ``sharp`` is ``False``).
        Raises:
            ValueError: If ``iso`` is not finite or ``adaptivity`` is not within [0, 1].
        """
        iso, adaptivity = float(iso), float(adaptivity)
        if not np.isfinite(iso):
            raise ValueError(f"Expected a finite 'iso', but got {iso}.")
        if not 0.0 <= adaptivity <= 1.0:
            raise ValueError(f"Expected an 'adaptivity' from 0 to 1, but got {adaptivity}.")
        if keep_faces:
            return self._kept_mesh(iso, (sharp, adaptivity, regions), quads, return_creases)
        if self.refiner is not None:  # its whole band first (:mod:`.ondemand`)
            options = {"sharp": sharp, "return_creases": return_creases, "quads": quads, "adaptivity": adaptivity}
            return refined(self, view=True).to_mesh(iso, regions=regions, **options)
        out, redistanced = None, self.stats.get("exact_distance", False)
        dual = sharp if sharp is not None else not redistanced or quads or adaptivity > 0.0
        if abs(iso) <= ISO_REACH * self.world_voxel_size:
            out = field_mesh(
                self, iso, sharp=dual, creases=return_creases, quads=quads, adaptivity=adaptivity, regions=regions
            )
        if out is None or not out["closed"]:  # the level leaves the finest band: the zero surface of its offset
            from .fieldops import offset

            grown = offset(self, iso)
            return grown.to_mesh(sharp=sharp, return_creases=return_creases, quads=quads, adaptivity=adaptivity)
        mesh = (out["verts"], out["faces"], out["sizes"]) if quads else (out["verts"], out["tris"])
        return (*mesh, out["creases"]) if return_creases else mesh

    def _kept_mesh(self, iso: float, options: tuple, quads: bool, return_creases: bool):
        """``to_mesh(keep_faces=True)``: the kept surface (``options``: sharp, adaptivity, regions) as ``to_mesh``
        returns a surface (its polygons triangles; no crease edges)."""
        if iso != 0.0:
            raise ValueError(f"Kept faces lie on the zero surface: expected 'iso' 0 with 'keep_faces', got {iso}.")
        sharp, adaptivity, regions = options
        surface = self.kept_surface(sharp=sharp, adaptivity=adaptivity, regions=regions)
        verts, tris = surface["verts"], surface["tris"]
        mesh = (verts, tris) if not quads else (verts, tris.ravel(), np.full(len(tris), 3, np.int32))
        return (*mesh, np.zeros((0, 2), dtype=np.int32)) if return_creases else mesh

    def _asked(self, points) -> AdaptiveField:
        """A view of this field built on demand with the finest octets its queries at ``points`` read
        (:mod:`.ondemand`)."""
        return refined(self, _as_points(points), view=True)

    def in_frame(self) -> AdaptiveField:
        """This field in its own frame (unplaced): the same arrays."""
        if self.placement is None:
            return self
        frame = copy.copy(self)
        frame.placement = None
        return frame

    def _frame_points(self, points) -> np.ndarray:
        """(N, 3) float32 points (validated) in the field's own frame."""
        pts = _as_points(points)
        return pts if self.placement is None else np.ascontiguousarray(self.placement.to_local(pts), dtype=np.float32)

    # -- booleans as operators --
    def __or__(self, other):
        return boolean.union(self, other)

    def __and__(self, other):
        return boolean.intersection(self, other)

    def __sub__(self, other):
        return boolean.difference(self, other)


# ``to_mesh`` extracts levels up to this many voxels from the surface from the field itself where every cube they
# cross lies in its finest band (measured at /256: closed to 0.5 voxel and leaking from 0.6, by 24-222 edges, to 1
# voxel, by 18-34 k, on a cube, cube - bore, spot and a blended union, marching cubes or sharp; the beetle with a
# ball already at 0.3), past it, or where it leaks, from its offset.
ISO_REACH = 0.5


def _as_points(points) -> np.ndarray:
    pts = np.ascontiguousarray(points, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"Expected 'points' of shape (N, 3), but got {pts.shape}.")
    if not np.isfinite(pts).all():
        raise ValueError(f"Expected finite 'points', but got {np.count_nonzero(~np.isfinite(pts))} NaN or inf values.")
    return pts
