"""The kept faces' judge started beside the rest of a boolean made along its seams.

A boolean made for kept faces (:func:`.boolean.combine` with ``seams=True``) refines its operands along the seams
first (:func:`.ondemand.for_boolean`). What follows (its candidate octets, their pruning, its nodes' values: 30-45 ms
on the bench's CAD pairs at /256) reads the operands and changes nothing of them, and the judge of their triangles
(:func:`.keep.kept_triangles`, 50-100 ms there, mostly numpy between small launches) reads only the operands as built
by then. So the judge runs in a thread of its own from the boolean's start: it finds the operands' own parts (their
sides, defects and slivers, kept with their meshes: the same however far a field is refined) while they are refined,
then judges the refined operands beside the rest of the boolean. The kept surface (:func:`.hybrid.kept_surface`) takes
its verdicts where it would judge the same operands clear of the same points, and judges them itself otherwise.

The thread takes the steps :func:`.seams.kept_along_seams` takes first: the own part of each operand that may hold a
part of its octets (:func:`crossing_leaves`), and no judge where one passes through itself (the result is made again
along all of such an operand, its judge then the new result's: such an operand is built whole in the thread, beside
the rest of the boolean). Verdicts are the same whichever thread finds them:
the same operands' arrays, the same points kept clear of (:mod:`.carried`), and each judge's record of its verdicts
for the next boolean (:mod:`.verdicts`) written as it would be. Not on CUDA, where a boolean's launches already fill
the device: there the kept surface judges as before.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import warp as wp

from .carried import carried
from .expression import Operation, leaves
from .keep import kept_triangles
from .ondemand import along_seams_only, built_leaves, built_on_demand, crosses_itself, refined
from .ownpart import gives_own_faces_up, own_region
from .parallel import run_tasks


def crossing_leaves(expression, voxel: float, device) -> list:
    """The leaves of a boolean's ``expression`` that pass through themselves or have defects other than holes
    (:func:`.ownpart.gives_own_faces_up`), of those that may hold a part of their finest octets (:func:`partly_built`);
    their own parts found side by side (each kept with its mesh for the judge)."""
    pairs = list(zip(leaves(expression), leaves(built_leaves(expression)), strict=True))
    found = {}
    tasks = [
        lambda k=k, view=view: found.update({k: gives_own_faces_up(view, voxel)})
        for k, (_, view) in enumerate(pairs)
        if partly_built(view, expression)
    ]
    run_tasks(tasks, device)
    return [leaf for k, (leaf, _) in enumerate(pairs) if found.get(k, False)]


def partly_built(view, expression) -> bool:
    """Whether a boolean along its seams may hold a part of the octets of its leaf read as ``view``: it was built on
    demand, or its octets are kept along the seams alone (:func:`.ondemand.along_seams_only`, beside any of the other
    leaves)."""
    others = [leaf for leaf in leaves(expression) if leaf.sources is not view.sources]
    return built_on_demand(view) or any(along_seams_only(view, other) for other in others)


@dataclass
class JudgeView:
    """What the judge reads of a boolean result: its expression (the operands read as built), voxel size, device."""

    expression: object
    voxel_size: float
    device: object


class EarlyJudge:
    """The judge of a boolean's operands, running in a thread of its own (module docstring): it finds their own parts
    while they are refined, then waits for the refined operands (:meth:`proceed`)."""

    def __init__(self, expression, voxel: float, device):
        self._found = None
        self._crossing = None
        self._ahead = None
        self._refined = None
        self._given = threading.Event()
        self._checked = threading.Event()
        self._looked = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(expression, voxel, device), daemon=True)
        self._thread.start()

    def proceed(self, expression) -> None:
        """Go on with the boolean's ``expression`` over its refined operands (None: stop, nothing to judge)."""
        self._refined = expression
        self._given.set()

    def _run(self, unrefined, voxel: float, device) -> None:
        try:
            self._ahead = _made_about_crossings(crossing_leaves(unrefined, voxel, device), voxel, device)
            self._looked.set()
            self._given.wait()
            expression = self._refined
            if expression is None:
                return
            self._crossing = crossing_leaves(expression, voxel, device)
            if not self.about(self._crossing):  # made again along all of such an operand (:mod:`.seams`)
                run_tasks([lambda leaf=leaf: refined(leaf) for leaf in self._crossing], device)
                return
            self._checked.set()
            view = JudgeView(built_leaves(expression), voxel, device)
            avoid = carried(view)
            self._found = (view, avoid, kept_triangles(view, avoid=avoid))
        except Exception:  # noqa: BLE001 (the kept surface judges again, and meets the error in its own thread)
            self._crossing = None
        finally:
            self._looked.set()
            self._checked.set()

    def crossed_ahead(self) -> bool:
        """Whether a leaf of the boolean passes through itself, as found before its operands were refined: each such
        leaf then built whole and marked (:func:`.ondemand.crosses_itself`), so that the boolean made along its
        seams from here on is made about its crossings too."""
        self._looked.wait()
        return bool(self._ahead)

    def about(self, crossing) -> bool:
        """Whether the boolean was made about the crossings of every leaf of ``crossing`` (:meth:`crossed_ahead`)."""
        ahead = {id(source) for leaf in self._ahead or () for source in leaf.sources.values()}
        return all(id(source) in ahead for leaf in crossing or () for source in leaf.sources.values())

    def crossing(self) -> list | None:
        """:func:`crossing_leaves` of the boolean's expression, once the thread has found them (None: it failed)."""
        self._checked.wait()
        return self._crossing

    def take(self, field, avoid) -> list | None:
        """The verdicts (:func:`.keep.kept_triangles`) for ``field`` (a view of the boolean, its operands read as
        built) judged clear of the points ``avoid``, when the thread judged the same (once: they are let go);
        else None."""
        self._thread.join()
        found, self._found = self._found, None
        if found is None:
            return None
        view, their_avoid, judged = found
        same = view.voxel_size == field.voxel_size and same_operands(view.expression, field.expression)
        return judged if same and np.array_equal(their_avoid, avoid) else None


