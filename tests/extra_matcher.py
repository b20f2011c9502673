"""A matcher added from outside the project, in this one file and one ``register`` call:
point-to-point ICP without trimming (Besl & McKay 1992) — nearest reference point from a k-d tree,
pairs beyond ``max_dist`` dropped, the closed-form 2-D rigid step."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from mbicp_viz.core.events import (
    Correspondences,
    FinishEvent,
    IterationEvent,
    PairKind,
    PairStatus,
    StartEvent,
)
from mbicp_viz.core.matchers import Matcher, register
from mbicp_viz.core.params import StopParams, param
from mbicp_viz.core.result import MatchResult, Termination
from mbicp_viz.core.se2 import Pose2


@dataclass(frozen=True)
class P2pParams(StopParams):
    max_dist: float = param(1.0, unit="m", lo=0.01, hi=100.0, help="no pair farther than this")

    def hard_cut(self) -> tuple[str, float] | None:
        return f"max_dist, {self.max_dist:g} m", self.max_dist


def step(a: np.ndarray, b: np.ndarray) -> Pose2:
    """The rigid motion taking points ``a`` onto ``b`` in the least-squares sense."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    h = (a - ca).T @ (b - cb)
    th = math.atan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    t = cb - Pose2(0.0, 0.0, th).apply(ca[None])[0]
    return Pose2(float(t[0]), float(t[1]), th)


def match(ref, obj, guess: Pose2, params: P2pParams, observer=None) -> MatchResult:
    ref_pts, obj_pts = ref.points(), obj.points()
    tree, est, err, keep = cKDTree(ref_pts), guess, math.inf, np.zeros(0, dtype=bool)
    if observer:
        observer(StartEvent("p2p", params, ref_pts, obj_pts, np.arange(len(obj_pts)), guess, None))
    reason, it = Termination.MAX_ITERATIONS, 0
    for it in range(1, params.MaxIter + 1):
        moved = est.apply(obj_pts)
        d, j = tree.query(moved)
        keep = d <= params.max_dist
        if keep.sum() < 3:
            reason = Termination.TOO_FEW_PAIRS
            break
        inc = step(moved[keep], ref_pts[j[keep]])
        before, est = est, inc @ est
        err = float(np.mean(np.sum((inc.apply(moved[keep]) - ref_pts[j[keep]]) ** 2, axis=1)))
        if observer:
            n = len(moved)
            status = np.where(keep, PairStatus.KEPT, PairStatus.OUTSIDE_BR).astype(np.int8)
            pairs = Correspondences(
                np.arange(n), ref_pts[j], np.full(n, PairKind.POINT, dtype=np.int8),
                np.stack([j, np.full(n, -1)], axis=1), d, status, moved,
            )  # fmt: skip
            observer(
                IterationEvent(
                    it, before, est, moved, np.zeros(0, dtype=int), pairs, None, err, inc
                )
            )
        if params.small(inc):
            reason = Termination.CONVERGED
            break
    kept = int(keep.sum())
    result = MatchResult(
        "p2p", est, reason.converged, reason, it, err, kept, len(keep) - kept, None, None
    )
    if observer:
        observer(FinishEvent(result))
    return result


register(Matcher("p2p", "Point-to-point ICP, untrimmed", P2pParams, __name__, (90, 90, 90)))
