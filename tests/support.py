"""Helpers shared by tests and benchmarks: mesh loading and analytic test shapes (no bpy)."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED_MESHES = ROOT.parent / "shared" / "meshes"
SAMPLE_MESHES = ROOT / "samples"


def mesh_path(name: str) -> Path:
    """Path of a test mesh: the repository's bundled samples first, then ``../shared/meshes``."""
    for folder in (SAMPLE_MESHES, SHARED_MESHES):
        path = folder / name
        if path.exists():
            return path
    raise FileNotFoundError(f"No test mesh named {name!r} in {SAMPLE_MESHES} or {SHARED_MESHES}")


def load_obj(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a Wavefront .obj as (V,3) float32 vertices and (T,3) int32 triangles (polygons fan-triangulated)."""
    verts, faces = [], []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for line in handle:
            if line.startswith("v "):
                verts.append(line.split()[1:4])
            elif line.startswith("f "):
                idx = [int(tok.split("/")[0]) for tok in line.split()[1:]]
                faces.append(idx)
    vertices = np.asarray(verts, dtype=np.float64).astype(np.float32)
    tris = []
    for poly in faces:
        poly = [i - 1 if i > 0 else len(vertices) + i for i in poly]
        tris.extend((poly[0], poly[k], poly[k + 1]) for k in range(1, len(poly) - 1))
    return vertices, np.asarray(tris, dtype=np.int32).reshape(-1, 3)


def load_mesh(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Load a named test mesh (e.g. ``"spot.obj"``): fresh arrays each call, the file read once a process (the
    bunny's takes half a second)."""
    verts, tris = _read_mesh(name)
    return verts.copy(), tris.copy()


@functools.cache
def _read_mesh(name: str) -> tuple[np.ndarray, np.ndarray]:
    return load_obj(mesh_path(name))


def sample_points(verts, tris, h: float, n: int, seed: int = 0) -> np.ndarray:
    """(n, 3) float32 points around a mesh: half uniform in its bounding box grown by 5 % of its diagonal on every side
    (a flat mesh's box too has a volume), half near its surface (area-weighted surface samples moved by isotropic
    normal noise of ``h``, and of ``4 h`` for every other one)."""
    rng = np.random.default_rng(seed)
    verts = np.asarray(verts, dtype=np.float64)
    tris = np.asarray(tris)
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    pad = 0.05 * float(np.linalg.norm(hi - lo))
    uniform = rng.uniform(lo - pad, hi + pad, size=(n // 2, 3))
    m = n - n // 2
    face = rng.integers(0, len(tris), m)
    base = (verts[tris[face]] * rng.dirichlet([1.0, 1.0, 1.0], m)[:, :, None]).sum(axis=1)
    noise = rng.normal(0.0, 1.0, (m, 3)) * np.where(np.arange(m) % 2 == 0, h, 4.0 * h)[:, None]
    return np.concatenate([uniform, base + noise]).astype(np.float32)


def uv_sphere(radius: float = 1.0, center=(0.0, 0.0, 0.0), rings: int = 48, segments: int = 96):
    """A closed, outward-oriented UV sphere: (V,3) float32, (T,3) int32."""
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    verts = np.concatenate([[[0.0, 0.0, 1.0]], ring, [[0.0, 0.0, -1.0]]]) * radius + np.asarray(center)
    top, bottom = 0, len(verts) - 1
    idx = 1 + np.arange((rings - 1) * segments).reshape(rings - 1, segments)
    nxt = np.roll(idx, -1, axis=1)
    cap_top = np.stack([np.full(segments, top), idx[0], nxt[0]], axis=1)
    cap_bot = np.stack([np.full(segments, bottom), nxt[-1], idx[-1]], axis=1)
    a, b, c, d = idx[:-1], nxt[:-1], idx[1:], nxt[1:]
    quads = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])
    tris = np.concatenate([cap_top, quads, cap_bot]).astype(np.int32)
    return verts.astype(np.float32), tris


def box_mesh(half=(1.0, 1.0, 1.0), center=(0.0, 0.0, 0.0), subdivisions: int = 1):
    """A closed, outward-oriented axis-aligned box, each face split into ``subdivisions``² quads."""
    n = subdivisions
    g = np.linspace(-1.0, 1.0, n + 1)
    verts, tris = [], []
    for axis in range(3):
        for side in (-1.0, 1.0):
            u, v = np.meshgrid(g, g, indexing="ij")
            pts = np.zeros((n + 1, n + 1, 3))
            a1, a2 = (axis + 1) % 3, (axis + 2) % 3
            pts[..., axis] = side
            pts[..., a1] = u
            pts[..., a2] = v
            base = sum(len(x) for x in verts)
            verts.append(pts.reshape(-1, 3))
            ids = base + np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
            q00, q10, q01, q11 = ids[:-1, :-1], ids[1:, :-1], ids[:-1, 1:], ids[1:, 1:]
            t1 = np.stack([q00, q10, q11], -1).reshape(-1, 3)
            t2 = np.stack([q00, q11, q01], -1).reshape(-1, 3)
            faces = np.concatenate([t1, t2])
            if side < 0:
                faces = faces[:, ::-1]
            tris.append(faces)
    verts = np.concatenate(verts) * np.asarray(half) + np.asarray(center)
    verts, inverse = np.unique(np.round(verts, 9), axis=0, return_inverse=True)
    tris = inverse.reshape(-1)[np.concatenate(tris)]
    return verts.astype(np.float32), tris.astype(np.int32)


def torus_mesh(major: float = 1.0, minor: float = 0.35, rings: int = 96, segments: int = 48):
    """A closed, outward-oriented torus around the z axis."""
    u = np.linspace(0.0, 2.0 * np.pi, rings, endpoint=False)
    v = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    x = (major + minor * np.cos(vv)) * np.cos(uu)
    y = (major + minor * np.cos(vv)) * np.sin(uu)
    z = minor * np.sin(vv)
    verts = np.stack([x, y, z], -1).reshape(-1, 3)
    ids = np.arange(rings * segments).reshape(rings, segments)
    a, b = ids, np.roll(ids, -1, axis=0)
    c, d = np.roll(ids, -1, axis=1), np.roll(np.roll(ids, -1, axis=0), -1, axis=1)
    tris = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return verts.astype(np.float32), tris.astype(np.int32)


def signed_volume(verts, tris) -> float:
    """Volume enclosed by a closed, outward-oriented triangle mesh (divergence theorem)."""
    v = np.asarray(verts, dtype=np.float64)[np.asarray(tris)]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def edge_use_counts(tris) -> np.ndarray:
    """How many triangles use each undirected edge (a watertight 2-manifold gives 2 everywhere)."""
    t = np.asarray(tris, dtype=np.int64)
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e[:, 0] * (int(t.max(initial=0)) + 1) + e[:, 1], return_counts=True)
    return counts


