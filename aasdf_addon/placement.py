"""Where a cached field can be placed, and under which key a field is kept: duplicates share fields at any scale.

A field built under one world matrix is placed where another puts its object by the similarity between the two
(``placement``), a rigid motion and a uniform scale within ``PLACE_MAX_SCALE``; the boolean resamples it there. A field
is kept under its geometry's key (``cache.geometry_key``). An object that a field of its geometry cannot reach that
way gets one of its own (``field_key``): under a uniform scale (mirrored or not), one per step of the voxel ladder
(``VOXEL_STEPS_PER_OCTAVE``), built at that step's scale, whatever the object's location, so duplicates at the same
scale, or within half a step of it, share one; under an uneven scale or a shear, one keyed by its whole world matrix.
"""

import hashlib

import numpy as np

from . import cache, transforms

# Steps of the voxel ladder per octave of size (a step is 2^(1/4), about 19 %).
VOXEL_STEPS_PER_OCTAVE = 4
# A cached field is placed where its object now is when that takes a rigid motion and a uniform scale within this
# factor of the one it was built under (half a ladder step); beyond it (or under an uneven scale or shear) it is not.
PLACE_MAX_SCALE = 2.0 ** (0.5 / VOXEL_STEPS_PER_OCTAVE)


def placement(matrix_now, matrix_built):
    """The similarity moving a field built under ``matrix_built`` to where ``matrix_now`` puts its object, or None
    when that needs an uneven scale, a shear or too large a scale (``PLACE_MAX_SCALE``), or either matrix has no
    inverse."""
    if not (transforms.invertible(matrix_now) and transforms.invertible(matrix_built)):
        return None
    relative = np.asarray(matrix_now, dtype=np.float64) @ np.linalg.inv(np.asarray(matrix_built, dtype=np.float64))
    linear = relative[:3, :3]
    scale = float(np.cbrt(abs(np.linalg.det(linear))))
    if not scale > 0.0 or max(scale, 1.0 / scale) > PLACE_MAX_SCALE * (1.0 + 1e-9):
        return None
    rotation = linear / scale
    if not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6):
        return None
    return relative


def ladder_scale(matrix):
    """``(step, matrix at that step's scale)`` for a similarity (a uniform scale ``s`` of a rotation or a mirror):
    the step of ``s`` on the voxel ladder nearest to it, and ``matrix`` with its scale set to ``2 ** (step / 4)``;
    None under an uneven scale or a shear."""
    matrix = np.asarray(matrix, dtype=np.float64)
    linear = matrix[:3, :3]
    scale = float(np.cbrt(abs(np.linalg.det(linear))))
    if not scale > 0.0:
        return None
    rotation = linear / scale
    if not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6):
        return None
    step = int(np.rint(np.log2(scale) * VOXEL_STEPS_PER_OCTAVE))
    snapped = matrix.copy()
    snapped[:3, :3] = rotation * 2.0 ** (step / VOXEL_STEPS_PER_OCTAVE)
    return step, snapped


def field_key(key: str, matrix, missing: dict):
    """Where an object's field comes from: ``(key, matrix to build under, (field, matrix built under) or None)``.

    The geometry's own ``key`` when a field under it (cached, or in ``missing``: key -> (matrix to build under,
    operands), about to be built) can be placed where ``matrix`` puts the object, or nothing is there yet; else a key
    of the object's own (see the module's docstring). A found field is counted as a cache hit.
    """
    candidates = [(key, np.asarray(matrix, dtype=np.float64))]
    snapped = ladder_scale(matrix)
    if snapped is not None:
        candidates.append((f"{key}:scale{snapped[0]}", snapped[1]))
    else:
        candidates.append((f"{key}:{hashlib.blake2b(np.asarray(matrix).tobytes(), digest_size=8).hexdigest()}", matrix))
    for candidate, build in candidates:
        if candidate in missing:
            if placement(matrix, missing[candidate][0]) is not None:
                return candidate, missing[candidate][0], None
            continue
        found = cache.find(candidate)
        if found is None or placement(matrix, found[1]) is not None:
            return candidate, build, found
    return candidates[-1][0], candidates[-1][1], None
