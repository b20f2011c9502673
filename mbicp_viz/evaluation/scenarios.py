"""Curated real-data scenarios (``recordings/scenarios/*.toml``): inputs, parameters, what to look
at.

A scenario names a real scan pair (or one scan and a known displacement), the initial guess, the
matchers to run and their parameters. Everything is deterministic, so the ``.rrd`` files made from
the scenarios are reproducible byte for byte in content (``rerun rrd compare --unordered``).

Fields (units at the edges: degrees named ``_deg``):

- ``title``, ``note``: what the scenario shows and what to look at.
- ``input``: scan file, relative to the scenario's folder's parent (``recordings/``).
- ``pair = [I, J]``: reference and object scan indices in the input.
- ``displacement_deg = [x, y, theta_deg]`` (optional, needs I == J): the object is the reference
  scan seen from a sensor at this pose, which is then the known answer.
- ``remove_block = [a, b]`` (optional): remove the valid beams between fractions a and b of the
  scan (an occlusion-like block, paper 000 §3.1) from the copy ``thin`` names: ``"reference"``
  (the default; the object's points there then have no counterpart, as the paper's trashcan
  experiment, §3.1 Figs. 11-12) or ``"object"``.
- ``guess_deg = [x, y, theta_deg]`` or ``guess = "log"`` (the poses/odometry the input stores).
- ``algorithms = [...]`` and ``[params.NAME]`` tables in the ``--params`` file format.
- ``teaching = true``: add the teaching layers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from mbicp_viz.core import MATCHERS, Params, Pose2, Scan
from mbicp_viz.errors import InputError
from mbicp_viz.readers import read_log
from mbicp_viz.readers.log import Frames
from mbicp_viz.readers.pair_match import PairMatch
from mbicp_viz.readers.params_toml import params_from_mapping, read_toml

from .pairs import Thin, block_mask, displaced_pair, stored_guess, stored_truth

_PACKAGE = Path(__file__).resolve().parent.parent


def recordings_dir() -> Path:
    """The curated recordings: shipped inside the package (``mbicp_viz/recordings``, installed), or
    the checkout's top-level ``recordings/``."""
    installed = _PACKAGE / "recordings"
    return installed if (installed / "scenarios").is_dir() else _PACKAGE.parent / "recordings"


def is_checkout(directory: Path) -> bool:
    """Whether ``directory`` is a checkout's ``recordings/`` (writable sources), not installed
    data."""
    return (directory.parent / "pyproject.toml").is_file()


@dataclass(frozen=True)
class Scenario:
    name: str
    title: str
    note: str
    ref: Scan
    obj: Scan
    guess: Pose2
    truth: Pose2 | None
    params: dict[str, Params]
    teaching: bool

    def match(self, params: Params) -> PairMatch:
        """One matcher on the scenario's pair from its guess, with the iterations' events (laser
        frame: a scenario is a pair of scans)."""
        from .single import Setup, match_pair

        s = Setup(self.guess, "given", self.truth, None if self.truth is None else "given")
        return match_pair(self.ref, self.obj, params, s, Frames(), indices=(0, 1), record=True)

    def matches(self) -> list[PairMatch]:
        """Every matcher of the scenario, in order."""
        return [self.match(p) for p in self.params.values()]


def _pose_deg(v, path, field) -> Pose2:
    if not (
        isinstance(v, list)
        and len(v) == 3
        and all(isinstance(c, (int, float)) and math.isfinite(c) for c in v)
    ):
        raise InputError("expected [x_m, y_m, theta_deg]", path, field=field)
    return Pose2(float(v[0]), float(v[1]), math.radians(v[2]))


def _pair(spec: dict, path: Path) -> tuple[Scan, Scan, Pose2 | None]:
    """(reference, object, known answer) of a scenario."""
    log = read_log(path.parent.parent / spec["input"])
    i, j = spec.get("pair", [0, 1])
    ref = log.scan(i)
    if "displacement_deg" not in spec:
        obj = log.scan(j)
        return ref, obj, stored_truth(ref, obj)
    if i != j:
        raise InputError(
            "a displacement needs the same scan twice: pair = [I, I]", str(path), field="pair"
        )
    truth = _pose_deg(spec["displacement_deg"], str(path), "displacement_deg")
    keep = block_mask(ref.n_valid, *spec["remove_block"]) if "remove_block" in spec else None
    thin = spec.get("thin", Thin.reference.value)
    if thin not in {t.value for t in Thin}:
        raise InputError(f"choose {' or '.join(t.value for t in Thin)}", str(path), field="thin")
    return *displaced_pair(ref, truth, keep, thin), truth


def load_scenario(path: Path) -> Scenario:
    spec = read_toml(path)
    ref, obj, truth = _pair(spec, path)
    g = spec.get("guess_deg")
    guess = (
        stored_guess(ref, obj)[0]
        if spec.get("guess") == "log"
        else (_pose_deg(g, str(path), "guess_deg") if g is not None else Pose2())
    )
    names = spec.get("algorithms", list(MATCHERS))
    unknown = [a for a in names if a not in MATCHERS]
    if unknown:
        raise InputError(f"unknown algorithm {unknown[0]!r}", str(path), field="algorithms")
    tables = spec.get("params", {})
    params = {
        a: params_from_mapping(MATCHERS[a].params_type, tables.get(a, {}), str(path), f"params.{a}")
        for a in names
    }
    return Scenario(
        path.stem,
        spec.get("title", path.stem),
        spec.get("note", ""),
        ref,
        obj,
        guess,
        truth,
        params,
        bool(spec.get("teaching", False)),
    )


def scenario_paths(directory: Path | None = None) -> list[Path]:
    return sorted(((directory or recordings_dir()) / "scenarios").glob("*.toml"))


def find_scenario(name: str, directory: Path | None = None) -> Scenario:
    """The scenario called ``name`` (its file's stem), or an error listing the known ones."""
    known = {p.stem: p for p in scenario_paths(directory)}
    if name not in known:
        raise InputError(
            f"unknown scenario {name!r}; known: {', '.join(known) or 'none found'}",
            field="--scenario",
        )
    return load_scenario(known[name])
