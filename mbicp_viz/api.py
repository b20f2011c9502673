"""The Python API: what the commands do, as functions a script or a notebook calls
(``import mbicp_viz as mv``; ``docs/api.md`` shows each in use).

Thin glue over the rooms below, as ``cli/`` is: every name here does what its command does, with
the same options and the same errors. Poses are ``Pose2`` (metres, radians; ``pose_deg`` takes
degrees) and map the object scan's frame into the reference scan's; a match of a log's scans
reports the robot base's motion when the log knows the laser's mount (``frame="laser"``: the
laser's). Every bad input is an ``InputError`` naming file, line and field, as the command line
prints it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mbicp_viz.choices import DEFAULT_TYPESTORE, MATCH_BUDGET_S, Guess
from mbicp_viz.core import (
    MATCHERS,
    MatchResult,
    ParamError,
    Params,
    Pose2,
    Scan,
    ScanError,
    make_scan,
    uniform_bearings,
)
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.run_score import RunScore
from mbicp_viz.readers import ReadOptions, ScanLog
from mbicp_viz.readers.pair_match import PairMatch

__all__ = [
    "Debugger",
    "InputError",
    "MatchResult",
    "PairMatch",
    "Params",
    "Pose2",
    "RunScore",
    "Scan",
    "ScanLog",
    "close_loops",
    "lesson_picture",
    "lesson_step",
    "match",
    "match_scans",
    "matchers",
    "open_debugger",
    "params",
    "pose_deg",
    "read_log",
    "read_rows",
    "report",
    "run",
    "run_lesson_step",
    "scan",
    "score_run",
    "show",
    "write_rows",
    "write_rrd",
]


def _input_errors(fn):
    """The core's errors (a scan, a parameter) as the one error type users see."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except ScanError as e:
            s = e.source
            raise InputError(e.reason, s.path, s.line, f"scan {s.index}") from None
        except ParamError as e:
            raise InputError(e.message, field=e.name) from None

    return wrapper


def matchers() -> list[str]:
    """The matchers' names, as ``--algo`` takes them."""
    return list(MATCHERS)


def pose_deg(x: float, y: float, theta_deg: float) -> Pose2:
    """A pose from metres and degrees."""
    return Pose2(float(x), float(y), math.radians(theta_deg))


@_input_errors
def read_log(
    path: str | Path,
    *,
    topic: str | None = None,
    typestore: str = DEFAULT_TYPESTORE,
    mount_deg: tuple[float, float, float] | None = None,
    upside_down: bool = False,
    deskew: str | None = None,
) -> ScanLog:
    """A recording (CARMEN, text, JSON, ROS 1/2 bag, MCAP ...), as ``--topic``, ``--typestore``,
    ``--mount X Y THETA_DEG``, ``--upside-down`` and ``--deskew`` read it. Scans are read when
    asked for (``log.scan(k)``, record numbers); ``log.consecutive_pairs()`` lists the pairs a run
    matches."""
    from mbicp_viz.readers import read_log as read

    if deskew not in (None, "odometry", "velocity"):
        raise InputError("expected None, 'odometry' or 'velocity'", field="deskew")
    mount = None if mount_deg is None else pose_deg(*mount_deg)
    return read(path, ReadOptions(topic, typestore, mount, upside_down, deskew))


@_input_errors
def scan(
    ranges,
    bearings=None,
    *,
    angle_min: float | None = None,
    angle_increment: float | None = None,
    range_min: float = 0.0,
    range_max: float = math.inf,
    stamp: float | None = None,
) -> Scan:
    """A scan from arrays: ranges [m] with their bearings [rad], or with ``angle_min`` and
    ``angle_increment`` [rad] as a LaserScan message gives them. Readings that are not finite or
    outside (``range_min``, ``range_max``) are invalid, as a reader marks them."""
    ranges = np.asarray(ranges, float)
    if bearings is None:
        if angle_min is None or angle_increment is None:
            raise InputError("give bearings, or angle_min and angle_increment", field="bearings")
        bearings = uniform_bearings(ranges.size, angle_min, angle_increment)
    return make_scan(ranges, bearings, range_min=range_min, range_max=range_max, stamp=stamp)


