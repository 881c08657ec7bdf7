"""The booleans' combinations as Warp functions: hard, round (polynomial smooth) and chamfer min/max.

A round blend of radius ``k`` replaces ``min(a, b)`` by the polynomial smooth minimum; a chamfer by
``min(a, b, (a + b - k) / sqrt(2))``: where two surfaces meet at a right angle, a flat bevel (the plane a + b = k on a
union's concave seam, a + b = -k on an intersection's convex one) meets each face ``k`` from the seam. Both are
monotone in each argument, which gives a boolean the brackets it prunes with (:func:`chamfer_bracket`) and the tests
of whether an operand can decide the result (:func:`chamfer_needs`).
"""

from __future__ import annotations

import warp as wp

BLEND_MODES = {"round": 0, "chamfer": 1}


def lipschitz(mode: int, blend: float, la: float, lb: float) -> float:
    """A bound on the gradient of a boolean of fields bounded by ``la`` and ``lb``: min and max keep the larger, and so
    does a round blend (its gradient is h grad a + (1 - h) grad b); a chamfer's plane (a + b - k) / sqrt(2) has up to
    (la + lb) / sqrt(2) where the operands' gradients agree (sqrt(2) over two distances, more over a chamfered
    boolean: a chamfer over a chamfer about 1.71)."""
    if mode == 1 and blend > 0.0:
        return max(la, lb, (la + lb) * 0.7071067811865476)
    return max(la, lb)


# 1 / sqrt(2), and sqrt(2) - 1: the chamfer's plane and where it stops mattering
SQRT_HALF = wp.constant(0.7071067811865476)
SQRT2_MINUS_1 = wp.constant(0.41421356237309515)


@wp.func
def sdf_smooth_min(a: float, b: float, k: float) -> float:
    """Polynomial smooth minimum of radius ``k`` (``k = 0``: min)."""
    if k <= 0.0:
        return wp.min(a, b)
    h = wp.clamp(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


@wp.func
def sdf_chamfer_min(a: float, b: float, k: float) -> float:
    """Chamfer minimum of size ``k``: ``min(a, b, (a + b - k) / sqrt(2))`` (``k = 0``: min)."""
    if k <= 0.0:
        return wp.min(a, b)
    return wp.min(wp.min(a, b), (a + b - k) * SQRT_HALF)


@wp.func
def sdf_combine(op: int, a: float, b: float, k: float, mode: int) -> float:
    """union = min, intersection = max, difference (a minus b) = max(a, -b); blended by ``k > 0``, round
    (``mode`` 0) or chamfer (1)."""
    if mode == 1:
        if op == 0:
            return sdf_chamfer_min(a, b, k)
        if op == 1:
            return -sdf_chamfer_min(-a, -b, k)
        return -sdf_chamfer_min(-a, b, k)
    if op == 0:
        return sdf_smooth_min(a, b, k)
    if op == 1:
        return -sdf_smooth_min(-a, -b, k)
    return -sdf_smooth_min(-a, b, k)


@wp.func
def chamfer_needs(op: int, va: float, ra: float, tb: float, rb: float, k: float) -> wp.vec2i:
    """(need a, need b) for a chamfer: whether each operand, known within its bracket (``va`` +- ``ra``, and the
    second as the operation sees it, ``tb`` +- ``rb``), can change the result. ``min(a, b, (a + b - k) / sqrt(2))``
    is ``a`` exactly when b >= max(a, (sqrt(2) - 1) a + k), increasing in a; the maximum is the mirror image."""
    need_a = int(1)
    need_b = int(1)
    if op == 0:
        if tb - rb >= wp.max(va + ra, SQRT2_MINUS_1 * (va + ra) + k):
            need_b = 0
        elif va - ra >= wp.max(tb + rb, SQRT2_MINUS_1 * (tb + rb) + k):
            need_a = 0
    else:
        if tb + rb <= wp.min(va - ra, SQRT2_MINUS_1 * (va - ra) - k):
            need_b = 0
        elif va + ra <= wp.min(tb - rb, SQRT2_MINUS_1 * (tb - rb) - k):
            need_a = 0
    return wp.vec2i(need_a, need_b)


@wp.func
def chamfer_bracket(op: int, va: float, ra: float, tb: float, rb: float, k: float) -> wp.vec2:
    """(lowest, highest) chamfer result over the operands' brackets (the second as the operation sees it): the
    chamfer is monotone, so its values at the brackets' ends."""
    if op == 0:
        return wp.vec2(sdf_chamfer_min(va - ra, tb - rb, k), sdf_chamfer_min(va + ra, tb + rb, k))
    return wp.vec2(-sdf_chamfer_min(-(va - ra), -(tb - rb), k), -sdf_chamfer_min(-(va + ra), -(tb + rb), k))


@wp.func
def result_bracket(op: int, va: float, ra: float, tb: float, rb: float, k: float, mode: int) -> wp.vec2:
    """(lowest, highest) value of the boolean, blended by ``k`` (round or chamfer ``mode``), over the operands'
    brackets (``va`` +- ``ra``, and the second as the operation sees it, ``tb`` +- ``rb``): min, max and both blends
    are monotone in each argument (the smooth minimum's derivatives are h and 1 - h), so their values at the
    brackets' ends."""
    if mode == 1:
        return chamfer_bracket(op, va, ra, tb, rb, k)
    if op == 0:
        return wp.vec2(sdf_smooth_min(va - ra, tb - rb, k), sdf_smooth_min(va + ra, tb + rb, k))
    return wp.vec2(-sdf_smooth_min(-(va - ra), -(tb - rb), k), -sdf_smooth_min(-(va + ra), -(tb + rb), k))


@wp.func
def blend_matters(op: int, va: float, ra: float, tb: float, rb: float, k: float, mode: int) -> bool:
    """Whether both operands can shape the blended result over their brackets (elsewhere it is one of them alone,
    as the hard boolean is): they differ by less than ``k`` somewhere for a round blend; :func:`chamfer_needs` both
    for a chamfer."""
    if k <= 0.0:
        return False
    if mode == 1:
        needs = chamfer_needs(op, va, ra, tb, rb, k)
        return needs[0] == 1 and needs[1] == 1
    return wp.abs(va - tb) - ra - rb < k
