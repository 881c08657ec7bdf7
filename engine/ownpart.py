"""A kept-faces judge's leaf on its own: what its triangles give whatever the other leaves are (:mod:`.keep`).

Each triangle's side of the leaf's own field (read half a voxel in front of and behind it), the leaf's defects (its
repeated triangles, and a mesh of every defect to measure distances to) and its slivers to split as strips; kept with
its source mesh from boolean to boolean, and placed with a moved leaf.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from functools import partial

import numpy as np
import warp as wp

from .defects import CROSSING_VOXELS, near_internal, own_defects
from .ondemand import built_on_demand, own_sides
from .ownside import THIN, TINY_VOXELS, outward, side_at
from .samples import edge_turns
from .slivers import strip_parents
from .trimeasures import triangle_measures

# A triangle partly keepable is split while its longest edge is above this many voxels.
SPLIT_VOXELS = 1.5
# A triangle's own field is read this many voxels in front of and behind it (its sign must change there).
SIDE_VOXELS = 0.5


@dataclass
class _Own:
    """What a leaf's own triangles give whatever the other leaves are: their defects (:func:`.defects.own_defects`: the
    repeated triangles, and a mesh of every defect to measure distances to), each one's side of the leaf's own field
    (:func:`.ownside.side_at`, half a voxel out), and which are slivers to split as strips
    (:func:`.slivers.strip_parents`)."""

    values: object  # the leaf field's values array it was read from (the same field: the same array); None: its mesh
    offset: float
    device: object
    defects: np.ndarray  # (T,) bool: repeated triangles
    side: np.ndarray  # (T,) int8
    defect_mesh: object  # wp.Mesh or None
    strips: tuple  # (strip, apex) per triangle
    thin: int  # the side of a part thinner than the field sees (:func:`.ownside.outward`)
    turns: tuple | None = None  # :func:`.samples.edge_turns` of its triangles where unplaced (a placed one's: found)
    beyond_holes: bool = False  # a defect other than a hole's edge (:func:`.defects.own_defects`)


# A leaf's own part, kept with its source mesh: an unplaced leaf's source is the same object at every boolean its
# cached field enters (a drag's every move judges the unmoved operand's triangles against the moved one), a placed
# leaf's is made anew (nothing kept). Entries go with their sources.
_OWN: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def own_part(leaf, source, voxel: float, device) -> _Own:
    """The :class:`_Own` of a leaf and its (world) ``source``, from the last boolean that judged that source with the
    same field and voxel size, else found."""
    offset = SIDE_VOXELS * voxel
    own = _OWN.get(source)
    # (a field built on demand reads its sides off its mesh: the same however far it is refined)
    same = own is not None and (own.values is leaf.values or own.values is None and built_on_demand(leaf))
    if same and own.offset == offset and own.device == device:
        return own
    own = _placed_own(leaf, voxel, device)
    if own is not None:
        return own
    verts, tris = source.verts, source.tris.astype(np.int64)
    measures = triangle_measures(verts, tris)
    centres, normals = measures.centres, measures.normals
    # a field built on demand: off its mesh, or where that is not clear off its field with the octets there built
    on_demand = built_on_demand(leaf)

    def sides(turn: int, rows) -> np.ndarray:  # (a gap's walls face away from it on a mesh inside out: ownside)
        reading = partial(side_at, rays=source.bvh(device), tiny=TINY_VOXELS * voxel, turn=turn)
        args = (leaf, centres[rows], normals[rows], offset)
        return own_sides(*args, reading, tris[rows]) if on_demand else reading(*args)

    side = sides(1, slice(None))
    # (from the faces not read internal: the same whichever way gaps are read)
    thin = outward(side, measures.doubled_areas)
    internal = np.flatnonzero(side == 0)
    if thin < 0 and len(internal):  # inside out: the faces read internal read again, a gap's walls turned
        side[internal] = sides(-1, internal)
    side = np.where(side == THIN, thin, side).astype(np.int8)
    # where the mesh passes through itself, some triangle has its own inside on both sides (an internal face): only
    # then are its crossings looked for, and only near those (the bunny's 69 k triangles take 0.07 s)
    shortest = CROSSING_VOXELS * voxel if (side == 0).any() else None
    near = None if shortest is None else near_internal(verts, tris, measures, side == 0, shortest, device)
    defects, points, parts, beyond_holes = own_defects(verts, tris, shortest, device, near)
    defect_mesh = None
    if len(parts) and not defects.all():
        defect_mesh = wp.Mesh(
            points=wp.array(points, dtype=wp.vec3, device=device),
            indices=wp.array(parts.reshape(-1), dtype=wp.int32, device=device),
        )
    strips = strip_parents(verts, tris, SPLIT_VOXELS * voxel, measures)
    values = None if on_demand else leaf.values
    own = _Own(values, offset, device, defects, side, defect_mesh, strips, thin, edge_turns(verts, tris), beyond_holes)
    _OWN[source] = own
    return own


def gives_own_faces_up(leaf, voxel: float) -> bool:
    """Whether a (mesh) leaf's faces are given up somewhere whatever the other leaves are, other than about its holes
    (whose caps a field built on demand builds first): where some triangle has its own inside on both sides (it passes
    through itself), or about a defect other than a hole's edge (a repeated triangle, an edge of more than two faces
    or listed the same way by two); the voxel surface must be made there."""
    own = own_part(leaf, next(iter(leaf.world_sources().values())), voxel, leaf.device)
    return bool((own.side == 0).any() or own.beyond_holes)


def own_region(leaf, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Where a (mesh) leaf's faces may be given up whatever the other leaves are, in its own frame: its defects as the
    judge measures distances to them (crossings included) and its triangles that read internal or repeat another (a
    mesh of nothing else has no defect mesh), as ``(points (P, 3) float32, tris (D, 3) int32)``."""
    frame = leaf.in_frame()
    source = next(iter(frame.world_sources().values()))
    own = own_part(frame, source, voxel / (1.0 if leaf.placement is None else leaf.placement.scale), leaf.device)
    points, tris = source.verts.astype(np.float32), source.tris[(own.side == 0) | own.defects].astype(np.int32)
    if own.defect_mesh is None:
        return points, tris
    parts = own.defect_mesh.indices.numpy().reshape(-1, 3) + len(points)
    return np.concatenate([points, own.defect_mesh.points.numpy()]), np.concatenate([tris, parts])


def _placed_own(leaf, voxel: float, device) -> _Own | None:
    """A placed leaf's :class:`_Own` from its unplaced source's (kept with it from move to move): a placement turns,
    moves and scales it alike on every axis, so the sides and slivers are the same and the defects' mesh is placed.
    None for an unplaced leaf, or a placement that mirrors (its triangles turn over: found afresh)."""
    placement = leaf.placement
    if placement is None or placement.mirrors or len(leaf.sources) != 1:
        return None
    own = own_part(leaf.in_frame(), next(iter(leaf.sources.values())), voxel / placement.scale, device)
    defect_mesh = own.defect_mesh
    if defect_mesh is not None:
        points = placement.to_world(defect_mesh.points.numpy()).astype(np.float32)
        defect_mesh = wp.Mesh(points=wp.array(points, dtype=wp.vec3, device=device), indices=defect_mesh.indices)
    parts = (own.defects, own.side, defect_mesh, own.strips, own.thin)
    return _Own(leaf.values, SIDE_VOXELS * voxel, device, *parts, beyond_holes=own.beyond_holes)
