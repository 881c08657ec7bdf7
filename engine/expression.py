"""What a boolean was made of: the tree of operations over the operand fields a result came from.

A boolean's node values keep only the combined distance, so how near the *other* operands' surfaces are to one
operand's face cannot be read off the result. A result therefore keeps its expression: the hard or blended operation
at each inner node and, at the leaves, the operand fields themselves (built or placed fields, offsets and shells;
never an intermediate boolean's arrays). :mod:`.keep` asks the leaves for their distances and evaluates the signs of
the tree to decide which faces of which operand are the result's surface.

Memory: a result holds its leaves alive (the add-on's cache holds them anyway); an intermediate boolean of a chain is
not held.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

OP_UNION, OP_INTERSECTION, OP_DIFFERENCE = 0, 1, 2


@dataclass(frozen=True)
class Operation:
    """An inner node: ``op`` (OP_UNION, OP_INTERSECTION, OP_DIFFERENCE: a minus b) of two sub-expressions, blended
    over ``blend`` world units (0: hard)."""

    op: int
    blend: float
    a: object  # Operation or a leaf field
    b: object

    @cached_property
    def leaf_list(self) -> tuple:
        """The leaves, left to right (found once: a judge of each of 100 leaves asked for them a few times a round)."""
        return tuple(leaves(self.a) + leaves(self.b))

    @cached_property
    def widest(self) -> float:
        """The largest blend radius in the tree (found once)."""
        return max(self.blend, widest_blend(self.a), widest_blend(self.b))


def expression_of(field):
    """The expression a field stands for where it is: its own when it is a boolean (kept in its own frame: placed as
    the field is, :func:`placed`), else the field itself (a leaf)."""
    tree = getattr(field, "expression", None)
    if tree is None:
        return field
    where = getattr(field, "placement", None)
    return tree if where is None else placed(tree, where.matrix, where.scale)


def combined(op: int, blend: float, a, b) -> Operation:
    """The expression of ``op`` applied to fields ``a`` and ``b`` (booleans contribute their own trees)."""
    return Operation(int(op), float(blend), expression_of(a), expression_of(b))


def placed(expression, matrix, scale: float):
    """``expression`` moved by ``matrix`` (a similarity of ``scale``): every leaf placed there
    (``AdaptiveField.transformed``; a leaf used twice, once) and every blend scaled: a placed boolean's operands where
    it is, for the faces a boolean over it keeps."""
    moved = {}

    def walk(node):
        if isinstance(node, Operation):
            return Operation(node.op, node.blend * scale, walk(node.a), walk(node.b))
        if id(node) not in moved:
            moved[id(node)] = node.transformed(matrix)
        return moved[id(node)]

    return walk(expression)


def leaves(expression) -> list:
    """The leaf fields of an expression, left to right (a field used twice is listed twice)."""
    if isinstance(expression, Operation):
        return list(expression.leaf_list)
    return [expression]


def widest_blend(expression) -> float:
    """The largest blend radius anywhere in the tree (0 for hard booleans and leaves)."""
    if isinstance(expression, Operation):
        return expression.widest
    return 0.0


def evaluate_signs(expression, values: list) -> np.ndarray:
    """The hard boolean of per-leaf values (a list of (N,) arrays in :func:`leaves` order): (N,) float values whose
    sign is the result's side. Blends are taken as hard: the callers use it only where every operand but one is
    farther than the blend radius, where a blend equals the hard operation."""
    it = iter(values)

    def walk(node):
        if not isinstance(node, Operation):
            return next(it)
        a, b = walk(node.a), walk(node.b)
        if node.op == OP_UNION:
            return np.minimum(a, b)
        if node.op == OP_INTERSECTION:
            return np.maximum(a, b)
        return np.maximum(a, -b)

    return walk(expression)
