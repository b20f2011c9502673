"""Curated real-data scenarios (``recordings/scenarios/*.toml``): inputs, parameters, what to look at.

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
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core import MATCHERS, Params, Pose2, Scan, ScanSource, make_scan, relative

from .errors import InputError
from .inputs import stored_guess
from .params_io import params_from_mapping
from .readers import read_log

def recordings_dir() -> Path:
    """``$MBICP_VIZ_RECORDINGS``, else ``./recordings`` when run from a checkout, else the source tree's."""
    import os

    env = os.environ.get("MBICP_VIZ_RECORDINGS")
    if env:
        return Path(env)
    here = Path.cwd() / "recordings"
    return here if (here / "scenarios").is_dir() else Path(__file__).resolve().parent.parent / "recordings"


RECORDINGS = recordings_dir()


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


def _pose_deg(v, path, field) -> Pose2:
    if not (isinstance(v, list) and len(v) == 3 and all(isinstance(c, (int, float)) for c in v)):
        raise InputError("expected [x_m, y_m, theta_deg]", path, field=field)
    return Pose2(float(v[0]), float(v[1]), math.radians(v[2]))


def seen_from(scan: Scan, T: Pose2, keep: np.ndarray | None = None) -> Scan:
    """The points of ``scan`` as a sensor at pose T (in the scan's frame) sees them."""
    pts = scan.points() if keep is None else scan.points()[keep]
    p = T.inverse().apply(pts)
    b = np.arctan2(p[:, 1], p[:, 0])
    order = np.argsort(b, kind="stable")
    b = b[order]
    unique = np.concatenate(([True], np.diff(b) > 0))
    return make_scan(np.hypot(*p[order].T)[unique], b[unique],
                     source=ScanSource(f"{scan.source.path} (displaced)", scan.source.index))


def thinned(scan: Scan, keep: np.ndarray) -> Scan:
    """``scan`` with the valid readings where ``keep`` is False marked invalid.

    The beams stay (uniform bearings, as PSM's reference needs); ``keep`` runs over the valid readings.
    """
    valid = scan.valid.copy()
    valid[scan.valid_indices()[~keep]] = False
    return make_scan(scan.ranges, scan.bearings, valid=valid, source=scan.source)


THIN = ("reference", "object")  # the copy of a displaced scan that loses points (``thin``)


def displaced_pair(scan: Scan, truth: Pose2, keep: np.ndarray | None, thin: str) -> tuple[Scan, Scan]:
    """(reference, object) from one scan: the object is the scan seen from ``truth``; ``keep``
    (over the valid readings) thins the reference or the object, as ``thin`` says."""
    if keep is None or thin == "object":
        return scan, seen_from(scan, truth, keep)
    return thinned(scan, keep), seen_from(scan, truth)


def block_mask(n: int, a: float, b: float) -> np.ndarray:
    keep = np.ones(n, dtype=bool)
    keep[int(round(a * n)):int(round(b * n))] = False
    return keep


def load_scenario(path: Path) -> Scenario:
    try:
        spec = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise InputError("no such scenario file", str(path)) from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"invalid TOML: {e}", str(path)) from None
    log = read_log(path.parent.parent / spec["input"])
    i, j = spec.get("pair", [0, 1])
    ref = log.scan(i)
    truth = None
    if "displacement_deg" in spec:
        if i != j:
            raise InputError("a displacement needs the same scan twice: pair = [I, I]", str(path), field="pair")
        truth = _pose_deg(spec["displacement_deg"], str(path), "displacement_deg")
        keep = block_mask(ref.n_valid, *spec["remove_block"]) if "remove_block" in spec else None
        thin = spec.get("thin", "reference")
        if thin not in THIN:
            raise InputError(f"choose {' or '.join(THIN)}", str(path), field="thin")
        ref, obj = displaced_pair(ref, truth, keep, thin)
    else:
        obj = log.scan(j)
        if ref.pose is not None and obj.pose is not None:
            truth = relative(ref.pose, obj.pose)
    g = spec.get("guess_deg")
    guess = stored_guess(ref, obj)[0] if spec.get("guess") == "log" else (
        _pose_deg(g, str(path), "guess_deg") if g is not None else Pose2())
    algos = spec.get("algorithms", list(MATCHERS))
    unknown = [a for a in algos if a not in MATCHERS]
    if unknown:
        raise InputError(f"unknown algorithm {unknown[0]!r}", str(path), field="algorithms")
    tables = spec.get("params", {})
    params = {a: params_from_mapping(a, tables.get(a, {}), str(path)) for a in algos}
    return Scenario(path.stem, spec.get("title", path.stem), spec.get("note", ""), ref, obj, guess, truth, params,
                    bool(spec.get("teaching", False)))


def scenario_paths(directory: Path = RECORDINGS) -> list[Path]:
    return sorted((directory / "scenarios").glob("*.toml"))
