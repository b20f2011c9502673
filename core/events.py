"""Typed events a matcher sends to its observer: one start, one per iteration, one finish.

Events are data, not drawing: arrays and numbers that the front ends (rerun, viser, tests)
turn into layers. A matcher builds them only when an observer is attached.

Frames: ``ref_points`` are in the reference frame; ``obj_points`` in the object frame;
``moved_points`` are the object points mapped into the reference frame by ``estimate_before``.
Every pose is the pose of the object frame in the reference frame.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .result import MatchResult
from .se2 import Pose2


class PairKind(enum.IntEnum):
    """How the target of a correspondence was obtained."""

    POINT = 0  # a reference point
    INTERPOLATED = 1  # a point on the segment between two reference points


class PairStatus(enum.IntEnum):
    """Why a candidate correspondence was (not) used by the minimisation."""

    KEPT = 0
    OUTSIDE_BR = 1  # metric distance above the radial window Br (MbICP) / max distance (ICP)
    TRIMMED = 2  # beyond the best 'filter' fraction (trimmed estimator)
    MAD = 3  # above median + k*MAD (paper 000 §2.4.2)
    DOUBLE = 4  # one of several object points on one reference point, far beyond the nearest (CSM)


@dataclass(frozen=True, eq=False)
class Correspondences:
    """Candidate pairs of one iteration, one row per object point that found a target.

    obj_index: (K,) index into the start event's ``obj_points``.
    target:    (K, 2) target point in the reference frame.
    kind:      (K,) PairKind.
    ref_index: (K, 2) reference point indices (into ``ref_points``) the target uses; the
               second is -1 for POINT pairs, the segment's other end for INTERPOLATED ones.
    distance:  (K,) the matcher's pair distance (metric distance for MbICP, Euclidean for ICP,
               range difference for the polar matchers) [m].
    status:    (K,) PairStatus.
    source:    (K, 2) where each pair starts in the reference frame: the moved object point, or for
               the polar matchers the object scan's surface projected onto a reference bearing.
    """

    obj_index: np.ndarray
    target: np.ndarray
    kind: np.ndarray
    ref_index: np.ndarray
    distance: np.ndarray
    status: np.ndarray
    source: np.ndarray

    @property
    def kept(self) -> np.ndarray:
        return self.status == PairStatus.KEPT

    def count(self, kind: PairKind | None = None, status: PairStatus | None = None) -> int:
        m = np.ones(len(self.kind), dtype=bool)
        if kind is not None:
            m &= self.kind == kind
        if status is not None:
            m &= self.status == status
        return int(np.count_nonzero(m))


@dataclass(frozen=True, eq=False)
class Resampling:
    """Grid resampling of the object scan (paper 000 §2.3), in the object sensor frame.

    origin: (2,) lower-left corner of the grid [m]; cell_size [m];
    cells: (C, 2) integer (row, col) of each occupied cell, relative to the grid origin;
    sensor_cell: (2,) (row, col) of the cell holding the sensor;
    ratio: (C,) sampling ratio eta_i = d_i / d_max of each occupied cell;
    count: (C,) points in the cell before, kept_count: (C,) after;
    kept: (M,) indices into ``obj_points`` of the points kept.
    """

    origin: np.ndarray
    cell_size: float
    cells: np.ndarray
    sensor_cell: np.ndarray
    ratio: np.ndarray
    count: np.ndarray
    kept_count: np.ndarray
    kept: np.ndarray


@dataclass(frozen=True, eq=False)
class StartEvent:
    algorithm: str
    params: object  # the matcher's frozen parameter dataclass
    ref_points: np.ndarray  # (Nr, 2) reference frame
    obj_points: np.ndarray  # (No, 2) object frame, every valid point before resampling
    used: np.ndarray  # (Nu,) indices into obj_points that the matcher iterates on
    initial_guess: Pose2
    resampling: Resampling | None


@dataclass(frozen=True, eq=False)
class PolarStep:
    """What a polar matcher (PSM, PMWN) computed in one iteration, all in the reference frame.

    bearings: (N,) reference bearings [rad]; ref_ranges: (N,) preprocessed reference ranges;
    projected_ranges: (N,) the object scan projected onto those bearings at ``estimate_before``
    (NaN where no surface projects), and after the orientation step: ``projected_after``.
    shifts: (S,) bearing shifts tried by the orientation step; cost: (S,) the cost per shift
    (PSM: mean |range difference|; PMWN: that plus metric_weight * |shift angle|), NaN where too
    few pairs; best_shift: the refined minimum in shifts (fractional); fit: "parabola" (PSM),
    "V" (PMWN) or None when no orientation step ran; fit_abc: the cost at the integer minimum and
    its two neighbours, through which the fit passes. metric_weight: PMWN's adaptive lambda
    [m/rad], None for PSM. residuals, weights: (K,) translation residuals [m] and their weights.
    circle_points: (K, 2) PMWN's projected-circle points Delta r_i u_i, circle_centre: (2,) its
    fitted centre (T/2); None for PSM and with ``surface_jacobian`` (the circle holds for Diosi's
    model only).
    """

    bearings: np.ndarray
    ref_ranges: np.ndarray
    projected_ranges: np.ndarray
    shifts: np.ndarray
    cost: np.ndarray
    best_shift: float | None
    fit: str | None
    fit_abc: tuple[float, float, float] | None
    metric_weight: float | None
    residuals: np.ndarray
    weights: np.ndarray
    circle_points: np.ndarray | None
    circle_centre: np.ndarray | None


@dataclass(frozen=True)
class HeldDirection:
    """Improved MbICP with ``hold_weak``: the direction an iteration's step left alone because the
    surfaces its pairs lie on barely fix the motion there (a corridor's axis), and why."""

    condition_number: (
        float  # of the pairs' point-to-line information in (x, y, L theta), above hold_weak
    )
    direction: tuple[float, float, float]  # unit vector in (x, y, L theta)
    length: float  # L [m]

    @property
    def heading_deg(self) -> float:
        """Heading of the direction's translational part, degrees in (-90, 90]."""
        a = math.degrees(math.atan2(self.direction[1], self.direction[0]))
        return a - 180.0 if a > 90.0 else a + 180.0 if a <= -90.0 else a


@dataclass(frozen=True, eq=False)
class IterationEvent:
    iteration: int  # 1-based
    estimate_before: Pose2
    estimate_after: Pose2
    moved_points: np.ndarray  # (Nu, 2) used object points mapped by estimate_before
    hidden: np.ndarray  # indices into obj_points dropped by the projection filter this iteration
    pairs: Correspondences
    threshold: float | None  # rejection threshold on pair distance [m] (MAD, trim cut, or None)
    error: float  # mean squared Euclidean residual of the kept pairs after the step [m^2]
    increment: (
        Pose2  # the step composed this iteration (estimate_after = increment @ estimate_before)
    )
    polar: PolarStep | None = None  # PSM / PMWN only
    note: str = ""  # what else happened, in words (ICP / PL-ICP: a restart began, the run kept)
    held: HeldDirection | None = (
        None  # improved MbICP with hold_weak: the direction its step left alone
    )
    extrapolated: float = (
        0.0  # improved MbICP with extrapolate: the step went on by this many times its own length
    )


@dataclass(frozen=True, eq=False)
class FinishEvent:
    result: MatchResult


Event = StartEvent | IterationEvent | FinishEvent
Observer = Callable[[Event], None]


def broadcast(*observers: Observer) -> Observer:
    """One observer that hands every event to each of ``observers`` in turn."""

    def send(event: Event) -> None:
        for o in observers:
            o(event)

    return send


class Recorder:
    """An observer that keeps every event in memory (tests, front ends replaying a run)."""

    def __init__(self):
        self.events: list[Event] = []

    def __call__(self, event: Event) -> None:
        self.events.append(event)

    @property
    def start(self) -> StartEvent:
        return next(e for e in self.events if isinstance(e, StartEvent))

    @property
    def iterations(self) -> list[IterationEvent]:
        return [e for e in self.events if isinstance(e, IterationEvent)]

    @property
    def finish(self) -> FinishEvent:
        return next(e for e in self.events if isinstance(e, FinishEvent))
