"""MbICP's metric distance and metric least squares, and the robust statistics of paper 000.

Norm on SE(2) (MbICP, T-RO 2006, eq. 1; paper 000 eq. 4): ||q|| = sqrt(x^2 + y^2 + L^2 theta^2).
The metric distance between points is the norm of the smallest motion taking one onto the
other (paper 000 eq. 3); linearising the rotation gives the closed form used here.
"""

from __future__ import annotations

import numpy as np

from .tiers import elementwise, kernel, run


def metric_distance_sq(p: np.ndarray, q: np.ndarray, L: float) -> np.ndarray:
    """Squared metric distance of the motion taking reference point ``q`` onto point ``p``.

    d^2 = |p - q|^2 - (p x q)^2 / (|q|^2 + L^2)   (MbICP eq. 12 with delta = p - q; note that
    delta x q = p x q). The original C code scores candidates this way, with the reference point
    in the denominator. Broadcasts over leading axes.
    """
    px, py, qx, qy = p[..., 0], p[..., 1], q[..., 0], q[..., 1]
    return run(metric_sq, px, py, qx, qy, qx * qx + qy * qy + L * L)


@elementwise
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
    return float(
        minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12}).fun
    )


@kernel
def _select(b: np.ndarray, k: int) -> float:
    """Hoare's quickselect in place: afterwards b[k] = np.sort(b)[k], nothing after it is smaller
    and nothing before it larger."""
    lo, hi = 0, len(b) - 1
    while lo < hi:
        pivot = b[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while b[i] < pivot:
                i += 1
            while b[j] > pivot:
                j -= 1
            if i <= j:
                b[i], b[j] = b[j], b[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return b[k]


@kernel
def kth_smallest(a: np.ndarray, k: int) -> float:
    """``np.sort(a)[k]`` by selection on a copy: linear time, and a loop numba compiles in a tenth
    of a second where its sort, median and argsort take one each."""
    return _select(a.copy(), k)


@kernel
def median(a: np.ndarray) -> float:
    """``np.median(a)``: the middle element, or the two middle ones halved; one selection finds
    the lower, the smallest of what lies after it is the upper."""
    n = len(a)
    b = a.copy()
    k = (n - 1) // 2
    low = _select(b, k)
    if n % 2 == 1:
        return low
    high = b[k + 1]
    for i in range(k + 2, n):
        high = min(high, b[i])
    return 0.5 * (low + high)


@kernel
def mad_threshold(distances: np.ndarray, k: float = 2.0) -> float:
    """Rejection threshold d_rej = median + k * MAD (paper 000 eq. 5, §2.4.2)."""
    med = median(distances)
    return med + k * median(np.abs(distances - med))


@kernel
def metric_normal_equations(
    p: np.ndarray, c: np.ndarray, L: float
) -> tuple[np.ndarray, np.ndarray]:
    """A, b of MbICP's metric least squares: A q = b minimises sum (c_i - q(p_i))^T M(c_i) (...).

    Linearised residual e_i = (c_i - p_i) - J_i q with J_i = [[1, 0, -p_iy], [0, 1, p_ix]] and
    M(c) = I - r r^T / (|c|^2 + L^2), r = (c_y, -c_x): the original builds M from the associated
    reference point (MbICP §III-C).
    """
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for i in range(len(p)):
        px, py, cx, cy = p[i, 0], p[i, 1], c[i, 0], c[i, 1]
        dx, dy = cx - px, cy - py
        k = cx * cx + cy * cy + L * L
        m11, m12, m22 = 1.0 - cy * cy / k, cx * cy / k, 1.0 - cx * cx / k
        g1, g2 = px * m12 - py * m11, px * m22 - py * m12  # the theta column of J^T M
        A[0, 0] += m11
        A[0, 1] += m12
        A[1, 1] += m22
        A[0, 2] += g1
        A[1, 2] += g2
        A[2, 2] += px * g2 - py * g1
        b[0] += m11 * dx + m12 * dy
        b[1] += m12 * dx + m22 * dy
        b[2] += g1 * dx + g2 * dy
    A[1, 0], A[2, 0], A[2, 1] = A[0, 1], A[0, 2], A[1, 2]
    return A, b


@kernel
def adjugate3(A: np.ndarray):
    """The adjugate of the 3x3 A and its determinant, A^-1 = adj / det: written out, so that the
    compiled and the interpreted kernels compute the same numbers (LAPACK's inverse is not
    numpy's), and a symmetric A gets an exactly symmetric inverse."""
    adj = np.empty((3, 3))
    adj[0, 0] = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    adj[1, 0] = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    adj[2, 0] = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    adj[0, 1] = A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]
    adj[0, 2] = A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]
    adj[1, 1] = A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]
    adj[1, 2] = A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]
    adj[2, 1] = A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]
    adj[2, 2] = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    return adj, A[0, 0] * adj[0, 0] + A[0, 1] * adj[1, 0] + A[0, 2] * adj[2, 0]


