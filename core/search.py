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

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from .params import Params, param
from .scan import Scan
from .se2 import Pose2, wrap_angle


@dataclass(frozen=True)
class SearchParams(Params):
    """The window and grid of the correlative search (around the given guess)."""

    window_xy: float = param(1.5, unit="m", lo=0.0, hi=20.0, help="candidates within +/- this in x and in y")
    window_theta: float = param(math.radians(40.0), unit="rad", lo=0.0, hi=math.pi,
                                help="candidates within +/- this in rotation")
    cell: float = param(0.1, unit="m", lo=0.01, hi=1.0, help="grid step in x and y (and of the likelihood field)")
    angle_step: float = param(math.radians(1.0), unit="rad", lo=math.radians(0.05), hi=math.radians(10.0),
                              help="grid step in rotation")
    # 1.5 cells: at sigma = one cell the field is nearly binary at its own resolution and a point's
    # score jumps as it crosses a cell. Measured on Intel's 909 consecutive pairs (docs/results.md):
    # the search alone within 0.1 m and 3 deg 839 -> 848, improved MbICP refining it 879 -> 885.
    sigma: float = param(0.15, unit="m", lo=0.005, hi=2.0,
                         help="likelihood exp(-d^2 / sigma^2) of a point d metres from the reference scan")
    weight_cap: float = param(8.0, unit="m", lo=0.1, hi=1000.0,
                              help="a point weighs its range, up to this (the arc its beam covers)")


@dataclass(frozen=True)
class SearchResult:
    pose: Pose2  # best candidate: pose of the object frame in the reference frame
    score: float  # its summed weighted likelihood
    best_per_angle: np.ndarray  # (A,) best score at each candidate rotation (the search's profile)
    angles: np.ndarray  # (A,) candidate rotations [rad], relative to the guess


def likelihood_field(points: np.ndarray, origin: np.ndarray, shape: tuple[int, int], cell: float,
                     sigma: float) -> np.ndarray:
    """exp(-d^2 / sigma^2) per cell, d the distance from the cell centre to the nearest point [m]."""
    occupied = np.ones(shape, dtype=bool)
    ij = np.round((points - origin) / cell).astype(np.int64)
    occupied[ij[:, 0], ij[:, 1]] = False
    return np.exp(-((distance_transform_edt(occupied) * cell / sigma) ** 2))


def correlative_search(ref: Scan, obj: Scan, guess: Pose2 = Pose2(), params: SearchParams | None = None
                       ) -> SearchResult:
    """The pose in the window around ``guess`` whose object points best meet the reference scan.

    Candidates: rotations guess.theta + k angle_step and translations guess + (i, j) cell, all
    within the window. For one rotation every translation is scored at once: each point adds the
    window of the likelihood field it can land in.
    """
    p = params if params is not None else SearchParams()
    R = ref.points()
    O = obj.points()
    w = np.minimum(np.hypot(O[:, 0], O[:, 1]), p.weight_cap)
    n = int(round(p.window_xy / p.cell))
    reach = float(np.hypot(O[:, 0], O[:, 1]).max()) + math.hypot(guess.x, guess.y) + p.window_xy + 3 * p.cell
    origin = np.minimum(R.min(axis=0), -reach)
    shape = tuple(np.ceil((np.maximum(R.max(axis=0), reach) - origin) / p.cell).astype(int) + 1)
    field = likelihood_field(R, origin, shape, p.cell, p.sigma)
    k = int(round(p.window_theta / p.angle_step))
    angles = np.arange(-k, k + 1) * p.angle_step
    best_per_angle = np.empty(len(angles))
    best, best_pose = -1.0, guess
    # every (2n+1)^2 window of the field, as a view: a point at cell u scores window u - n
    windows = np.lib.stride_tricks.sliding_window_view(field, (2 * n + 1, 2 * n + 1))
    for a, dth in enumerate(angles):
        theta = guess.theta + dth
        moved = Pose2(guess.x, guess.y, theta).apply(O)
        u = np.round((moved - origin) / p.cell).astype(np.int64) - n
        score = np.einsum("p,pij->ij", w, windows[u[:, 0], u[:, 1]])
        ij = np.unravel_index(int(np.argmax(score)), score.shape)
        best_per_angle[a] = score[ij]
        if score[ij] > best:
            best = float(score[ij])
            best_pose = Pose2(float(guess.x + (ij[0] - n) * p.cell), float(guess.y + (ij[1] - n) * p.cell),
                              float(wrap_angle(theta)))
    return SearchResult(best_pose, best, best_per_angle, angles)
