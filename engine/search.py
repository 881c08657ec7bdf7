"""How the octets search a mesh (:mod:`.distance`): which triangles are slivers, in which frame the BVH is searched,
and the :class:`OctetSearch` that carries these and the mesh to the octet kernels.

Slivers and the frame are decided once per build from the triangles alone. Slivers (long thin triangles: a cylinder's
sides) take the octets' capsule test, which skips those beside the nearest one; a mesh whose slanted parts give its
triangles loose bounding boxes is searched through a turned copy whose boxes fit them (:func:`search_frame`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp


@dataclass
class OctetSearch:
    """How a mesh's octets search it (the arguments of :func:`.distance.finest_distances` of those names): the
    mesh, the radius its centre queries try first and the fallback, the box search, the turned copy and its
    rotation, the slivers, the triangles' mean area (whether an octet may start from the triangles of the one before
    it: :data:`.distance.OCTET_REUSE_MIN_AREA`)."""

    mesh_id: int
    query_radius: float
    far_dist: float
    box_search: bool
    search_id: int | None = None  # None: the mesh itself
    frame: np.ndarray | None = None
    slivers: wp.array | None = None
    mean_area: float = 0.0

    def __post_init__(self):
        if self.search_id is None:
            self.search_id = self.mesh_id


# A triangle is a sliver, for the octets' capsule test, when its longest edge exceeds this many cells and its height
# over that edge is under SLIVER_HEIGHT cells.
SLIVER_LENGTH = 4.0
SLIVER_HEIGHT = 2.0


@wp.kernel(enable_backward=False)
def _sliver_kernel(
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    length: float,
    height: float,
    sliver: wp.array[wp.uint8],
):
    """Whether triangle ``tid``'s longest edge exceeds ``length`` and its height over that edge is under ``height``."""
    t = wp.tid()
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    longest = wp.sqrt(wp.max(wp.length_sq(b - a), wp.max(wp.length_sq(c - b), wp.length_sq(a - c))))
    sliver[t] = wp.uint8(0)
    if longest > length and wp.length(wp.cross(b - a, c - a)) < height * longest:
        sliver[t] = wp.uint8(1)


def slivers(verts: np.ndarray, tris: np.ndarray, spacing: float, device=None) -> wp.array:
    """(T,) uint8 Warp array: 1 for the long thin triangles (SLIVER_LENGTH, SLIVER_HEIGHT) whose longest edge less
    their height bounds their distance much better than their plane and box do (a cylinder's sides beside each
    other). Taken by every long triangle, the test cost meshes without slivers 6-8 % of their finest distances (cow,
    fandisk, homer)."""
    out = wp.empty(len(tris), dtype=wp.uint8, device=device)
    wp.launch(
        _sliver_kernel,
        dim=len(tris),
        inputs=[
            wp.array(verts, dtype=wp.vec3, device=device),
            wp.array(tris, dtype=wp.int32, device=device),
            SLIVER_LENGTH * spacing,
            SLIVER_HEIGHT * spacing,
            out,
        ],
        device=device,
    )
    return out


# A mesh is searched in another frame where that spares each octet at least this many candidate triangles (a turned
# box's 12 triangles gain nothing measurable; a turned cylinder of 512 slivers 230).
SEARCH_FRAME_SAVING = 16.0


@wp.kernel(enable_backward=False)
def _grown_boxes_kernel(
    verts: wp.array[wp.vec3],
    tris: wp.array2d[wp.int32],
    frame: wp.mat33,
    grow: float,
    volume: wp.array[wp.float32],
    cross: wp.array[wp.vec3],
):
    """The volume of triangle ``tid``'s bounding box in the rotation ``frame``, grown by ``grow`` on every axis, and
    (where ``cross`` is not empty) its edges' cross product."""
    t = wp.tid()
    a = verts[tris[t, 0]]
    b = verts[tris[t, 1]]
    c = verts[tris[t, 2]]
    if cross.shape[0] > 0:
        cross[t] = wp.cross(b - a, c - a)
    a = frame * a
    b = frame * b
    c = frame * c
    size = wp.max(a, wp.max(b, c)) - wp.min(a, wp.min(b, c)) + wp.vec3(grow)
    volume[t] = size[0] * size[1] * size[2]


def search_frame(verts: np.ndarray, tris: np.ndarray, octet: float, device=None) -> np.ndarray | None:
    """A rotation (3, 3) under which the octets (of edge ``octet``) meet far fewer candidate triangles, or None.

    The octets' candidate search (:func:`_finest_octet_distance_kernel`) finds triangles by their boxes in the BVH. A
    mesh whose long or flat parts are slanted has boxes far larger than the triangles: a cylinder turned about two
    axes has sides 0.85 long and 0.006 wide whose boxes are a third of the diagonal on every axis and overlap all
    around it, so every octet beside it meets hundreds of them and its centre query walks most of the BVH. Distances
    do not change under a rotation: the queries may run on the mesh turned so its parts lie along the axes. Tried:
    the principal axes of the vertices (a cylinder's axis) and the frame of the two largest triangles' normals most
    apart (a box's faces). The candidates an octet meets are estimated as the volume of the triangles' boxes, each
    grown by an octet, over the volume of the band around the surface, at most every triangle."""
    count = len(tris)
    points = wp.array(verts, dtype=wp.vec3, device=device)
    corners = wp.array(tris, dtype=wp.int32, device=device)
    volume = wp.empty(count, dtype=wp.float32, device=device)
    cross = wp.empty(count, dtype=wp.vec3, device=device)

    def grown_volume(rotation, edges):
        turn = wp.mat33(*(float(x) for x in np.reshape(rotation, -1)))
        wp.launch(
            _grown_boxes_kernel,
            dim=count,
            inputs=[points, corners, turn, 2.0 * octet],
            outputs=[volume, edges],
            device=device,
        )
        return float(volume.numpy().sum(dtype=np.float64))

    own_volume = grown_volume(np.eye(3), cross)
    edges = cross.numpy()
    areas = np.linalg.norm(edges, axis=1)
    band = max(float(areas.sum(dtype=np.float64)) * octet, 1e-30)  # twice the area (the cross products') x octet

    def candidates(grown: float) -> float:
        return min(grown / band, float(count))

    own = candidates(own_volume)
    # no frame makes a triangle's grown box smaller than the octet's own cube: fine meshes stop here
    if own - candidates(count * (2.0 * octet) ** 3) < SEARCH_FRAME_SAVING:
        return None
    frames = []
    centred = np.asarray(verts, dtype=np.float64) - np.mean(verts, axis=0)
    frames.append(np.linalg.eigh(centred.T @ centred)[1].T)
    if areas.max() > 0.0:
        normals = edges / np.maximum(areas, 1e-30)[:, None]
        first = normals[np.argmax(areas)].astype(np.float64)
        large = normals[areas >= 0.5 * areas.max()]
        second = large[np.argmin(np.abs(large @ first))].astype(np.float64)
        second = second - (second @ first) * first
        if np.linalg.norm(second) > 1e-3:
            second /= np.linalg.norm(second)
            frames.append(np.stack([first, second, np.cross(first, second)]))
    no_edges = wp.empty(0, dtype=wp.vec3, device=device)
    counts = [candidates(grown_volume(frame, no_edges)) for frame in frames]
    best = int(np.argmin(counts))
    return frames[best] if own - counts[best] >= SEARCH_FRAME_SAVING else None
