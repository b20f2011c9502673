"""The record of one pair's match: which scans, which matcher with which parameters, from which
guess, what came out, and how it scores against the answer and the odometry when the log has them.

One record for every producer and consumer: ``match --json`` prints it, ``eval sequence`` and
``tune`` write it as rows, the ``.rrd`` export stores it beside the iterations, the debugger holds
one per shown matcher (with the iterations' events), and ``serve LOG --rows`` reopens a pair from
it. Its JSON form is one flat object with stable keys (scripts rely on them); rows written by
earlier versions read back.

Frames: ``guess`` and ``truth`` are the laser's motion (object frame in the reference frame, what
the matcher works in); ``result`` is the motion of ``frame`` (the robot base's when the log knows
the laser's mount, else the laser's); ``error_*`` compare the laser's motion with ``truth`` (the
frame the paper's criteria are stated in), ``odometry_*`` the reported motion with the odometry's.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from mbicp_viz.core import (
    MATCHERS,
    Degeneracy,
    IterationEvent,
    MatchResult,
    Params,
    Pose2,
    Recorder,
    StartEvent,
    Termination,
)
from mbicp_viz.core.pickled import by_value
from mbicp_viz.errors import InputError

from .params_toml import params_from_mapping

# What a rows file without a field that reopens a pair lacks, and how to get one that has it.
_REGENERATE = (
    "missing (rows are written by `mbicp-viz eval sequence --out`; a file from an older version "
    "lacks the fields that reopen a pair: run it again)"
)


class Suspicion(StrEnum):
    """A sign, seen without truth, that a pair's match went wrong (evaluation/health.py decides
    them; their names are the keys of a record's ``flags``)."""

    STOPPED_EARLY = "stopped early"
    WEAK_DIRECTION = "weak direction"
    LITTLE_OVERLAP = "little overlap"
    ODOMETRY_JUMP = "jumps against odometry"
    SIGMA = "sigma inconsistent with the step"
    OUT_OF_PLACE = "scan out of place"
    DISAGREE = "matchers disagree"  # two configurations' runs (evaluation/versus.py)


class Verdict(StrEnum):
    """What became of a loop-closure candidate's match (evaluation/loops.py decides)."""

    ACCEPTED = "accepted"
    AMBIGUOUS = "response surface ambiguous"
    LOW_OVERLAP = "low overlap"
    WEAK = "weak direction"
    NOT_CONVERGED = "match did not converge"
    INCONSISTENT = "inconsistent with other closures"
    SET_ASIDE = "rejected by hand"


@by_value
@dataclass(frozen=True, slots=True)
class Score:
    """The laser's motion against the known answer (the frame the paper's criteria are in)."""

    error_xy: float  # [m]
    error_theta: float  # [rad]
    success: bool  # within the consecutive-pair criteria (evaluation/criteria.py)
    inliers_match: float | None = None  # a failure: share of points on the reference as matched
    inliers_truth: float | None = None  # ... and at the answer

    @property
    def truth_doubted(self) -> bool:
        """A failure where more object points land on the reference at the matched pose than at
        the answer: the scans themselves side with the matcher (or cannot tell the two apart)."""
        return not self.success and self.inliers_match > self.inliers_truth


