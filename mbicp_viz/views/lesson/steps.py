"""A lesson step: one small TOML file in ``recordings/lesson/`` (sorted by file name), read, run
and told.

A step is a scenario (``evaluation/scenarios.py``: ``input``, ``pair``, ``displacement_deg``,
``remove_block``, ``guess_deg``, ``algorithms``, ``[params.NAME]``) with what a lesson adds:

- ``title``; ``text``: a few sentences in Markdown citing the paper, whose numbers are
  ``{placeholders}`` filled from the step's own run (``lesson/facts.py``); ``try``: what to try.
- ``layers = [...]``: the layers shown when the step opens (``LAYERS`` names them); the others stay
  a click away.
- ``iteration``: the iteration shown when the step opens (default: the last).
- ``[variant]``: ``name``, ``matcher`` and parameters of one more run of a matcher, not shown,
  whose numbers the text may quote under ``{name.*}`` ("without the grid ...").
- ``[distances]``: ``values`` and ``mad_k``, a list of distances to reject by paper 000's rule
  (§2.4.2, Fig. 9); drawn as a dot plot, quoted as ``{distances.*}``.
- ``L_try``: an L [m] whose ellipse the text may compare (``{metric.ratio_try}``).
- ``view_m = [x_min, y_min, x_max, y_max]``: the part of the scene the step's picture shows
  (reference frame, metres); default: all of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mbicp_viz.core import MATCHERS, Params
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.scenarios import Scenario, load_scenario, recordings_dir
from mbicp_viz.readers.pair_match import PairMatch
from mbicp_viz.readers.params_toml import params_from_mapping, read_toml
from mbicp_viz.views import scene

from . import facts as F

# The names a step's ``layers`` use for the scene's kinds of layer.
LAYERS: dict[str, scene.Style] = {
    "reference": scene.REFERENCE,
    "truth": scene.TRUTH,
    "initial": scene.INITIAL,
    "odometry": scene.ODOMETRY,
    "object": scene.OBJECT,
    "object_after": scene.OBJECT_AFTER,
    "hidden": scene.HIDDEN,
    "pairs": scene.PAIR_POINT,
    "interpolated": scene.PAIR_INTERPOLATED,
    "rejected": scene.PAIR_REJECTED,
    "grid": scene.GRID,
    "ellipses": scene.ISO_METRIC,
    "circles": scene.ISO_EUCLID,
    "pmwn_circle": scene.CIRCLE,
    "held": scene.HELD,
    "estimate": scene.ESTIMATE,
    "beams": scene.BEAMS,
    "invalid": scene.INVALID,
    "sensor": scene.SENSOR,
}


def lesson_dir() -> Path:
    return recordings_dir() / "lesson"


@dataclass(frozen=True)
class Variant:
    name: str
    matcher: str
    params: Params


@dataclass(frozen=True)
class Step:
    number: int  # 1-based, in file-name order
    path: Path
    title: str
    text: str  # template
    try_text: str  # template
    scenario: Scenario
    layers: tuple[scene.Style, ...]
    iteration: int | None  # None: the last
    variant: Variant | None = None
    distances: np.ndarray | None = None
    mad_k: float = 2.0
    L_try: float | None = None
    window: tuple[float, float, float, float] | None = None  # [m], reference frame


def _text(spec: dict, key: str, path: Path) -> str:
    value = spec.get(key)
    if not isinstance(value, str) or not value.strip():
        raise InputError("expected a non-empty string", str(path), field=key)
    return " ".join(value.split())


def _layers(spec: dict, path: Path) -> tuple[scene.Style, ...]:
    keys = spec.get("layers")
    if not isinstance(keys, list) or not keys or not all(isinstance(k, str) for k in keys):
        raise InputError(
            f"expected a list of layer names from: {', '.join(LAYERS)}", str(path), field="layers"
        )
    unknown = [k for k in keys if k not in LAYERS]
    if unknown:
        raise InputError(
            f"unknown layer {unknown[0]!r}; known: {', '.join(LAYERS)}", str(path), field="layers"
        )
    return tuple(LAYERS[k] for k in keys)


def _positive(value, path: Path, field: str) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not (math.isfinite(value) and value > 0)
    ):
        raise InputError(f"expected a positive number, got {value!r}", str(path), field=field)
    return float(value)


def _variant(spec: dict, path: Path) -> Variant | None:
    """One more run of a step's matcher: its ``[params.MATCHER]`` table with the variant's keys
    over it."""
    table = spec.get("variant")
    if table is None:
        return None
    table = dict(table)
    name, matcher = table.pop("name", None), table.pop("matcher", None)
    if not isinstance(name, str) or not name.isidentifier():
        raise InputError(
            'expected a name for the variant\'s numbers, e.g. "without_grid"',
            str(path),
            field="variant.name",
        )
    if matcher not in MATCHERS:
        raise InputError(
            f"expected one of {', '.join(MATCHERS)}", str(path), field="variant.matcher"
        )
    values = {**spec.get("params", {}).get(matcher, {}), **table}
    return Variant(
        name,
        matcher,
        params_from_mapping(MATCHERS[matcher].params_type, values, str(path), "variant"),
    )


def _distances(spec: dict, path: Path) -> tuple[np.ndarray | None, float]:
    table = spec.get("distances")
    if table is None:
        return None, 2.0
    values = table.get("values")
    if not (
        isinstance(values, list)
        and len(values) >= 3
        and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0
            for v in values
        )
    ):
        raise InputError(
            "expected a list of at least 3 non-negative numbers",
            str(path),
            field="distances.values",
        )
    return np.asarray(values, float), _positive(table.get("mad_k", 2.0), path, "distances.mad_k")


def _iteration(spec: dict, path: Path) -> int | None:
    k = spec.get("iteration", "last")
    if k == "last":
        return None
    if isinstance(k, bool) or not isinstance(k, int) or k < 0:
        raise InputError(
            f'expected a whole number >= 0 or "last", got {k!r}', str(path), field="iteration"
        )
    return k


def _window(spec: dict, path: Path) -> tuple[float, float, float, float] | None:
    w = spec.get("view_m")
    if w is None:
        return None
    if not (
        isinstance(w, list)
        and len(w) == 4
        and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in w
        )
        and w[0] < w[2]
        and w[1] < w[3]
    ):
        raise InputError(
            "expected [x_min, y_min, x_max, y_max] in metres, minima below maxima",
            str(path),
            field="view_m",
        )
    return tuple(float(v) for v in w)


MAX_MATCHERS = 2  # a step's picture shows its matchers side by side


def load_step(path: Path, number: int) -> Step:
    spec = read_toml(path)
    distances, mad_k = _distances(spec, path)
    scenario = load_scenario(path)
    if len(scenario.params) > MAX_MATCHERS:
        raise InputError(
            f"a step shows at most {MAX_MATCHERS} matchers side by side",
            str(path),
            field="algorithms",
        )
    return Step(
        number,
        path,
        _text(spec, "title", path),
        _text(spec, "text", path),
        _text(spec, "try", path),
        scenario,
        _layers(spec, path),
        _iteration(spec, path),
        _variant(spec, path),
        distances,
        mad_k,
        _positive(spec["L_try"], path, "L_try") if "L_try" in spec else None,
        _window(spec, path),
    )


def step_paths(directory: Path | None = None) -> list[Path]:
    return sorted((directory or lesson_dir()).glob("*.toml"))


def load_lesson(directory: Path | None = None) -> list[Step]:
    paths = step_paths(directory)
    if not paths:
        raise InputError(f"no lesson steps (*.toml) in {directory or lesson_dir()}", field="--dir")
    return [load_step(p, k) for k, p in enumerate(paths, 1)]


@dataclass
class StepRun:
    """A step after its runs: what it shows, and its text with the numbers filled in."""

    step: Step
    runs: list[PairMatch]
    variant: PairMatch | None
    facts: F.Facts
    text: str
    try_text: str

    @property
    def iteration(self) -> int:
        """The iteration the step opens at."""
        n = max((len(r.iterations) for r in self.runs), default=0)
        return n if self.step.iteration is None else min(self.step.iteration, n)

    def layers(
        self, run: PairMatch, iteration: int | None = None, shown_only: bool = False
    ) -> list[scene.Layer]:
        """Everything ``run`` draws at ``iteration`` (default: the step's), as the debugger draws it
        (``scene.pair_layers``); ``shown_only``: only the kinds the step shows (and every plot)."""
        s = self.step.scenario
        layers = scene.pair_layers(
            s.ref,
            s.obj,
            run.matcher,
            run.start,
            run.iterations,
            self.iteration if iteration is None else iteration,
            run.truth,
            run.odometry,
        )
        if shown_only:
            layers = [
                ly
                for ly in layers
                if getattr(ly, "style", None) not in scene.STYLES or ly.style in self.step.layers
            ]
        return scene.compared(layers, run.matcher) if len(self.runs) > 1 else layers

    def distance_layers(self) -> list[scene.Layer]:
        """The step's list of distances as a dot plot (paper 000 Fig. 9), when it has one."""
        d = self.facts.get("distances")
        return (
            []
            if d is None
            else scene.distance_layers(self.step.distances, d["threshold"], d["sigma_threshold"])
        )


def run_step(step: Step) -> StepRun:
    """Run the step's matchers (and its variant), gather its numbers, fill in its text."""
    s = step.scenario
    runs = s.matches()
    v = step.variant
    variant = s.match(v.params) if v is not None else None
    facts: F.Facts = {
        "scan": F.scan_facts(s.ref),
        "object_scan": F.scan_facts(s.obj),
        "guess": F.pose_facts(s.guess),
    }
    named = [(r.matcher, r) for r in runs] + ([(v.name, variant)] if variant is not None else [])
    for name, run in named:
        facts[name] = F.run_facts(
            run, s.truth, len(run.iterations) if step.iteration is None else step.iteration
        )
    L = next((p.L for p in s.params.values() if hasattr(p, "L")), None)
    if L is not None:
        facts["metric"] = F.metric_facts(s.ref, L, step.L_try)
    if step.distances is not None:
        facts["distances"] = F.distance_facts(step.distances, step.mad_k)
    if s.truth is not None:
        facts["truth"] = F.pose_facts(s.truth)
    return StepRun(
        step,
        runs,
        variant,
        facts,
        F.render(step.text, facts, str(step.path), "text"),
        F.render(step.try_text, facts, str(step.path), "try"),
    )
