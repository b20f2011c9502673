"""Grid resampling of the object scan (paper 000 §2.3).

Square cells over the bounding rectangle of the object points, in the sensor frame. A cell's
distance to the sensor's cell is counted in rows and columns, d_i = sqrt(drow^2 + dcol^2); its
sampling ratio is eta_i = d_i / d_max; a cell with n points keeps n' = ceil(n * eta_i) of them:
the first and the last in scan order and n' - 2 at regular intervals between (Fig. 5a).
Near-sensor cells are thinned, far cells kept, which evens out the density.
"""

from __future__ import annotations

import numpy as np

from .events import Resampling
from .tiers import kernel, run


@kernel(inline="always")
def regular_pick(n: int, n_keep: int, rank: int) -> bool:
    """Whether position ``rank`` of a run of ``n`` items is among ``n_keep`` regularly spaced picks.

    The picks are round(m (n - 1) / (n_keep - 1)), m = 0 .. n_keep - 1: first and last included
    when n_keep >= 2, only the first when n_keep == 1, none when n_keep == 0.
    """
    k = float(n_keep)
    step = (n - 1.0) / max(k - 1.0, 1.0) if k > 1.0 else 0.0
    m = np.floor(rank / step + 0.5) if step > 0.0 else 0.0
    return k >= 1.0 and np.floor(m * step + 0.5) == rank and m < max(k, 1.0)


@kernel
def _resample(rc, sensor, order, cell_id):
    """The rest of ``grid_resample`` once the points' cells are sorted (numpy's stable argsort:
    numba's costs seconds of compilation): cells, ratio, count, kept count and kept points."""
    n = len(rc)
    n_cells = 1
    for i in range(1, n):
        n_cells += cell_id[order[i]] != cell_id[order[i - 1]]
    cells, count = np.empty((n_cells, 2), dtype=np.int64), np.zeros(n_cells, dtype=np.int64)
    dist = np.empty(n_cells)
    c = -1
    for i in range(n):
        if i == 0 or cell_id[order[i]] != cell_id[order[i - 1]]:
            c += 1
            cells[c, 0], cells[c, 1] = rc[order[i], 0], rc[order[i], 1]
            dist[c] = np.hypot(float(cells[c, 0] - sensor[0]), float(cells[c, 1] - sensor[1]))
        count[c] += 1
    d_max = 0.0
    for c in range(n_cells):
        d_max = max(d_max, dist[c])
    # plain loops: numba compiles them in a fraction of the time of array expressions
    ratio, n_keep = np.empty(n_cells), np.empty(n_cells, dtype=np.int64)
    for c in range(n_cells):
        ratio[c] = dist[c] / d_max if d_max > 0 else 1.0
        # a tiny tolerance keeps ceil(n * eta) from jumping up on round-off (e.g. 3 * 1/3)
        n_keep[c] = int(np.ceil(count[c] * ratio[c] - 1e-9))
    keep = np.zeros(n, dtype=np.bool_)
    n_kept, i = 0, 0
    for c in range(n_cells):
        for rank in range(count[c]):
            keep[order[i]] = regular_pick(count[c], n_keep[c], rank)
            n_kept += keep[order[i]]
            i += 1
    kept = np.empty(n_kept, dtype=np.int64)
    k = 0
    for i in range(n):
        if keep[i]:
            kept[k] = i
            k += 1
    return cells, ratio, count, n_keep, kept


@kernel
def _cells(points, cell_size: float):
    """Each point's cell (row = y, column = x) counted from the bounding rectangle's corner, the
    sensor's cell, a cell id in row-major order, and that corner."""
    n = len(points)
    origin = np.empty(2)
    for c in range(2):
        origin[c] = np.inf
        for i in range(n):
            origin[c] = min(origin[c], points[i, c])
    rc, cell_id = np.empty((n, 2), dtype=np.int64), np.empty(n, dtype=np.int64)
    n_cols = 0
    for i in range(n):
        rc[i, 0] = int(np.floor((points[i, 1] - origin[1]) / cell_size))
        rc[i, 1] = int(np.floor((points[i, 0] - origin[0]) / cell_size))
        n_cols = max(n_cols, rc[i, 1] + 1)
    for i in range(n):
        cell_id[i] = rc[i, 0] * n_cols + rc[i, 1]
    sensor = np.empty(2, dtype=np.int64)
    sensor[0], sensor[1] = (
        int(np.floor((0.0 - origin[1]) / cell_size)),
        int(np.floor((0.0 - origin[0]) / cell_size)),
    )
    return rc, sensor, cell_id, origin


def grid_resample(points: np.ndarray, cell_size: float) -> Resampling:
    """Resample sensor-frame ``points`` (scan order) on a grid of ``cell_size`` metres."""
    # nothing within the matcher's range: no cells (the match then ends with too few pairs)
    if len(points) == 0:
        return Resampling(
            np.zeros(2),
            float(cell_size),
            np.zeros((0, 2), np.int64),
            np.zeros(2, np.int64),
            np.zeros(0),
            np.zeros(0, np.int64),
            np.zeros(0, np.int64),
            np.zeros(0, np.int64),
        )
    rc, sensor, cell_id, origin = run(
        _cells, np.ascontiguousarray(points, dtype=float), float(cell_size)
    )
    order = np.argsort(cell_id, kind="stable")  # stable: scan order inside each cell
    cells, ratio, count, n_keep, kept = run(_resample, rc, sensor, order, cell_id)
    return Resampling(origin, float(cell_size), cells, sensor, ratio, count, n_keep, kept)
