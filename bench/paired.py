"""Paired timing: AASDF and the tool it is compared with, run alternately, compared round by round.

This machine's speed drifts by 10-20 % within minutes (other tenants of the host). Timing all runs of one method and
then all runs of the other puts that drift into the ratio; running them in turns, in alternating order (ours first in
even rounds, theirs first in odd ones), and taking the median of the per-round ratios compares each pair of runs
under the same conditions.
"""

from __future__ import annotations

import statistics


def paired(ours, theirs, repeat: int, *, warm_up: bool = True) -> dict:
    """Time ``ours`` against ``theirs`` in ``repeat`` alternating rounds, after one warm-up call of each (``warm_up``;
    callables that warm up on their own, in processes of their own, need none).

    Args:
        ours, theirs: Callables returning a dict with ``"seconds"`` (and anything else, kept).
        repeat: Rounds (at least 1).
    Returns:
        ``ours`` and ``theirs``: the run of median time of each; ``ratio``: median of ours / theirs per round;
        ``low`` and ``high``: the smallest and largest per-round ratio.
    """
    if warm_up:
        ours()
        theirs()
    runs_ours, runs_theirs = [], []
    for k in range(max(1, repeat)):
        if k % 2 == 0:
            runs_ours.append(ours())
            runs_theirs.append(theirs())
        else:
            runs_theirs.append(theirs())
            runs_ours.append(ours())
    ratio, low, high = round_ratios([r["seconds"] for r in runs_ours], [r["seconds"] for r in runs_theirs])
    return {
        "ours": _median_run(runs_ours),
        "theirs": _median_run(runs_theirs),
        "ratio": ratio,
        "low": low,
        "high": high,
    }


def round_ratios(ours: list, theirs: list) -> tuple[float, float, float]:
    """(median, smallest, largest) of the per-round ratios ours[k] / theirs[k] of two lists of seconds."""
    ratios = [o / t for o, t in zip(ours, theirs, strict=True)]
    return statistics.median(ratios), min(ratios), max(ratios)


def _median_run(runs: list) -> dict:
    order = sorted(range(len(runs)), key=lambda i: runs[i]["seconds"])
    return runs[order[len(runs) // 2]]
