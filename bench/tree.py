"""A CSG tree as a user meets it: evaluated cold, again with nothing changed, after its file was reloaded, and dragged.

The tree has five inputs and two outputs, kept faces on (the Output node's default) at the tree's default settings
(/128 of each output's inputs, 5 levels, padding 2): ``Carved`` = (bunny ∪ spot) − a ``Cutters`` collection of two
balls, ``Joined`` = spot ∪ a post. In one ``bpy`` process with the add-on registered, each round runs

- **cold**: the field cache cleared and the result objects removed: the tree's first evaluation;
- **again**: evaluated again with nothing changed (Evaluate pressed twice);
- **reloaded**: the file saved in a temporary folder and opened again (which empties the field cache), then
  evaluated; the save and the load are not timed.

Times are wall clock around ``bpy.ops.aasdf.evaluate_tree``; the ratios are the median of the rounds' again / cold and
reloaded / cold, with the smallest and largest in brackets (``bench/paired.py``: each pair in the same round).

Then the drag of ``bench/addon.py`` (``--drag-moves`` moves of the cutter through a one-output tree, bunny − spot at
/256, against as many geometry-nodes SDF evaluations, alternating rounds), with kept faces and remeshed, and the
seconds of each stage summed over the drag's moves: where a drag's time goes.

    .venv/bin/python bench/tree.py [--repeat 5] [--drag-moves 10] [--drag-repeat 3] [--no-drag] [--no-tree]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from bench import addon, baselines  # noqa: E402
from bench.paired import round_ratios  # noqa: E402
from bench.pipeline import cases  # noqa: E402

OUTPUTS = ("Carved", "Joined")


def build_scene():
    """The five inputs and the tree (see the module docstring); returns the tree's name."""
    from aasdf.aasdf_addon import nodes
    from tests.support import cylinder_mesh, uv_sphere

    bpy.ops.wm.read_homefile(use_empty=True)
    bunny, spot = cases()["bunny+spot"]
    lo, hi = spot[0].min(axis=0), spot[0].max(axis=0)
    centre, diag = 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))
    inputs = {"bunny": baselines.mesh_object("bunny", *bunny), "spot": baselines.mesh_object("spot", *spot)}
    cutters = bpy.data.collections.new("Cutters")
    bpy.context.scene.collection.children.link(cutters)
    for k, z in enumerate((0.25, -0.25)):
        ball = uv_sphere(0.15 * diag, center=centre + np.array([0.1, 0.0, z]) * diag, rings=48, segments=96)
        cutters.objects.link(baselines.mesh_object(f"ball{k}", *ball, link=False))
    post = cylinder_mesh(0.12 * diag, 0.8 * diag, center=centre + np.array([-0.2, 0.0, 0.0]) * diag)
    inputs["post"] = baselines.mesh_object("post", *post)

    tree = bpy.data.node_groups.new("Bench", nodes.TREE)
    tree.auto_update = False
    node = {}
    for name, obj in inputs.items():
        node[name] = tree.nodes.new(nodes.OBJECT)
        node[name].object = obj
    node["cutters"] = tree.nodes.new(nodes.COLLECTION)
    node["cutters"].collection = cutters
    both, difference, joined = (tree.nodes.new(kind) for kind in (nodes.UNION, nodes.DIFFERENCE, nodes.UNION))
    carved_out, joined_out = tree.nodes.new(nodes.OUTPUT), tree.nodes.new(nodes.OUTPUT)
    carved_out.object_name, joined_out.object_name = OUTPUTS
    link = tree.links.new
    link(node["bunny"].outputs[0], both.inputs[0])
    link(node["spot"].outputs[0], both.inputs[0])
    link(both.outputs[0], difference.inputs["Base"])
    link(node["cutters"].outputs[0], difference.inputs["Cutters"])
    link(difference.outputs[0], carved_out.inputs[0])
    link(node["spot"].outputs[0], joined.inputs[0])
    link(node["post"].outputs[0], joined.inputs[0])
    link(joined.outputs[0], joined_out.inputs[0])
    bpy.context.view_layer.update()
    return tree.name


