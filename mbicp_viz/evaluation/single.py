"""One pair, matched as ``match`` and ``compare`` do: the guess and where it came from, the result,
how well it lays the scans on each other, and its error when the answer is known."""

from __future__ import annotations

import time
from dataclasses import dataclass

from mbicp_viz.choices import Guess
from mbicp_viz.core import (
    MatchResult,
    Params,
    Pose2,
    Recorder,
    Scan,
    SearchParams,
    match,
    pose_error,
)
from mbicp_viz.core.agreement import inlier_fraction
from mbicp_viz.readers.log import Frames

from .pairs import ScanPair, pair_guess, stored_truth


@dataclass(frozen=True)
class Setup:
    """Where a pair's match starts and what it is judged against."""

    guess: Pose2
    guess_source: (
        str  # "scan poses", "odometry", "identity", "search", "given", "search around ..."
    )
    truth: Pose2 | None
    truth_source: str | None


def setup(
    pair: ScanPair,
    guess: Guess,
    given: Pose2 | None = None,
    search_around: bool = False,
    truth: Pose2 | None = None,
    search: SearchParams | None = None,
) -> Setup:
    """The initial guess — ``given``, else of kind ``guess`` — optionally refined by the correlative
    search around it; the answer — ``truth``, else the log's scan poses unless the guess came from
    them (a match started at its own answer proves nothing)."""
    g, source = (
        (given, "given") if given is not None else pair_guess(pair.ref, pair.obj, guess, search)
    )
    if search_around:
        from mbicp_viz.core.search import correlative_search

        g, source = (
            correlative_search(pair.ref, pair.obj, g, search).pose,
            f"searched around {source}",
        )
    if truth is not None:
        return Setup(g, source, truth, "given")
    stored = stored_truth(pair.ref, pair.obj)
    if stored is not None and source != "scan poses":
        return Setup(g, source, stored, "the log's scan poses")
    return Setup(g, source, None, None)


@dataclass(frozen=True)
class Outcome:
    result: MatchResult
    time_ms: float
    on_ref: float  # fraction of object points within INLIER_RADIUS_M of a reference point
    recorder: Recorder | None
    interpreted: bool = (
        False  # run while numba compiled the kernels in the background (core/tiers.py)
    )


def run(ref: Scan, obj: Scan, guess: Pose2, params: Params, record: bool = False) -> Outcome:
    from mbicp_viz.core import tiers

    rec = Recorder() if record else None
    compiling = tiers.compiling()  # a compile the match's first kernel starts runs at its end
    t0 = time.perf_counter()
    result = match(ref, obj, guess, params, rec)
    ms = 1000.0 * (time.perf_counter() - t0)
    return Outcome(
        result, ms, inlier_fraction(ref, obj, result.pose), rec, compiling or tiers.compiling()
    )


def reported(result: MatchResult, frames: Frames, base: bool) -> MatchResult:
    """The result in the frame it is reported in: the robot base's motion when ``base`` and the
    laser's mount is known, else the laser's."""
    return result.conjugated(frames.mount) if frames.reports_base(base) else result


def result_row(ref: int, obj: int, r: MatchResult, time_ms: float) -> dict:
    """The stable JSON record of one match (``match --json``, ``eval sequence``): scripts rely on
    these keys."""
    return {
        "ref": ref,
        "obj": obj,
        "x": r.pose.x,
        "y": r.pose.y,
        "theta": r.pose.theta,
        "iterations": r.iterations,
        "converged": r.converged,
        "reason": r.reason.value,
        "time_ms": time_ms,
    }


def row(indices: tuple[int, int], s: Setup, o: Outcome, frames: Frames, base: bool = True) -> dict:
    """The JSON record of ``match --json`` (the keys of ``eval sequence``'s rows, and more)."""
    r = reported(o.result, frames, base)
    out = (
        result_row(*indices, r, o.time_ms)
        | r.as_dict()
        | {
            "on_ref": o.on_ref,
            "guess": s.guess_source,
            "frame": frames.frame_name(base),
            "interpreted": o.interpreted,
        }
    )
    if s.truth is not None:
        et, er = pose_error(r.pose, frames.reported(s.truth, base))
        out |= {"error_xy": et, "error_theta": er, "truth": s.truth_source}
    return out
