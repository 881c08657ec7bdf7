"""A mesh's field built on a set of finest octets: its levels placed, distances, signs (:func:`.build.build_field`'s
steps 2 to 4), again with more octets where an open mesh's surface across its holes needs them, or where a field
refined on demand is asked for more (:mod:`.ondemand`); what the build found of the mesh kept with the field.
"""

from __future__ import annotations

import time

from . import distance, fim, search, signs, sweeping
from .field import AdaptiveField
from .holes import changed_top_cells, sign_change_octets
from .layout import level_layout, match_levels, upper_levels
from .octree import add_octets, code_bits, merge_unique, parent_octets
from .plan import check_budget
from .sampling import LEAF_TOLERANCE
from .signs import NO_BOXES
from .sources import SourceMesh

# Rounds of refining coarse leaves the zero set crosses (open meshes: the surface across a hole).
MAX_SIGN_REFINEMENTS = 4

# A closed mesh's field is read off its mesh (its build's BVH, kept with its source: :func:`finished`) for exact values
# where booleans sample it (``AdaptiveField.distance_mesh``), when the mesh has at most one triangle per this many
# nodes (the BVH with its winding-number data, points and indices holds about 140 bytes a triangle, measured 112-135
# beside the arrays on spheres of 100 k and 500 k triangles; the field 18 a node): where the BVH is no larger than the
# field, a query of it replaces the field's nodes.
KEEP_BVH_NODES_PER_TRIANGLE = 8


class LevelBuilder:
    """Builds the field on a set of finest octets: its levels placed, distances (finest exactly, coarser solved
    bottom-up), signs top-down; a refinement round's build keeps what the latest one found (``previous``)."""

    def __init__(self, plan, facts, mesh, search_mesh, winding, device, field_id, timings):
        self.plan, self.facts, self.mesh, self.search_mesh = plan, facts, mesh, search_mesh
        self.winding, self.device, self.field_id, self.timings = winding, device, field_id, timings
        self.expansions = None  # the signs' expansions of the latest build, which a refinement round keeps
        self.above = None  # level 1's octets where the finest octets are a part of the band (:mod:`.ondemand`)
        self.upper = (None, None)  # (``above``, :func:`.layout.upper_levels` of it), found once for refinements
        voxel_size, padding = plan["voxel_size"], plan["padding"]
        # a band node lies within (padding + 1) cells (L-inf) of a triangle; misses fall back to the domain diagonal
        self.query_radius = facts["diag"] if plan["levels"] == 1 else (padding + 2) * voxel_size * 1.75

    def build(self, octets, previous=None, *, finest_only: bool = False) -> AdaptiveField:
        """The field on the finest ``octets``; ``previous``: an earlier build, whose nodes keep their values;
        ``finest_only``: it has every coarse node this one has (a field refined on demand: ``above`` fixes them), so
        only the finest level is found (its new octets' distances, their signs from the levels above)."""
        plan, timings = self.plan, self.timings
        if self.above is not None and not finest_only:  # octets a round across the holes adds: their parents too
            end_bit = 3 * code_bits(plan["fine_dims"])
            up = parent_octets(octets, 1, end_bit=end_bit, presorted=True)
            self.above = merge_unique(self.above, up, end_bit=end_bit)
        # every node's place first, so each level's values are computed where they are kept
        layout = level_layout(octets, plan["top_dims"], plan["levels"], self.device, timings, above=self._upper())
        # each node's index in the earlier build (-1: new), shared by distances and signs
        prev_index = None if previous is None else match_levels(layout["codes"], layout["offsets"], previous)
        # its closest points and sources, decoded once for the finest level's take and the coarse levels'
        earlier = (
            previous,
            prev_index,
            None if previous is None else (previous.closest_points, previous.node_sources()),
        )
        if finest_only:
            dist, proj, source, tri, neighbours, sweeps = self.finest(layout, *earlier)
        else:
            dist, proj, source, tri, neighbours, sweeps = self.distances(layout, *earlier)
        values, sign_stats, self.expansions = signs.sign_levels(
            self.winding,
            layout,
            dist,
            neighbours,
            origin=plan["origin"],
            voxel_size=plan["voxel_size"],
            hole_caps=self.facts["caps"],
            previous=previous,
            prev_index=prev_index,
            known=self.expansions,
            timings=timings,
            coarse_known=finest_only,
        )
        return AdaptiveField.from_layout(
            layout,
            voxel_size=plan["voxel_size"],
            origin=plan["origin"],
            values=values,
            proj=proj,
            source=source,
            triangles=tri,
            field_ids=(self.field_id,),
            timings=timings,
            stats={"fim_sweeps": sweeps, **sign_stats},
        )

    def _upper(self):
        """``above`` with the levels over it (:func:`.layout.upper_levels`), found once while it stays."""
        if self.above is None or self.plan["levels"] <= 2:
            return self.above
        if self.upper[0] is not self.above:
            self.upper = (self.above, upper_levels(self.above, self.plan["top_dims"], self.plan["levels"]))
        return self.upper[1]

    def finest(self, layout, previous, prev_index, decoded):
        """:meth:`distances` where ``previous`` has every coarse node: they take its values, and only the finest
        level's new octets are searched."""
        plan, timings = self.plan, self.timings
        t0 = time.perf_counter()
        dist, proj, source, tri, _ = distance.finest_distances(
            self._octet_search(),
            layout,
            origin=plan["origin"],
            voxel_size=plan["voxel_size"],
            field_id=self.field_id,
            previous=previous,
            prev_index=prev_index,
            decoded=decoded,
        )
        timings["finest_distance"] = timings.get("finest_distance", 0.0) + time.perf_counter() - t0
        neighbours = fim.known_levels(layout, previous, prev_index, dist, proj, source, decoded)
        return dist, proj, source, tri, neighbours, {}

    def _octet_search(self) -> search.OctetSearch:
        facts = self.facts
        return search.OctetSearch(
            self.mesh.id,
            self.query_radius,
            facts["diag"],
            facts["box_search"],
            self.search_mesh.id,
            facts["frame"],
            facts["thin"],
            mean_area=facts["mean_area"],
        )

    def distances(self, layout, previous, prev_index, decoded):
        """The nodes' distances: the finest exactly (octet by octet), the coarser levels solved bottom-up."""
        plan, timings = self.plan, self.timings
        origin, voxel_size = plan["origin"], plan["voxel_size"]
        t0 = time.perf_counter()
        octets_search = self._octet_search()
        dist, proj, source, tri, octet_points = distance.finest_distances(
            octets_search,
            layout,
            origin=origin,
            voxel_size=voxel_size,
            field_id=self.field_id,
            previous=previous,
            prev_index=prev_index,
            decoded=decoded,
        )
        timings["finest_distance"] = timings.get("finest_distance", 0.0) + time.perf_counter() - t0
        neighbours, sweeps = fim.solve_levels(
            self.mesh.id,
            layout,
            dist,
            proj,
            source,
            origin=origin,
            voxel_size=voxel_size,
            top_tolerance=LEAF_TOLERANCE,
            octet_points=octet_points,
            previous=previous,
            prev_index=prev_index,
            decoded=decoded,
            timings=timings,
            # the dense top level by fast sweeping in its 8 orderings (one round, then the BVH refinement) rather than
            # the fast iterative method's 2: 8 sweeps against 12-23, its solve 0.75-0.97x (fandisk, homer, rocker-arm,
            # spot, the bunny at /512)
            level_solver=sweeping.solve_level,
            exact_level=lambda k, known_nodes, below: distance.level_distances(
                octets_search, layout, k, dist, proj, known_nodes, below, origin=origin, voxel_size=voxel_size
            ),
        )
        return dist, proj, source, tri, neighbours, sweeps


