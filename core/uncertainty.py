"""Covariance and degeneracy of a finished match."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .metric import adjugate3
from .result import Degeneracy, MatchResult, Termination
from .se2 import Pose2
from .tiers import kernel, run

# Length that scales rotation in the degeneracy indicator of the matchers without a metric length
# (ICP, PSM, PMWN): MbICP's default L, so that indicators compare across matchers.
DEGENERACY_LENGTH_M = 3.0


@kernel
def _covariance(A: np.ndarray, error: float, n_pairs: int):
    """sigma^2 A^-1 with sigma^2 the residual per degree of freedom (n_pairs pairs, 3 unknowns),
    and whether it exists (A invertible). A is the matcher's final normal matrix; ``error`` the
    mean squared residual per pair."""
    adj, det = adjugate3(A)
    if n_pairs <= 3 or det == 0.0 or not np.isfinite(det):
        return np.zeros((3, 3)), False
    sigma2 = error * n_pairs / (2 * n_pairs - 3)  # two scalar residuals per pair
    return sigma2 * (adj / det), True


def surface_tangents(points: np.ndarray, full_circle: bool, at: np.ndarray) -> np.ndarray:
    """Unit surface direction at the scan points ``at`` (central differences in scan order;
    one-sided at the ends of a partial scan); (1, 0) where neighbours coincide. Only where asked:
    the final pairs' targets are a fraction of the scan."""
    return run(_tangents, points, bool(full_circle), np.asarray(at, dtype=np.int64))


@kernel
def _tangents(points, full_circle, at):
    n = len(points)
    out = np.empty((len(at), 2))
    for k in range(len(at)):
        after, before = at[k] + 1, at[k] - 1
        if full_circle:
            after, before = after % n, before % n
        else:
            after, before = min(after, n - 1), max(before, 0)
        tx, ty = points[after, 0] - points[before, 0], points[after, 1] - points[before, 1]
        norm = np.hypot(tx, ty)
        out[k, 0], out[k, 1] = (tx / norm, ty / norm) if norm > 0 else (1.0, 0.0)
    return out


@kernel
def surface_information(targets: np.ndarray, tangents: np.ndarray, L: float) -> np.ndarray:
    """H = sum of r_i r_i^T with r_i = n_i^T J_i in (x, y, L theta): what the surfaces under the
    targets fix of the motion (n_i the normal, perpendicular to the tangent; J_i = [[1, 0, -y_i],
    [0, 1, x_i]] the Jacobian of the target moved by a small (x, y, theta)). A pair constrains its
    surface's normal only: motion along a wall is free."""
    H = np.zeros((3, 3))
    for k in range(len(targets)):
        nx, ny = -tangents[k, 1], tangents[k, 0]
        row = (nx, ny, (nx * -targets[k, 1] + ny * targets[k, 0]) / L)
        for i in range(3):
            for j in range(3):
                H[i, j] += row[i] * row[j]
    return H


def degeneracy(targets: np.ndarray, tangents: np.ndarray, L: float) -> Degeneracy | None:
    """Point-to-line information of the final pairs, in (x, y, L*theta) (see ``Degeneracy``):
    its condition number, eigenvalues and weakest direction."""
    if len(targets) < 3:
        return None
    return _degeneracy(*run(_eigen, run(surface_information, targets, tangents, float(L))), L)


@kernel
def _eigen(H: np.ndarray):
    """The condition number, the ascending eigenvalues (clipped at 0) and the weakest direction of
    the symmetric H, that direction's largest component positive (a sign for the record)."""
    w, V = np.linalg.eigh(H)
    w = np.maximum(w, 0.0)
    cond = w[2] / w[0] if w[0] > 1e-12 * max(w[2], 1e-300) else np.inf
    v = V[:, 0].copy()
    big = 0
    for i in range(1, 3):
        if abs(v[i]) > abs(v[big]):
            big = i
    return cond, w, v if v[big] >= 0 else -v


def _degeneracy(cond: float, w: np.ndarray, v: np.ndarray, L: float) -> Degeneracy:
    return Degeneracy(float(cond), tuple(v.tolist()), tuple(w.tolist()), L)


@kernel
def _final_numbers(A, error, n_kept, targets, ref_points, full_circle, ref_index, L):
    """``build_result``'s numbers in one compiled call (a match's final system is small: numpy's
    per-call costs were most of them): covariance, whether it exists, and the degeneracy's
    condition number, eigenvalues and weakest direction (condition NaN: fewer than 3 pairs)."""
    cov, has_cov = _covariance(A, error, n_kept)
    if len(targets) < 3:
        return cov, has_cov, np.nan, np.zeros(3), np.zeros(3)
    H = surface_information(targets, _tangents(ref_points, full_circle, ref_index), L)
    cond, w, v = _eigen(H)
    return cov, has_cov, cond, w, v


@dataclass(frozen=True, eq=False)
class FinalSystem:
    """What the last successful iteration leaves for the result's covariance and degeneracy."""

    A: np.ndarray  # (3, 3) normal matrix in (x, y, theta)
    error: float  # mean squared residual per kept pair [m^2]
    targets: np.ndarray  # (K, 2) kept targets, reference frame
    ref_index: np.ndarray  # (K,) reference point of each kept target
    n_kept: int
    n_rejected: int


def build_result(
    name: str,
    est: Pose2,
    reason: Termination,
    iterations: int,
    last: FinalSystem | None,
    ref_points: np.ndarray,
    full_circle: bool,
    L: float,
) -> MatchResult:
    """The MatchResult of a finished loop (``ref_points``: the reference scan's points in scan
    order)."""
    if last is None:
        return MatchResult(name, est, False, reason, iterations, float("nan"), 0, 0, None, None)
    cov, has_cov, cond, w, v = run(
        _final_numbers,
        last.A,
        float(last.error),
        int(last.n_kept),
        last.targets,
        ref_points,
        bool(full_circle),
        np.asarray(last.ref_index, dtype=np.int64),
        float(L),
    )
    return MatchResult(
        name,
        est,
        reason.converged,
        reason,
        iterations,
        last.error,
        last.n_kept,
        last.n_rejected,
        cov if has_cov else None,
        None if np.isnan(cond) else _degeneracy(cond, w, v, L),
    )
