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

from mbicp_viz.readers.rows import EvalRow

# Successful Intel matches stay below 40 (99th percentile, 427 pairs from the identity); half of
# the failures' final constraints are above 19, a fifth above 50.
DEGENERATE_CONDITION = 50.0
LOW_OVERLAP = 0.5  # share of object points within 5 cm of the reference at the stored pose


def failed(row: EvalRow) -> bool:
    """Scored rows fail outside the criteria; unscored ones when the matcher did not converge."""
    return not row.success if row.success is not None else not row.converged


def failure_reason(row: EvalRow) -> str:
    if not row.converged:
        return f"stopped early ({row.reason})"
    if row.inliers_truth is not None and row.inliers_truth < LOW_OVERLAP:
        return (
            f"low overlap ({100 * row.inliers_truth:.0f} % of the object points on the "
            "reference at the stored pose)"
        )
    if row.condition_number is not None and row.condition_number > DEGENERATE_CONDITION:
        return f"degenerate direction (condition number {row.condition_number:.0f})"
    return "wrong basin (converged elsewhere)"


def worst_first(rows: list[EvalRow]) -> list[EvalRow]:
    """The failed rows: the largest translation error first, then rotation error, then order."""
    return sorted(
        (r for r in rows if failed(r)),
        key=lambda r: (-(r.error_xy or 0.0), -(r.error_theta or 0.0), r.line),
    )


def failure_label(rank: int, row: EvalRow) -> str:
    """One line per failure, as the debugger's list shows it."""
    error = (
        ""
        if row.error_xy is None
        else f"{row.error_xy:.3f} m, {math.degrees(row.error_theta):.2f} deg: "
    )
    return f"{rank}. scans {row.ref} -> {row.obj}: {error}{failure_reason(row)}"


def failure_summary(rows: list[EvalRow], path: str, shown: int = 3) -> list[str]:
    """The worst failures, for the end of ``eval sequence``."""
    bad = worst_first(rows)
    if not bad:
        return []
    lines = [
        f"worst failures of {len(bad)}:",
        *(f"  {failure_label(k + 1, r)}" for k, r in enumerate(bad[:shown])),
    ]
    return lines + [f"open them as they failed: mbicp-viz serve LOG --rows {path}"]
