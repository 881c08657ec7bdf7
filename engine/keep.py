"""Which of the operands' own triangles are the result's surface, decided with the fields.

A boolean result keeps its expression (:mod:`.expression`): the operand fields at its leaves. A triangle of a leaf
built from a mesh is *kept* when, everywhere on it (at samples about a voxel apart, their spacing taken as slack),

- every other leaf's surface is farther than the band, and the other leaf's sign is the same all over it (a field
  that jumps across an open mesh's holes is also read a band away along the axes, where its sign must not change);
- none of its own mesh's defects is within the band: open, non-manifold or inconsistently oriented edges, duplicated
  triangles; and its own field crosses it from inside to outside everywhere (no part of it is an internal face of an
  overlapping or self-intersecting shell; where both sides read outside, a part thinner than the field sees, it faces
  the way most of the mesh does; where both read inside across a gap of its mesh narrower than the field sees, it is
  that gap's wall: :mod:`.ownside`);
- its leaf's field changes sign across it, and the expression, with every other leaf's sign as it is there, changes
  sign with it: the triangle is on the result's surface, facing its outside (flipped for a subtracted operand, turned
  outward for an inside-out shell).

A triangle that is only partly so and larger than ``SPLIT_VOXELS`` is split (:func:`.refine.split_triangles`) and its
pieces judged again, so that large faces crossed by a seam keep their far parts; a sliver (a fine cylinder's wall
triangle, a voxel wide and hundreds long) is cut across into pieces about as wide as it is, so that the kept border
near a seam is made of short pieces rather than ever narrower needles (in one pass, where the distances read along it
say the rounds would cut it: :mod:`.precut`), and the kept border's vertices on a straight run of it go
(:func:`.refine.straighten_borders`). A small piece (samples a voxel apart) is split only where a sample reads the
margin a kept piece's must: else one kept there would lie in a pocket between its samples, smaller than its splits
make. Nothing here intersects meshes: the fields decide inside and outside; distances come from the leaves' meshes
(exact, through their BVHs) or fields. The band is ``BAND_VOXELS`` of the result's voxels, widened by the widest
blend. A round's checks run in two kernel launches (:mod:`.judging`), sample by sample (here) for many leaves.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import verdicts
from .coplanar import (
    COPLANAR_VOXELS,
    TIED_OPPOSITE,
    TIED_SAME,
    TIES,
    coplanar_readings,
    coplanar_triangles,
    flush_triangles,
    internal_triangles,
    source_verts_near,
    tied_to_earlier,
    tied_values,
    triangles_near,
    unflushed,
)
from .defects import defects_and
from .expression import evaluate_signs, leaves, widest_blend
from .judging import MAX_TABLE_LEAVES, PARTLY_TIE, FusedJudge, sign_patterns
from .jumps import clear_of
from .leafreads import LeafReads
from .orient import patch_flips
from .otherleaves import (
    NEAR_BOX_VOXELS,
    NearRows,
    box_arrays,
    boxes_meet,
    leaf_boxes,
    leaf_bvh,
    leaf_jumps,
    leaf_margin,
    mesh_leaf,
)
from .ownpart import SPLIT_VOXELS, own_part
from .ownside import THIN, TINY_VOXELS, side_at
from .parallel import run_tasks
from .precut import cut_strips, predicted_margins
from .refine import merge_kept, restore_whole, straighten_borders
from .rounds import DROPPED, KEPT, UNKNOWN, judge_unknown, split_rounds
from .samples import edge_turns, per_triangle_min, same_all_over, triangle_samples
from .slivers import Splitter
from .sources import mesh_distances
from .trimeasures import unit_normals

# Kept faces stay this many result voxels from any other surface and from their mesh's defects: the voxel surface of
# the seams is joined to them there (the join takes about a voxel of it).
BAND_VOXELS = 1.0
# Samples are this many voxels apart; a point of a triangle lies within SLACK of one of its samples.
SAMPLE_VOXELS = 1.0
SLACK_VOXELS = 0.75
MAX_SPLIT_ROUNDS = 24
# A kept border vertex this many voxels or less off the line through its neighbours on the border is collapsed, into
# a border edge of at most STRAIGHT_RUN_VOXELS: a longer one is the apex of a fan of strip triangles as long, which
# cut through the voxel surface where the seam's band is not flat (cube | tilted cube: 1,280 crossing pairs with runs
# as long as the source triangles, 22 with runs of 4 voxels, 186 of 16).
STRAIGHT_VOXELS = 1e-4
STRAIGHT_RUN_VOXELS = 4.0
# Points to keep clear of (where a join gave kept faces up) count as defects this many voxels across (octahedra).
AVOID_VOXELS = 1.0
# Where under one in this many of a leaf's triangles lie in another leaf's planes, the other leaf's flush and inside
# walls are looked for about those alone (:meth:`_Judge._near_coplanar`).
FEW_COPLANAR = 16

FOUND_FLAGS = ("signs_only", "own_only")  # what a judge finds for :mod:`.verdicts` besides each triangle's margin


class _Judge:
    """The checks of one leaf's triangles against the rest of the expression (see the module docstring); ``avoid``
    (P, 3) points count as its own defects (``AVOID_VOXELS`` across)."""

    def __init__(self, field, index: int, source, reads: tuple, fused: bool = True, avoid=None):
        self.expression = field.expression
        self.leaves = leaves(self.expression)
        self.index, self.device, self.voxel = index, field.device, field.voxel_size
        voxel = self.voxel
        self.band = BAND_VOXELS * voxel + widest_blend(self.expression)
        self.spacing, self.slack = SAMPLE_VOXELS * voxel, SLACK_VOXELS * voxel
        self.ray_start = TINY_VOXELS * voxel  # (a gap's wall: :mod:`.ownside`)
        self.tiny = 1e-3 * voxel
        # per leaf :func:`leaf_bvh`, :func:`leaf_jumps`, :func:`leaf_boxes`; and all read together (:mod:`.leafreads`)
        self.bvhs, self.jumps, self.boxes, self.reads = reads
        own = own_part(self.leaves[index], source, voxel, self.device)
        self.tris, self.defects, self.defect_mesh = source.tris.astype(np.int64), own.defects, own.defect_mesh
        self.avoid, self.avoiding = avoid, avoid is not None and len(avoid) > 0
        if self.avoiding:
            self.defect_mesh = defects_and(own.defect_mesh, avoid, 0.5 * AVOID_VOXELS * voxel, self.device)
        # a shell with internal faces (overlapping or self-intersecting) is read a band away on both sides, so that
        # kept faces stay a band from where it crosses itself; a clean one half a voxel away (a band would reach
        # across its own concave creases)
        self.crossing = bool((own.side == 0).any())
        self.side_offset = self.band if self.crossing else own.offset
        self.side, self.thin = own.side, own.thin  # each source triangle's side (and a thin part's)
        self.turns = own.turns  # (the source triangles' longest edges, where found with the own part)
        self.strips = own.strips
        self.fused = self._fused() if fused else None
        self.coplanar = self._coplanar_faces(source)  # (T,) bool or None: sample by sample with their planes
        self.normals = None if self.coplanar is None else unit_normals(source.verts, self.tris)
        self.flush = {}  # (other leaf, whose): :meth:`_flush`
        self.near = NearRows(self.bvhs, self.jumps, self.boxes)  # where each other leaf is read

    def _coplanar_faces(self, source) -> np.ndarray | None:
        """(T,) bool the triangles in another leaf's plane (:func:`.coplanar.coplanar_triangles`) where the
        expression can cross with both: faces that may be kept there once (a union's facing one way, a difference's
        touching); None where there is none (faces that can only be internal there are judged as any), or where the
        expression blends (a blend of two coinciding surfaces moves off both: none of their faces is the result's).
        With more than MAX_TABLE_LEAVES other leaves, every such triangle (their 3^n sign patterns are not listed: 16
        cubes in a row, face to face, took over 4 GB)."""
        if widest_blend(self.expression) > 0.0:
            return None
        if not len(source.verts):
            return None
        meets = boxes_meet(box_arrays(self.boxes), *source.box(), 2.0 * COPLANAR_VOXELS * self.voxel)  # (others: none)
        meshes = [None if j == self.index or not meets[j] else b for j, b in enumerate(self.bvhs)]
        flagged = np.zeros(len(self.tris), dtype=bool)
        for j, bits in enumerate(coplanar_triangles(source.verts, self.tris, meshes, self.voxel, self.device)):
            if bits is not None and self._facing(j) < 0:  # one way is the other's other way
                bits = ((bits & TIED_SAME) << 1) | ((bits & TIED_OPPOSITE) >> 1)
            for bit, tie in TIES if bits is not None else ():
                others = [k for k in range(len(self.leaves)) if k not in (j, self.index)]
                if len(others) > MAX_TABLE_LEAVES:
                    flagged |= (bits & bit) > 0
                    continue
                patterns = sign_patterns(len(others))
                signs = [np.full(len(patterns), tie if k == j else -1, np.int8) for k in range(len(self.leaves))]
                for col, k in enumerate(others):
                    signs[k] = patterns[:, col]
                if self._crossing(signs)[0].any():
                    flagged |= (bits & bit) > 0
        return flagged if flagged.any() else None

    def _fused(self) -> FusedJudge | None:
        """The fused path of this judge (:mod:`.judging`), where there are few enough other leaves for a table of
        their sign patterns."""
        others = [j for j in range(len(self.leaves)) if j != self.index]
        if len(others) > MAX_TABLE_LEAVES:
            return None
        patterns = sign_patterns(len(others))
        signs = [np.zeros(len(patterns), np.int8)] * len(self.leaves)
        for k, j in enumerate(others):
            signs[j] = patterns[:, k]
        crosses, flips = self._crossing(signs)
        return FusedJudge(
            others=[(self.leaves[j], self.bvhs[j], self.jumps[j]) for j in others],
            table=crosses.astype(np.int8) | (flips.astype(np.int8) << 1),
            defect_mesh=self.defect_mesh,
            band=self.band,
            spacing=self.spacing,
            slack=self.slack,
            slack_share=SLACK_VOXELS / SAMPLE_VOXELS,
            sample_share=SAMPLE_VOXELS / SLACK_VOXELS,
            defects=self.defects,
            side=self.side,
            own=self.leaves[self.index],
            crossing=self.crossing,
            side_offset=self.side_offset,
            thin_side=self.thin,
            device=self.device,
            own_rays=self.bvhs[self.index],
            ray_start=self.ray_start,
        )

    def slack_of(self, longest) -> np.ndarray:
        """(T,) the slack of each triangle's checks: its samples' spacing (``SAMPLE_VOXELS`` apart, or an eighth of its
        longest edge when that is more) times ``SLACK_VOXELS / SAMPLE_VOXELS``."""
        return np.maximum(longest / 8.0, self.spacing) * (SLACK_VOXELS / SAMPLE_VOXELS)

    def partly_slack(self, slack) -> np.ndarray:
        """What a piece's largest margin is raised by to be partly keepable (module docstring): its ``slack`` where
        larger than the least, else 0 (bench pairs: the same area kept, a third fewer pieces in the last rounds)."""
        return np.where(np.asarray(slack) > self.slack + PARTLY_TIE * self.spacing, slack, 0.0)

    def margins(self, points: np.ndarray, reach: float) -> np.ndarray:
        """(N,) float32 about how far the other surfaces are from each point: :func:`.precut.predicted_margins`."""
        return predicted_margins(self, points, reach)

    def _readings(self, points: np.ndarray, reach: float, planes=None) -> tuple[np.ndarray, list]:
        """The general path's reading at each point: ``(margin, signs)``, (N,) float32 as :meth:`margins` and per leaf
        (N,) int8 its sign (-1 for the judged leaf itself). With ``planes`` ((N, 3) the points' faces' normals, (N,)
        how far each is read), a mesh leaf's triangles in a point's plane are read as
        :func:`.coplanar.coplanar_readings` reads them: no surface, and where the point lies on one, the leaf's sign
        tied to the face's (+2 / -2)."""
        margin = np.full(len(points), reach, dtype=np.float32)
        signs, indexed = [], self.near.index(points)
        pad = reach + NEAR_BOX_VOXELS * self.voxel
        near_leaf, outside = self.near.near(indexed, pad), None
        plain = [j for j in np.flatnonzero(near_leaf) if j != self.index and (planes is None or self.bvhs[j] is None)]
        read = self.near.read_together(self.reads, indexed, plain, pad, reach)
        for j, other in enumerate(self.leaves):
            if j == self.index:
                signs.append(np.full(len(points), -1, np.int8))
                continue
            if not near_leaf[j]:  # (no row near its box: outside it everywhere, one array for all such leaves)
                outside = np.ones(len(points), np.int8) if outside is None else outside
                signs.append(outside)
                continue
            bvh, near, sign = self.bvhs[j], np.full(len(points), reach, np.float32), np.ones(len(points), np.int8)
            at, values, distance = read.get(j) or (self.near.rows(j, indexed, pad), None, None)
            if not len(at):  # (none near: its surface farther than the reach, and outside it)
                pass
            elif planes is None or bvh is None:
                reading = (self.band, reach, self.device, distance, values, self.band + self.slack)
                near[at], sign[at] = leaf_margin(other, bvh, self.jumps[j], points[at], *reading)
            else:  # where tied, its sign is the tie's: its field is read at the other points alone
                d, tie = self._coplanar(j, points[at], planes[0][at], planes[1][at])
                s, rows = (2 * tie).astype(np.int8), np.flatnonzero(tie == 0)
                d[rows], s[rows] = leaf_margin(
                    other, bvh, self.jumps[j], points[at[rows]], self.band, reach, self.device, d[rows]
                )
                near[at], sign[at] = d, s
            margin = np.minimum(margin, near)
            signs.append(sign)
        if self.defect_mesh is not None:
            margin = np.minimum(margin, mesh_distances(self.defect_mesh, points, reach, self.device))
        return margin, signs

    def _coplanar(self, j: int, points, normals, reach) -> tuple[np.ndarray, np.ndarray]:
        """:func:`.coplanar.coplanar_readings` of leaf ``j``'s mesh at points of this leaf's faces (unit ``normals``);
        where a point lies on that leaf's face, this leaf's own faces out of its plane and not flush with that leaf
        count too: where this leaf's face ends and the other's goes on in the plane, there is a seam."""
        own, bvh = self.bvhs[self.index], self.bvhs[j]
        theirs, their_surface = self._flush(j, "theirs")
        earlier = j < self.index
        distance, tie, live = coplanar_readings(
            bvh, own, theirs, points, normals, reach, self.voxel, self.device, earlier, surface=their_surface
        )
        tied = np.flatnonzero(live)  # (tied to a face inside the result, as where it only touches: no seam of ours)
        if len(tied):
            ours, our_surface = self._flush(j, "ours")
            ends, _, _ = coplanar_readings(
                own, bvh, ours, points[tied], normals[tied], reach[tied], self.voxel, self.device, across=True,
                surface=our_surface,
            )  # fmt: skip
            distance[tied] = np.minimum(distance[tied], ends)
        return distance, tie * np.int8(self._facing(j))

    def _facing(self, j: int) -> int:
        """-1 where exactly one of this leaf and leaf ``j`` is placed by a reflection: its triangles, turned with
        it, face inwards, so a face of one facing the other's way does so the other way round; else 1."""
        mirrors = [getattr(self.leaves[k].placement, "mirrors", False) for k in (self.index, j)]
        return -1 if mirrors[0] != mirrors[1] else 1

    def _flush(self, j: int, whose: str) -> tuple:
        """(flags as a Warp array, :func:`.coplanar.unflushed` BVH) of leaf ``j``'s triangles flush with this leaf's
        and inside the result (``"theirs"``), or of this leaf's flush with ``j``'s (``"ours"``): found once a judge,
        when first needed."""
        if (j, whose) not in self.flush:
            own, bvh = self.bvhs[self.index], self.bvhs[j]
            mesh, other = (bvh, own) if whose == "theirs" else (own, bvh)
            near = self._near_coplanar(mesh)  # (the only triangles the readings meet)
            flags = flush_triangles(mesh, other, self.voxel, self.device, near)
            if whose == "theirs":
                flags |= internal_triangles(self.leaves, j, self.expression, near, flags, self.voxel)
            self.flush[(j, whose)] = (
                wp.array(flags, dtype=wp.uint8, device=self.device),
                unflushed(mesh, flags, self.device),
            )
        return self.flush[(j, whose)]

    def _near_coplanar(self, mesh) -> np.ndarray:
        """(G,) bool the triangles of ``mesh`` (a BVH) within reach of this leaf's faces in other leaves' planes: the
        coplanar readings' (the band, a face's slack and spacing) or, where more, four bands (an internal wall counts
        that far), and a voxel. Found here alone, the flush and internal walls of a mesh with a few faces in another's
        planes are looked for about those (rocker arm ∪ its copy moved by a voxel: 14 of 20,088; 100 -> 14 ms a judge);
        where one in FEW_COPLANAR or more are, every triangle (the copy in place: 20 k queries of a thousand triangles
        each took 27 ms, for all)."""
        if FEW_COPLANAR * int(np.count_nonzero(self.coplanar)) > len(self.coplanar):
            return np.ones(mesh.indices.shape[0] // 3, dtype=bool)
        corners = source_verts_near(self.leaves[self.index], np.flatnonzero(self.coplanar)).astype(np.float64)
        longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
        reach = max(4.0 * self.band, self.band + float(self.slack_of(longest).max()) + self.spacing) + self.voxel
        return triangles_near(mesh, corners, reach, self.device)

    def judge(self, verts, tris, parent, longest, turn, beyond: float | None = None):
        """Per triangle (pieces of original triangles ``parent``): kept, partly keepable, and flipped. A triangle is
        sampled about ``SAMPLE_VOXELS`` apart, or an eighth of its longest edge when that is more (a large triangle
        near a seam is split anyway), its samples' spacing the slack of its checks (``longest``, ``turn``: (T,) each
        one's longest edge and the corner it starts at, :func:`.samples.edge_turns`). With ``beyond``, every sample
        is read, its distances up to ``beyond`` farther than the checks need; ``self.found`` keeps, per triangle, the
        least of them (``margin``) and whether its verdict is the others' signs' alone (``signs_only``: no sample
        where the expression crosses) or its own mesh's (``own_only``: a defect, or its field crossing it nowhere),
        for :mod:`.verdicts`. In two launches where the fused path applies (:meth:`_fused`), else sample by sample;
        triangles in another leaf's planes (:mod:`.coplanar`) sample by sample with their planes, apart."""
        apart = np.zeros(len(tris), dtype=bool) if self.coplanar is None else self.coplanar[parent]
        if apart.any():
            return self._judge_apart(verts, tris, parent, longest, turn, beyond, apart)
        if self.fused is None:
            return self._judge_samples(verts, tris, parent, longest, 0.0 if beyond is None else beyond)
        kept, partly, flip, found = self.fused(verts, tris, parent, longest, turn, beyond)
        if found is not None:
            self.found = found
        return kept, partly, flip

    def _judge_apart(self, verts, tris, parent, longest, turn, beyond, apart: np.ndarray):
        """:meth:`judge` of the triangles ``apart`` (in another leaf's planes) with their planes, of the rest as ever;
        what is found for :mod:`.verdicts` of the ones apart lets none be reused (a margin of 0)."""
        out = [np.zeros(len(tris), dtype=bool) for _ in range(3)]
        found = {"margin": np.zeros(len(tris), np.float32), **{k: np.zeros(len(tris), bool) for k in FOUND_FLAGS}}
        rest = np.flatnonzero(~apart)
        if len(rest):
            self.found = None
            for k, verdict in enumerate(self.judge(verts, tris[rest], parent[rest], longest[rest], turn[rest], beyond)):
                out[k][rest] = verdict
            for key, value in (self.found or {}).items():
                found[key][rest] = value
        rows = np.flatnonzero(apart)
        for k, verdict in enumerate(self._judge_samples(verts, tris[rows], parent[rows], longest[rows], 0.0, True)):
            out[k][rows] = verdict
        self.found = found
        return tuple(out)

    def _judge_samples(self, verts, tris, parent, longest, beyond: float, coplanar: bool = False):
        """:meth:`judge` with every sample placed, each other leaf read at all of them, reduced per triangle; with
        ``coplanar``, read with their faces' planes (each face its own corners: a corner reads by its face's plane)."""
        if coplanar:
            verts, tris = verts[tris].reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3)
        used, local = np.unique(tris, return_inverse=True)
        local = local.reshape(-1, 3)
        slack = self.slack_of(longest)
        spacing = slack * (SAMPLE_VOXELS / SLACK_VOXELS)
        points, first = triangle_samples(verts[used], local, spacing, self.device)
        reach = self.band + float(slack.max()) + self.spacing + beyond
        planes = None
        if coplanar:  # each sample its face's normal, and the reach its own face's checks need
            owner = np.r_[np.arange(len(used)) // 3, np.repeat(np.arange(len(tris)), np.diff(first))]
            planes = (self.normals[parent][owner], (self.band + slack + self.spacing + beyond)[owner])
        margin, signs = self._readings(points, reach, planes)
        same = ~self.defects[parent]
        crosses, flips = self._crossing(signs)
        # the other leaves' signs the same all over each triangle; in other leaves' planes, where a face there begins
        # (tied) and the wall it begins at is no surface (it lies inside), the way the expression crosses
        varied = [flips.astype(np.int8)] if coplanar else signs[: self.index] + signs[self.index + 1 :]
        varied = list({id(s): s for s in varied if len(s)}.values())  # (one array may stand for many leaves)
        varied = [s for s in varied if s.min() != s.max()]  # (the rest: leaves far from every sample)
        if varied:  # (one reduction for all of them)
            same &= same_all_over(varied, local, len(used), first)
        if coplanar:  # a face in an earlier leaf's plane, both crossing there: that leaf's to keep
            margin = np.where(tied_to_earlier(signs, self.index) & crosses, 0.0, margin)
        bounds = np.stack([np.where(crosses, margin, -1.0), np.where(crosses, -margin, 1.0), margin], axis=1)
        least, most, nearest = per_triangle_min(bounds, local, len(used), first).T * np.array([[1.0], [-1.0], [1.0]])
        side, crossed, partly_crossed = self._own_sides(verts[used], local, points, first, parent)
        kept = same & crossed & (least > self.band + slack)
        raised = slack if coplanar else self.partly_slack(slack)  # (readings in a plane jump where its faces end)
        partly = partly_crossed & (most + raised > self.band + self.slack) & ~self.defects[parent]
        self.found = {
            "margin": nearest,
            "signs_only": most < 0.0,
            "own_only": self.defects[parent] | ~partly_crossed,
        }
        return kept, partly, flips[local[:, 0]] ^ (side < 0)

    def _own_sides(self, verts, tris, points, first, parent):
        """How the leaf's own field crosses each triangle: (T,) its side at the centre (:func:`.ownside.side_at`),
        whether every sample (corners, rows) has that side, not 0, and whether any has one. Parts of a triangle that
        its own field does not cross (a self-intersecting or overlapping shell's internal faces) are not kept. On a
        shell that nowhere crosses itself a piece has its source triangle's (``parent``) side, found already."""
        if not self.crossing:  # a shell that nowhere crosses itself: its side at the centre holds all over
            centre = self.side[parent]
            return centre, centre != 0, centre != 0
        normals = unit_normals(verts, tris)
        owner = np.repeat(np.arange(len(tris)), np.diff(first))
        centres = verts[tris].mean(axis=1)
        whose = np.concatenate([np.repeat(np.arange(len(tris)), 3), owner])
        at = np.concatenate([verts[tris].reshape(-1, 3), points[len(verts) :]])
        # samples pulled a voxel towards their triangle's centre: at a crease of the mesh the field is 0 just behind
        # or in front of the edge itself. Those within a voxel of it would land on it: the centre's own test (a scan's
        # triangles, all under a voxel, are read once each rather than four times)
        towards = centres[whose] - at
        length = np.linalg.norm(towards, axis=1, keepdims=True)
        far = length[:, 0] > self.spacing
        whose, at = whose[far], at[far] + towards[far] * (self.spacing / length[far])
        side = side_at(
            self.leaves[self.index], np.concatenate([centres, at]), np.r_[normals, normals[whose]], self.side_offset,
            rays=self.bvhs[self.index], tiny=self.ray_start, turn=self.thin,
        )  # fmt: skip
        side[side == THIN] = self.thin
        centre, rest = side[: len(tris)], side[len(tris) :]
        wrong = np.bincount(whose, weights=rest != centre[whose], minlength=len(tris))
        crossed = np.bincount(whose, weights=rest != 0, minlength=len(tris))
        return centre, (wrong == 0) & (centre != 0), (crossed > 0) | (centre != 0)

    def _crossing(self, signs: list) -> tuple[np.ndarray, np.ndarray]:
        """Per sample: whether the expression changes sign with this leaf's value (every other leaf's sign as it is
        there), and whether the result's inside is then on the leaf's outside."""
        inside = evaluate_signs(self.expression, tied_values(signs, self.index, -self.tiny))
        outside = evaluate_signs(self.expression, tied_values(signs, self.index, self.tiny))
        crosses = (inside < 0) != (outside < 0)
        return crosses, crosses & (outside < 0)


def kept_triangles(field, *, fused: bool = True, avoid=None, previous: list | None = None) -> list[dict]:
    """The triangles of each mesh leaf of a boolean's expression that are its surface (see the module docstring).

    Args:
        field: An unplaced :class:`.field.AdaptiveField` with an ``expression`` (a boolean result).
        fused: Judge in two launches a round where that applies (:mod:`.judging`); False: always sample by sample
            (the same verdicts, slower).
        avoid: Optional (P, 3) points (the field's frame) every leaf keeps clear of as of a defect of its own (where
            a join gave kept faces up: their far parts are kept as pieces); verdicts are reused where the last judge
            kept clear of the same points near the leaf (:mod:`.verdicts`).
        previous: This function's answer for the same field with fewer ``avoid`` points: a leaf none of the points
            comes near enough to change a verdict of is taken from it, not judged again.
    Returns:
        One dict per mesh leaf: ``field_id``, ``source`` (the placed :class:`.sources.SourceMesh`); the leaf's mesh
        after splitting: ``verts`` (V', 3) float32 (the source's V first, midpoints after), ``tris`` (T', 3) int64,
        ``parent`` (T',) int64 the source triangle each lies in; ``kept`` (T',) bool and ``flip`` (T',) bool (the
        triangle faces the result's inside as it stands).
    """
    expression = getattr(field, "expression", None)
    if expression is None:
        return []
    every = leaves(expression)
    _check_distinct_ids(every)
    # built once, before the leaves are judged side by side
    bvhs = [leaf_bvh(leaf, field.device) for leaf in every]
    reads = (bvhs, [leaf_jumps(leaf, field.device) for leaf in every], leaf_boxes(every))
    reads += (LeafReads(every, bvhs, field.device),)
    judged = [
        (i, *next(iter(leaf.world_sources().items())))
        for i, leaf in enumerate(every)
        if mesh_leaf(leaf) and len(next(iter(leaf.sources.values())).tris)
    ]
    out = [None] * len(judged)

    def task(k):
        i, field_id, source = judged[k]
        if previous is not None and not _avoid_reaches(field, source, avoid):
            out[k] = next(leaf for leaf in previous if leaf["field_id"] == field_id)
            return
        out[k] = {"field_id": field_id, "source": source, **_judge_leaf(field, i, source, reads, fused, avoid)}

    run_tasks([lambda k=k: task(k) for k in range(len(judged))], field.device)
    return out


def _check_distinct_ids(every: list) -> None:
    """Refuse leaves that share a field id but are different meshes: their faces could not be told apart (a kept
    face's source triangle is looked up by id; two fields built by separate ``build_field`` calls both have id 0).
    Copies of one field (placed, relabelled) share their mesh and may share the id."""
    seen = {}
    for leaf in every:
        for field_id, source in leaf.sources.items():
            if seen.setdefault(field_id, source).tris is not source.tris:
                raise ValueError(
                    f"Two operands of this boolean are different meshes with the same field id {field_id}: their "
                    "kept faces cannot be told apart. Build them with engine.build_fields (ids 0, 1, ...), or give "
                    "each its own id (build_field(..., field_id=k), or field.relabel(k))."
                )


def _avoid_reaches(field, source, avoid) -> bool:
    """Whether a point of ``avoid`` lies near enough to the (world) ``source`` triangles to change a verdict: within
    the band, the slack of its largest triangle and an avoided point's radius (``AVOID_VOXELS``)."""
    if avoid is None or not len(avoid):
        return False
    voxel = field.voxel_size
    corners = source.verts[source.tris].astype(np.float64)
    longest = float(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max())
    slack = max(longest / 8.0, SAMPLE_VOXELS * voxel) * (SLACK_VOXELS / SAMPLE_VOXELS)
    reach = BAND_VOXELS * voxel + widest_blend(field.expression) + slack + (0.5 * AVOID_VOXELS + 1.0) * voxel
    near = mesh_distances(source.bvh(field.device), np.asarray(avoid, dtype=np.float32), reach, field.device)
    return bool((near < reach).any())


def _judge_leaf(field, index: int, source, reads: tuple, fused: bool, avoid) -> dict:
    """Judge a leaf's triangles, splitting the partly keepable ones until they are small (module docstring)."""
    verts, tris = source.verts, source.tris.astype(np.int64)
    judge = _Judge(field, index, source, reads, fused, avoid)
    parent = np.arange(len(tris), dtype=np.int64)
    status, flip = _first_round(field, index, judge, verts, tris)
    ends = np.full((len(verts), 2), -1, dtype=np.int64)
    split_edge = SPLIT_VOXELS * field.voxel_size
    splitter = Splitter(verts, tris, split_edge, judge.strips)
    cut = cut_strips(judge, splitter, verts, status == UNKNOWN, split_edge)
    if cut is not None:  # slivers cut where the rounds would cut them, the pieces judged
        verts, tris, rows, ends = cut
        parent, flip, status = parent[rows], flip[rows], status[rows]
        judge_unknown(judge, verts, tris, parent, flip, status, split_edge)
    pieces = (verts, tris, parent, flip, status, ends)
    verts, tris, parent, flip, status, ends = split_rounds(judge, splitter, pieces, split_edge, MAX_SPLIT_ROUNDS - 1)
    status[status == UNKNOWN] = DROPPED
    tris, rows = merge_kept(verts, tris, status == KEPT, ends)
    parent, kept, flip = parent[rows], status[rows] == KEPT, flip[rows]
    flip_of = np.zeros(len(source.tris), dtype=bool)
    flip_of[parent[kept]] = flip[kept]
    ends = np.concatenate([ends, np.full((len(verts) - len(ends), 2), -1, dtype=np.int64)])
    verts, tris, parent, kept = restore_whole(verts, tris, parent, kept, ends, source.tris.astype(np.int64))
    straight = (STRAIGHT_VOXELS * field.voxel_size, STRAIGHT_RUN_VOXELS * field.voxel_size)
    tris, rows = straighten_borders(verts, tris, kept, parent, len(source.verts), *straight)
    parent, kept = parent[rows], kept[rows]
    flip = patch_flips(verts, tris, kept, flip_of[parent], field.device)  # turned as its patch is
    return {"verts": verts, "tris": tris, "parent": parent, "kept": kept, "flip": flip & kept}


def _first_round(field, index: int, judge: _Judge, verts, tris) -> tuple[np.ndarray, np.ndarray]:
    """Each source triangle's status after the first round (KEPT, DROPPED, or UNKNOWN: to be split and judged again)
    and flip: the verdicts the last boolean over the same fields found, where its distances bound them
    (:mod:`.verdicts`), the rest judged whole, with distances read far enough for the next boolean to reuse where
    the leaves were judged before elsewhere (:func:`.verdicts.worth_recording`: a drag)."""
    unplaced = next(iter(judge.leaves[index].sources.values()))
    longest, turn = edge_turns(verts, tris) if judge.turns is None else judge.turns
    slack = judge.slack_of(longest)
    # moves are bounded by a leaf's distances read off its mesh (and where its sign may jump, by its jump spheres)
    bounded = [b is not None and (j is None or not j.anywhere) for b, j in zip(judge.bvhs, judge.jumps, strict=True)]
    setting = (field.expression, index, field.voxel_size, judge.band)
    reach = judge.band + (verdicts.REUSE_VOXELS + AVOID_VOXELS + 1.0) * field.voxel_size + float(slack.max())
    avoided = verdicts.avoided_near(judge.leaves, judge.bvhs, index, judge.avoid, reach, field.device)
    found = verdicts.reused(unplaced, *setting, slack, bounded, avoided)
    status, flip, margin = (
        found if found is not None else (np.zeros(len(tris), np.int8), np.zeros(len(tris), bool), np.zeros(len(tris)))
    )
    status, flip, margin = status.copy(), flip.copy(), margin.astype(np.float32)
    apart = np.zeros(len(tris), dtype=bool) if judge.coplanar is None else judge.coplanar
    status[apart] = UNKNOWN  # (in another leaf's planes: judged afresh, never recorded)
    todo = np.flatnonzero(status == UNKNOWN)
    # kept for the next boolean where it can reuse them: another leaf's moves bounded (read off its mesh)
    reusable = any(e for j, e in enumerate(bounded) if j != index)
    if reusable and not verdicts.worth_recording(unplaced, *setting):  # a first boolean over these fields
        verdicts.mark_judged(unplaced, *setting)
        reusable = False
    beyond = verdicts.REUSE_VOXELS * field.voxel_size if reusable else None
    kept, partly, flip[todo] = judge.judge(verts, tris[todo], todo, longest[todo], turn[todo], beyond)
    split = partly & ~kept & (longest[todo] > SPLIT_VOXELS * field.voxel_size)
    status[todo] = np.where(kept, KEPT, np.where(split, UNKNOWN, DROPPED))
    if not reusable:
        return status, flip
    # what the next boolean may reuse: kept whole, or dropped by signs alone or by the mesh itself
    margin[todo] = np.where(judge.found["own_only"], np.inf, judge.found["margin"])
    rows = todo[np.isfinite(margin[todo])]  # (not where the mesh itself decided)
    for jumps in (jumps for j, jumps in enumerate(judge.jumps) if j != index and jumps is not None):
        margin[rows] = clear_of(jumps, verts, tris[rows], margin[rows])
    record = status.copy()
    dropped_by_distance = (status[todo] == DROPPED) & ~judge.found["signs_only"] & ~judge.found["own_only"]
    record[todo[dropped_by_distance]] = UNKNOWN
    record[apart] = UNKNOWN
    verdicts.remember(unplaced, *setting, record, flip, margin, avoided)
    return status, flip
