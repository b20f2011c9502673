"""``eval flags``: how far the signs of evaluation/health.py can be trusted, on a run whose truth is
known: how often a flagged pair is a real failure (precision) and how many failures go unflagged
(recall), for all signs together and for each.

Two kinds of truth: a run scored pair by pair (``eval sequence --truth pose``: a failure is outside
the consecutive-pair criteria), or a relations file (Kümmerle et al. 2009) whose short relations
(both ends within ``LOCAL_S`` seconds) each cover a stretch of the run's pairs: a stretch fails
when the chained matches between its two scans miss the relation by more than the consecutive-pair
criteria, and a flagged pair counts as a real failure when it lies in a failed stretch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbicp_viz.core import pose_error
from mbicp_viz.readers.pair_match import PairMatch, Suspicion
from mbicp_viz.readers.relations import Relation

from .criteria import CONSECUTIVE
from .run_score import relation_errors
from .trajectory import accumulate

LOCAL_S = 10.0  # a relation this short covers a few dozen pairs, no loop


@dataclass(frozen=True)
class FlagCheck:
    """Flags against failures, over the pairs (or stretches) that have a truth."""

    sign: str  # a sign's name, or "any sign"
    flagged: int  # flagged pairs with a truth
    true: int  # of those, real failures
    failures: int  # failures (pairs or stretches)
    caught: int  # of those, flagged (a stretch: one of its pairs)

    def line(self) -> str:
        precision = f"{100 * self.true / self.flagged:.0f} %" if self.flagged else "-"
        recall = f"{100 * self.caught / self.failures:.0f} %" if self.failures else "-"
        return (
            f"{self.sign}: {self.flagged} flagged, {self.true} of them failures (precision "
            f"{precision}); {self.caught} of {self.failures} failures flagged (recall {recall})"
        )


def _checks(flags: list[set[Suspicion]], bad: np.ndarray, caught) -> list[FlagCheck]:
    """One check for any sign, then one per sign seen; ``caught(mask)`` counts the failures a
    mask of flagged pairs catches."""
    out = []
    for sign in [None, *[s for s in Suspicion if any(s in f for f in flags)]]:
        mask = np.array([bool(f) if sign is None else sign in f for f in flags], bool)
        total, hit = caught(mask)
        name = "any sign" if sign is None else str(sign)
        out.append(FlagCheck(name, int(mask.sum()), int((mask & bad).sum()), total, hit))
    return out


# the signs read from the odometry: no test of anything where the odometry is the truth
_FROM_ODOMETRY = {Suspicion.ODOMETRY_JUMP, Suspicion.SIGMA}


def odometry_is_truth(rows: list[PairMatch]) -> bool:
    """Whether every scored row's odometry is its truth (a corrected log whose odometry was
    re-anchored at the corrected poses): the odometry's signs then know the answer."""
    both = [r for r in rows if r.truth is not None and r.odometry is not None]
    return bool(both) and all(max(pose_error(r.odometry, r.truth)) < 1e-9 for r in both)


def check_scored(rows: list[PairMatch]) -> list[FlagCheck]:
    """Against each pair's own score (rows of ``eval sequence --truth pose``); where the odometry
    is the truth its signs are left out (``odometry_is_truth``)."""
    scored = [r for r in rows if r.score is not None]
    bad = np.array([not r.score.success for r in scored], bool)
    skip = _FROM_ODOMETRY if odometry_is_truth(scored) else set()
    flags = [set(r.flags) - skip for r in scored]
    return _checks(flags, bad, lambda mask: (int(bad.sum()), int((mask & bad).sum())))


def check_relations(
    rows: list[PairMatch], stamps: list[float], relations: list[Relation], tolerance: float
) -> list[FlagCheck]:
    """Against the short relations: each covers the pairs between its two scans (``stamps``: one
    per scan the rows visit, on the relations' clock)."""
    local = [rel for rel in relations if 0.0 < rel.t2 - rel.t1 <= LOCAL_S]
    e = relation_errors(np.asarray(stamps, float), accumulate(rows), local, tolerance)
    stretches = [
        (i, j, not CONSECUTIVE.correct(et, er))
        for (i, j), et, er in zip(e.ends, e.trans, e.rot)
        if i < j
    ]
    covered, bad = np.zeros(len(rows), bool), np.zeros(len(rows), bool)
    for i, j, failed in stretches:
        covered[i:j] = True
        bad[i:j] |= failed
    flags = [set(r.flags) if c else set() for r, c in zip(rows, covered)]
    failed = [(i, j) for i, j, f in stretches if f]
    return _checks(
        flags, bad, lambda mask: (len(failed), sum(bool(mask[i:j].any()) for i, j in failed))
    )
