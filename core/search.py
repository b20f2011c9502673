"""A global initial guess: correlative search over a window of poses (Olson, ICRA 2009).

The local matchers converge from a guess inside their basin (tenths of a metre, tens of degrees).
When there is no usable guess — consecutive scans seconds apart, a lost odometry — the pose is
first searched on a grid: the reference scan becomes a likelihood field (how close each cell is to
a reference point), and every candidate pose of the object scan is scored by the likelihood its
points land on. The best candidate is the guess a matcher then refines. Each object point weighs
the arc its beam covers (its range, capped): sparse far structure — often the only thing that
fixes the position along a corridor — counts per metre of surface, not per beam (the concern of
paper 000 §2.3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from .params import ParamError, SearchParams
from .scan import Scan
from .se2 import Pose2, wrap_angle


@dataclass(frozen=True)
class SearchResult:
    pose: Pose2  # best candidate of the fine pass: pose of the object frame in the reference frame
    coarse: Pose2  # best candidate of the coarse pass, around which the fine pass searched
    score: float  # the coarse best's summed weighted likelihood
    # (A,) best coarse score at each candidate rotation (the search's profile)
    best_per_angle: np.ndarray
    angles: np.ndarray  # (A,) candidate rotations of the coarse pass [rad], relative to the guess


# Bounds on what a search may cost whatever its parameters: point placements scored (time), and
# window elements held at once (memory; the defaults stay in one batch, so their sums are
# unchanged).
MAX_WORK = 5e8
WINDOW_ELEMENTS = 4_000_000
# A likelihood field of more cells than this (about 30 bytes a cell while it is built) is built tile
# by tile: memory then follows the scene's surfaces, not the square of the scans' range.
DENSE_CELLS = 12_000_000
TILE = 512  # cells a side
ZERO_SIGMAS = 27.3  # exp(-27.3^2) underflows to 0.0: no reference point farther counts at all


def likelihood_field(
    points: np.ndarray, origin: np.ndarray, shape: tuple[int, int], cell: float, sigma: float
) -> np.ndarray:
    """exp(-d^2 / sigma^2) per cell, d the distance from the cell centre to the nearest point [m];
    points outside the grid are ignored (zero everywhere when none is inside)."""
    return _field_of_cells(np.round((points - origin) / cell).astype(np.int64), shape, cell, sigma)


def _field_of_cells(
    ij: np.ndarray, shape: tuple[int, int], cell: float, sigma: float
) -> np.ndarray:
    """``likelihood_field`` of points already in cells ``ij`` of the grid."""
    ij = ij[np.all((ij >= 0) & (ij < np.array(shape)), axis=1)]
    if len(ij) == 0:
        return np.zeros(shape)
    occupied = np.ones(shape, dtype=bool)
    occupied[ij[:, 0], ij[:, 1]] = False
    return np.exp(-((distance_transform_edt(occupied) * cell / sigma) ** 2))


def correlative_search(
    ref: Scan, obj: Scan, guess: Pose2 = Pose2(), params: SearchParams | None = None
) -> SearchResult:
    """The pose in the window around ``guess`` whose object points best meet the reference scan.

    Two passes, coarse to fine (Olson 2009 searches at two resolutions as well): the coarse grid
    over the whole window, then ``fine_cell`` / ``fine_angle_step`` within 1.5 coarse cells and 2
    coarse angle steps of its best candidate, on a sharper field (``fine_sigma``). The coarse
    optimum is only as good as its grid; the fine pass puts the guess within a few centimetres and
    a fraction of a degree of the likelihood's peak.
    """
    p = params if params is not None else SearchParams()
    ref_pts = ref.points()
    obj_pts = obj.points()
    w = np.minimum(np.hypot(obj_pts[:, 0], obj_pts[:, 1]), p.weight_cap)
    pose, score, best_per_angle, angles = _grid_pass(ref_pts, obj_pts, w, guess, p)
    found = pose
    if p.refine:
        fine = p.replace(
            window_xy=1.5 * p.cell,
            window_theta=2 * p.angle_step,
            cell=p.fine_cell,
            angle_step=p.fine_angle_step,
            sigma=p.fine_sigma,
        )
        found = _grid_pass(ref_pts, obj_pts, w, pose, fine)[0]
    return SearchResult(found, pose, score, best_per_angle, angles)


def _grid_pass(
    ref_pts: np.ndarray, obj_pts: np.ndarray, w: np.ndarray, guess: Pose2, g: SearchParams
) -> tuple[Pose2, float, np.ndarray, np.ndarray]:
    """Best candidate of one grid (window, cell, angle step and sigma of ``g``) around ``guess``,
    its score, the best score per rotation and the rotations.

    For one rotation every translation is scored at once: each point adds the window of the
    likelihood field it can land in. The field covers only where the object points can land (at
    every candidate rotation, any translation of the window), plus 3 sigma for the reference points
    just outside, so a fine field stays small. Where that is still too large to hold (long-range
    scans: 150 m at 2 cm is 2e8 cells), the field is built tile by tile (``_tiled_scores``)."""
    n = int(round(g.window_xy / g.cell))
    k = int(round(g.window_theta / g.angle_step))
    work = (2 * k + 1) * len(obj_pts) * (2 * n + 1) ** 2
    if work > MAX_WORK:
        raise ParamError(
            "window_xy",
            f"a search of +/-{g.window_xy:g} m in {g.cell:g} m cells and +/-"
            f"{np.degrees(g.window_theta):g} deg in {np.degrees(g.angle_step):g} deg steps "
            f"scores {work:.2g} point placements (at most {MAX_WORK:.0e}): narrow the "
            "window or coarsen the grid",
        )
    angles = np.arange(-k, k + 1) * g.angle_step
    moved = [Pose2(guess.x, guess.y, guess.theta + dth).apply(obj_pts) for dth in angles]
    landing = np.concatenate(moved)
    margin = g.window_xy + 3 * g.sigma + 2 * g.cell
    origin = landing.min(axis=0) - margin
    shape = tuple(np.ceil((landing.max(axis=0) + margin - origin) / g.cell).astype(int) + 1)
    # a point at cell u scores the window starting at cell u - n
    starts = [np.round((m - origin) / g.cell).astype(np.int64) - n for m in moved]
    if shape[0] * shape[1] <= DENSE_CELLS:
        field = likelihood_field(ref_pts, origin, shape, g.cell, g.sigma)
        scores = (_window_scores(field, u, w, n) for u in starts)
    else:
        scores = iter(_tiled_scores(ref_pts, origin, shape, starts, w, n, g))
    best_per_angle = np.empty(len(angles))
    best, best_pose = -1.0, guess
    for a, (dth, score) in enumerate(zip(angles, scores)):
        ij = np.unravel_index(int(np.argmax(score)), score.shape)
        best_per_angle[a] = score[ij]
        if score[ij] > best:
            best = float(score[ij])
            best_pose = Pose2(
                float(guess.x + (ij[0] - n) * g.cell),
                float(guess.y + (ij[1] - n) * g.cell),
                float(wrap_angle(guess.theta + dth)),
            )
    return best_pose, best, best_per_angle, angles


def _window_scores(field: np.ndarray, u: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    """Summed weighted field over the (2n+1)^2 windows starting at cells ``u`` of ``field``."""
    # every (2n+1)^2 window of the field, as a view; points scored at once: memory bounded
    windows = np.lib.stride_tricks.sliding_window_view(field, (2 * n + 1, 2 * n + 1))
    chunk = max(1, WINDOW_ELEMENTS // (2 * n + 1) ** 2)
    return sum(
        np.einsum("p,pij->ij", w[k : k + chunk], windows[u[k : k + chunk, 0], u[k : k + chunk, 1]])
        for k in range(0, len(u), chunk)
    )


def _tiled_scores(
    ref_pts: np.ndarray,
    origin: np.ndarray,
    shape: tuple[int, int],
    starts: list[np.ndarray],
    w: np.ndarray,
    n: int,
    g: SearchParams,
) -> list[np.ndarray]:
    """``_window_scores`` of every rotation over a field too large to hold, one tile at a time.

    Exact: exp(-d^2 / sigma^2) is 0.0 in floating point beyond ``ZERO_SIGMAS`` sigma, so a tile's
    field needs only the reference points within that reach of it, and a tile with none adds
    nothing. A tile holds the windows that start in it (its core plus a 2n halo); only the sums'
    order differs from the dense field's."""
    reach = int(np.ceil(ZERO_SIGMAS * g.sigma / g.cell)) + 1
    ref_cells = np.round((ref_pts - origin) / g.cell).astype(np.int64)
    scores = [np.zeros((2 * n + 1, 2 * n + 1)) for _ in starts]
    keys = [u // TILE for u in starts]
    for tile in np.unique(np.concatenate(keys), axis=0):
        lo = tile * TILE  # the tile's core: window starts lo .. lo + TILE - 1
        hi = np.minimum(lo + TILE + 2 * n, shape)  # + the halo its windows reach into
        # the field around it as far as a reference point can count, within the grid
        a0, a1 = np.maximum(lo - reach, 0), np.minimum(hi + reach, shape)
        near = np.all((ref_cells >= a0) & (ref_cells < a1), axis=1)
        if not near.any():
            continue
        around = _field_of_cells(ref_cells[near] - a0, tuple(a1 - a0), g.cell, g.sigma)
        field = around[lo[0] - a0[0] : hi[0] - a0[0], lo[1] - a0[1] : hi[1] - a0[1]]
        for a, u in enumerate(starts):
            mine = np.all(keys[a] == tile, axis=1)
            if mine.any():
                scores[a] += _window_scores(field, u[mine] - lo, w[mine], n)
    return scores