@_input_errors
def params(matcher: str = "improved", file: str | Path | None = None, **values) -> Params:
    """A matcher's parameters: its defaults, or a preset's (``file="poor-guess"``) or a TOML file's
    (``--params``), with ``values`` over them as the TOML names them (angles as ``NAME_deg``)."""
    from mbicp_viz.readers.params_toml import make_params, with_values

    base = make_params(matcher, file)
    return with_values(base, values, table=matcher) if values else base


def _params(p: str | Params) -> Params:
    if isinstance(p, str):
        return params(p)
    if not isinstance(p, Params):
        raise InputError(
            f"expected a matcher's name or its parameters, got {type(p).__name__}",
            field="params",
        )
    return p


def _guess(guess: Pose2 | str | None) -> tuple[Pose2 | None, Guess]:
    if guess is None or isinstance(guess, Pose2):
        return guess, Guess.stored
    try:
        return None, Guess(guess)
    except ValueError:
        raise InputError(
            f"expected a Pose2 or one of {', '.join(g.value for g in Guess)}", field="guess"
        ) from None


def _setup(ref: Scan, obj: Scan, log: ScanLog, guess, search: bool, truth: Pose2 | None):
    from mbicp_viz.evaluation.pairs import ScanPair
    from mbicp_viz.evaluation.single import setup

    given, kind = _guess(guess)
    return setup(ScanPair(ref, obj, log.path, log), kind, given, search, truth)


@_input_errors
def match_scans(
    ref: Scan,
    obj: Scan,
    params: str | Params = "improved",
    *,
    guess: Pose2 | str | None = None,
    search: bool = False,
    truth: Pose2 | None = None,
    budget_s: float | None = MATCH_BUDGET_S,
) -> PairMatch:
    """Match ``obj`` onto ``ref`` with every iteration kept: ``guess`` a pose, or where it comes
    from ("stored": the scans' poses, else odometry, else the identity; "identity"; "odometry";
    "search"); ``search=True`` refines it by the correlative search; ``truth`` scores the result.
    The record's pose is the laser's motion."""
    from mbicp_viz.evaluation.single import match_pair

    s = _setup(ref, obj, ScanLog("<memory>", [ref, obj]), guess, search, truth)
    return match_pair(ref, obj, _params(params), s, record=True, budget_s=budget_s)


@_input_errors
def match(
    log: ScanLog,
    i: int,
    j: int,
    params: str | Params = "improved",
    *,
    guess: Pose2 | str | None = None,
    search: bool = False,
    truth: Pose2 | None = None,
    frame: str = "base",
    budget_s: float | None = MATCH_BUDGET_S,
) -> PairMatch:
    """``mbicp-viz match LOG --pair I J``: scans ``i`` and ``j`` of ``log`` (record numbers),
    matched as ``match_scans`` does, the result reported in the robot base's frame when the log
    knows the laser's mount (``frame="laser"``: the laser's)."""
    from mbicp_viz.evaluation.single import match_pair

    if frame not in ("base", "laser"):
        raise InputError("expected 'base' or 'laser'", field="frame")
    ref, obj = log.scan(i), log.scan(j)
    s = _setup(ref, obj, log, guess, search, truth)
    return match_pair(
        ref,
        obj,
        _params(params),
        s,
        log.frames,
        frame == "base",
        indices=(i % log.records, j % log.records),
        stream=log.topic,
        record=True,
        budget_s=budget_s,
    )


def report(m: PairMatch) -> str:
    """``match``'s printed report of a match: guess, one line per iteration, result, agreement."""
    from mbicp_viz.views.text import match_report

    truth = m.truth if m.frame == "laser" else None  # the truth is the laser's motion
    return "\n".join(match_report(f"scans {m.ref} -> {m.obj}", m, m.frame, truth))