def _made_about_crossings(crossing: list, voxel: float, device) -> list:
    """The leaves of ``crossing`` (they pass through themselves) built whole and marked as crossing about their own
    regions (:func:`.ownpart.own_region`), as :func:`.seams.kept_along_seams` would after the boolean."""
    run_tasks([lambda leaf=leaf: refined(leaf) for leaf in crossing], device)
    for leaf in crossing:
        crosses_itself(leaf, own_region(leaf, voxel), voxel)
    return crossing


def start_judge(expression, voxel: float, device) -> EarlyJudge | None:
    """The judge of a boolean's operands (``expression`` over them before they are refined) started beside the
    boolean: :meth:`EarlyJudge.proceed` gives it the refined ones (None on CUDA)."""
    if wp.get_device(device).is_cuda:
        return None
    return EarlyJudge(expression, voxel, device)


def early_verdicts(field, avoid) -> list | None:
    """What the early judge of the boolean ``field`` is a view of found for it, clear of ``avoid`` (None: judge)."""
    early = getattr(field, "early_judge", None)
    return None if early is None else early.take(field, avoid)


def same_operands(a, b) -> bool:
    """Whether two expressions are the same operations over the same operands, each read off the same arrays at the
    same placement."""
    if isinstance(a, Operation) or isinstance(b, Operation):
        return (
            isinstance(a, Operation)
            and isinstance(b, Operation)
            and (a.op, a.blend) == (b.op, b.blend)
            and same_operands(a.a, b.a)
            and same_operands(a.b, b.b)
        )
    if a.values is not b.values or a.field_ids != b.field_ids or a.sources.keys() != b.sources.keys():
        return False
    if any(a.sources[k] is not b.sources[k] for k in a.sources):
        return False
    if a.placement is None or b.placement is None:
        return a.placement is None and b.placement is None
    return bool(np.array_equal(a.placement.matrix, b.placement.matrix))
