"""Laser scans: ranges at bearings, with a validity mask.

Invalid readings (no return, NaN, inf, outside [range_min, range_max]) are masked and
never turned into points. Bearings are in the sensor frame, strictly increasing, in radians.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field

import numpy as np

from .errors import ScanError, ScanSource, UnusableScan
from .se2 import Pose2


@dataclass(frozen=True, eq=False)
class Scan:
    """One 2-D laser scan.

    ``pose`` is the pose of the sensor frame in the log's world frame when the log stores one
    (corrected or estimated), ``odometry`` the raw odometry pose in the odometry frame.
    """

    ranges: np.ndarray  # (N,) metres; invalid entries may hold anything
    # (N,) radians, strictly increasing, sensor frame; shared by the scans of a stream that have
    # the same (``bearing_layout``): never written to
    bearings: np.ndarray
    valid: np.ndarray  # (N,) bool
    pose: Pose2 | None = None
    odometry: Pose2 | None = None
    stamp: float | None = None  # seconds
    source: ScanSource = field(default_factory=ScanSource)
    beam_times: np.ndarray | None = None  # (N,) [s] when each beam was measured, after ``stamp``
    raw: Scan | None = (
        None  # the scan as measured, when this one is corrected for motion (core/deskew.py)
    )

    @property
    def n_valid(self) -> int:
        return int(np.count_nonzero(self.valid))

    def points(self, max_range: float = np.inf) -> np.ndarray:
        """(M, 2) Cartesian points of the valid readings below ``max_range`` (a matcher's range
        limit), in scan order, sensor frame."""
        return self.points_and_bearings(max_range)[0]

    def points_and_bearings(self, max_range: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """``points(max_range)`` and their bearings [rad], shared: not to be written to."""
        return self._valid_points(max_range)[:2]

    def directions(self, max_range: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """The cosine and sine of the bearing of each of ``points(max_range)``, shared."""
        return self._valid_points(max_range)[2:4]

    def _valid_points(self, max_range: float) -> tuple[np.ndarray, ...]:
        """``points.valid_points``, kept on the scan, which never changes: a run reads each scan's
        points four times (as the reference and the object of a match, and again for its
        agreement), a tenth of a pair's time outside the matcher's loop at 1081 beams. A limit
        above every valid reading is no limit, so the matcher's 1000 m and the agreement's none
        share one computation."""
        memo = self.__dict__.setdefault("_memo", {})  # frozen: set past __setattr__
        every = memo.get(np.inf)
        if every is None:
            every = memo[np.inf] = self._compute_points(np.inf)
        top = every[5]  # the longest valid reading (NaN: one is NaN)
        if max_range > top:
            return every
        if max_range not in memo:
            memo[max_range] = self._compute_points(float(max_range))
        return memo[max_range]

    def _compute_points(self, max_range: float) -> tuple[np.ndarray, ...]:
        from .points import directions, valid_points
        from .tiers import run

        b = np.ascontiguousarray(self.bearings)
        return run(
            valid_points,
            np.ascontiguousarray(self.ranges),
            b,
            *directions(b),
            np.ascontiguousarray(self.valid),
            max_range,
        )

    def has_finite_points(self) -> bool:
        """Whether it has valid readings and each is a finite point: a point r (cos b, sin b) is
        finite exactly when r and b are (|r cos b| <= |r|). Found with its points."""
        return bool(self._valid_points(np.inf)[4])

    def __getstate__(self) -> dict:
        """Pickled without what ``_valid_points`` keeps (a worker computes its own)."""
        return {k: v for k, v in self.__dict__.items() if k != "_memo"}

    def valid_indices(self) -> np.ndarray:
        return np.flatnonzero(self.valid)

    def angular_span(self) -> float:
        return float(self.bearings[-1] - self.bearings[0]) if len(self.bearings) else 0.0

    def is_full_circle(self) -> bool:
        """True when the beams cover the whole circle (wrap-around neighbours exist)."""
        n = len(self.bearings)
        if n < 2:
            return False
        step = self.angular_span() / (n - 1)
        return self.angular_span() + 1.5 * step >= 2.0 * np.pi


# No 2-D laser scanner returns a reading beyond this; a larger number is a damaged value, masked
# as an invalid reading like a no-return code (formats without a range_max get this one).
ABSURD_RANGE_M = 1000.0


@dataclass(frozen=True, eq=False)
class BearingLayout:
    """What a scan's bearings are, found once for a stream's scans (``bearing_layout``)."""

    # the bearings as a reader gave them (a copy, the next are compared to it; shared: never
    # written to)
    given: np.ndarray
    bearings: np.ndarray  # the bearings a scan keeps (those past a full turn dropped), shared
    keep: np.ndarray | None  # which beams a scan keeps; None: all
    min_step: float  # the least gap between neighbours (inf: fewer than two, or one not finite)
    error: str | None  # why no scan can have them (ScanError's reason), else None
    # what compiled code finds of ``given`` once for every scan of the layout (its cosines and
    # sines: ``points.directions``), by name
    derived: dict = field(default_factory=dict)


# The layouts met last, the latest first: a stream's scans share one (a laser's bearings do not
# change), a few streams or files may alternate. A 1081-beam scan's bearings were checked, copied,
# differenced and masked in 20 of the 36 us that making it took, and pickled with each scan sent
# to a worker. Found by the bearings' bytes: equal numbers, a zero's sign included (a stream's
# scans, a worker's unpickled chunk), not by a caller's array (it may write new bearings into it);
# but a layout's own array, which its scans share and never write, is known by itself (a bag's
# stream hands it on: readers/rosbag.py).
_LAYOUTS: list[BearingLayout] = []
_LAYOUTS_KEPT = 8
# Bearings of more beams than any 2-D laser has (a damaged or hostile file) are checked each time,
# never kept: the layouts kept hold at most 8 MB
KEPT_BEAMS_MAX = 65536
_LAYOUTS_LOCK = threading.Lock()  # a debugger's threads read scans


def _fresh_lock() -> None:
    # a fork while another thread held the lock would leave it held in the child for ever
    global _LAYOUTS_LOCK
    _LAYOUTS_LOCK = threading.Lock()


os.register_at_fork(after_in_child=_fresh_lock)


def bearing_layout(bearings) -> BearingLayout:
    """The layout of ``bearings`` (any 1-D sequence of floats): the one of equal bearings when one
    was met lately, else found and kept."""
    b = np.asarray(bearings, dtype=float).reshape(-1)
    if len(b) > KEPT_BEAMS_MAX:
        return _layout(b)
    bits = b.view(np.uint64)
    with _LAYOUTS_LOCK:
        for k, known in enumerate(_LAYOUTS):
            # a scan's own bearings are its layout's, never written to: known without a comparison
            if (bearings is known.bearings and known.keep is None) or np.array_equal(
                known.given.view(np.uint64), bits
            ):
                _LAYOUTS.insert(0, _LAYOUTS.pop(k))
                return known
    layout = _layout(b)
    with _LAYOUTS_LOCK:
        _LAYOUTS.insert(0, layout)
        del _LAYOUTS[_LAYOUTS_KEPT:]
    return layout


def _layout(b: np.ndarray) -> BearingLayout:
    given = b.copy()
    steps = np.diff(b)
    finite = bool(np.all(np.isfinite(b)))
    min_step = float(np.abs(steps).min()) if finite and len(steps) else np.inf

    def refused(reason: str) -> BearingLayout:
        return BearingLayout(given, given, None, min_step, reason)

    if not finite:
        return refused("bearings contain NaN or inf")
    if len(b) > 1 and not np.all(steps > 0):
        return refused("bearings must be strictly increasing")
    keep = None
    if len(b) > 2:
        step = (b[-1] - b[0]) / (len(b) - 1)
        if b[-1] - b[0] > 2.0 * np.pi + 1.5 * step:
            return refused(
                f"bearings span {np.degrees(b[-1] - b[0]):.4f} degrees: more than 360 degrees "
                "and one step"
            )
        # beams past it repeat the first directions: dropped
        turn = b < b[0] + 2.0 * np.pi - 0.5 * step
        keep = None if turn.all() else turn
    elif len(b) == 2 and b[1] - b[0] >= 2.0 * np.pi:
        return refused("two beams a full turn apart")
    # C-contiguous and writable (numba compiles a kernel once per array kind, and the warm-up
    # compiles these: core/tiers.py), apart from what a reader holds
    kept = np.array(given if keep is None else given[keep])
    return BearingLayout(given, kept, keep, min_step, None)


def make_scan(
    ranges,
    bearings,
    *,
    range_min: float = 0.0,
    range_max: float = np.inf,
    invalid_values: tuple[tuple[float, float], ...] = (),
    valid=None,
    pose: Pose2 | None = None,
    odometry: Pose2 | None = None,
    stamp: float | None = None,
    source: ScanSource | None = None,
    beam_times=None,
) -> Scan:
    """Build a checked Scan.

    ``invalid_values`` lists closed intervals of no-return codes (e.g. SICK's 81.83-81.91 m).
    A reading is valid when it is finite, strictly above ``range_min`` (and 0), strictly below
    ``range_max`` and ``ABSURD_RANGE_M`` and outside every no-return interval. A 360-degree scan
    whose last beams point where its first do (a span of 2 pi, up to one step more) loses those
    closing beams. Raises ScanError for inconsistent arrays, UnusableScan when nothing is valid.
    """
    source = source or ScanSource()
    # Copies, C-contiguous and writable whatever the reader gave (a broadcast or a buffer's view):
    # numba compiles a kernel once per array kind, and the warm-up compiles these (core/tiers.py).
    # The bearings are their layout's, checked and copied once for a stream's scans.
    r = np.array(ranges, dtype=float).reshape(-1)
    b = np.asarray(bearings, dtype=float).reshape(-1)
    if r.shape != b.shape:
        raise ScanError(source, f"{len(r)} ranges but {len(b)} bearings")
    if len(r) == 0:
        raise UnusableScan(source, "empty scan (no beams)")
    # the given array, not a view of it: a layout's own is known without a comparison
    layout = bearing_layout(bearings)
    if layout.error is not None:
        raise ScanError(source, layout.error)
    v = None if valid is None else np.asarray(valid, dtype=bool).reshape(-1)
    if v is not None and v.shape != r.shape:
        raise ScanError(source, f"{len(v)} validity flags for {len(r)} beams")
    t = None if beam_times is None else np.asarray(beam_times, dtype=float).reshape(-1)
    if t is not None and (t.shape != r.shape or not np.all(np.isfinite(t))):
        raise ScanError(
            source, f"{len(t)} beam times for {len(r)} beams, or a time that is not a number"
        )
    b, keep = layout.bearings, layout.keep
    if keep is not None:
        r, v, t = r[keep], None if v is None else v[keep], None if t is None else t[keep]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & (r > max(range_min, 0.0)) & (r < min(range_max, ABSURD_RANGE_M))
        for lo, hi in invalid_values:
            ok &= ~((r >= lo) & (r <= hi))
    if v is not None:
        ok &= v
    if not ok.any():
        raise UnusableScan(source, f"no valid reading among {len(r)} beams")
    return Scan(r, b, ok, pose, odometry, stamp, source, t)


def uniform_bearings(n: int, start: float, increment: float) -> np.ndarray:
    return start + increment * np.arange(n)