@_input_errors
def run(
    log: ScanLog,
    params: str | Params = "improved",
    *,
    guess: str = "stored",
    limit: int | None = None,
    frame: str = "base",
    workers: int | None = 1,
    budget_s: float | None = MATCH_BUDGET_S,
    keyframe_m: float = 0.0,
    keyframe_deg: float = 30.0,
) -> list[PairMatch]:
    """``eval sequence``: every consecutive pair of usable scans matched in order (the first
    ``limit``), one record each, spread over ``workers`` processes (None: every core); with
    ``keyframe_m`` > 0 (``--keyframe-m``), each scan against the last key frame, a new one after
    ``keyframe_m`` metres or ``keyframe_deg`` degrees, on one process."""
    from mbicp_viz.evaluation.keyframes import KeyFrames
    from mbicp_viz.evaluation.sequence import match_sequence

    if not (math.isfinite(keyframe_m) and keyframe_m >= 0):
        raise InputError(f"expected a distance >= 0 m, got {keyframe_m}", field="keyframe_m")
    if not (math.isfinite(keyframe_deg) and 0 <= keyframe_deg <= 180):
        raise InputError(f"expected 0 to 180 degrees, got {keyframe_deg}", field="keyframe_deg")

    if frame not in ("base", "laser"):
        raise InputError("expected 'base' or 'laser'", field="frame")
    if not isinstance(guess, str):
        raise InputError("a run's guess is where it comes from, e.g. 'odometry'", field="guess")
    _, kind = _guess(guess)
    return match_sequence(
        log,
        _params(params),
        limit,
        kind,
        workers=workers,
        base=frame == "base",
        budget_s=budget_s,
        keyframes=KeyFrames(keyframe_m, math.radians(keyframe_deg)) if keyframe_m > 0 else None,
    )


def close_loops(log: ScanLog, rows: list[PairMatch], *, loop_gap_m: float = 10.0):
    """``eval sequence --close-loops``: the run's loops closed (evaluation/loops.py) with its own
    matcher and parameters, key frames ``loop_gap_m`` metres apart along the run or more being
    candidates. Returns a ``LoopRun``: ``.optimised`` (a pose per scan of the run), ``.closures``
    (each candidate's match and verdict), ``.summary()``."""
    from mbicp_viz.evaluation.loops import LoopParams
    from mbicp_viz.evaluation.loops import close_loops as close

    if not (math.isfinite(loop_gap_m) and loop_gap_m >= 0):
        raise InputError(f"expected a distance >= 0 m, got {loop_gap_m}", field="loop_gap_m")
    if not rows:
        raise InputError("a run of at least one pair", field="rows")
    return close(log, rows, rows[0].params, LoopParams(min_path_m=loop_gap_m))


def write_rows(rows: list[PairMatch], path: str | Path) -> None:
    """A run's records as the rows file ``eval sequence --out`` writes (JSON lines), whole."""
    from mbicp_viz.outputs import write_text
    from mbicp_viz.readers.rows import rows_text

    write_text(path, rows_text([r.to_json() for r in rows]))


def read_rows(path: str | Path, log: ScanLog | None = None) -> list[PairMatch]:
    """A rows file (``eval sequence --out``, ``write_rows``), checked against ``log`` if given."""
    from mbicp_viz.readers.rows import read_rows as read
    from mbicp_viz.readers.rows import rows_of_log

    return read(path) if log is None else rows_of_log(path, log)


def score_run(
    log: ScanLog,
    rows: list[PairMatch],
    relations: str | Path,
    *,
    offset: float = 0.0,
    tolerance: float = 0.025,
    loops=None,
) -> list[RunScore]:
    """``eval relations LOG RELATIONS --run ROWS``: the run's trajectories (matches chained, their
    Kalman fusion with the odometry, the raw odometry) scored on a relations file (Kümmerle et al.
    2009); ``offset`` [s] is added to the log's stamps, ``tolerance`` [s] finds a relation's
    scans; with ``loops`` (``close_loops``'s), the run with its loops closed too."""
    from mbicp_viz.evaluation.run_score import LOOPS_CLOSED, run_tracks, score_track
    from mbicp_viz.readers.relations import read_relations

    rel = read_relations(str(relations))
    tracks = run_tracks(log, rows, "rows", offset)
    if loops is not None:
        tracks[LOOPS_CLOSED] = (tracks["matches chained"][0], loops.optimised)
    return [score_track(name, t, poses, rel, tolerance) for name, (t, poses) in tracks.items()]