@kernel
def solve3(A: np.ndarray, b: np.ndarray):
    """x with A x = b for the 3x3 normal equations (Cramer's rule, as small systems are solved),
    and whether A was invertible and x finite."""
    adj, det = adjugate3(A)
    x = np.zeros(3)
    scale = max(abs(A[0, 0]), abs(A[1, 1]), abs(A[2, 2]), 1e-300)
    if not abs(det) > 1e-14 * scale**3:
        return x, False
    for i in range(3):
        x[i] = (adj[i, 0] * b[0] + adj[i, 1] * b[1] + adj[i, 2] * b[2]) / det
    return x, bool(np.isfinite(x).all())


@kernel
def weakest_direction(A: np.ndarray, L: float):
    """The condition number of the normal matrix A (in x, y, theta) in the coordinates
    (x, y, L theta), where translation and rotation share a unit, and its weakest direction
    there (unit vector; eigenvalues of the symmetric 3x3 in closed form, Smith 1961)."""
    d = np.array([1.0, 1.0, 1.0 / L])
    M = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            M[i, j] = A[i, j] * d[i] * d[j]
    q = (M[0, 0] + M[1, 1] + M[2, 2]) / 3.0
    p1 = M[0, 1] ** 2 + M[0, 2] ** 2 + M[1, 2] ** 2
    p2 = (M[0, 0] - q) ** 2 + (M[1, 1] - q) ** 2 + (M[2, 2] - q) ** 2 + 2.0 * p1
    p = np.sqrt(p2 / 6.0)
    if p == 0.0:  # a multiple of the identity: no direction is weaker
        return 1.0, np.array([1.0, 0.0, 0.0])
    B = (M - q * np.eye(3)) / p
    r = 0.5 * (
        B[0, 0] * (B[1, 1] * B[2, 2] - B[1, 2] * B[2, 1])
        - B[0, 1] * (B[1, 0] * B[2, 2] - B[1, 2] * B[2, 0])
        + B[0, 2] * (B[1, 0] * B[2, 1] - B[1, 1] * B[2, 0])
    )
    phi = np.arccos(min(max(r, -1.0), 1.0)) / 3.0
    largest = q + 2.0 * p * np.cos(phi)
    smallest = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    # the eigenvector of the smallest: the longest cross product of two rows of M - smallest I
    N = M - smallest * np.eye(3)
    best, v = -1.0, np.zeros(3)
    for a, b in ((0, 1), (0, 2), (1, 2)):
        # written out: numba's np.cross and 1-D matmul cost seconds of compilation for three
        # products
        c = np.array(
            [
                N[a, 1] * N[b, 2] - N[a, 2] * N[b, 1],
                N[a, 2] * N[b, 0] - N[a, 0] * N[b, 2],
                N[a, 0] * N[b, 1] - N[a, 1] * N[b, 0],
            ]
        )
        n = np.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
        if n > best:
            best, v = n, c / n if n > 0.0 else c
    cond = largest / smallest if smallest > 1e-12 * largest else np.inf
    return cond, v