def refined_across_holes(levels: LevelBuilder, field, base_octets, plan: dict, facts: dict, winding) -> AdaptiveField:
    """Across a hole of an open mesh the inside/outside boundary (winding number 0.5) runs away from any triangle,
    through coarse leaves: those leaves are refined to the finest level, in rounds, so the surface there can be
    extracted too. A closed, consistently oriented mesh (even a self-intersecting one) changes its winding number
    only across its triangles, which the finest level covers: nothing to check."""
    fine_dims, top_dims = plan["fine_dims"], plan["top_dims"]
    caps = facts["caps"]
    rounds = 0
    refine_seconds = 0.0
    region = None
    while plan["levels"] > 1 and not facts["clean"] and facts["encloses"] and rounds < MAX_SIGN_REFINEMENTS:
        t_refine = time.perf_counter()
        # off the caps over the holes the winding number stays near an integer (see hole_caps): the zero set can
        # only leave the band near them (no caps: the edges cancel, it never does)
        extra = sign_change_octets(field, caps if caps is not None else NO_BOXES, region, winding)
        refine_seconds += time.perf_counter() - t_refine
        if len(extra) == 0:
            break
        rounds += 1
        region = changed_top_cells(extra, top_dims, plan["levels"])
        check_budget(fine_dims, plan["top_count"], field.level_counts[0] + 8 * 27 * len(extra))
        t0 = time.perf_counter()
        base_octets = add_octets(base_octets, extra, fine_dims // 2, end_bit=3 * code_bits(fine_dims // 2))
        levels.timings["finest_cells"] += time.perf_counter() - t0
        queries = field.stats["sign_queries"]
        field = levels.build(base_octets, previous=field)
        field.stats["sign_queries"] = {k: v + queries.get(k, 0) for k, v in field.stats["sign_queries"].items()}
    field.stats["sign_refinements"] = rounds
    field.timings["sign_check"] = refine_seconds
    return field


def finished(field, plan: dict, facts: dict, mesh, field_id: int, band: int | None = None) -> AdaptiveField:
    """``field`` with what its build found about its mesh (``stats``) and its source mesh, which keeps the build's
    ``mesh`` as its BVH: what reads the mesh later (the kept faces' judge, the carried attributes' closest triangles,
    the crease vertices pulled back) would build it again, 0.35-0.45 us a triangle on one thread (the cache counts
    it). ``band``: the finest octets of its whole band, where it holds a part of them (:mod:`.ondemand`)."""
    clean, encloses, tris = facts["clean"], facts["encloses"], plan["triangles"]
    field.stats["clean_mesh"] = clean
    field.stats["flat"] = not encloses
    # a closed mesh's closest points lie on the field's surface (an open mesh's surface runs across its holes too,
    # away from any closest point)
    field.stats["surface_points"] = clean
    field.stats["problem_faces"] = int(facts["problem"].sum())
    if facts["caps"] is not None:  # where its sign may jump away from its triangles (:mod:`.ondemand`)
        field.stats["hole_caps"] = facts["caps"]
    source = SourceMesh(plan["vertices"], tris, plan["triangle_ids"])
    # a closed mesh's field is its signed distance everywhere: booleans read it from the mesh itself where they sample
    # it (where its BVH costs no more than the field)
    nodes = field.node_count if band is None else field.node_count - field.level_counts[0] + 8 * band
    field.stats["mesh_distance"] = clean and encloses and len(tris) * KEEP_BVH_NODES_PER_TRIANGLE <= nodes
    source.adopt(mesh)
    field.sources = {field_id: source}
    return field
