"""The exact minimiser of a sum of weighted point correspondences over SE(2) (Censi, ICRA 2008,
"An ICP variant using a point-to-line metric", §IV and its appendix: GPC).

min over (t, theta) of sum_k (R(theta) p_k + t - q_k)^T C_k (R(theta) p_k + t - q_k), with C_k = I
(point to point) or n_k n_k^T (point to line). In x = (t_x, t_y, cos theta, sin theta) the cost is
the quadratic x^T A x - 2 b^T x, minimised on the constraint x_3^2 + x_4^2 = 1: with a Lagrange
multiplier l, (A + l W) x = b, W = diag(0, 0, 1, 1). Eliminating t leaves (S + l I) r = h for the
rotation part r, and |r| = 1 is a quartic in l whose largest real root is the global minimum (the
one for which S + l I is positive definite). Above -lambda_min(S), |(S + l I)^-1 h| falls from
infinity to 0, so that root is found by bisection (numba compiles a polynomial solver's
eigenvalue routine for seconds; the bisection is exact to the last bit all the same).
"""

from __future__ import annotations

import numpy as np

from .tiers import kernel


@kernel
def normal_terms(p, q, C):
    """A (4, 4) and b (4,) of the cost for correspondences p, q (K, 2) with weights C (K, 2, 2)."""
    A = np.zeros((4, 4))
    b = np.zeros(4)
    for k in range(len(p)):
        px, py, qx, qy = p[k, 0], p[k, 1], q[k, 0], q[k, 1]
        c00, c01, c11 = C[k, 0, 0], 0.5 * (C[k, 0, 1] + C[k, 1, 0]), C[k, 1, 1]
        # M_k = [[1, 0, px, -py], [0, 1, py, px]] maps x to R p + t; accumulate M^T C M and M^T C q
        m = ((1.0, 0.0), (0.0, 1.0), (px, py), (-py, px))  # the columns of M_k
        for i in range(4):
            ci0 = c00 * m[i][0] + c01 * m[i][1]  # (C M_k)[:, i]
            ci1 = c01 * m[i][0] + c11 * m[i][1]
            b[i] += ci0 * qx + ci1 * qy
            for j in range(4):
                A[j, i] += m[j][0] * ci0 + m[j][1] * ci1
    return A, b


@kernel
def _norm2(s00, s01, s11, h0, h1, lam):
    """|(S + lam I)^-1 h|^2 for the symmetric 2x2 S."""
    k00, k11 = s00 + lam, s11 + lam
    det = k00 * k11 - s01 * s01
    r0, r1 = (k11 * h0 - s01 * h1) / det, (-s01 * h0 + k00 * h1) / det
    return r0 * r0 + r1 * r1


@kernel
def _largest_root(s00, s01, s11, h0, h1):
    """The multiplier at which |(S + lam I)^-1 h| = 1, lam > -lambda_min(S): bisection between
    -lambda_min (norm infinite) and -lambda_min + |h| (norm at most 1)."""
    lam_min = 0.5 * (s00 + s11) - np.sqrt(0.25 * (s00 - s11) ** 2 + s01 * s01)
    lo, hi = -lam_min, -lam_min + np.hypot(h0, h1) + 1e-300
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if _norm2(s00, s01, s11, h0, h1, mid) > 1.0:
            lo = mid
        else:
            hi = mid
    return hi


@kernel
def solve(A, b):
    """(t_x, t_y, theta) minimising x^T A x - 2 b^T x on the circle; ok False when the
    translation is unconstrained (A's translation block singular) or nothing fixes the rotation (h
    = 0)."""
    a00, a01, a11 = A[0, 0], A[0, 1], A[1, 1]
    det_a = a00 * a11 - a01 * a01
    if not abs(det_a) > 1e-12 * max(1.0, abs(a00) + abs(a11)) ** 2:
        return 0.0, 0.0, 0.0, False
    i00, i01, i11 = a11 / det_a, -a01 / det_a, a00 / det_a  # A_t^-1 (symmetric)
    b00, b01, b10, b11 = A[0, 2], A[0, 3], A[1, 2], A[1, 3]  # B: translation rows, rotation columns
    # G = A_t^-1 B, S = D - B^T G, h = b_r - G^T b_t
    g00, g01 = i00 * b00 + i01 * b10, i00 * b01 + i01 * b11
    g10, g11 = i01 * b00 + i11 * b10, i01 * b01 + i11 * b11
    s00 = A[2, 2] - (b00 * g00 + b10 * g10)
    s11 = A[3, 3] - (b01 * g01 + b11 * g11)
    s01 = 0.5 * (A[2, 3] + A[3, 2]) - 0.5 * (b00 * g01 + b10 * g11 + b01 * g00 + b11 * g10)
    h0 = b[2] - (g00 * b[0] + g10 * b[1])
    h1 = b[3] - (g01 * b[0] + g11 * b[1])
    lam = _largest_root(s00, s01, s11, h0, h1)
    k00, k11 = s00 + lam, s11 + lam
    det_k = k00 * k11 - s01 * s01
    if not det_k > 0.0:
        return 0.0, 0.0, 0.0, False
    r0, r1 = (k11 * h0 - s01 * h1) / det_k, (-s01 * h0 + k00 * h1) / det_k
    c0, c1 = b[0] - (b00 * r0 + b01 * r1), b[1] - (b10 * r0 + b11 * r1)
    return i00 * c0 + i01 * c1, i01 * c0 + i11 * c1, np.arctan2(r1, r0), True