def evaluate(tree_name: str) -> float:
    """Seconds of one ``aasdf.evaluate_tree``."""
    t0 = time.perf_counter()
    status = bpy.ops.aasdf.evaluate_tree(tree=tree_name)
    seconds = time.perf_counter() - t0
    if status != {"FINISHED"}:
        raise RuntimeError(f"aasdf.evaluate_tree returned {status}")
    return seconds


def fields_built() -> int:
    from aasdf.aasdf_addon import cache

    return cache.stats()["builds"]


def measure(repeat: int) -> dict:
    """Cold, again and reloaded, ``repeat`` rounds after a warm-up round."""
    from aasdf.aasdf_addon import cache

    tree = build_scene()
    folder = tempfile.mkdtemp(prefix="aasdf-tree-")
    out = {"cold": [], "again": [], "reloaded": []}
    built = {}
    for k in range(repeat + 1):
        cache.clear()
        for name in OUTPUTS:
            if name in bpy.data.objects:
                bpy.data.objects.remove(bpy.data.objects[name])
        for case in ("cold", "again", "reloaded"):
            if case == "reloaded":
                path = str(Path(folder) / f"round{k}.blend")
                bpy.ops.wm.save_as_mainfile(filepath=path)
                bpy.ops.wm.open_mainfile(filepath=path)
            before = fields_built()
            seconds = evaluate(tree)
            built[case] = fields_built() - before
            if k:
                out[case].append(seconds)
    result = {case: statistics.median(times) for case, times in out.items()}
    for case in ("again", "reloaded"):
        result[f"{case}_ratio"] = round_ratios(out[case], out["cold"])
    result["built"] = built
    return result


def ratio(r, digits: int = 3) -> str:
    return f"{r[0]:.{digits}f}× ({r[1]:.{digits}f}–{r[2]:.{digits}f})"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--drag-moves", type=int, default=10)
    parser.add_argument("--drag-repeat", type=int, default=3)
    parser.add_argument("--no-drag", action="store_true")
    parser.add_argument("--no-tree", action="store_true", help="the drag alone")
    args = parser.parse_args(argv)
    addon.register()
    print(f"# CSG tree benchmark — {addon.machine()}; {args.repeat} rounds after a warm-up\n")
    if not args.no_tree:
        m = measure(args.repeat)
        built = m["built"]
        print("| cold s | again s | again / cold | reloaded s | reloaded / cold ", end="")
        print("| fields built cold / again / reloaded |")
        print("|---|---|---|---|---|---|")
        print(
            f"| {m['cold']:.3f} | {m['again']:.3f} | {ratio(m['again_ratio'])} | {m['reloaded']:.3f} "
            f"| {ratio(m['reloaded_ratio'])} | {built['cold']} / {built['again']} / {built['reloaded']} |",
            flush=True,
        )
    if args.no_drag:
        return
    a, b = cases()["bunny+spot"]
    points = np.vstack([a[0], b[0]])
    voxel = float(np.linalg.norm(points.max(0) - points.min(0))) / 256
    print(f"\n## A drag through a CSG tree: {args.drag_moves} moves of the cutter, bunny − spot, /256\n")
    rows = []
    for keep_faces in (True, False):
        d = addon.drag(a, b, voxel, moves=args.drag_moves, repeat=args.drag_repeat, keep_faces=keep_faces)
        rows.append(("kept faces" if keep_faces else "remeshed", d))
    names = list(rows[0][1]["stages"])
    print("| surface | AASDF s | GN SDF s | AASDF / GN | fields built | " + " | ".join(names) + " |")
    print("|" + "|".join(["---"] * (5 + len(names))) + "|")
    for label, d in rows:
        stages = " | ".join(f"{d['stages'][name]:.2f}" for name in names)
        print(f"| {label} | {d['ours']:.2f} | {d['theirs']:.2f} | {ratio(d['ratio'], 2)} | {d['built']} | {stages} |")


if __name__ == "__main__":
    main()
