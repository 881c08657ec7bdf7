"""Where a field sits in the world: a similarity transform (rotation or reflection, uniform scale, translation).

A field is built in its mesh's own frame; ``AdaptiveField.transformed(matrix)`` places it without rebuilding anything.
Distances scale with the uniform scale and keep their sign (a reflection turns the surface over but not its inside),
so every query maps world points to the field's frame, reads the field there and scales the distance back; a boolean
resamples a placed operand onto its own lattice from the operand's cells, as it does an operand of another spacing.
A matrix that scales unevenly or shears is refused: such a mesh needs a field of its own.
"""

from __future__ import annotations

import numpy as np


class Placement:
    """``world = scale * rotation @ local + translation``.

    Attributes:
        rotation: (3, 3) float64 orthonormal (a reflection when its determinant is -1).
        scale: Positive uniform scale.
        translation: (3,) float64.
    """

    def __init__(self, matrix):
        matrix = np.asarray(matrix, dtype=np.float64)
        if matrix.shape != (4, 4):
            raise ValueError(f"Expected a (4, 4) 'matrix', but got {matrix.shape}.")
        if not np.all(np.isfinite(matrix)):
            raise ValueError("Expected a finite 'matrix', but got NaN or infinite entries.")
        if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
            raise ValueError(f"Expected an affine 'matrix' (last row 0, 0, 0, 1), but got {matrix[3].tolist()}.")
        linear = matrix[:3, :3]
        scales = np.linalg.norm(linear, axis=0)
        scale = float(scales.mean())
        if not scale > 0.0:
            raise ValueError("Expected a 'matrix' that keeps volume, but it collapses space.")
        rotation = linear / scale
        if not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-5):
            raise ValueError(
                "Expected a rotation, a uniform scale and a translation, but the matrix scales unevenly or shears "
                f"(axis scales {', '.join(f'{s:.4g}' for s in scales)}): build a field of the transformed mesh instead."
            )
        self.matrix = matrix
        self.rotation = rotation
        self.scale = scale
        self.translation = matrix[:3, 3].copy()

    @property
    def is_identity(self) -> bool:
        return bool(np.allclose(self.matrix, np.eye(4), rtol=0.0, atol=1e-12))

    @property
    def mirrors(self) -> bool:
        return bool(np.linalg.det(self.rotation) < 0.0)

    def then(self, matrix) -> Placement:
        """This placement followed by ``matrix`` (another similarity)."""
        return Placement(np.asarray(matrix, dtype=np.float64) @ self.matrix)

    def to_world(self, points) -> np.ndarray:
        """(N, 3) float64 world positions of (N, 3) points of the field's frame."""
        return self.scale * (np.asarray(points, dtype=np.float64) @ self.rotation.T) + self.translation

    def to_local(self, points) -> np.ndarray:
        """(N, 3) float64 positions in the field's frame of (N, 3) world points."""
        return ((np.asarray(points, dtype=np.float64) - self.translation) @ self.rotation) / self.scale

    def place_surface(self, verts, tris) -> tuple[np.ndarray, np.ndarray]:
        """A surface extracted in the field's own frame, placed: float32 vertices moved and, for a reflection, every
        triangle turned over so it still faces out."""
        verts = self.to_world(verts).astype(np.float32)
        return verts, np.ascontiguousarray(tris[:, ::-1]) if self.mirrors else tris

    def content_box(self, lo, hi, verts) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) world corners of the box around ``verts`` (the field's frame) placed, grown by the narrowest
        margin of the domain (lo, hi) beyond them: what a placed field holds, where the box around its turned domain
        (``box``) reaches far beyond it (spot turned 17 degrees about two axes: a box of 2.8 times the volume, a
        boolean's top level of 1.9 times the nodes)."""
        own_lo, own_hi = verts.min(axis=0), verts.max(axis=0)
        margin = self.scale * float(min((own_lo - lo).min(), (hi - own_hi).min()))
        placed = self.to_world(verts)
        return placed.min(axis=0) - margin, placed.max(axis=0) + margin

    def box(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) world corners of the box (lo, hi) of the field's frame, placed."""
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        world = self.to_world(corners)
        return world.min(axis=0), world.max(axis=0)
