"""``eval sequence``: match every consecutive pair of a log."""

from __future__ import annotations

import math
import time

from core import MatchResult, Params, Pose2, Scan, match, pose_error, relative
from core.agreement import inlier_fraction
from core.search import correlative_search

from .errors import InputError
from .inputs import consecutive_pairs, stored_guess
from .pool import ordered_map
from .readers import ScanLog

GUESSES = ("stored", "pose", "odometry", "identity", "search")
# Paper 000 §3.1's failure threshold, used for the success rate against known poses.
SUCCESS_M, SUCCESS_RAD = 0.1, math.radians(3.0)


def succeeded(et: float, er: float) -> bool:
    """Translation error et [m] and rotation error er [rad] within the success thresholds."""
    return bool(et < SUCCESS_M and er < SUCCESS_RAD)


def truth_doubted(row: dict) -> bool:
    """A failed pair where more object points land on the reference at the matched pose than at
    the stored one: the scans themselves side with the matcher (or cannot tell the two apart)."""
    return not row["success"] and row["inliers_match"] > row["inliers_truth"]


def scored(ref: Scan, obj: Scan, pose: Pose2, truth: Pose2) -> dict:
    """Error of ``pose`` against ``truth`` and, for a failure, what the points say of each (the
    fields ``truth_doubted`` reads)."""
    et, er = pose_error(pose, truth)
    row = {"error_xy": et, "error_theta": er, "success": succeeded(et, er)}
    if not row["success"]:  # is the matcher wrong, or the stored pose? Ask the points.
        row |= {"inliers_match": inlier_fraction(ref, obj, pose), "inliers_truth": inlier_fraction(ref, obj, truth)}
    return row


def result_row(ref: int, obj: int, r: MatchResult, time_ms: float) -> dict:
    """The stable JSON record of one match (``match --json``, ``eval sequence``): scripts rely on these keys."""
    return {"ref": ref, "obj": obj, "x": r.pose.x, "y": r.pose.y, "theta": r.pose.theta,
            "iterations": r.iterations, "converged": r.converged, "reason": r.reason.value, "time_ms": time_ms}


def pair_guess(ref: Scan, obj: Scan, kind: str) -> tuple[Pose2, str]:
    """The initial guess: ``stored`` (poses, else odometry, else identity), one source explicitly, or
    ``search``: the correlative search around the identity (core/search.py), using nothing stored."""
    if kind == "stored":
        return stored_guess(ref, obj)
    if kind == "identity":
        return Pose2(), "identity"
    if kind == "search":
        return correlative_search(ref, obj).pose, "search"
    a, b = (ref.pose, obj.pose) if kind == "pose" else (ref.odometry, obj.odometry)
    if a is None or b is None:
        raise InputError(f"the log stores no {kind} for scans {ref.source.index} and {obj.source.index}",
                         ref.source.path, field="--guess")
    return relative(a, b), kind


def match_sequence(log: ScanLog, params: Params, limit: int | None = None, guess: str = "stored",
                   truth: str | None = None, on_row=None, workers: int | None = None) -> list[dict]:
    """One row per consecutive pair, in order; with ``truth="pose"`` also the error against the log's
    scan poses. Pairs are spread over ``workers`` processes (default: every core; the standard
    library's pool); ``on_row`` sees each row as it arrives, and Ctrl-C keeps the rows so far."""
    if truth == "pose" and guess in ("pose", "stored"):
        raise InputError("the scan poses cannot be both the truth and the guess: use --guess identity or odometry",
                         field="--truth")
    jobs = [(log.path, i, j, log.scans[i], log.scans[j], params, guess, truth) for i, j in consecutive_pairs(log, limit)]
    return ordered_map(_match_row, jobs, workers, on_row)


def _match_row(job) -> dict:
    path, i, j, ref, obj, params, guess, truth = job
    t0 = time.perf_counter()
    g, source = pair_guess(ref, obj, guess)
    t1 = time.perf_counter()
    r = match(ref, obj, g, params)
    row = result_row(i, j, r, 1000.0 * (time.perf_counter() - t1)) | {"guess": source}
    if guess == "search":
        row["guess_ms"] = 1000.0 * (t1 - t0)
    if truth == "pose":
        if ref.pose is None or obj.pose is None:
            raise InputError(f"scan {i} or {j} has no pose to score against", path, field="--truth")
        row |= scored(ref, obj, r.pose, relative(ref.pose, obj.pose))
    return row


def _ceiling_row(job) -> tuple[bool, list[tuple[bool, bool]]]:
    ref, obj, params = job
    truth = relative(ref.pose, obj.pose)
    rows = [scored(ref, obj, match(ref, obj, truth, p).pose, truth) for p in params]
    found = succeeded(*pose_error(correlative_search(ref, obj).pose, truth))
    return found, [(r["success"], truth_doubted(r)) for r in rows]


def ceiling(log: ScanLog, params: list[Params], limit: int | None = None, workers: int | None = None,
            on_row=None) -> tuple[int, list[int], list[int], int]:
    """What a log allows on its consecutive pairs, against its scan poses: how many pairs the
    correlative search alone finds, and how many each matcher keeps when started at the truth itself
    (its fixed point: no guess can do better). Of the pairs a matcher leaves, those where more object
    points lie on the reference at its pose than at the stored one are counted as doubting the truth
    (see ``truth_doubted``). Returns (search hits, hits per matcher, doubts per matcher, pairs)."""
    pairs = consecutive_pairs(log, limit)
    for i, j in pairs:
        if log.scans[i].pose is None or log.scans[j].pose is None:
            raise InputError(f"scan {i} or {j} has no pose to score against", log.path, field="poses")
    rows = ordered_map(_ceiling_row, [(log.scans[i], log.scans[j], params) for i, j in pairs], workers, on_row)
    per_matcher = [[r[1][k] for r in rows] for k in range(len(params))]
    return (sum(r[0] for r in rows), [sum(ok for ok, _ in m) for m in per_matcher],
            [sum(doubt for _, doubt in m) for m in per_matcher], len(rows))
