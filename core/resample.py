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


def regular_picks(n: np.ndarray, n_keep: np.ndarray, rank: np.ndarray) -> np.ndarray:
    """Whether position ``rank`` of a run of ``n`` items is among ``n_keep`` regularly spaced picks.

    The picks are round(m (n - 1) / (n_keep - 1)), m = 0 .. n_keep - 1: first and last included
    when n_keep >= 2, only the first when n_keep == 1, none when n_keep == 0.
    """
    n = n.astype(float)
    k = n_keep.astype(float)
    step = np.where(k > 1, (n - 1) / np.maximum(k - 1, 1), 0.0)
    m = np.where(step > 0, np.floor(rank / np.where(step > 0, step, 1) + 0.5), 0)
    pick = np.floor(m * step + 0.5)
    return (k >= 1) & (pick == rank) & (m < np.maximum(k, 1))


def grid_resample(points: np.ndarray, cell_size: float) -> Resampling:
    """Resample sensor-frame ``points`` (scan order) on a grid of ``cell_size`` metres."""
    origin = points.min(axis=0)
    rc = np.floor((points - origin) / cell_size).astype(np.int64)[:, ::-1]  # (row=y, col=x)
    sensor = np.floor((np.zeros(2) - origin) / cell_size).astype(np.int64)[::-1]
    ncols = int(rc[:, 1].max()) + 1
    cell_id = rc[:, 0] * ncols + rc[:, 1]
    order = np.argsort(cell_id, kind="stable")  # stable: scan order inside each cell
    sid = cell_id[order]
    starts = np.flatnonzero(np.concatenate(([True], sid[1:] != sid[:-1])))
    count = np.diff(np.append(starts, len(sid)))
    cells = rc[order][starts]
    dist = np.hypot(*(cells - sensor).T.astype(float))
    ratio = dist / dist.max() if dist.max() > 0 else np.ones(len(cells))
    # a tiny tolerance keeps ceil(n * eta) from jumping up on round-off (e.g. 3 * 1/3)
    n_keep = np.ceil(count * ratio - 1e-9).astype(np.int64)
    cell_of = np.repeat(np.arange(len(cells)), count)
    rank = np.arange(len(sid)) - starts[cell_of]
    keep_sorted = regular_picks(count[cell_of], n_keep[cell_of], rank)
    kept = np.sort(order[keep_sorted])
    return Resampling(origin, float(cell_size), cells, sensor, ratio, count, n_keep, kept)
