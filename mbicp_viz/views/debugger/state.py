"""One debugger tab's model: the pair, the matchers and their parameters, the guess, the runs and
what is shown at an iteration. No viser here: the panels and the wiring read and drive it, and
tests drive it directly.

A change (parameter, guess, pair, matcher) re-runs the match and keeps every iteration's events;
moving through iterations reads them back without re-matching. A change that fails keeps the
last good runs and says why.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from mbicp_viz.choices import MATCH_BUDGET_S
from mbicp_viz.core import (
    MATCHERS,
    FieldSpec,
    ParamError,
    Params,
    Pose2,
    ScanError,
    SearchParams,
    field_specs,
)
from mbicp_viz.core.budget import Halt
from mbicp_viz.core.params import check_value
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.failures import Reason, failed, failure_kind
from mbicp_viz.evaluation.pairs import Guess, known_answer, pair_guess
from mbicp_viz.evaluation.single import Setup, match_pair
from mbicp_viz.readers import ReadOptions, ScanLog, read_log
from mbicp_viz.readers.pair_match import PairMatch
from mbicp_viz.readers.params_toml import presets_for

from .. import scene


@dataclass
class Source:
    """What the debugger opens: a log (any two scans can be picked) or one fixed pair, and how the
    first match is set up (guess, matchers, parameters; a scenario's note)."""

    label: str
    log: ScanLog
    pair: tuple[int, int] = (0, 1)
    pick_pair: bool = False
    guess: Pose2 | None = None  # a fixed guess; None: ``guess_kind`` of each pair
    guess_kind: Guess = Guess.stored
    truth: Pose2 | None = None  # None: the stored poses' relative pose, when the log has them
    params: dict[str, Params] = field(default_factory=dict)
    matchers: tuple[str, ...] = ("improved",)
    search: SearchParams = field(default_factory=SearchParams)
    note: str = ""  # Markdown shown above the panels (a scenario's "what to look at")
    teaching: bool = False  # iso-distance curves on from the start
    # an evaluation's failed pairs, worst first
    failures: Sequence[PairMatch] = field(default_factory=list)
    # its flagged pairs (evaluation/health.py), the most suspicious first
    suspects: Sequence[PairMatch] = field(default_factory=list)
    # its rows when they are a run (eval sequence): run view (evaluation/run_rows.RunRows)
    run: Sequence[PairMatch] | None = None
    versus: object | None = None  # evaluation/versus.Versus: a second run of the same pairs
    relations: list | None = None  # Kümmerle et al.'s relations to score the run on (run view)
    offset: float = 0.0  # added to the log's stamps to meet the relations'
    loops: object | None = None  # evaluation/loops.LoopRun: the run with its loops closed
    # views/debugger/background.Background: a run being matched, its view opened once it is
    background: object | None = None
    rows_label: str = ""  # the rows file they come from, and how many rows it holds
    opened: PairMatch | None = None  # the row the first match reopens
    options: ReadOptions | None = None  # how the log was read (to read another of its scan streams)
    shown: tuple[str, ...] | None = (
        None  # the layers (legend labels) shown at first; None: each style's default
    )
    lesson: tuple = ()  # the lesson's steps (lesson/steps.py), in lesson mode
    lesson_step: int = 0  # the step a new tab opens (0-based)
    budget_s: float = MATCH_BUDGET_S  # each match stops after it (0: no limit)
    view: tuple[float, float, float, float] | None = (
        None  # what "fit the view" shows [m]; None: the reference scan
    )


# What the preset picker shows for a matcher's parameters: its defaults, a preset's name, or
# neither.
DEFAULTS, TYPED = "defaults", "as typed"

# What a failed match can raise that the user must read rather than a traceback.
MATCH_ERRORS = (
    ScanError,
    ParamError,
    InputError,
    ValueError,
    FloatingPointError,
    np.linalg.LinAlgError,
)


def parse_entry(spec: FieldSpec, typed: str):
    """The value a user typed into a parameter's box, exactly, in the field's own type (degrees for
    radian fields become radians); ParamError naming the field for anything else. Nothing is
    rounded or clamped: a value outside the bounds is refused."""
    s = typed.strip()
    if spec.type is bool:
        if s.lower() not in ("true", "false"):
            raise ParamError(spec.name, f"expected true or false, got {typed!r}")
        return s.lower() == "true"
    try:
        v = float(s)
    except ValueError:
        raise ParamError(spec.name, f"not a number: {typed!r}") from None
    if not math.isfinite(v):
        raise ParamError(spec.name, f"must be finite, got {typed!r}")
    if spec.type is int:
        if not v.is_integer():
            raise ParamError(spec.name, f"expected a whole number, got {typed!r}")
        v = int(v)
    elif spec.unit == "rad":
        v = math.radians(v)
    try:
        return check_value(spec, v)
    except ParamError:
        if spec.unit != "rad":
            raise
        lo, hi = (None if b is None else round(math.degrees(b), 6) for b in (spec.lo, spec.hi))
        raise ParamError(spec.name, f"{typed} deg is outside [{lo}, {hi}] deg") from None


def parsed(params: Params, typed: dict[str, str]) -> Params:
    """``params`` with the fields the user typed, each exactly as typed (``parse_entry``)."""
    specs = {s.name: s for s in field_specs(type(params))}
    return params.replace(**{name: parse_entry(specs[name], text) for name, text in typed.items()})


def shown_value(spec: FieldSpec, value) -> str:
    """A parameter as its box shows it (degrees for radian fields), round-tripping
    ``parse_entry``."""
    if spec.type is bool:
        return "true" if value else "false"
    if spec.unit == "rad":
        return repr(round(math.degrees(value), 9))
    return repr(value)


def box_label(spec: FieldSpec) -> str:
    unit = "deg" if spec.unit == "rad" else spec.unit
    return spec.name if unit in ("1", "bool", "count") else f"{spec.name} [{unit}]"


# What a user chooses, restored together when a change fails (``DebugState._change``)
_CHOSEN = ("source", "pair", "opened", "matchers", "params", "guess", "guess_source")


def shown_at_first(source: Source) -> dict[str, bool]:
    """Which layers (by legend label) a tab shows first: the source's, else each style's default
    (in teaching, the iso-distance curves too)."""
    if source.shown is not None:
        return {s.label: s.label in source.shown for s in scene.STYLES}
    teach = (scene.ISO_METRIC, scene.ISO_EUCLID) if source.teaching else ()
    return {s.label: s.on or s in teach for s in scene.STYLES}


# The layers that show why a pair failed, and only those (the Layers panel brings the others):
# low overlap is the reference against the object scan at the known answer; a degenerate or wrong
# basin match is where the object scan ended against both.
WHY_LAYERS = {
    Reason.LOW_OVERLAP: (scene.REFERENCE, scene.TRUTH),
    Reason.DEGENERATE: (scene.REFERENCE, scene.TRUTH, scene.OBJECT, scene.HELD),
    Reason.WRONG_BASIN: (scene.REFERENCE, scene.TRUTH, scene.OBJECT),
}


def showing_why(row: PairMatch, visible: dict[str, bool]) -> dict[str, bool]:
    """The layers a failed row opens with: the ones its reason is seen in (a match that stopped
    early is seen in its iterations: the layers stay)."""
    why = WHY_LAYERS.get(failure_kind(row)) if failed(row) else None
    if why is None:
        return visible
    return {label: label in {s.label for s in why} for label in visible}


def preset_name(matcher: str, params: Params) -> str:
    """What a matcher's parameters are: ``DEFAULTS``, the name of a preset, or ``TYPED``."""
    if params == MATCHERS[matcher].params_type():
        return DEFAULTS
    return next((n for n, p in presets_for(matcher).items() if p == params), TYPED)


class DebugState:
    """The model of one tab."""

    def __init__(self, source: Source):
        self.source = source
        self.params: dict[str, Params] = {
            n: source.params.get(n, m.params_type()) for n, m in MATCHERS.items()
        }
        self.search = source.search
        self.matchers: list[str] = list(source.matchers)
        self.pair = source.pair
        self.opened: PairMatch | None = None  # the evaluation row last reopened
        self.guess, self.guess_source = self._pair_guess()
        self.visible = shown_at_first(source)  # layer (legend label) -> shown
        if source.opened is not None:
            self._apply_row(source.opened)
        self.runs: list[PairMatch] = []  # one per shown matcher, with its events
        self.iteration = 0
        self.iso_point: int | None = None
        self.match_ms = 0.0
        self.halt = Halt()  # the last match's: the page's stop raises it
        self.message = ""  # the last failure, shown to the user

    # ---- the pair ---------------------------------------------------------------------------
    @property
    def ref(self):
        return self.source.log.scan(self.pair[0])

    @property
    def obj(self):
        return self.source.log.scan(self.pair[1])

    def setup(self) -> Setup:
        """Where the match starts, and the known answer: the source's, else the log's scan poses
        unless the guess came from them."""
        answer = known_answer(self.ref, self.obj, self.guess_source, self.source.truth)
        return Setup(self.guess, self.guess_source, *answer)

    def truth(self) -> Pose2 | None:
        return self.setup().truth

    def _pair_guess(self) -> tuple[Pose2, str]:
        if self.source.guess is not None:
            return self.source.guess, "given"
        return pair_guess(self.ref, self.obj, self.source.guess_kind, self.search)

    def _change(self, apply: Callable[[], None]) -> str | None:
        """Make a change the user asked for and re-match: None, or why either failed, and then
        everything the user chose is as it was (the last good runs stay shown)."""
        old = {name: copy.copy(getattr(self, name)) for name in _CHOSEN}
        try:
            apply()
            err = self.rematch()
        except InputError as e:
            err = str(e)
        if err:
            for name, value in old.items():
                setattr(self, name, value)
        return err

    def set_pair(self, i: int, j: int) -> str | None:
        """Open scans ``i`` and ``j`` (record numbers) with the source's kind of guess."""
        n = self.source.log.records
        if not (0 <= i < n and 0 <= j < n) or i == j:
            return f"scan numbers must be two different numbers in 0..{n - 1}"

        def apply():
            self.pair = (i, j)
            self.ref, self.obj  # noqa: B018 - an unusable scan is refused here
            self.guess, self.guess_source = self._pair_guess()

        return self._change(apply)

    def set_topic(self, topic: str) -> str | None:
        """Read another scan stream of the file (a bag's topic, a CARMEN log's laser message type)
        and open its first consecutive pair."""
        src = self.source
        options = replace(src.options or ReadOptions(), topic=topic)
        try:
            log = read_log(src.log.path, options)
            if len(log.record_numbers(2)) < 2:
                raise InputError(
                    f"topic {topic} has fewer than two usable scans", log.path, field="topic"
                )
        except InputError as e:
            return str(e)

        def apply():
            self.source = replace(src, log=log, options=options)
            self.pair = log.consecutive_pairs(1)[0]
            self.guess, self.guess_source = self._pair_guess()

        return self._change(apply)

    def _apply_row(self, row: PairMatch) -> None:
        self.pair, self.opened = (row.ref, row.obj), row
        self.ref, self.obj  # noqa: B018 - an unusable scan is refused here
        self.matchers, self.params[row.matcher] = [row.matcher], row.params
        self.guess, self.guess_source = row.guess, f"the evaluation's guess ({row.guess_source})"
        self.visible = showing_why(row, self.visible)

    def open_row(self, row: PairMatch) -> str | None:
        """Reopen an evaluated pair exactly as the evaluation ran it: its scans, matcher,
        parameters and initial guess. None, or why not (then nothing changes)."""
        return self._change(lambda: self._apply_row(row))

    # ---- matching ---------------------------------------------------------------------------
    def rematch(self) -> str | None:
        """Re-run every shown matcher; None, or why it failed (the last good runs are kept)."""
        t0 = time.perf_counter()
        log, setup = self.source.log, self.setup()
        self.halt = Halt()
        try:
            runs = [
                match_pair(
                    self.ref,
                    self.obj,
                    self.params[n],
                    setup,
                    log.frames,
                    indices=self.pair,
                    stream=log.topic,
                    record=True,
                    budget_s=self.source.budget_s,
                    halt=self.halt,
                )
                for n in self.matchers
            ]
        except MATCH_ERRORS as e:
            self.message = f"The match failed and the last good result is kept: {e}"
            return self.message
        self.match_ms = 1000.0 * (time.perf_counter() - t0)
        self.runs = runs
        self.iteration = self.max_iteration()  # show where the match ended
        self.message = ""
        return None

    def max_iteration(self) -> int:
        return max((len(r.iterations) for r in self.runs), default=0)

    def set_matchers(self, names: list[str]) -> str | None:
        unknown = [n for n in names if n not in MATCHERS]
        if not names or unknown:
            return f"choose at least one of {', '.join(MATCHERS)}"
        return self._change(lambda: setattr(self, "matchers", list(names)))

    def set_params(self, matcher: str, typed: dict[str, str]) -> str | None:
        """Apply what the user typed into a matcher's parameter boxes (re-matching once when
        anything changed); None, or why it is refused (then nothing changes)."""
        try:
            new = parsed(self.params[matcher], typed)
        except ParamError as e:
            return str(e)
        return self._use_params(matcher, new)

    def use_preset(self, matcher: str, name: str) -> str | None:
        """A matcher's defaults (``DEFAULTS``) or one of its presets (``--params NAME``), as
        ``set_params`` applies typed values."""
        return self._use_params(
            matcher,
            MATCHERS[matcher].params_type() if name == DEFAULTS else presets_for(matcher)[name],
        )

    def _use_params(self, matcher: str, new: Params) -> str | None:
        if new == self.params[matcher]:
            return None
        if matcher not in self.matchers:  # not shown: nothing to re-match
            self.params[matcher] = new
            return None
        return self._change(lambda: self.params.__setitem__(matcher, new))

    def set_search(self, typed: dict[str, str]) -> str | None:
        """The correlative search's parameters, for the next search (nothing is re-matched)."""
        try:
            self.search = parsed(self.search, typed)
        except ParamError as e:
            return str(e)
        return None

    def set_guess(self, guess: Pose2, source: str = "typed") -> str | None:
        if not all(math.isfinite(v) for v in (guess.x, guess.y, guess.theta)):
            return "the initial guess must be finite numbers"

        def apply():
            self.guess, self.guess_source = guess, source

        return self._change(apply)

    def search_guess(self) -> str | None:
        """Replace the guess by the correlative search's best pose around it (core/search.py)."""
        from mbicp_viz.core.search import correlative_search

        try:
            found = correlative_search(self.ref, self.obj, self.guess, self.search)
        except ParamError as e:  # a search its parameters make too costly
            return f"the search was refused: {e}"
        return self.set_guess(
            found.pose, f"searched within {self.search.window_text()} of the last guess"
        )

    def pair_label(self) -> str:
        """The pair, for a log; a fixed pair's label (the source's) says which scans it is."""
        return f"scans {self.pair[0]} -> {self.pair[1]}" if self.source.pick_pair else ""
