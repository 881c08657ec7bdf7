"""The other leaves of a boolean read at a kept-faces judge's samples in one launch for all of them.

A judge (:mod:`.keep`) reads each other leaf near its samples: the leaf's field, linearly, for its sign (and its value
where it has no mesh), and its mesh's distance (:mod:`.otherleaves`). One launch per leaf and query costs 0.2-1 ms
of Python whatever its size, and a plate's judge with 100 bores read 1,500 of them over its rounds, each bore's judge
its neighbours' a round. Here every (leaf, sample) pair is a thread of one launch: the leaves' field arguments are an
array of structs, their BVHs an array of ids; the values are those of ``AdaptiveField.sample(method="linear")`` and
:func:`.sources.mesh_distances`, bit for bit (the same device functions, the points placed in each leaf's frame by
its own placement as ``sample`` places them).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .parallel import launch_split
from .queries import linear_value
from .sampling import FieldArg


@wp.kernel(enable_backward=False)
def _reads_kernel(
    fields: wp.array[FieldArg],
    meshes: wp.array[wp.uint64],
    leaf: wp.array[wp.int32],
    frame: wp.array[wp.vec3],
    world: wp.array[wp.vec3],
    reach: float,
    query: int,
    values: wp.array[wp.float32],
    distance: wp.array[wp.float32],
):
    """Pair ``i``: leaf ``leaf[i]``'s linear value at ``frame[i]`` (its own frame) and, with ``query`` 1, its mesh's
    distance from ``world[i]`` (``reach`` where farther, or where the leaf has no mesh)."""
    i = wp.tid()
    j = leaf[i]
    values[i] = linear_value(fields[j], frame[i])
    distance[i] = reach
    mesh = meshes[j]
    if mesh != wp.uint64(0) and query == 1:
        q = wp.mesh_query_point_no_sign(mesh, world[i], reach)
        if q.result:
            distance[i] = wp.length(world[i] - wp.mesh_eval_position(mesh, q.face, q.u, q.v))


class LeafReads:
    """The leaves of a boolean (``leaves``, with their BVHs ``bvhs``: :func:`.otherleaves.leaf_bvh`, None for a leaf
    without a mesh), read together (:meth:`read`). A leaf built on demand refines what it reads first (its own
    ``sample``): ``batched`` is False for it, and its callers read it alone."""

    def __init__(self, leaves: list, bvhs: list, device):
        self.device = device
        self.batched = [getattr(leaf, "refiner", None) is None for leaf in leaves]
        self.leaves = leaves
        self.fields = wp.array([leaf.arg() for leaf in leaves], dtype=FieldArg, device=device)
        ids = [0 if bvh is None else int(bvh.id) for bvh in bvhs]
        self.meshes = wp.array(np.array(ids, dtype=np.uint64), dtype=wp.uint64, device=device)

    def read(self, parts: list, reach: float, distances: bool = True) -> list:
        """Per part ``(j, points)`` (a batched leaf and (M, 3) float32 world points): ``(values, distance)`` (M,)
        float32 each, the leaf's linear value (in world units) and its mesh's distance up to ``reach`` (with
        ``distances``; else ``reach``)."""
        sizes = [len(points) for _, points in parts]
        n = int(sum(sizes))
        if not n:
            return [(np.zeros(0, np.float32), np.zeros(0, np.float32)) for _ in parts]
        world = np.concatenate([np.asarray(points, dtype=np.float32) for _, points in parts]).reshape(-1, 3)
        frame = np.concatenate([self._in_frame(j, points) for j, points in parts]).reshape(-1, 3)
        leaf = np.repeat(np.array([j for j, _ in parts], dtype=np.int32), sizes)
        device = self.device
        args = [
            wp.array(a, dtype=t, device=device)
            for a, t in ((leaf, wp.int32), (np.ascontiguousarray(frame), wp.vec3), (world, wp.vec3))
        ]
        values = wp.empty(n, dtype=wp.float32, device=device)
        distance = wp.empty(n, dtype=wp.float32, device=device)
        launch_split(
            _reads_kernel,
            n,
            lambda lo, k: [
                self.fields, self.meshes, *(a[lo : lo + k] for a in args), float(reach), int(distances),
                values[lo : lo + k], distance[lo : lo + k],
            ],
            device,
        )  # fmt: skip
        values, distance = values.numpy(), distance.numpy()
        out, start = [], 0
        for (j, _), size in zip(parts, sizes, strict=True):
            placement = self.leaves[j].placement
            v = values[start : start + size]
            out.append((v if placement is None else v * np.float32(placement.scale), distance[start : start + size]))
            start += size
        return out

    def _in_frame(self, j: int, points: np.ndarray) -> np.ndarray:
        """(M, 3) float32 world ``points`` in leaf ``j``'s own frame, as its ``sample`` places them."""
        placement = self.leaves[j].placement
        pts = np.asarray(points, dtype=np.float32)
        return pts if placement is None else np.ascontiguousarray(placement.to_local(pts), dtype=np.float32)
