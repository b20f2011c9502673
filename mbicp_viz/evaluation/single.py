"""One pair's match and its record (``readers/pair_match.PairMatch``): the guess and where it came
from, the result, how well it lays the scans on each other, its distance from the odometry and its
error when the answer is known. Every command and front end that matches a pair makes it here."""

from __future__ import annotations

import time
from dataclasses import dataclass

from mbicp_viz.choices import MATCH_BUDGET_S, Guess
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
from mbicp_viz.core.agreement import agreement, inlier_fraction
from mbicp_viz.core.budget import Halt, limited
from mbicp_viz.readers.log import Frames
from mbicp_viz.readers.pair_match import PairMatch, Score

from .criteria import CONSECUTIVE
from .health import pair_flags
from .pairs import ScanPair, known_answer, pair_guess, stored_odometry


@dataclass(frozen=True)
class Setup:
    """Where a pair's match starts and what it is judged against."""

    guess: Pose2 = Pose2()  # laser frame
    guess_source: str = "given"  # "scan poses", "odometry", "identity", "search", "searched ..."
    truth: Pose2 | None = None  # laser frame
    truth_source: str | None = None


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
    return Setup(g, source, *known_answer(pair.ref, pair.obj, source, truth))


def reported(result: MatchResult, frames: Frames, base: bool) -> MatchResult:
    """The result in the frame it is reported in: the robot base's motion when ``base`` and the
    laser's mount is known, else the laser's."""
    return result.conjugated(frames.mount) if frames.reports_base(base) else result


def scored(ref: Scan, obj: Scan, pose: Pose2, truth: Pose2) -> Score:
    """The laser's motion ``pose`` against ``truth``: its error, whether it is within the
    consecutive-pair criteria and, for a failure, what the points say of each."""
    et, er = pose_error(pose, truth)
    if CONSECUTIVE.correct(et, er):
        return Score(et, er, True)
    # is the matcher wrong, or the stored pose? Ask the points.
    return Score(et, er, False, inlier_fraction(ref, obj, pose), inlier_fraction(ref, obj, truth))


def match_pair(
    ref: Scan,
    obj: Scan,
    params: Params,
    s: Setup = Setup(),
    frames: Frames = Frames(),  # noqa: B008 - frozen
    base: bool = True,
    *,
    indices: tuple[int, int] | None = None,
    stream: str | None = None,
    record: bool = False,
    budget_s: float | None = MATCH_BUDGET_S,
    halt: Halt | None = None,
) -> PairMatch:
    """Match one pair from ``s.guess`` and make its record: the result reported in the frame
    ``base`` chooses, how well it lays the scans on each other, its distance from the log's
    odometry and, with ``s.truth``, its error; ``record`` keeps every iteration's events.
    ``indices`` are the record numbers (default: the scans' own). The match stops after
    ``budget_s`` seconds (None or 0: no limit) or when ``halt`` is raised (core/budget.py)."""
    from mbicp_viz.core import tiers

    rec = Recorder() if record else None
    compiling = tiers.compiling()  # a compile the match's first kernel starts runs at its end
    t0 = time.perf_counter()
    with limited(budget_s or None, halt):
        result = match(ref, obj, s.guess, params, rec)
    ms = 1000.0 * (time.perf_counter() - t0)
    shown = reported(result, frames, base)
    odometry, odometry_shown, fields = stored_odometry(ref, obj), None, {}
    if odometry is not None:
        odometry_shown = frames.reported(odometry, base)
        et, er = pose_error(shown.pose, odometry_shown)
        fields = {"odometry": odometry, "odometry_xy": et, "odometry_theta": er}
    i, j = indices if indices is not None else (ref.source.index, obj.source.index)
    on_ref, overlap = agreement(ref, obj, result.pose)
    return PairMatch(
        i,
        j,
        params,
        s.guess,
        s.guess_source,
        shown,
        frames.frame_name(base),
        on_ref,
        stream,
        ms,
        interpreted=compiling or tiers.compiling(),
        truth=s.truth,
        truth_source=s.truth_source,
        score=scored(ref, obj, result.pose, s.truth) if s.truth is not None else None,
        events=rec,
        overlap=overlap,
        flags=pair_flags(shown, overlap, odometry_shown),
        **fields,
    )