def write_rrd(
    matches: PairMatch | list[PairMatch],
    path: str | Path,
    *,
    log: ScanLog | None = None,
    teaching: bool = False,
    loops=None,
) -> None:
    """An ``.rrd`` for rerun's viewer, written whole: matches of a pair (``match --rrd``, each
    matcher under its own root; ``teaching``: iso-distance curves and pair-distance histograms),
    or with ``log`` a run's rows (``eval sequence --rrd``; with ``loops``, ``close_loops``'s, the
    run with its loops closed in a view of its own)."""
    from mbicp_viz.views import rrd

    matches = [matches] if isinstance(matches, PairMatch) else list(matches)
    if log is not None:
        rrd.record_sequence(log, matches, str(path), loops=loops)
    else:
        rrd.record(matches, str(path), teaching=teaching)


def show(
    matches: PairMatch | list[PairMatch],
    *,
    log: ScanLog | None = None,
    teaching: bool = False,
    width: int = 960,
    height: int = 640,
):
    """Inline in a notebook (rerun's notebook viewer, ``pip install "mbicp-viz[notebook]"``): what
    ``write_rrd`` writes, with the same blueprint. Returns the widget (a cell shows it)."""
    from mbicp_viz.views import notebook

    matches = [matches] if isinstance(matches, PairMatch) else list(matches)
    if log is not None:
        return notebook.run_viewer(log, matches, width, height)
    return notebook.match_viewer(matches, teaching, width, height)


@dataclass
class Debugger:
    """The debugger serving in this process (``open_debugger``): its ``url``; ``stop()`` ends it,
    ``wait()`` serves until Ctrl-C; a notebook cell shows it embedded."""

    app: object

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.app.port}"

    def stop(self) -> None:
        self.app.stop()

    def wait(self) -> None:
        try:
            self.app.server.sleep_forever()
        except KeyboardInterrupt:
            pass
        finally:
            self.stop()

    def _repr_html_(self) -> str:
        return (
            f'<a href="{self.url}" target="_blank">{self.url}</a><br>'
            f'<iframe src="{self.url}" width="100%" height="720" style="border:0"></iframe>'
        )

    def __enter__(self) -> Debugger:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


@_input_errors
def open_debugger(
    log: ScanLog | str | Path,
    pair: tuple[int, int] | None = None,
    *,
    rows: list[PairMatch] | None = None,
    guess: str = "stored",
    port: int = 0,
) -> Debugger:
    """``mbicp-viz serve LOG [--pair I J] [--rows ROWS]`` from a script: the debugger on
    127.0.0.1 (``port`` 0: any free one) in a background thread, on the pair ``pair`` or, with a
    run's ``rows``, its run view and its worst pair."""
    from mbicp_viz.views.debugger.app import App
    from mbicp_viz.views.debugger.sources import log_source

    if not isinstance(log, ScanLog):
        log = read_log(log)
    _, kind = _guess(guess)
    run = [replace(r, line=k) for k, r in enumerate(rows or (), 1)]  # the report names a row's line
    label = f"the rows given: {len(run)} rows" if run else ""
    source = log_source(log.path, log, pair, kind, run=run, rows_label=label)
    return Debugger(App(source, "127.0.0.1", port))


def lesson_step(number: int, directory: str | Path | None = None):
    """Step ``number`` (1: the first) of the lesson (``mbicp-viz lesson``; ``directory``: a folder
    of steps, default the bundled lesson). ``step.scenario`` holds its scans (``ref``, ``obj``),
    ``guess``, ``truth`` and each matcher's ``params``."""
    from mbicp_viz.views.lesson.steps import load_lesson

    steps = load_lesson(None if directory is None else Path(directory))
    if not 1 <= number <= len(steps):
        raise InputError(f"the lesson has {len(steps)} steps", field="number")
    return steps[number - 1]


def run_lesson_step(step):
    """A step's matchers run: ``.runs`` (their records), ``.text`` and ``.try_text`` with the
    run's numbers filled in, as the lesson shows them."""
    from mbicp_viz.views.lesson.steps import run_step

    return run_step(step)


def lesson_picture(step_run) -> bytes:
    """The step's picture as the lesson opens it (PNG)."""
    from mbicp_viz.views.lesson.handout import step_png

    return step_png(step_run)
