"""MbICP's metric distance and least squares; paper 000's MAD rejection; CSM's exact pose solver
(GPC)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mbicp_viz.core import PairStatus
from mbicp_viz.core.gpc import normal_terms, solve
from mbicp_viz.core.metric import (
    mad_threshold,
    metric_distance_sq,
    metric_exact_sq,
    metric_normal_equations,
    solve3,
)
from mbicp_viz.core.rejection import reject

# Paper 000 §2.4.2, Figure 9: 21 correspondence distances.
PAPER_DISTANCES = np.array(
    [
        12.281,
        12.270,
        12.712,
        11.932,
        11.053,
        10.768,
        11.077,
        11.685,
        6.393,
        6.001,
        5.549,
        38.760,
        86.305,
        34.497,
        2.988,
        3.227,
        1.297,
        3.539,
        6.409,
        12.477,
        12.381,
    ]
)


def test_paper_mad_example():
    assert np.median(PAPER_DISTANCES) == pytest.approx(11.07, abs=0.01)
    status, thr = reject(PAPER_DISTANCES, 1e9, 1.0, True, 2.0, 0.0)
    rejected = PAPER_DISTANCES[status == PairStatus.MAD]
    assert sorted(rejected) == [34.497, 38.760, 86.305]
    assert thr == pytest.approx(mad_threshold(PAPER_DISTANCES, 2.0))


def test_mean_plus_two_sigma_rejects_only_the_largest():
    # The paper's contrast: mean + n*sigma is distorted by the outliers themselves.
    thr = PAPER_DISTANCES.mean() + 2 * PAPER_DISTANCES.std()
    assert list(PAPER_DISTANCES[PAPER_DISTANCES > thr]) == [86.305]


def test_mad_floor_never_rejects_close_pairs():
    d = np.array([0.0, 0.0, 0.0, 0.0, 0.05])
    status, thr = reject(d, 1.0, 1.0, True, 2.0, 0.1)
    assert thr == pytest.approx(0.1) and np.all(status == PairStatus.KEPT)


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.floats(0.0, 2.0, allow_nan=False), min_size=1, max_size=40),
    st.floats(0.0, 1.5),
    st.floats(0.5, 3.0),
)
def test_mad_decides_alike_whether_its_threshold_is_shown_or_not(d, floor, k):
    """The matcher's unrecorded run skips MAD's selections where no pair lies above the floor: the
    same decisions, and the threshold it shows when recorded."""
    d = np.array(d)
    shown, thr = reject(d, 1.0, 1.0, True, k, floor)
    unshown, thr_unshown = reject(d, 1.0, 1.0, True, k, floor, False)
    assert np.array_equal(shown, unshown)
    inside = d[d <= 1.0]
    if len(inside) and inside.max() <= floor:
        assert np.isnan(thr_unshown) and np.all(shown[d <= 1.0] == PairStatus.KEPT)
    else:
        assert thr_unshown == thr or (np.isnan(thr) and np.isnan(thr_unshown))


def test_trimming_keeps_the_best_fraction():
    d = np.arange(20, dtype=float)
    status, thr = reject(d, 100.0, 0.75, False, 0.0, 0.0)
    assert np.count_nonzero(status == PairStatus.KEPT) == 15
    assert np.all(status[15:] == PairStatus.TRIMMED) and thr == 15.0


small = st.floats(-0.05, 0.05, allow_nan=False)
far = st.floats(-8.0, 8.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(far, far, small, small, st.floats(0.5, 5.0))
def test_closed_form_matches_brute_force_minimisation(qx, qy, dx, dy, L):
    """The linearised closed form (MbICP eq. 12) against min over (x, y, theta) of the norm."""
    q = np.array([qx, qy])
    p = q + np.array([dx, dy])
    exact = metric_exact_sq(q, p, L)
    approx = metric_distance_sq(p, q, L)
    # The linearisation drops the rotation's second-order term: turning by theta moves q by about
    # |q| theta^2 / 2 along the ray, which changes the squared distance by up to |p - q| |q| theta^2
    # (theta as the closed form picks it, at most |p - q| |q| / (|q|^2 + L^2)).
    d, r = float(np.hypot(dx, dy)), float(np.hypot(qx, qy))
    theta = d * r / (r * r + L * L)
    assert approx == pytest.approx(exact, rel=0.05, abs=1.5 * d * r * theta**2 + 1e-9)
    assert approx <= np.dot(p - q, p - q) + 1e-12  # never above the Euclidean distance


def test_metric_is_euclidean_along_the_ray_and_shrinks_across_it():
    q = np.array([4.0, 0.0])
    L = 3.0
    assert metric_distance_sq(q + [0.1, 0.0], q, L) == pytest.approx(0.01)
    # across the ray: scaled by L^2 / (|q|^2 + L^2) (the ellipse of paper 000 Fig. 3)
    assert metric_distance_sq(q + [0.0, 0.1], q, L) == pytest.approx(0.01 * 9 / 25, rel=1e-2)


@settings(max_examples=40, deadline=None)
@given(small, small, st.floats(-0.01, 0.01))
def test_metric_least_squares_recovers_a_small_motion(x, y, t):
    rng = np.random.default_rng(0)
    p = rng.uniform(-5, 5, (50, 2))
    c, s = np.cos(t), np.sin(t)
    target = p @ np.array([[c, -s], [s, c]]).T + [x, y]
    A, b = metric_normal_equations(p, target, 3.0)
    q, ok = solve3(A, b)
    assert ok
    np.testing.assert_allclose(q, np.linalg.solve(A, b), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(q, [x, y, t], atol=5e-4)


def rotation(t):
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


@settings(max_examples=40, deadline=None)
@given(st.floats(-3, 3), st.floats(-3, 3), st.floats(-np.pi + 0.01, np.pi - 0.01))
def test_gpc_point_to_point_recovers_any_motion(x, y, t):
    rng = np.random.default_rng(1)
    p = rng.uniform(-5, 5, (30, 2))
    q = p @ rotation(t).T + [x, y]
    tx, ty, th, ok = solve(*normal_terms(p, q, np.tile(np.eye(2), (30, 1, 1))))
    assert ok
    np.testing.assert_allclose(
        [tx, ty, (th - t + np.pi) % (2 * np.pi) - np.pi], [x, y, 0.0], atol=1e-8
    )


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000))
def test_gpc_point_to_line_is_the_global_minimum(seed):
    """For any rotation the best translation is closed-form; the cost over the rotation is then
    one-dimensional: a fine grid finds its global minimum, which GPC's pose must match."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(-5, 5, (25, 2))
    q = (
        p @ rotation(rng.uniform(-np.pi, np.pi)).T
        + rng.uniform(-2, 2, 2)
        + rng.normal(0, 0.05, (25, 2))
    )
    n = rng.normal(size=(25, 2))
    n /= np.linalg.norm(n, axis=1)[:, None]
    C = n[:, :, None] * n[:, None, :]
    tx, ty, th, ok = solve(*normal_terms(p, q, C))

    def cost(theta):
        r = p @ rotation(theta).T - q
        t_best = np.linalg.solve(C.sum(axis=0), -np.einsum("kij,kj->i", C, r))
        e = r + t_best
        return np.einsum("ki,kij,kj->", e, C, e)

    grid = np.linspace(-np.pi, np.pi, 20001)
    assert ok and cost(th) <= min(cost(g) for g in grid) + 1e-9