@by_value
@dataclass(frozen=True, slots=True)
class PairMatch:
    """One pair's match."""

    ref: int  # record numbers in the log (two files: the first scan of each, 0 and 0)
    obj: int
    params: Params  # every parameter of the matcher (its name: ``matcher``)
    guess: Pose2  # the initial guess, laser frame
    guess_source: str  # "scan poses", "odometry", "identity", "search", "given", ...
    result: MatchResult  # the motion of ``frame``
    frame: str  # "laser", or the robot base's frame name
    on_ref: float | None = None  # share of object points within 5 cm of the reference
    stream: str | None = None  # the scan stream read (a bag's topic ...; None: its only one)
    time_ms: float | None = None  # the match's wall time (None: not kept, as in a recording)
    guess_ms: float | None = None  # the correlative search's time, when it made the guess
    interpreted: bool = False  # run while numba compiled the kernels (core/tiers.py)
    truth: Pose2 | None = None  # the known answer, laser frame
    truth_source: str | None = None  # "given", "the log's scan poses"
    score: Score | None = None  # the laser's motion against ``truth``
    odometry: Pose2 | None = None  # the laser's motion by the log's odometry
    odometry_xy: float | None = None  # [m] the reported motion against the odometry's
    odometry_theta: float | None = None  # [rad]
    overlap: float | None = None  # share of object points on the reference's surface
    # the signs, seen without truth, that the match went wrong, each with its deciding numbers
    # (evaluation/health.py; a pose difference as [m], [rad])
    flags: dict[Suspicion, tuple[float, ...]] = field(default_factory=dict)
    # the run's events (the debugger, the lesson, the .rrd export replay them); not in JSON
    events: Recorder | None = field(default=None, compare=False, repr=False)
    line: int | None = field(default=None, compare=False)  # where it was read from

    @property
    def matcher(self) -> str:
        return self.result.algorithm

    @property
    def start(self) -> StartEvent:
        return self.events.start

    @property
    def iterations(self) -> list[IterationEvent]:
        return self.events.iterations

    def to_json(self, timings: bool = True) -> dict:
        """The JSON object (``timings=False``: without the wall times and the compile state, which
        differ run to run — a recording is the same every time it is made)."""
        r = self.result
        out = {"ref": self.ref, "obj": self.obj} | r.as_dict()
        out["time_ms"] = self.time_ms
        out |= {
            "guess": self.guess_source,
            "guess_pose": _xyt(self.guess),
            "on_ref": self.on_ref,
            "overlap": self.overlap,
            "flags": {str(k): list(v) for k, v in self.flags.items()},
            "frame": self.frame,
            "stream": self.stream,
            "params": self.params.as_dict(),
            "interpreted": self.interpreted,
        }
        if self.odometry is not None:
            out |= {
                "odometry_pose": _xyt(self.odometry),
                "odometry_xy": self.odometry_xy,
                "odometry_theta": self.odometry_theta,
            }
        if self.truth is not None:
            out |= {"truth": self.truth_source, "truth_pose": _xyt(self.truth)}
        if (sc := self.score) is not None:
            out |= {"error_xy": sc.error_xy, "error_theta": sc.error_theta, "success": sc.success}
            if sc.inliers_match is not None:
                out |= {"inliers_match": sc.inliers_match, "inliers_truth": sc.inliers_truth}
        if self.guess_ms is not None:
            out["guess_ms"] = self.guess_ms
        if not timings:
            for key in ("time_ms", "guess_ms", "interpreted"):
                out.pop(key, None)
        return out

    def json_line(self) -> str:
        return json.dumps(self.to_json())


def _xyt(p: Pose2) -> list[float]:
    return [p.x, p.y, p.theta]


class _Fields:
    """One object's fields, each checked for its type; errors name the line and the field."""

    def __init__(self, obj: dict, path: str, line: int):
        self.obj, self.path, self.line = obj, path, line

    def error(self, key: str, message: str) -> InputError:
        return InputError(message, self.path, self.line, key)

    def get(self, key: str, kinds: tuple[type, ...], what: str, optional: bool = False):
        if key not in self.obj:
            if optional:
                return None
            raise self.error(key, _REGENERATE)
        v = self.obj[key]
        if isinstance(v, bool) != (bool in kinds) or not isinstance(v, kinds):
            raise self.error(key, f"expected {what}, got {json.dumps(v)[:40]}")
        return v

    def count(self, key: str) -> int:
        v = self.get(key, (int,), "a count")
        if v < 0:
            raise self.error(key, f"expected a count, got {v}")
        return v

    def number(self, key: str, optional: bool = False, finite: bool = True) -> float | None:
        v = self.get(key, (int, float), "a number", optional)
        if v is not None and finite and not math.isfinite(v):
            raise self.error(key, f"expected a finite number, got {v}")
        return None if v is None else float(v)

    def numbers(self, key: str, n: int, optional: bool = False) -> list[float] | None:
        v = self.get(key, (list,), f"a list of {n} numbers", optional)
        if v is None:
            return None
        if len(v) != n or any(
            isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c)
            for c in v
        ):
            raise self.error(key, f"expected {n} finite numbers, got {json.dumps(v)[:60]}")
        return [float(c) for c in v]

    def pose(self, key: str, optional: bool = False) -> Pose2 | None:
        v = self.numbers(key, 3, optional)
        return None if v is None else Pose2(*v)

    def text(self, key: str, what: str, optional: bool = False, null: bool = False) -> str | None:
        """A string (or ``null``: None); one object for every row holding the same (a long run's
        rows repeat their names and sources)."""
        v = self.get(key, (str, type(None)) if null else (str,), what, optional)
        return None if v is None else sys.intern(v)

    def flag(self, key: str, optional: bool = False) -> bool | None:
        return self.get(key, (bool,), "true or false", optional)


def _matcher(f: _Fields) -> str:
    # "algorithm" is the key's name in every file written so far
    name = f.text("algorithm", "a matcher's name")
    if name not in MATCHERS:
        raise f.error("algorithm", f"unknown matcher {name!r}; known: {', '.join(MATCHERS)}")
    return name


# A run's rows repeat one parameter set: each set is checked once (two thirds of the reading time
# of a 13,630-row run went into checking the same parameters again). Params are frozen.
_PARAMS_SEEN: dict[tuple[str, str], Params] = {}


