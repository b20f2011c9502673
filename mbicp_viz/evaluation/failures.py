"""The failed pairs of an evaluation, worst first, each with the reason a user looks for first.

The reasons, checked in this order:
- **stopped early**: the matcher did not converge (iteration cap, too few pairs, ...);
- **low overlap**: even at the stored pose, fewer than half of the object points lie on the
  reference: the scans share too little for any local matcher;
- **degenerate direction**: it converged, but its final constraints are ill-conditioned (a
  corridor: paper 000 §3.3), so the pose slid along the weakest direction;
- **wrong basin**: it converged, well constrained, somewhere else (the guess was too far).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import StrEnum

from mbicp_viz.readers.pair_match import PairMatch

# Successful Intel matches stay below 40 (99th percentile, 427 pairs from the identity); half of
# the failures' final constraints are above 19, a fifth above 50.
DEGENERATE_CONDITION = 50.0
LOW_OVERLAP = 0.5  # share of object points within 5 cm of the reference at the stored pose


def failed(row: PairMatch) -> bool:
    """Scored rows fail outside the criteria; unscored ones when the matcher did not converge."""
    return not row.score.success if row.score is not None else not row.result.converged


class Reason(StrEnum):
    STOPPED_EARLY = "stopped early"
    LOW_OVERLAP = "low overlap"
    DEGENERATE = "degenerate direction"
    WRONG_BASIN = "wrong basin"


def failure_kind(row: PairMatch) -> Reason:
    """Why a failed row failed, the first of the module's reasons that holds."""
    if not row.result.converged:
        return Reason.STOPPED_EARLY
    on_truth = row.score.inliers_truth if row.score is not None else None
    if on_truth is not None and on_truth < LOW_OVERLAP:
        return Reason.LOW_OVERLAP
    deg = row.result.degeneracy
    if deg is not None and deg.condition_number > DEGENERATE_CONDITION:
        return Reason.DEGENERATE
    return Reason.WRONG_BASIN


def failure_reason(row: PairMatch) -> str:
    """The reason with the number that decided it."""
    kind = failure_kind(row)
    if kind is Reason.STOPPED_EARLY:
        return f"{kind} ({row.result.reason.value})"
    if kind is Reason.LOW_OVERLAP:
        return (
            f"{kind} ({100 * row.score.inliers_truth:.0f} % of the object points on the "
            "reference at the stored pose)"
        )
    if kind is Reason.DEGENERATE:
        return f"{kind} (condition number {row.result.degeneracy.condition_number:.0f})"
    return f"{kind} (converged elsewhere)"


def worst_first(rows: Sequence[PairMatch]) -> Sequence[PairMatch]:
    """The failed rows: the largest translation error first, then rotation error, then order
    (each made when read: a run over a rows file may have thousands)."""
    from .run_rows import RunRows  # it ranks with this module's ``failed``

    return RunRows.of(rows).worst_first() if len(rows) else []


def failure_label(rank: int, row: PairMatch) -> str:
    """One line per failure, as the debugger's list shows it."""
    sc = row.score
    error = "" if sc is None else f"{sc.error_xy:.3f} m, {math.degrees(sc.error_theta):.2f} deg: "
    return f"{rank}. scans {row.ref} -> {row.obj}: {error}{failure_reason(row)}"


def failure_summary(rows: list[PairMatch], shown: int = 3) -> list[str]:
    """The worst failures, for the end of ``eval sequence``."""
    bad = worst_first(rows)
    if not bad:
        return []
    return [
        f"worst failures of {len(bad)}:",
        *(f"  {failure_label(k + 1, r)}" for k, r in enumerate(bad[:shown])),
    ]
