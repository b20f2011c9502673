"""``eval sequence``: match every consecutive pair of a log; ``eval ceiling``: what its truth
allows."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace
from functools import partial

import numpy as np

from mbicp_viz.choices import MATCH_BUDGET_S
from mbicp_viz.core import Params, SearchParams, match
from mbicp_viz.core.warmup import load_kernels
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ScanLog
from mbicp_viz.readers.pair_match import PairMatch, Suspicion

from .criteria import CONSECUTIVE, Criteria
from .health import out_of_place
from .keyframes import KeyFrames
from .pairs import STORED_ANSWER, Guess, pair_guess, stored_truth
from .pool import ordered_map
from .single import Setup, match_pair, scored


def truth_summary(rows: Sequence[PairMatch]) -> list[str]:
    """How many scored rows succeeded, and of the failures how many the points side with (a
    list, or a ``RunRows``' columns)."""
    from mbicp_viz.core.agreement import INLIER_RADIUS_M

    from .run_rows import RunRows

    run = RunRows.of(rows)
    ok, doubted = int(run.column("success").sum()), int(run.column("doubted").sum())
    return [
        f"against the scan poses: {ok}/{len(rows)} within {CONSECUTIVE.text()} "
        f"({100.0 * ok / len(rows):.1f} %)",
        f"failures where more object points lie within {100 * INLIER_RADIUS_M:.0f} cm of the "
        "reference at the "
        f"matched pose than at the scan poses: {doubted} of {len(rows) - ok}",
    ]


def match_sequence(
    log: ScanLog,
    params: Params,
    limit: int | None = None,
    guess: Guess | str = Guess.stored,
    truth: str | None = None,
    on_row=None,
    workers: int | None = None,
    search: SearchParams | None = None,
    base: bool = True,
    done: Sequence[PairMatch] = (),
    budget_s: float | None = MATCH_BUDGET_S,
    keyframes: KeyFrames | None = None,
    keep: bool = True,
) -> list[PairMatch]:
    """One record per consecutive pair of usable scans, in order (with ``keyframes``, per scan
    against the last key frame, evaluation/keyframes.py, on one process): the match's motion (of
    the robot's base when ``base`` and the log knows the laser's mount), how well it lays the scans
    on each other, its distance from the log's odometry when the log has some, and with
    ``truth="pose"`` its error against the log's scan poses, and the signs that it went wrong
    (evaluation/health.py: a pair's own, and whether its first scan is out of place). The pairs of
    ``done`` are left out (a run resumed from its rows: only their count and the last two are
    read, before the run). Each match stops after ``budget_s`` (core/budget.py). Pairs are spread
    over ``workers`` processes (default: every core); ``on_row`` sees each row as it arrives, and
    Ctrl-C keeps the rows so far. Without ``keep`` no row is kept and none returned: ``on_row``
    takes them (a run of any length in bounded memory)."""
    guess = Guess(guess)
    if truth == "pose" and guess in (Guess.pose, Guess.stored):
        raise InputError(
            "the scan poses cannot be both the truth and the guess: use --guess identity or "
            "odometry",
            field="--truth",
        )
    # The pairs are found as the log is read, front to back once: a lazily read log is not read
    # a first time only to list them (so ``todo`` bounds the pairs left: its unusable records are
    # not known yet). A resumed run goes on from its last row's second scan.
    resumed = len(done)
    todo = log.records - 1 - resumed if limit is None else limit - resumed
    last = done[-1].obj if resumed else 0
    key = keyframes.key_after(done[-1]) if keyframes is not None and resumed else 0
    stamps: dict[int, float | None] = {}  # of the scans sent and not yet seen back
    steady, rows, newest = Steadiness(log, done[-2:], stamps), [], None

    def job(i: int, ref, j: int, obj) -> tuple:
        return (log.path, i, j, ref, obj, params, guess, truth, search, log.frames, base)

    def consecutive():  # made as the workers need them
        scans = log.scans_from(last)
        i, ref = next(scans, (None, None))
        for _, (j, obj) in zip(range(todo), scans):
            stamps[i], stamps[j] = ref.stamp, obj.stamp
            yield job(i, ref, j, obj)
            i, ref = j, obj

    def from_key_frames():  # one at a time: a scan's reference depends on the match before
        scans = log.scans_from(key)
        i, ref = next(scans, (None, None))
        sent = 0
        for j, obj in scans:
            if sent == todo:
                return
            if j <= last:  # a resumed run's scans matched before
                continue
            yield job(i, ref, j, obj)
            sent += 1
            if keyframes.due(newest):
                i, ref = j, obj

    def take(m: PairMatch) -> None:  # the rows share one parameters object (Params.__reduce__)
        nonlocal newest
        newest = steady.amend(m)
        if keep:
            rows.append(newest)
        if on_row is not None:
            on_row(newest)

    if todo > 0:
        load_kernels(params)  # once, before a pool forks its workers
        ordered_map(
            partial(match_row, stream=log.topic, budget_s=budget_s),
            consecutive() if keyframes is None else from_key_frames(),
            workers if keyframes is None else 1,
            take,
            todo,
            keep=False,
        )
    if newest is None and not resumed:  # no pair found: the error of a log without two usable scans
        log.consecutive_pairs(1)
    return rows


def match_row(job, stream: str | None, budget_s: float | None) -> PairMatch:
    path, i, j, ref, obj, params, guess, truth, search, frames, base = job
    t0 = time.perf_counter()
    g, source = pair_guess(ref, obj, guess, search, missing_ok=True)
    guess_ms = 1000.0 * (time.perf_counter() - t0)
    answer = None
    if truth == "pose":
        answer = stored_truth(ref, obj)
        if answer is None:
            raise InputError(f"scan {i} or {j} has no pose to score against", path, field="--truth")
    s = Setup(g, source, answer, None if answer is None else STORED_ANSWER)
    m = match_pair(
        ref, obj, params, s, frames, base, indices=(i, j), stream=stream, budget_s=budget_s
    )
    return replace(m, guess_ms=guess_ms) if guess is Guess.search else m


class Steadiness:
    """Marks each row, in the run's order, whose first scan is out of place (health.out_of_place:
    the motion jumps and returns), from the two rows before it. ``stamps`` holds the stamps of
    the scans of rows still to come (each taken once its row is seen); the rows of ``done`` are
    read from the log."""

    def __init__(self, log: ScanLog, done: list[PairMatch], stamps: dict[int, float | None]):
        self.stamps = stamps
        self.last = [(m, self._dt(log.scan(m.ref).stamp, log.scan(m.obj).stamp)) for m in done]

    @staticmethod
    def _dt(a: float | None, b: float | None) -> float | None:
        return b - a if a is not None and b is not None and b > a else None

    def amend(self, m: PairMatch) -> PairMatch:
        dt = self._dt(self.stamps.pop(m.ref, None), self.stamps.get(m.obj))
        steps = (*self.last, (m, dt))
        if len(steps) == 3 and steps[0][0].obj == steps[1][0].ref and steps[1][0].obj == m.ref:
            jump = out_of_place(tuple(r for r, _ in steps), tuple(d for _, d in steps))
            if jump is not None:
                m = replace(m, flags=m.flags | {Suspicion.OUT_OF_PLACE: jump})
        self.last = [*self.last, (m, dt)][-2:]
        return m


# Agreement with odometry: paper-independent, a wheel encoder's few centimetres over a scan pair.
ODOMETRY_AGREEMENT = Criteria("odometry agreement", 0.05, math.radians(1.0))


def odometry_summary(rows: Sequence[PairMatch]) -> str | None:
    """How far the matches are from the log's odometry, when it has some (a list, or a
    ``RunRows``' columns)."""
    from .run_rows import RunRows

    if not len(rows):
        return None
    run = RunRows.of(rows)
    xy = run.column("odometry_xy")
    near = ~np.isnan(xy)
    if not near.any():
        return None
    xy, theta = xy[near], run.column("odometry_theta")[near]
    ok = sum(map(ODOMETRY_AGREEMENT.correct, xy.tolist(), theta.tolist()))
    med_xy = float(np.median(xy))
    med_th = math.degrees(float(np.median(theta)))
    return (
        f"against the odometry: {ok}/{len(xy)} within {ODOMETRY_AGREEMENT.text()} "
        f"({100.0 * ok / len(xy):.1f} %); median difference {1000 * med_xy:.1f} mm, {med_th:.3f} "
        "deg"
    )


def _ceiling_row(job) -> tuple[bool, list[tuple[bool, bool]]]:
    from mbicp_viz.core.search import correlative_search

    ref, obj, params = job
    truth = stored_truth(ref, obj)
    rows = [scored(ref, obj, match(ref, obj, truth, p).pose, truth) for p in params]
    found = CONSECUTIVE.judge(correlative_search(ref, obj).pose, truth)
    return found, [(r.success, r.truth_doubted) for r in rows]


def ceiling_summary(
    names: list[str], found: int, kept: list[int], doubted: list[int], n: int
) -> list[str]:
    """``ceiling``'s figures in words: the search alone, then each matcher started at the truth."""
    from mbicp_viz.core.agreement import INLIER_RADIUS_M

    within = CONSECUTIVE.text()
    lines = [f"correlative search alone: {found}/{n} within {within} ({100 * found / n:.1f} %)"]
    for name, k, d in zip(names, kept, doubted):
        lines.append(
            f"{name} started at the scan poses: {k}/{n} stay within {within} ({100 * k / n:.1f} "
            "%); of the "
            f"{n - k} it leaves, {d} lay more object points within {100 * INLIER_RADIUS_M:.0f} cm "
            "of the "
            "reference"
        )
    return lines


def ceiling(
    log: ScanLog,
    params: list[Params],
    limit: int | None = None,
    workers: int | None = None,
    on_row=None,
) -> tuple[int, list[int], list[int], int]:
    """What a log allows on its consecutive pairs, against its scan poses: how many pairs the
    correlative search alone finds, and how many each matcher keeps when started at the truth itself
    (its fixed point: no guess can do better). Of the pairs a matcher leaves, those where more
    object points lie on the reference at its pose than at the stored one are counted as doubting
    the truth (``Score.truth_doubted``). Returns (search hits, hits per matcher, doubts per matcher,
    pairs)."""
    pairs = log.consecutive_pairs(limit)
    for i, j in pairs:
        if stored_truth(log.scan(i), log.scan(j)) is None:
            raise InputError(
                f"scan {i} or {j} has no pose to score against", log.path, field="poses"
            )
    rows = ordered_map(
        _ceiling_row, [(log.scan(i), log.scan(j), params) for i, j in pairs], workers, on_row
    )
    per_matcher = [[r[1][k] for r in rows] for k in range(len(params))]
    return (
        sum(r[0] for r in rows),
        [sum(ok for ok, _ in m) for m in per_matcher],
        [sum(doubt for _, doubt in m) for m in per_matcher],
        len(rows),
    )
