"""A scan's Cartesian points, compiled (``Scan.points`` imports this module, and numba with it,
when it is first called: reading a log needs neither)."""

from __future__ import annotations

import numpy as np

from .tiers import kernel


@kernel
def valid_points(ranges, bearings, valid, max_range: float):
    """The points (M, 2) of the valid readings below ``max_range``, in scan order, and their
    bearings. Compiled because every match reads both scans' points: numpy's masks, trigonometry
    and stacking cost more per call than the arithmetic."""
    n = 0
    for i in range(len(ranges)):
        n += valid[i] and ranges[i] < max_range
    pts, b = np.empty((n, 2)), np.empty(n)
    k = 0
    for i in range(len(ranges)):
        if valid[i] and ranges[i] < max_range:
            pts[k, 0], pts[k, 1], b[k] = (
                ranges[i] * np.cos(bearings[i]),
                ranges[i] * np.sin(bearings[i]),
                bearings[i],
            )
            k += 1
    return pts, b