def is_watertight(tris) -> bool:
    """Every undirected edge is shared by exactly two triangles, and each directed edge appears once."""
    t = np.asarray(tris, dtype=np.int64)
    if len(t) == 0:
        return False
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    codes = directed[:, 0] * (int(t.max()) + 1) + directed[:, 1]
    if len(np.unique(codes)) != len(codes):
        return False
    return bool(np.all(edge_use_counts(t) == 2))


def cylinder_mesh(radius: float = 1.0, height: float = 2.0, segments: int = 96, center=(0.0, 0.0, 0.0)):
    """A closed, outward-oriented cylinder along z: (V,3) float32, (T,3) int32."""
    ang = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(ang), radius * np.sin(ang)], axis=1)
    bottom = np.c_[ring, np.full(segments, -height / 2)]
    top = np.c_[ring, np.full(segments, height / 2)]
    verts = np.vstack([bottom, top, [[0, 0, -height / 2], [0, 0, height / 2]]]) + np.asarray(center)
    i = np.arange(segments)
    j = (i + 1) % segments
    cb, ct = 2 * segments, 2 * segments + 1
    sides = np.r_[np.c_[i, j, segments + j], np.c_[i, segments + j, segments + i]]
    caps = np.r_[np.c_[np.full(segments, cb), j, i], np.c_[np.full(segments, ct), segments + i, segments + j]]
    return verts.astype(np.float32), np.r_[sides, caps].astype(np.int32)


def hex_prism_mesh(circumradius: float = 1.0, height: float = 2.0):
    """A closed, outward-oriented hexagonal prism along z, centred at the origin (a cylinder of 6 segments)."""
    return cylinder_mesh(circumradius, height, segments=6)


def rotation(axis: int, degrees: float) -> np.ndarray:
    """(3, 3) float64 rotation by ``degrees`` about coordinate axis ``axis`` (0 = x, 1 = y, 2 = z)."""
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    a, b = [k for k in range(3) if k != axis]
    m = np.eye(3)
    m[a, a], m[a, b], m[b, a], m[b, b] = c, -s, s, c
    return m


