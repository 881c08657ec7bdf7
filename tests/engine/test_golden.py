"""Golden fingerprints: the fields, booleans and surfaces of a few fixed cases, hashed bit for bit.

A change meant to move no number (a refactor, a faster kernel computing the same thing) must keep every
fingerprint. A change meant to move results updates ``golden.json`` in the same commit, by running
``python tests/engine/test_golden.py --write`` and saying in the commit message why the numbers moved.
"""

import hashlib
import json
import sys
from pathlib import Path

if __name__ == "__main__":  # run as a script: the repository root on the path and BLAS's kernels pinned, as the
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # test harness does (tests/conftest.py)
    import tests.conftest  # noqa: F401

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import engine
from tests.support import load_mesh

GOLDEN = Path(__file__).with_name("golden.json")
RES = 128


def _digest(*arrays) -> str:
    digest = hashlib.blake2b(digest_size=12)
    for array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(str((array.dtype.str, array.shape)).encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


# Cases whose sharp surface (dual contouring with creases) is fingerprinted too.
SHARP_CASES = ("spot - bunny",)


def field_fingerprint(field, sharp: bool = False) -> dict:
    """Per level, a hash of its nodes' Morton codes and values; one of the marching-cubes surface; with ``sharp``
    one of the sharp surface and its crease edges."""
    codes, values = field.codes.numpy(), field.values.numpy()
    levels = [_digest(codes[field.level_slice(k)], values[field.level_slice(k)]) for k in range(field.levels)]
    verts, tris = field.to_mesh(sharp=False)
    fingerprint = {"levels": levels, "counts": list(field.level_counts), "surface": _digest(verts, tris)}
    if sharp:
        fingerprint["sharp"] = _digest(*field.to_mesh(sharp=True, return_creases=True))
    return fingerprint


def _voxel(*meshes) -> float:
    points = np.concatenate([m[0] for m in meshes])
    return float(np.linalg.norm(points.max(0) - points.min(0)) / RES)


def _cases():
    spot = load_mesh("spot.obj")
    bunny = load_mesh("stanford-bunny.obj")
    # the bunny scaled to spot's size and moved into it: an open operand in both booleans
    scaled = ((bunny[0] - bunny[0].mean(0)) * 6.0 + spot[0].mean(0) + np.float32([0.2, 0.1, 0.0])).astype(np.float32)
    yield "spot", lambda: engine.build_field(*spot, voxel_size=_voxel(spot))
    yield "bunny", lambda: engine.build_field(*bunny, voxel_size=_voxel(bunny))

    def pair():
        h = _voxel(spot, (scaled, bunny[1]))
        return engine.build_fields([spot, (scaled, bunny[1])], voxel_size=h)

    yield "spot - bunny", lambda: engine.difference(*pair())
    yield "spot | bunny blend", lambda: engine.union(*pair(), blend=0.05)


def fingerprints() -> dict:
    return {name: field_fingerprint(make(), name in SHARP_CASES) for name, make in _cases()}


@pytest.mark.parametrize("name", [name for name, _ in _cases()])
def test_fields_and_surfaces_match_their_golden_fingerprints(name):
    expected = json.loads(GOLDEN.read_text())[name]
    make = dict(_cases())[name]
    assert field_fingerprint(make(), name in SHARP_CASES) == expected


if __name__ == "__main__":
    got = fingerprints()
    if "--write" in sys.argv:
        GOLDEN.write_text(json.dumps(got, indent=1) + "\n")
    print(json.dumps(got, indent=1))
