"""``eval sequence``: match every consecutive pair of a log."""

from __future__ import annotations

import time

from core import MatchResult, Params, match

from .inputs import consecutive_pairs, stored_guess
from .readers import ScanLog


def result_row(ref: int, obj: int, r: MatchResult, time_ms: float) -> dict:
    """The stable JSON record of one match (``match --json``, ``eval sequence``): scripts rely on these keys."""
    return {"ref": ref, "obj": obj, "x": r.pose.x, "y": r.pose.y, "theta": r.pose.theta,
            "iterations": r.iterations, "converged": r.converged, "reason": r.reason.value, "time_ms": time_ms}


def match_sequence(log: ScanLog, params: Params, limit: int | None = None, on_row=None) -> list[dict]:
    """One row per consecutive pair; keys ``ref obj x y theta iterations converged reason time_ms`` (stable)."""
    rows = []
    for i, j in consecutive_pairs(log, limit):
        ref, obj = log.scans[i], log.scans[j]
        guess, source = stored_guess(ref, obj)
        t0 = time.perf_counter()
        r = match(ref, obj, guess, params)
        ms = 1000.0 * (time.perf_counter() - t0)
        row = result_row(i, j, r, ms) | {"guess": source}
        rows.append(row)
        if on_row is not None:
            on_row(row)
    return rows
