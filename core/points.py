"""A scan's Cartesian points, compiled (``Scan.points`` imports this module, and numba with it,
when it is first called: reading a log needs neither)."""

from __future__ import annotations

import numpy as np

from .scan import bearing_layout
from .tiers import kernel, run


def directions(bearings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cosine and sine of each of ``bearings`` (never to be written to), found once for the
    scans of their layout (``scan.bearing_layout``: a stream's scans, a worker's unpickled chunk),
    not twice a scan (as its points and as a reference's directions: 20 us a pair at 1081 beams)."""
    layout = bearing_layout(bearings)
    found = layout.derived.get("directions")
    if found is None:  # two threads may both compute it: the same numbers
        found = layout.derived["directions"] = run(_cos_sin, layout.given)
    return found


@kernel
def _cos_sin(bearings):
    c, s = np.empty(len(bearings)), np.empty(len(bearings))
    for i in range(len(bearings)):
        c[i], s[i] = np.cos(bearings[i]), np.sin(bearings[i])
    return c, s


@kernel
def valid_points(ranges, bearings, cos_b, sin_b, valid, max_range: float):
    """The points (M, 2) of the valid readings below ``max_range``, in scan order, their bearings,
    their bearings' cosines and sines (``cos_b``, ``sin_b``: of every beam), whether the scan
    has valid readings, each a finite range at a finite bearing, and its longest valid reading
    (-inf: none; NaN: one is NaN, as numpy's maximum says) — the last two whatever ``max_range``.
    Compiled because every match reads both scans' points: numpy's masks, trigonometry and
    stacking cost more per call than the arithmetic."""
    n, n_valid, finite, top, nan = 0, 0, True, -np.inf, False
    for i in range(len(ranges)):
        n += valid[i] and ranges[i] < max_range
        if valid[i]:
            n_valid += 1
            finite = finite and np.isfinite(ranges[i]) and np.isfinite(bearings[i])
            nan = nan or np.isnan(ranges[i])
            top = max(top, ranges[i])
    pts, b, c, s = np.empty((n, 2)), np.empty(n), np.empty(n), np.empty(n)
    k = 0
    for i in range(len(ranges)):
        if valid[i] and ranges[i] < max_range:
            pts[k, 0], pts[k, 1], b[k] = ranges[i] * cos_b[i], ranges[i] * sin_b[i], bearings[i]
            c[k], s[k] = cos_b[i], sin_b[i]
            k += 1
    return pts, b, c, s, n_valid > 0 and finite, np.nan if nan else top
