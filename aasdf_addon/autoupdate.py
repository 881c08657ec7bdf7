"""Auto Update of CSG trees: a depsgraph handler that only marks trees dirty, and a debounced timer that evaluates them.

A tree with ``auto_update`` on is marked dirty when one of its input objects changes geometry or transform, when an
input collection changes, or when the tree itself changes (links, nodes, settings: ``tree_changed``). Marking
(re)starts a ``bpy.app.timers`` timer that waits until nothing has changed for ``DEBOUNCE`` seconds, so dragging an
input evaluates once when the drag pauses instead of queueing an evaluation per step. The handler never evaluates.
``evaluate_now`` is the same evaluation on demand (``aasdf.evaluate_tree``); in the ``bpy`` module, where timers never
fire, it is the only way. ``unregister()`` removes the handlers and the timer.
"""

import time

import bpy

from . import csg, nodes, runtime

DEBOUNCE = 0.4  # seconds without changes before a dirty tree is evaluated

_dirty: set = set()  # session_uid of the trees to evaluate
_inputs: dict = {}  # tree session_uid -> session_uids of its input objects when it was last evaluated
_last_change = 0.0
_evaluating = False
_enabled = False  # between register() and unregister(): unregistering the tree types calls their update()


def csg_trees():
    return [tree for tree in bpy.data.node_groups if tree.bl_idname == nodes.TREE]


def is_dirty(tree) -> bool:
    return tree.session_uid in _dirty


def mark_dirty(tree):
    """Queue ``tree`` for the timer (when its Auto Update is on) and restart the debounce interval."""
    global _last_change
    if _evaluating or not _enabled or not tree.auto_update:
        return
    _dirty.add(tree.session_uid)
    _last_change = time.monotonic()
    if not bpy.app.timers.is_registered(_on_timer):
        bpy.app.timers.register(_on_timer, first_interval=DEBOUNCE)


def tree_changed(tree):
    """A tree's own links, nodes or settings changed."""
    if nodes.is_csg_tree(tree):
        mark_dirty(tree)


def evaluate_now(context, tree) -> list:
    """Evaluate a tree now (pending input updates are flushed first) and drop it from the queue.

    Raises:
        AasdfError: As ``csg.evaluate_tree``.
    """
    global _evaluating
    context.evaluated_depsgraph_get()  # delivers pending updates to the handler before the queue is cleared
    _dirty.discard(tree.session_uid)
    _evaluating = True
    try:
        return csg.evaluate_tree(context, tree)
    finally:
        _evaluating = False
        _inputs[tree.session_uid] = csg.input_objects(tree)[0]


def _on_timer():
    """Evaluate the dirty trees once nothing changed for ``DEBOUNCE`` s; returns the next interval or ``None``."""
    if not _dirty:
        return None
    wait = DEBOUNCE - (time.monotonic() - _last_change)
    if wait > 0.0:
        return wait
    context = bpy.context
    if context.mode != "OBJECT":  # editing an input: evaluate once back in Object Mode
        return DEBOUNCE
    engine = runtime.engine()
    for tree in csg_trees():
        if tree.session_uid in _dirty:
            try:
                evaluate_now(context, tree)
            except engine.AasdfError:
                pass  # the messages are on the nodes; the previous result stays
    return DEBOUNCE if _dirty else None


# ---- handlers ----


@bpy.app.handlers.persistent
def _on_depsgraph_update(scene, depsgraph):
    if _evaluating:
        return
    trees = [tree for tree in csg_trees() if tree.auto_update]  # dirty ones too: a change restarts the debounce
    if not trees:
        return
    moved, collections_changed = set(), set()
    for update in depsgraph.updates:
        data = update.id
        if isinstance(data, bpy.types.Object) and (update.is_updated_geometry or update.is_updated_transform):
            moved.add(data.original.session_uid)
        elif isinstance(data, bpy.types.Collection):
            collections_changed.add(data.original.session_uid)
    if not (moved or collections_changed):
        return
    for tree in trees:
        objects, collections = csg.input_objects(tree)
        # A collection is also reported when only relations were rebuilt: what counts is a change of its members.
        members_changed = collections_changed & collections and objects != _inputs.get(tree.session_uid)
        if moved & objects or members_changed:
            mark_dirty(tree)


@bpy.app.handlers.persistent
def _on_load_post(*_args):
    _dirty.clear()
    _inputs.clear()


_HANDLERS = (
    (bpy.app.handlers.depsgraph_update_post, _on_depsgraph_update),
    (bpy.app.handlers.load_post, _on_load_post),
)


def register():
    global _enabled
    _enabled = True
    for handlers, handler in _HANDLERS:
        if handler not in handlers:
            handlers.append(handler)


def unregister():
    global _evaluating, _enabled
    _enabled = False
    for handlers, handler in _HANDLERS:
        while handler in handlers:
            handlers.remove(handler)
    if bpy.app.timers.is_registered(_on_timer):
        bpy.app.timers.unregister(_on_timer)
    _dirty.clear()
    _inputs.clear()
    _evaluating = False
