"""Events -> drawable layers: the one scene mapping both front ends (rerun, viser) draw.

A layer is plain data (points, segments, boxes, scalars, text, a pose) under a path; the front
ends only translate layers into their own calls. Colours follow paper 000's figures: reference
red, object blue, correspondences black; interpolated and rejected pairs get their own colours.
Everything is in the reference frame, metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import numpy as np

from core import FinishEvent, IterationEvent, PairKind, PairStatus, Pose2, StartEvent

RGB = tuple[int, int, int]
REFERENCE: RGB = (220, 40, 40)
OBJECT: RGB = (40, 90, 220)
OBJECT_AFTER: RGB = (150, 180, 245)
PAIR_POINT: RGB = (20, 20, 20)
PAIR_INTERPOLATED: RGB = (0, 160, 90)
PAIR_REJECTED: RGB = (245, 160, 0)
HIDDEN: RGB = (170, 170, 170)
ERROR: RGB = (90, 90, 90)
THRESHOLD: RGB = (245, 160, 0)


@dataclass(frozen=True, eq=False)
class Points:
    path: str
    xy: np.ndarray  # (N, 2)
    color: RGB | np.ndarray  # one colour, or (N, 3)
    radius: float


@dataclass(frozen=True, eq=False)
class Segments:
    path: str
    starts: np.ndarray  # (N, 2)
    ends: np.ndarray  # (N, 2)
    color: RGB
    width: float


@dataclass(frozen=True, eq=False)
class Boxes:
    path: str
    centers: np.ndarray  # (N, 2)
    half_size: float
    colors: np.ndarray  # (N, 3)
    labels: list[str]


@dataclass(frozen=True)
class Scalar:
    path: str
    value: float
    color: RGB


@dataclass(frozen=True)
class Text:
    path: str
    text: str
    level: str = "INFO"


@dataclass(frozen=True)
class Frame:
    """The estimate: the pose of the object frame in the reference frame."""

    path: str
    pose: Pose2


Layer = Union[Points, Segments, Boxes, Scalar, Text, Frame]

# Paths, relative to a run's root; the front ends and the blueprint rely on them.
SCANS = "scene"
PLOTS = "plots"
LOG = "log"


def ratio_colors(ratio: np.ndarray) -> np.ndarray:
    """Cell colour by sampling ratio: pale for thinned near cells, saturated blue for kept far ones."""
    r = np.clip(ratio, 0.0, 1.0)[:, None]
    return np.round((1 - r) * np.array([235, 235, 235]) + r * np.array(OBJECT)).astype(np.uint8)


def start_layers(ev: StartEvent) -> list[Layer]:
    """Static layers: the reference scan, the object scan at the initial guess, the resampling grid."""
    layers: list[Layer] = [
        Points(f"{SCANS}/reference", ev.ref_points, REFERENCE, 0.02),
        Points(f"{SCANS}/object_initial", ev.initial_guess.apply(ev.obj_points), HIDDEN, 0.01),
    ]
    rs = ev.resampling
    if rs is not None:
        # the grid lives in the object sensor frame: draw it where the initial guess puts it
        centers = rs.origin + (rs.cells[:, ::-1] + 0.5) * rs.cell_size
        layers.append(Boxes(f"{SCANS}/resampling_grid", ev.initial_guess.apply(centers), rs.cell_size / 2,
                            ratio_colors(rs.ratio),
                            [f"eta={e:.2f} kept {k}/{n}" for e, k, n in zip(rs.ratio, rs.kept_count, rs.count)]))
    return layers


def iteration_layers(start: StartEvent, ev: IterationEvent) -> list[Layer]:
    """Layers of one iteration: where the object was, its pairs by kind and status, where it went."""
    p = ev.pairs
    moved_of = np.empty(len(start.obj_points), dtype=np.int64)
    moved_of[start.used] = np.arange(len(start.used))
    src = ev.moved_points[moved_of[p.obj_index]]
    kept = p.status == PairStatus.KEPT
    point = kept & (p.kind == PairKind.POINT)
    inter = kept & (p.kind == PairKind.INTERPOLATED)
    layers: list[Layer] = [
        Points(f"{SCANS}/object", ev.moved_points, OBJECT, 0.02),
        Points(f"{SCANS}/object_after", ev.estimate_after.apply(start.obj_points[start.used]), OBJECT_AFTER, 0.012),
        Points(f"{SCANS}/hidden", ev.estimate_before.apply(start.obj_points[ev.hidden]), HIDDEN, 0.015),
        Segments(f"{SCANS}/pairs/point", src[point], p.target[point], PAIR_POINT, 0.004),
        Segments(f"{SCANS}/pairs/interpolated", src[inter], p.target[inter], PAIR_INTERPOLATED, 0.004),
        Segments(f"{SCANS}/pairs/rejected", src[~kept], p.target[~kept], PAIR_REJECTED, 0.003),
        Points(f"{SCANS}/interpolated_targets", p.target[inter], PAIR_INTERPOLATED, 0.012),
        Frame(f"{SCANS}/estimate", ev.estimate_after),
        Scalar(f"{PLOTS}/error", ev.error, ERROR),
        Text(f"{LOG}", iteration_text(ev)),
    ]
    if ev.threshold is not None:
        layers.append(Scalar(f"{PLOTS}/threshold", ev.threshold, THRESHOLD))
    return layers


def iteration_text(ev: IterationEvent) -> str:
    p = ev.pairs
    n_kept = p.count(status=PairStatus.KEPT)
    by = {s.name.lower(): p.count(status=s) for s in PairStatus if s != PairStatus.KEPT}
    rej = ", ".join(f"{v} {k}" for k, v in by.items() if v) or "none"
    thr = f"{ev.threshold:.3f} m" if ev.threshold is not None else "-"
    return (f"iteration {ev.iteration}: {len(p.kind)} pairs ({p.count(kind=PairKind.INTERPOLATED)} interpolated), "
            f"{n_kept} kept, rejected: {rej}; threshold {thr}; error {ev.error:.3e} m^2; "
            f"step ({ev.increment.x:+.4f} m, {ev.increment.y:+.4f} m, {math.degrees(ev.increment.theta):+.3f} deg)")


def finish_layers(ev: FinishEvent) -> list[Layer]:
    r = ev.result
    level = "INFO" if r.converged else "WARN"
    text = (f"{r.algorithm}: {'converged' if r.converged else 'NOT converged (' + r.reason.value + ')'} after "
            f"{r.iterations} iterations; pose {r.pose}; error {r.error:.3e} m^2; "
            f"pairs kept {r.pairs_kept}, rejected {r.pairs_rejected}")
    if r.degeneracy is not None:
        text += (f"; condition number {r.degeneracy.condition_number:.1f}, weakest direction heading "
                 f"{r.degeneracy.weakest_heading_deg:+.0f} deg")
    return [Text(LOG, text, level), Frame(f"{SCANS}/estimate", r.pose)]
