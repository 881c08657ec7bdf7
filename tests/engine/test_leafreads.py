"""The other leaves of a boolean read together at a kept-faces judge's samples (engine/leafreads.py), and a triangle's
many sign columns compared by one hash (engine/samples.same_all_over)."""

import numpy as np

import engine
from engine.leafreads import LeafReads
from engine.otherleaves import leaf_bvh
from engine.samples import HASHED_FROM, same_all_over, triangle_samples
from engine.sources import mesh_distances
from tests.metrics import mesh_volume
from tests.support import box_mesh, cylinder_mesh, is_watertight, rotation


def test_leaves_read_together_give_each_leafs_own_reads_bit_for_bit():
    ball = cylinder_mesh(0.3, 0.8, segments=24, center=(0.2, 0.0, 0.0))
    cube = box_mesh((0.4, 0.3, 0.5), center=(-0.1, 0.1, 0.0))
    fa, fb = engine.build_fields([ball, cube], voxel_size=0.02)
    matrix = np.eye(4)
    matrix[:3, :3] = 1.3 * rotation(2, 23.0)
    matrix[:3, 3] = (0.05, -0.1, 0.02)
    leaves = [fa, fb.transformed(matrix), engine.offset(fa, 0.05)]  # plain, placed (turned, scaled), no mesh
    bvhs = [leaf_bvh(leaf, "cpu") for leaf in leaves]
    assert bvhs[0] is not None and bvhs[1] is not None and bvhs[2] is None
    reads = LeafReads(leaves, bvhs, "cpu")
    rng = np.random.default_rng(2)
    parts = [(j, rng.uniform(-0.8, 0.8, size=(n, 3)).astype(np.float32)) for j, n in ((1, 500), (0, 300), (2, 40))]
    parts.append((0, np.zeros((0, 3), np.float32)))
    for (j, points), (values, distance) in zip(parts, reads.read(parts, 0.07), strict=True):
        assert np.array_equal(values, leaves[j].sample(points, method="linear"))
        want = (
            np.full(len(points), 0.07, np.float32) if bvhs[j] is None else mesh_distances(bvhs[j], points, 0.07, "cpu")
        )
        assert np.array_equal(distance, want)
    values, distance = reads.read(parts[:1], 0.07, distances=False)[0]
    assert np.array_equal(values, leaves[1].sample(parts[0][1], method="linear")) and (distance == 0.07).all()


def test_many_sign_columns_compared_by_one_hash_say_what_each_column_says():
    verts = np.random.default_rng(3).uniform(0.0, 4.0, size=(60, 3))
    tris = np.random.default_rng(4).integers(0, 60, size=(80, 3))
    points, first = triangle_samples(verts, tris, np.full(len(tris), 0.5), "cpu")
    rng = np.random.default_rng(5)
    for count in (HASHED_FROM - 1, HASHED_FROM, 40):
        columns = [np.ones(len(points), np.int8) for _ in range(count)]
        for column in columns[::3]:  # a few samples of some columns differ
            column[rng.integers(0, len(points), 4)] = rng.choice([-1, 0], 4)
        want = np.ones(len(tris), dtype=bool)
        for column in columns:
            corners = column[tris]
            for t in range(len(tris)):
                own = column[len(verts) + first[t] : len(verts) + first[t + 1]]
                values = np.r_[corners[t], own]
                want[t] &= values.min() == values.max()
        got = same_all_over(columns, tris, len(verts), first)
        assert np.array_equal(got, want) and 0 < got.sum() < len(tris), count


def test_a_plate_with_many_bores_reads_them_together_and_keeps_what_reading_each_keeps(monkeypatch):
    plate = box_mesh((1.0, 1.0, 0.1))
    xs = np.linspace(-0.6, 0.6, 4)
    bores = [cylinder_mesh(0.08, 0.6, segments=16, center=(x, y, 0.0)) for x in xs for y in xs]
    fields = engine.build_fields([plate, *bores], voxel_size=np.linalg.norm([2.0, 2.0, 0.6]) / 128, refine="auto")

    def cut():
        cutters = fields[1:]
        while len(cutters) > 1:
            cutters = [engine.union(*cutters[i : i + 2]) for i in range(0, len(cutters), 2)]
        return engine.difference(fields[0], cutters[0], seams=True).kept_surface()

    launches = []
    sample = engine.AdaptiveField.sample
    monkeypatch.setattr(engine.AdaptiveField, "sample", lambda f, *a, **k: launches.append(1) or sample(f, *a, **k))
    together = cut()
    read_together = len(launches)
    launches.clear()
    monkeypatch.setattr(LeafReads, "__init__", _one_by_one(LeafReads.__init__))
    alone = cut()
    assert read_together < 0.35 * len(launches), (read_together, len(launches))  # measured 34 of 272
    for key in ("verts", "tris", "kept", "triangle_id"):
        assert np.array_equal(together[key], alone[key])
    assert is_watertight(together["tris"]) and together["kept"].sum() > 1000  # measured 3,084
    volume = 0.8 - 16 * np.pi * 0.08**2 * 0.2 * np.sin(2 * np.pi / 16) * 16 / (2 * np.pi)  # the 16-sided bores
    assert abs(mesh_volume(together["verts"], together["tris"]) - volume) < 0.0008 * volume  # measured 0.028 %


def _one_by_one(init):
    def one_by_one(self, leaves, bvhs, device):
        init(self, leaves, bvhs, device)
        self.batched = [False] * len(leaves)  # each leaf read in launches of its own, as before

    return one_by_one


def test_rows_found_together_are_the_rows_box_by_box():
    from engine.otherleaves import NearRows

    rng = np.random.default_rng(7)
    partial = 0
    for trial in range(24):  # thin, far, tiny, huge and everywhere boxes about clouds of every spread
        points = rng.random((int(rng.integers(1, 3000)), 3)) * rng.choice([1e-3, 1.0, 1e6]) + rng.choice([-100.0, 3.0])
        points[:, trial % 3] *= rng.choice([1.0, 1e-4])
        points = points.astype(np.float32 if trial % 2 else np.float64)
        low, high = points.min(axis=0), points.max(axis=0)
        boxes = []
        for k in range(20):
            centre = (low + (high - low) * rng.uniform(-0.3, 1.3, 3)).astype(np.float32)
            half = ((high - low) * rng.choice([0.0, 0.01, 0.1, 2.0]) * rng.random(3)).astype(np.float32)
            boxes.append(None if k % 9 == 0 else (centre - half, centre + half))
        near = NearRows([None] * 20, [None] * 20, boxes)
        pad = float((high - low).max() * rng.choice([0.0, 0.01, 0.1]))
        together = near.rows_of(list(range(20)), NearRows.index(points), pad)
        for j in range(20):
            assert np.array_equal(together[j], near.rows(j, NearRows.index(points), pad)), (trial, j)
            partial += 0 < len(together[j]) < len(points)
    assert partial > 60  # boxes that hold some of the points, not none or all (measured 135 of 480)