def quaternion_turn(w: float, x: float, y: float, z: float) -> np.ndarray:
    """(3, 3) the rotation of the unit quaternion ``w + xi + yj + zk`` (as the random sweeps draw them)."""
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def placed(mesh, turn: np.ndarray, shift) -> tuple:
    """``mesh`` (verts, tris) turned by ``turn`` (3, 3) about the origin, then moved by ``shift``: float32 vertices."""
    return (np.asarray(mesh[0], dtype=np.float64) @ turn.T + shift).astype(np.float32), mesh[1]


def normalised(mesh, center=(0.0, 0.0, 0.0), diagonal: float = 1.0, matrix=None):
    """``mesh`` (verts, tris) moved so its bounding box is centred at ``center`` with diagonal ``diagonal``, after
    the (3, 3) ``matrix`` (applied about the box centre) when given."""
    verts, tris = mesh
    v = np.asarray(verts, dtype=np.float64)
    v = (v - 0.5 * (v.min(0) + v.max(0))) * (diagonal / np.linalg.norm(v.max(0) - v.min(0)))
    if matrix is not None:
        v = v @ np.asarray(matrix, dtype=np.float64).T
    return (v + np.asarray(center, dtype=np.float64)).astype(np.float32), np.asarray(tris, dtype=np.int32)


def cad_pairs() -> dict:
    """The CAD-like boolean cases of the sharp-edge extraction, each operand normalised to bounding-box diagonal 1
    (creases at angles the lattice resolves: no wedge sharper than about 45 degrees): name -> (operation, operand a,
    operand b), ``DIFFERENCE`` meaning a minus b."""
    cube = box_mesh()
    tilt = rotation(0, 30.0) @ rotation(1, 30.0)
    r = 0.12  # a cylinder of radius r and diagonal 1 along z
    bore = normalised(cylinder_mesh(r, np.sqrt(1.0 - 8.0 * r * r), segments=128))
    turn = rotation(2, 20.0) @ rotation(0, 10.0)
    return {
        "fandisk - cylinder": (
            "DIFFERENCE",
            normalised(load_mesh("fandisk.obj")),
            normalised(bore, center=(0.0, 0.05, -0.05), matrix=rotation(1, 90.0)),
        ),
        "rocker-arm - cube": (
            "DIFFERENCE",
            normalised(load_mesh("rocker-arm.obj")),
            normalised(cube, center=(0.0, -0.25, -0.3), diagonal=0.6, matrix=rotation(2, 10.0) @ rotation(0, 15.0)),
        ),
        "cube | tilted cube": ("UNION", normalised(cube), normalised(cube, matrix=tilt)),
        "cube - bore": ("DIFFERENCE", normalised(cube, matrix=turn), normalised(bore, matrix=turn)),
        "hex prism & sphere": (
            "INTERSECT",
            normalised(hex_prism_mesh(1.0, 4.0), matrix=rotation(0, 25.0) @ rotation(2, 10.0)),
            normalised(uv_sphere(1.0, rings=96, segments=192)),
        ),
    }


def plate_and_bores(bore_segments: int = 36):
    """A 12-triangle plate (2 x 2 x 0.2) and four bores through it (cylinders of radius 0.2, ``bore_segments`` sides,
    one mesh): the plate minus the bores is the CAD case whose exact result has 604 triangles."""
    plate = box_mesh(half=(1.0, 1.0, 0.1))
    parts = [
        cylinder_mesh(0.2, 0.6, segments=bore_segments, center=(x, y, 0.0)) for x in (-0.5, 0.5) for y in (-0.5, 0.5)
    ]
    offsets = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])
    verts = np.concatenate([v for v, _ in parts]).astype(np.float32)
    tris = np.concatenate([t + o for (_, t), o in zip(parts, offsets, strict=True)]).astype(np.int32)
    return plate, (verts, tris)


def overlapping_boxes():
    """Two unit boxes (diagonal 1), the second's centre at (0.25, 0.2, 0.15), given as one mesh: it passes through
    itself, the faces of each inside the other internal faces."""
    box_v, box_t = normalised(box_mesh(), diagonal=1.0)
    other = normalised(box_mesh(), center=(0.25, 0.2, 0.15), diagonal=1.0)
    return np.concatenate([box_v, other[0]]), np.concatenate([box_t, other[1] + len(box_v)])
