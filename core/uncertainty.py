"""Covariance and degeneracy of a finished match."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .metric import linearised_jacobians
from .result import Degeneracy, MatchResult, Termination
from .se2 import Pose2

# Length that scales rotation in the degeneracy indicator of the matchers without a metric length
# (ICP, PSM, PMWN): MbICP's default L, so that indicators compare across matchers.
DEGENERACY_LENGTH_M = 3.0


def covariance(A: np.ndarray, error: float, n_pairs: int) -> np.ndarray | None:
    """sigma^2 A^-1 with sigma^2 the residual per degree of freedom (n_pairs pairs, 3 unknowns).

    A is the matcher's final normal matrix; ``error`` the mean squared residual per pair.
    """
    if n_pairs <= 3:
        return None
    try:
        inv = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return None
    sigma2 = error * n_pairs / (2 * n_pairs - 3)  # two scalar residuals per pair
    return sigma2 * inv


def surface_tangents(points: np.ndarray, full_circle: bool, at: np.ndarray) -> np.ndarray:
    """Unit surface direction at the scan points ``at`` (central differences in scan order; one-sided
    at the ends of a partial scan); (1, 0) where neighbours coincide. Only where asked: the final
    pairs' targets are a fraction of the scan."""
    n = len(points)
    after, before = at + 1, at - 1
    if full_circle:
        after %= n
        before %= n
    else:
        np.minimum(after, n - 1, out=after)
        np.maximum(before, 0, out=before)
    t = points[after] - points[before]
    norm = np.hypot(t[:, 0], t[:, 1])
    return np.where(norm[:, None] > 0, t / np.where(norm > 0, norm, 1.0)[:, None], np.array([1.0, 0.0]))


def degeneracy(targets: np.ndarray, tangents: np.ndarray, L: float) -> Degeneracy | None:
    """Point-to-line information of the final pairs, in (x, y, L*theta) (see ``Degeneracy``).

    ``tangents`` are the reference surface directions at the targets; the normal n_i is their
    perpendicular, and each pair constrains n_i^T J_i q only: motion along a wall is free.
    """
    if len(targets) < 3:
        return None
    n = np.column_stack((-tangents[:, 1], tangents[:, 0]))
    J = linearised_jacobians(targets)
    J[:, :, 2] /= L  # coordinates (x, y, L*theta)
    rows = np.einsum("ij,ijk->ik", n, J)  # n_i^T J_i, (N, 3)
    H = rows.T @ rows
    w, V = np.linalg.eigh(H)
    w = np.maximum(w, 0.0)
    cond = float(w[-1] / w[0]) if w[0] > 1e-12 * max(w[-1], 1e-300) else float("inf")
    v = V[:, 0] * (1 if V[np.argmax(np.abs(V[:, 0])), 0] >= 0 else -1)
    return Degeneracy(cond, tuple(float(c) for c in v), tuple(float(c) for c in w), L)


@dataclass(frozen=True, eq=False)
class FinalSystem:
    """What the last successful iteration leaves for the result's covariance and degeneracy."""

    A: np.ndarray  # (3, 3) normal matrix in (x, y, theta)
    error: float  # mean squared residual per kept pair [m^2]
    targets: np.ndarray  # (K, 2) kept targets, reference frame
    ref_index: np.ndarray  # (K,) reference point of each kept target
    n_kept: int
    n_rejected: int


def build_result(name: str, est: Pose2, reason: Termination, iterations: int, last: FinalSystem | None,
                 ref_points: np.ndarray, full_circle: bool, L: float) -> MatchResult:
    """The MatchResult of a finished loop (``ref_points``: the reference scan's points in scan order)."""
    if last is None:
        return MatchResult(name, est, False, reason, iterations, float("nan"), 0, 0, None, None)
    return MatchResult(
        name, est, reason.converged, reason, iterations, last.error, last.n_kept, last.n_rejected,
        covariance(last.A, last.error, last.n_kept),
        degeneracy(last.targets, surface_tangents(ref_points, full_circle, last.ref_index), L))