def _params(f: _Fields, matcher: str) -> Params:
    values = f.get("params", (dict,), "an object of the matcher's parameters")
    try:  # a flat object of numbers and names, as this tool writes it: its items are the key
        key = (matcher, tuple(values.items()))
        known = _PARAMS_SEEN.get(key)
    except TypeError:  # a value that is a list or an object (refused below)
        key = (matcher, json.dumps(values, sort_keys=True))
        known = _PARAMS_SEEN.get(key)
    if known is not None:
        return known
    try:
        p = params_from_mapping(MATCHERS[matcher].params_type, values, f.path, "params")
    except InputError as e:
        raise f.error(e.field, e.message) from None
    if len(_PARAMS_SEEN) < 256:  # bounded: a file of every row's own set cannot grow it
        _PARAMS_SEEN[key] = p
    return p


def _reason(f: _Fields) -> Termination:
    value = f.text("reason", "a stopping reason")
    try:
        return Termination(value)
    except ValueError:
        known = ", ".join(t.value for t in Termination)
        raise f.error("reason", f"unknown stopping reason {value!r}; known: {known}") from None


def _covariance(f: _Fields) -> np.ndarray | None:
    v = f.get("covariance", (list,), "a 3 x 3 matrix", optional=True)
    if v is None:
        return None
    rows = [r if isinstance(r, list) else None for r in v]
    if len(rows) != 3 or any(
        r is None
        or len(r) != 3
        or any(isinstance(c, bool) or not isinstance(c, (int, float)) for c in r)
        for r in rows
    ):
        raise f.error("covariance", f"expected a 3 x 3 matrix, got {json.dumps(v)[:60]}")
    return np.array(rows, dtype=float)


def _degeneracy(f: _Fields) -> Degeneracy | None:
    cond = f.number("condition_number", optional=True, finite=False)
    if cond is None:
        return None
    # files before the eigenvalues were written: unknown (NaN), the rest as recorded
    eig = f.numbers("eigenvalues", 3, optional=True) or [math.nan] * 3
    return Degeneracy(
        cond,
        tuple(f.numbers("weakest_direction", 3)),
        tuple(eig),
        f.number("degeneracy_length_m", optional=True) or math.nan,
    )


def _result(f: _Fields, matcher: str) -> MatchResult:
    reason = _reason(f)
    # strict JSON has no NaN: a match without kept pairs writes its error as null
    error = f.get("error", (int, float, type(None)), "a number or null", optional=True)
    return MatchResult(
        matcher,
        Pose2(f.number("x"), f.number("y"), f.number("theta")),
        f.flag("converged"),
        reason,
        f.count("iterations"),
        math.nan if error is None else float(error),
        f.count("pairs_kept"),
        f.count("pairs_rejected"),
        _covariance(f),
        _degeneracy(f),
    )


def _score(f: _Fields) -> Score | None:
    success = f.flag("success", optional=True)
    if success is None:
        return None
    return Score(
        f.number("error_xy"),
        f.number("error_theta"),
        success,
        f.number("inliers_match", optional=True),
        f.number("inliers_truth", optional=True),
    )


def _flags(f: _Fields) -> dict[Suspicion, tuple[float, ...]]:
    v = f.get("flags", (dict,), "an object of signs and their numbers", optional=True) or {}
    out = {}
    for name, numbers in v.items():
        try:
            key = Suspicion(name)
        except ValueError:
            known = ", ".join(s.value for s in Suspicion)
            raise f.error("flags", f"unknown sign {name!r}; known: {known}") from None
        if (
            not isinstance(numbers, list)
            or not 1 <= len(numbers) <= 2
            or any(isinstance(c, bool) or not isinstance(c, (int, float)) for c in numbers)
        ):
            raise f.error("flags", f"{name}: expected one or two numbers, got {numbers!r:.40}")
        out[key] = tuple(float(c) for c in numbers)
    return out


def parse_pair_match(obj, path: str, line: int) -> PairMatch:
    """One record's JSON object, every field checked; errors name the file, line and field."""
    if not isinstance(obj, dict):
        raise InputError("expected a JSON object (one matched pair)", path, line)
    f = _Fields(obj, path, line)
    matcher = _matcher(f)
    ref, obj_ = f.count("ref"), f.count("obj")
    optional = {
        key: f.number(key, optional=True)
        for key in ("on_ref", "overlap", "time_ms", "guess_ms", "odometry_xy", "odometry_theta")
    }
    return PairMatch(
        ref,
        obj_,
        _params(f, matcher),
        f.pose("guess_pose"),
        f.text("guess", "where the guess came from"),
        _result(f, matcher),
        f.text("frame", "a frame's name"),
        stream=f.text("stream", "a scan stream's name or null", optional=True, null=True),
        interpreted=bool(f.flag("interpreted", optional=True)),
        truth=f.pose("truth_pose", optional=True),
        odometry=f.pose("odometry_pose", optional=True),
        truth_source=f.text("truth", "where the answer came from", optional=True),
        score=_score(f),
        flags=_flags(f),
        line=line,
        **optional,
    )
