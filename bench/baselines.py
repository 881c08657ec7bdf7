"""What a Blender user would pick instead of AASDF, run on numpy meshes and timed (needs ``bpy``; tests/engine never
import this file).

Four references: the geometry-nodes SDF pipeline (Mesh to SDF Grid → SDF Grid Boolean → Grid to Mesh), geometry
nodes' Mesh to SDF Grid alone (construction), the Boolean modifier with its Exact and Manifold solvers, and
OpenVDB's ``createLevelSetFromPolygons`` as bundled with Blender. Every function builds fresh objects and node groups,
so repeated calls recompute instead of reusing Blender's evaluated data. Meshes are (V,3) float32 vertices and (T,3)
int32 triangles in world space; objects stay at the identity transform.

Run ``python bench/baselines.py [--quick]`` for the timing table of the spot and bunny cases.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import bpy
import numpy as np

OPERATIONS = ("UNION", "INTERSECT", "DIFFERENCE")
SOLVERS = ("EXACT", "MANIFOLD")  # bpy.types.BooleanModifier.solver also has "FLOAT"
MESH_TO_SDF_ENDS = ("VOLUME", "MESH")


# ---- objects and meshes ----


def mesh_object(name: str, verts, tris, *, link: bool = True) -> bpy.types.Object:
    """A new mesh object from (V,3) vertices and (T,3) triangles, filled with ``foreach_set`` (vectorised).

    Args:
        name: Name of the object and its mesh (Blender may add a ``.001`` suffix).
        verts: (V, 3) float vertex positions.
        tris: (T, 3) int triangle indices.
        link: Link the object into the scene's master collection.
    Returns:
        The ``bpy.types.Object``.
    """
    verts = np.ascontiguousarray(verts, dtype=np.float32).reshape(-1, 3)
    tris = np.ascontiguousarray(tris, dtype=np.int32).reshape(-1, 3)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(verts))
    mesh.vertices.foreach_set("co", verts.ravel())
    mesh.loops.add(3 * len(tris))
    mesh.loops.foreach_set("vertex_index", tris.ravel())
    mesh.polygons.add(len(tris))
    mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * len(tris), 3, dtype=np.int32))
    mesh.update(calc_edges=True)
    obj = bpy.data.objects.new(name, mesh)
    if link:
        bpy.context.scene.collection.objects.link(obj)
    return obj


def mesh_arrays(mesh: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """(V,3) float32 vertices and (T,3) int32 triangles of a mesh (n-gons triangulated by ``loop_triangles``)."""
    verts = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", verts)
    mesh.calc_loop_triangles()
    tris = np.empty(3 * len(mesh.loop_triangles), dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return verts.reshape(-1, 3), tris.reshape(-1, 3)


def is_closed(tris) -> bool:
    """Whether every undirected edge of (T,3) triangles is used by exactly two of them (and there is one)."""
    tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    if len(tris) == 0:
        return False
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def _operand(name: str, mesh) -> bpy.types.Object:
    """An object for a (verts, tris) pair, or the object itself."""
    if isinstance(mesh, bpy.types.Object):
        return mesh
    verts, tris = mesh
    return mesh_object(name, verts, tris)


def _evaluate(obj: bpy.types.Object) -> dict:
    """Evaluate the depsgraph (which runs the modifiers of ``obj``) and convert the result, timed together."""
    start = time.perf_counter()
    depsgraph = bpy.context.evaluated_depsgraph_get()  # evaluates everything tagged since the last call
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    seconds = time.perf_counter() - start
    verts, tris = mesh_arrays(mesh)
    faces = len(mesh.polygons)
    evaluated.to_mesh_clear()
    modifier_seconds = {m.name: m.execution_time for m in evaluated.modifiers}
    geometry = evaluated.evaluated_geometry()  # keep a reference: its volume dies with it
    grids = [(g.name, g.data_type) for g in geometry.volume.grids] if geometry.volume is not None else []
    return {
        "verts": verts,
        "tris": tris,
        "faces": faces,
        "seconds": seconds,
        "modifier_seconds": modifier_seconds,
        "grids": grids,
    }


def _settle() -> None:
    """Evaluate pending changes (new operand objects) so they are not counted in the next timing."""
    bpy.context.evaluated_depsgraph_get()


def _remove(*objects) -> None:
    for obj in objects:
        data = obj.data
        bpy.data.objects.remove(obj, do_unlink=True)
        if data is not None and data.users == 0:
            bpy.data.meshes.remove(data)


# ---- geometry nodes ----


def _gn_host(name: str, group: bpy.types.NodeTree) -> bpy.types.Object:
    host = mesh_object(name, np.zeros((0, 3)), np.zeros((0, 3)))
    host.modifiers.new("GeometryNodes", "NODES").node_group = group
    return host


def _gn_group(name: str) -> tuple[bpy.types.NodeTree, bpy.types.Node, bpy.types.Node]:
    group = bpy.data.node_groups.new(name, "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    group_in = group.nodes.new("NodeGroupInput")
    group_out = group.nodes.new("NodeGroupOutput")
    return group, group_in, group_out


def _gn_sdf(group, operand: bpy.types.Object, voxel_size: float, band_width: int):
    """Object Info (relative transform) → Mesh to SDF Grid; returns the grid socket."""
    info = group.nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "RELATIVE"
    info.inputs["Object"].default_value = operand
    to_sdf = group.nodes.new("GeometryNodeMeshToSDFGrid")
    to_sdf.inputs["Voxel Size"].default_value = voxel_size
    to_sdf.inputs["Band Width"].default_value = band_width
    group.links.new(info.outputs["Geometry"], to_sdf.inputs["Mesh"])
    return to_sdf.outputs["SDF Grid"]


def _gn_to_mesh(group, grid_socket, group_out, adaptivity: float = 0.0) -> None:
    to_mesh = group.nodes.new("GeometryNodeGridToMesh")
    to_mesh.inputs["Threshold"].default_value = 0.0  # the default 0.1 would offset the surface
    to_mesh.inputs["Adaptivity"].default_value = adaptivity
    group.links.new(grid_socket, to_mesh.inputs["Grid"])
    group.links.new(to_mesh.outputs["Mesh"], group_out.inputs["Geometry"])


def gn_sdf_boolean(
    a, b, op: str, voxel_size: float, band_width: int = 3, *, keep: bool = False, adaptivity: float = 0.0
) -> dict:
    """Geometry-nodes SDF boolean: Mesh to SDF Grid ×2 → SDF Grid Boolean → Grid to Mesh (Threshold 0).

    Timed: one depsgraph evaluation of a fresh object with a fresh node group plus ``to_mesh()`` — both SDF
    constructions, the boolean and the meshing; the operands are evaluated before the clock starts.

    Args:
        a, b: (verts, tris) pairs or existing mesh objects; ``DIFFERENCE`` is *a minus b*.
        op: ``"UNION"``, ``"INTERSECT"`` or ``"DIFFERENCE"``.
        voxel_size: Voxel size of both grids (world units).
        band_width: Narrow-band half width in voxels.
        keep: Keep the created objects and node group (otherwise they are removed).
        adaptivity: Grid to Mesh's Adaptivity (0 to 1).
    Returns:
        ``{"verts", "tris", "faces" (polygons), "seconds", "stage_seconds"}`` where ``stage_seconds`` holds the
        modifier's own ``execution_time`` as ``"modifier"`` (the rest of ``seconds`` is depsgraph and ``to_mesh``
        overhead).
    Raises:
        ValueError: If ``op`` is unknown.
    """
    if op not in OPERATIONS:
        raise ValueError(f"Expected 'op' in {OPERATIONS}, but got {op!r}.")
    obj_a, obj_b = _operand("gn_a", a), _operand("gn_b", b)
    _settle()
    group, _, group_out = _gn_group("gn_sdf_boolean")
    grid_a = _gn_sdf(group, obj_a, voxel_size, band_width)
    grid_b = _gn_sdf(group, obj_b, voxel_size, band_width)
    boolean = group.nodes.new("GeometryNodeSDFGridBoolean")
    boolean.operation = op
    if op == "DIFFERENCE":
        group.links.new(grid_a, boolean.inputs["Grid 1"])
        group.links.new(grid_b, boolean.inputs["Grid 2"])
    else:  # UNION / INTERSECT take every grid on one multi-input socket
        group.links.new(grid_a, boolean.inputs["Grid 2"])
        group.links.new(grid_b, boolean.inputs["Grid 2"])
    _gn_to_mesh(group, boolean.outputs["Grid"], group_out, adaptivity)
    host = _gn_host("gn_sdf_boolean", group)
    result = _evaluate(host)
    result["stage_seconds"] = {"modifier": result.pop("modifier_seconds")["GeometryNodes"]}
    del result["grids"]
    if not keep:
        _remove(host, *(o for o, src in ((obj_a, a), (obj_b, b)) if o is not src))
        bpy.data.node_groups.remove(group)
    return result


def gn_mesh_to_sdf(a, voxel_size: float, band_width: int = 3, *, end: str = "VOLUME", keep: bool = False) -> dict:
    """Geometry nodes' Mesh to SDF Grid alone, for the construction benchmark.

    Timed: one depsgraph evaluation of a fresh node group plus ``to_mesh()``. With ``end="VOLUME"`` the grid is
    stored with Store Named Grid into the output geometry (a volume), so the node must build it and nothing else
    runs; ``to_mesh()`` then returns an empty mesh. With ``end="MESH"`` a Grid to Mesh (Threshold 0) follows, and
    the timing includes the meshing.

    Returns:
        ``{"verts", "tris", "seconds", "stage_seconds", "grids"}``; ``grids`` lists ``(name, data_type)`` of the
        evaluated volume (``[("sdf", "FLOAT")]`` for ``"VOLUME"``), proof that the grid was built.
    Raises:
        ValueError: If ``end`` is not ``"VOLUME"`` or ``"MESH"``.
    """
    if end not in MESH_TO_SDF_ENDS:
        raise ValueError(f"Expected 'end' in {MESH_TO_SDF_ENDS}, but got {end!r}.")
    obj_a = _operand("gn_a", a)
    _settle()
    group, group_in, group_out = _gn_group("gn_mesh_to_sdf")
    grid = _gn_sdf(group, obj_a, voxel_size, band_width)
    if end == "MESH":
        _gn_to_mesh(group, grid, group_out)
    else:
        store = group.nodes.new("GeometryNodeStoreNamedGrid")
        store.data_type = "FLOAT"
        store.inputs["Name"].default_value = "sdf"
        group.links.new(grid, store.inputs["Grid"])
        group.links.new(store.outputs["Volume"], group_out.inputs["Geometry"])
    host = _gn_host("gn_mesh_to_sdf", group)
    result = _evaluate(host)
    result["stage_seconds"] = {"modifier": result.pop("modifier_seconds")["GeometryNodes"]}
    if not keep:
        _remove(host, *((obj_a,) if obj_a is not a else ()))
        bpy.data.node_groups.remove(group)
    return result


def gn_sdf_offset(a, voxel_size: float, distance: float, band_width: int | None = None, *, keep: bool = False) -> dict:
    """Geometry nodes' offset of a mesh's SDF: Mesh to SDF Grid → SDF Grid Offset → Grid to Mesh (Threshold 0).

    The grid holds distances only within its band, so an offset of ``distance`` needs a band of at least
    ``|distance| / voxel_size`` voxels plus the 3 the new surface needs on its far side (the default).

    Timed: one depsgraph evaluation of a fresh node group plus ``to_mesh()``.

    Returns:
        ``{"verts", "tris", "seconds", "stage_seconds", "band_width"}``.
    """
    if band_width is None:
        band_width = int(math.ceil(abs(distance) / voxel_size)) + 3
    obj_a = _operand("gn_a", a)
    _settle()
    group, _, group_out = _gn_group("gn_sdf_offset")
    grid = _gn_sdf(group, obj_a, voxel_size, band_width)
    node = group.nodes.new("GeometryNodeSDFGridOffset")
    node.inputs["Distance"].default_value = distance
    group.links.new(grid, node.inputs["Grid"])
    _gn_to_mesh(group, node.outputs["Grid"], group_out)
    host = _gn_host("gn_sdf_offset", group)
    result = _evaluate(host)
    result["stage_seconds"] = {"modifier": result.pop("modifier_seconds")["GeometryNodes"]}
    result["band_width"] = band_width
    del result["grids"]
    if not keep:
        _remove(host, *((obj_a,) if obj_a is not a else ()))
        bpy.data.node_groups.remove(group)
    return result


# ---- Boolean modifier ----


def boolean_modifier(a, b, op: str, solver: str, *, keep: bool = False) -> dict:
    """The Boolean modifier (``solver`` ``"EXACT"`` or ``"MANIFOLD"``; ``"FLOAT"`` also works) on object a.

    Timed: one depsgraph evaluation of a fresh copy of a with the modifier, plus ``to_mesh()``.

    Returns:
        ``{"verts", "tris", "seconds", "stage_seconds", "usable", "changed", "closed"}``. ``changed`` is False
        when the result equals operand a (how the Manifold solver answers a non-manifold operand: it logs
        "Cannot execute, non-manifold inputs" and passes a through); ``usable`` is True when the result has
        triangles and ``changed`` is True, or when a non-overlapping union/difference legitimately leaves a
        unchanged; ``closed`` is True when every edge of the result is shared by exactly two triangles.
    Raises:
        ValueError: If ``op`` or ``solver`` is unknown.
    """
    if op not in OPERATIONS:
        raise ValueError(f"Expected 'op' in {OPERATIONS}, but got {op!r}.")
    if solver not in (*SOLVERS, "FLOAT"):
        raise ValueError(f"Expected 'solver' in {(*SOLVERS, 'FLOAT')}, but got {solver!r}.")
    if isinstance(a, bpy.types.Object):
        verts_a, tris_a = mesh_arrays(a.data)
    else:
        verts_a, tris_a = (np.asarray(x) for x in a)
    obj_a = mesh_object("boolean_a", verts_a, tris_a)
    obj_b = _operand("boolean_b", b)
    obj_b.display_type = "WIRE"
    _settle()
    modifier = obj_a.modifiers.new("Boolean", "BOOLEAN")
    modifier.operation, modifier.solver, modifier.operand_type = op, solver, "OBJECT"
    modifier.object = obj_b
    result = _evaluate(obj_a)
    result["stage_seconds"] = {"modifier": result.pop("modifier_seconds")["Boolean"]}
    del result["grids"]
    same = (
        result["verts"].shape == np.shape(verts_a)
        and len(result["tris"]) == len(tris_a)
        and np.allclose(result["verts"], verts_a, atol=0.0)
    )
    result["changed"] = not same
    result["usable"] = len(result["tris"]) > 0 and (not same or _disjoint(verts_a, b, op))
    result["closed"] = is_closed(result["tris"])
    if not keep:
        _remove(obj_a, *((obj_b,) if obj_b is not b else ()))
    return result


def _disjoint(verts_a, b, op: str) -> bool:
    """Whether bounding boxes show that the boolean leaves a unchanged (no overlap; union/difference only)."""
    if op == "INTERSECT":
        return False
    verts_b = mesh_arrays(b.data)[0] if isinstance(b, bpy.types.Object) else np.asarray(b[0])
    lo = np.maximum(verts_a.min(axis=0), verts_b.min(axis=0))
    hi = np.minimum(verts_a.max(axis=0), verts_b.max(axis=0))
    return bool(np.any(lo > hi))


# ---- OpenVDB ----


def openvdb_level_set(verts, tris, voxel_size: float, half_width: float = 3.0) -> dict:
    """OpenVDB's mesh-to-level-set (Blender's bundled ``openvdb`` module), timed.

    Timed: ``openvdb.FloatGrid.createLevelSetFromPolygons`` only (numpy arrays are prepared before).

    Args:
        verts: (V, 3) float vertex positions (world units).
        tris: (T, 3) int triangle indices.
        voxel_size: Voxel size (world units).
        half_width: Narrow-band half width in voxels.
    Returns:
        ``{"grid", "seconds", "active_voxels", "memory_bytes"}``.
    """
    bpy.utils.expose_bundled_modules()
    import openvdb

    points = np.ascontiguousarray(verts, dtype=np.float32).reshape(-1, 3)
    triangles = np.ascontiguousarray(tris, dtype=np.uint32).reshape(-1, 3)
    transform = openvdb.createLinearTransform(voxelSize=voxel_size)
    start = time.perf_counter()
    grid = openvdb.FloatGrid.createLevelSetFromPolygons(
        points, triangles=triangles, transform=transform, halfWidth=half_width
    )
    seconds = time.perf_counter() - start
    return {
        "grid": grid,
        "seconds": seconds,
        "active_voxels": int(grid.activeVoxelCount()),
        "memory_bytes": int(grid.memUsage()),
    }


# ---- benchmark table ----


def benchmark_cases() -> dict:
    """The standard comparison cases: name → (a, b) as (verts, tris) pairs."""
    root = str(Path(__file__).resolve().parents[1])
    if root not in sys.path:
        sys.path.insert(0, root)
    from tests.support import load_mesh

    spot = load_mesh("spot.obj")
    shifted = (spot[0] + np.array([0.3, 0.0, 0.0], dtype=np.float32), spot[1])
    bunny_v, bunny_t = load_mesh("stanford-bunny.obj")
    # Scale the bunny to spot's size and put it where it overlaps spot's body.
    lo, hi = bunny_v.min(axis=0), bunny_v.max(axis=0)
    s_lo, s_hi = spot[0].min(axis=0), spot[0].max(axis=0)
    scale = 0.8 * np.linalg.norm(s_hi - s_lo) / np.linalg.norm(hi - lo)
    bunny = ((bunny_v - 0.5 * (lo + hi)) * scale + 0.5 * (s_lo + s_hi) + np.array([0.4, 0.0, 0.0]), bunny_t)
    return {"spot∪spot+0.3x": (spot, shifted), "bunny∪spot": (bunny, spot)}


def diagonal(*meshes) -> float:
    """The diagonal of the box around the meshes (each (verts, tris))."""
    verts = np.concatenate([m[0] for m in meshes])
    return float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0)))


def _volume(verts, tris) -> float:
    v = np.asarray(verts, dtype=np.float64)[np.asarray(tris)]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def main(argv=None) -> None:
    """Print the baseline table: ``python bench/baselines.py [--quick] [--repeat N]`` (args after ``--`` too)."""
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    quick = "--quick" in argv
    repeat = int(argv[argv.index("--repeat") + 1]) if "--repeat" in argv else (1 if quick else 3)
    bpy.ops.wm.read_homefile(use_empty=True)
    print(f"Blender {bpy.app.version_string}, {repeat} run(s) each, best time in seconds; op = UNION")
    print(f"{'case':15} {'div':>4} {'voxel':>8} {'method':22} {'seconds':>8} {'tris':>8} {'volume':>8} note")

    def row(case, div, voxel, method, seconds, tris="", volume="", note=""):
        volume = f"{volume:8.4f}" if volume != "" else ""
        print(f"{case:15} {div:>4} {voxel:>8} {method:22} {seconds:8.3f} {tris:>8} {volume:>8} {note}")

    for case, (a, b) in benchmark_cases().items():
        divisions = (256,) if quick else (256, 512)
        for div in divisions:
            voxel = diagonal(a, b) / div
            best = {}
            for _ in range(repeat):
                runs = {"GN SDF boolean": gn_sdf_boolean(a, b, "UNION", voxel)}
                runs["GN Mesh to SDF a"] = gn_mesh_to_sdf(a, voxel)
                runs["GN Mesh to SDF b"] = gn_mesh_to_sdf(b, voxel)
                runs["OpenVDB level set a"] = openvdb_level_set(*a, voxel)
                runs["OpenVDB level set b"] = openvdb_level_set(*b, voxel)
                for label, run in runs.items():
                    if label not in best or run["seconds"] < best[label]["seconds"]:
                        best[label] = run
            for label, run in best.items():
                if "tris" in run and len(run["tris"]):
                    extra = {"tris": len(run["tris"]), "volume": _volume(run["verts"], run["tris"])}
                elif "active_voxels" in run:
                    extra = {"note": f"{run['active_voxels']} active voxels"}
                else:
                    extra = {"note": f"grids {run['grids']}"}
                row(case, div, f"{voxel:.5f}", label, run["seconds"], **extra)
        for solver in SOLVERS:
            runs = [boolean_modifier(a, b, "UNION", solver) for _ in range(repeat)]
            run = min(runs, key=lambda r: r["seconds"])
            note = ("usable" if run["usable"] else "NOT usable") + ("" if run["changed"] else ", input returned")
            note += ", closed" if run["closed"] else ", open"
            volume = _volume(run["verts"], run["tris"]) if len(run["tris"]) else ""
            row(case, "-", "-", f"Boolean {solver}", run["seconds"], len(run["tris"]), volume, note)
        bpy.ops.wm.read_homefile(use_empty=True)


if __name__ == "__main__":
    main()
