"""MbICP's metric distance and metric least squares, and the robust statistics of paper 000.

Norm on SE(2) (MbICP, T-RO 2006, eq. 1; paper 000 eq. 4): ||q|| = sqrt(x^2 + y^2 + L^2 theta^2).
The metric distance between points is the norm of the smallest motion taking one onto the
other (paper 000 eq. 3); linearising the rotation gives the closed form used here.
"""

from __future__ import annotations

import numpy as np
from numba import vectorize
from scipy.linalg.lapack import dgesv


def metric_distance_sq(p: np.ndarray, q: np.ndarray, L: float) -> np.ndarray:
    """Squared metric distance of the motion taking reference point ``q`` onto point ``p``.

    d^2 = |p - q|^2 - (p x q)^2 / (|q|^2 + L^2)   (MbICP eq. 12 with delta = p - q; note that
    delta x q = p x q). The original C code scores candidates this way, with the reference point
    in the denominator. Broadcasts over leading axes.
    """
    px, py, qx, qy = p[..., 0], p[..., 1], q[..., 0], q[..., 1]
    return metric_sq(px, py, qx, qy, qx * qx + qy * qy + L * L)


@vectorize(cache=True)
def metric_sq(px, py, qx, qy, k):
    """``metric_distance_sq`` by component, k = |q|^2 + L^2: a ufunc (it broadcasts) that the
    compiled correspondence search calls too, so both round alike. Compiled for the types of its
    first call, not at import (a matcher that never calls it from numpy pays nothing)."""
    dx, dy = px - qx, py - qy
    c = px * qy - py * qx
    return dx * dx + dy * dy - c * c / k


def metric_exact_sq(p1: np.ndarray, p2: np.ndarray, L: float, max_theta: float = np.pi) -> float:
    """Brute-force min over motions q with q(p1) = p2 of x^2 + y^2 + L^2 theta^2 (tests, teaching).

    For a rotation theta the translation is forced to p2 - R(theta) p1, so one scalar search
    over theta suffices; a dense grid followed by a bounded refinement avoids local minima.
    """
    from scipy.optimize import minimize_scalar

    def cost(t):
        c, s = np.cos(t), np.sin(t)
        x = p2[0] - (c * p1[0] - s * p1[1])
        y = p2[1] - (s * p1[0] + c * p1[1])
        return x * x + y * y + L * L * t * t

    grid = np.linspace(-max_theta, max_theta, 2001)
    i = int(np.argmin([cost(t) for t in grid]))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    return float(minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12}).fun)


def _median(x: np.ndarray) -> float:
    """Median by one sort: np.median's dispatch costs more than the sort on scan-sized arrays."""
    s = np.sort(x)
    n = len(s)
    return 0.5 * float(s[(n - 1) // 2] + s[n // 2])


def mad_threshold(distances: np.ndarray, k: float = 2.0) -> float:
    """Rejection threshold d_rej = median + k * MAD (paper 000 eq. 5, §2.4.2)."""
    med = _median(distances)
    return med + k * _median(np.abs(distances - med))


def linearised_jacobians(points: np.ndarray) -> np.ndarray:
    """(N, 2, 3) Jacobians of q(p) ~ p + (x - theta p_y, y + theta p_x) at q = 0."""
    n = len(points)
    J = np.zeros((n, 2, 3))
    J[:, 0, 0] = 1.0
    J[:, 1, 1] = 1.0
    J[:, 0, 2] = -points[:, 1]
    J[:, 1, 2] = points[:, 0]
    return J


def metric_normal_equations(p: np.ndarray, c: np.ndarray, L: float) -> tuple[np.ndarray, np.ndarray]:
    """A, b of MbICP's metric least squares: A q = b minimises sum (c_i - q(p_i))^T M(c_i) (...).

    Linearised residual e_i = (c_i - p_i) - J_i q with J_i = [[1, 0, -p_iy], [0, 1, p_ix]] and
    M(c) = I - r r^T / (|c|^2 + L^2), r = (c_y, -c_x): the original builds M from the associated
    reference point (MbICP §III-C). Written out by hand: this is the hot loop.
    """
    px, py = p[:, 0], p[:, 1]
    cx, cy = c[:, 0], c[:, 1]
    dx, dy = cx - px, cy - py
    k = cx * cx + cy * cy + L * L
    # The nine per-pair terms are written into the rows of one array that one reduction sums.
    X = np.empty((9, len(p)))
    m11, m12, m22, g1, g2, gt, b1, b2, bt = X  # M = [[m11, m12], [m12, m22]]; (g1, g2): theta column of J^T M
    np.subtract(1.0, cy * cy / k, out=m11)
    np.divide(cx * cy, k, out=m12)
    np.subtract(1.0, cx * cx / k, out=m22)
    np.subtract(px * m12, py * m11, out=g1)
    np.subtract(px * m22, py * m12, out=g2)
    np.subtract(px * g2, py * g1, out=gt)
    np.add(m11 * dx, m12 * dy, out=b1)
    np.add(m12 * dx, m22 * dy, out=b2)
    np.add(g1 * dx, g2 * dy, out=bt)
    s = X.sum(axis=1)
    A = np.array([[s[0], s[1], s[3]], [s[1], s[2], s[4]], [s[3], s[4], s[5]]])
    return A, s[6:]


def solve3(A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """x with A x = b for the 3x3 normal equations, None when A is singular or x not finite.

    LAPACK's dgesv, as np.linalg.solve calls it, without the generic wrapper (a fifth of the
    cost: this runs once per iteration).
    """
    _, _, x, info = dgesv(A, b)
    return x if info == 0 and np.isfinite(x).all() else None


def mean_sq_residual(moved: np.ndarray, targets: np.ndarray) -> float:
    """Mean squared Euclidean distance between paired rows [m^2]."""
    d = moved - targets
    return float(np.einsum("ij,ij->", d, d)) / len(d)


def svd_fit(src: np.ndarray, dst: np.ndarray) -> tuple[float, float, float]:
    """Closed-form rigid motion (x, y, theta) minimising sum |dst - (R src + t)|^2 (Arun et al. 1987)."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    H = (src - ms).T @ (dst - md)
    U, _, Vt = np.linalg.svd(H)
    R = Vt.T @ U.T
    if np.linalg.det(R) < 0:  # reflection: flip the weakest axis
        Vt[1] *= -1.0
        R = Vt.T @ U.T
    t = md - R @ ms
    return float(t[0]), float(t[1]), float(np.arctan2(R[1, 0], R[0, 0]))
