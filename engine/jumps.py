"""Where the field of a messy mesh may change sign away from its surface: about its open, non-manifold and
misoriented edges.

A mesh field's sign is its generalised winding number's (inside where |w| >= 1/2). Across a closed surface w changes
by one; off the surface it is harmonic, so it crosses 1/2 in free space only where the surface is not a closed chain:
over the mesh's holes and about edges where it is non-manifold or turns its orientation (:mod:`.holes` caps the holes
there). A boolean's judge (:mod:`.keep`, :mod:`.judging`) reads such a field's sign a band away along the axes at
every sample to find those jumps, which costs six more readings a sample; it needs them only where a jump can be:
within the field's reach of the surface's own crossing (where the value is below two bands: the value overstates a
distance by a fraction of a voxel), or near the defect edges. Here the defect edges (vertices at one position taken
as one) are grouped into their connected pieces, each bounded by a sphere about its vertices' mean, widened by half
its radius (the cap a hole's loop spans bulges little past it); the judge probes a sample farther than two bands
from every sphere only where its value is below two bands.
"""

from __future__ import annotations

import weakref

import numpy as np
import warp as wp

from .components import connected_components
from .meshcheck import defect_edges

# A piece's sphere is its vertices' farthest distance from their mean, times this.
WIDEN = 1.5

_SPHERES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # source -> spheres


def jump_spheres(source) -> np.ndarray:
    """(H, 4) float32 ``(centre, radius)`` of spheres holding every defect edge of ``source`` (a :class:`.sources.
    SourceMesh`, world) and the caps they may bound; empty for a mesh whose every edge has two faces listing it once
    each way. Kept with the source."""
    found = _SPHERES.get(source)
    if found is not None:
        return found
    verts, _, bad = defect_edges(source.verts, source.tris)
    spheres = np.zeros((0, 4), np.float32)
    if len(bad):
        piece = connected_components(len(verts), bad[:, 0], bad[:, 1])
        used = np.unique(bad.ravel())
        labels, at = np.unique(piece[used], return_inverse=True)
        points = np.asarray(verts, dtype=np.float64)[used]
        centre = np.zeros((len(labels), 3))
        np.add.at(centre, at, points)
        centre /= np.bincount(at, minlength=len(labels))[:, None]
        radius = np.zeros(len(labels))
        np.maximum.at(radius, at, np.linalg.norm(points - centre[at], axis=1))
        spheres = np.c_[centre, WIDEN * radius].astype(np.float32)
    _SPHERES[source] = spheres
    return spheres


class JumpSpheres:
    """:func:`jump_spheres` of a mesh on a device, with a BVH of their boxes (``bvh_id`` 0: none); ``spheres`` None:
    a field that may jump anywhere (no mesh to bound where: ``anywhere``)."""

    def __init__(self, spheres: np.ndarray | None, device):
        self.anywhere = spheres is None
        spheres = np.zeros((0, 4), np.float32) if spheres is None else spheres
        self.spheres = wp.array(np.asarray(spheres, np.float32).reshape(-1, 4), dtype=wp.vec4, device=device)
        self.bvh, self.bvh_id = None, wp.uint64(0)
        if len(spheres):
            centre, radius = spheres[:, :3], spheres[:, 3:]
            lowers = wp.array(centre - radius, dtype=wp.vec3, device=device)
            uppers = wp.array(centre + radius, dtype=wp.vec3, device=device)
            self.bvh = wp.Bvh(lowers, uppers)
            self.bvh_id = wp.uint64(self.bvh.id)

    def near(self, points: np.ndarray, reach: float) -> np.ndarray:
        """(N,) bool: the points within ``reach`` of a sphere (all of them: ``anywhere``)."""
        if self.anywhere:
            return np.ones(len(points), dtype=bool)
        out = wp.zeros(len(points), dtype=wp.uint8, device=self.spheres.device)
        if len(points) and int(self.bvh_id) != 0:
            pts = wp.array(np.ascontiguousarray(points, dtype=np.float32), dtype=wp.vec3, device=self.spheres.device)
            wp.launch(_near_kernel, len(points), inputs=[self.bvh_id, self.spheres, pts, float(reach), out],
                      device=self.spheres.device)  # fmt: skip
        return out.numpy().astype(bool)


@wp.func
def sphere_gap(bvh: wp.uint64, spheres: wp.array[wp.vec4], x: wp.vec3, reach: float) -> float:
    """How far ``x`` lies from the nearest of the spheres (negative inside one), ``reach`` where none comes within it
    (``bvh`` of their boxes, 0: there are none)."""
    gap = reach
    if bvh != wp.uint64(0):
        query = wp.bvh_query_aabb(bvh, x - wp.vec3(reach), x + wp.vec3(reach))
        k = int(0)
        while wp.bvh_query_next(query, k):
            s = spheres[k]
            gap = wp.min(gap, wp.length(x - wp.vec3(s[0], s[1], s[2])) - s[3])
    return gap


@wp.func
def near_sphere(bvh: wp.uint64, spheres: wp.array[wp.vec4], x: wp.vec3, reach: float) -> bool:
    """Whether ``x`` lies within ``reach`` of one of the spheres (:func:`sphere_gap`)."""
    return sphere_gap(bvh, spheres, x, reach) < reach


@wp.kernel(enable_backward=False)
def _near_kernel(
    bvh: wp.uint64, spheres: wp.array[wp.vec4], points: wp.array[wp.vec3], reach: float, out: wp.array[wp.uint8]
):
    i = wp.tid()
    out[i] = wp.where(near_sphere(bvh, spheres, points[i], reach), wp.uint8(1), wp.uint8(0))


@wp.kernel(enable_backward=False)
def _clear_kernel(
    bvh: wp.uint64,
    spheres: wp.array[wp.vec4],
    centres: wp.array[wp.vec3],
    radii: wp.array[wp.float32],
    bound: wp.array[wp.float32],
):
    """Each ball (centre, radius)'s ``bound`` lowered to its gap to the nearest sphere (0 where they meet)."""
    i = wp.tid()
    r = radii[i]
    b = float(bound[i])
    if b > 0.0:
        b = wp.min(b, wp.max(sphere_gap(bvh, spheres, centres[i], b + r) - r, 0.0))
    bound[i] = b


def clear_of(jumps: JumpSpheres, verts: np.ndarray, tris: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """(T,) float32 ``bound`` (per triangle of ``verts``, ``tris``) lowered where a sphere of ``jumps`` comes nearer
    the triangle (a lower bound of the gap: from the ball about it at its centroid): how far each triangle can move
    against the field without its sign jumping there (``anywhere``: nowhere, 0)."""
    bound = np.ascontiguousarray(bound, dtype=np.float32).copy()
    if jumps.anywhere:
        return np.zeros_like(bound)
    if not len(tris) or int(jumps.bvh_id) == 0:
        return bound
    corners = np.asarray(verts, dtype=np.float64)[tris]
    centres = corners.mean(axis=1)
    radii = np.linalg.norm(corners - centres[:, None], axis=2).max(axis=1) * (1.0 + 1e-5) + 1e-6  # (float32)
    device = jumps.spheres.device
    out = wp.array(bound, dtype=wp.float32, device=device)
    args = [
        wp.array(x.astype(np.float32), dtype=t, device=device) for x, t in ((centres, wp.vec3), (radii, wp.float32))
    ]
    wp.launch(_clear_kernel, len(tris), inputs=[jumps.bvh_id, jumps.spheres, *args, out], device=device)
    return out.numpy()
