"""MbICP's correspondence search and the rejection floor schedule, on real scans."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mbicp_viz.core import ImprovedParams, Pose2, match, pose_error
from mbicp_viz.core.correspondence import (
    ReferenceIndex,
    bearing_bins,
    candidates,
    first_at_least,
    nearest,
    turn_mod,
)
from mbicp_viz.core.events import PairKind
from mbicp_viz.core.mbicp import rejection_floor
from mbicp_viz.core.metric import metric_distance_sq
from mbicp_viz.core.tiers import run
from mbicp_viz.evaluation.overlap import case_pair, make_cases
from mbicp_viz.readers import read_log

from .conftest import DATA


def polar(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.arctan2(points[:, 1], points[:, 0]), np.hypot(points[:, 0], points[:, 1])


def brute_force_nearest(ref: ReferenceIndex, moved: np.ndarray, Bw: float, L: float) -> np.ndarray:
    """Smallest squared metric distance over every reference point within +/-Bw of each point's
    bearing."""
    alpha = np.arctan2(moved[:, 1], moved[:, 0])
    gap = np.abs((ref.bearings[None, :] - alpha[:, None] + np.pi) % (2 * np.pi) - np.pi)
    d2 = metric_distance_sq(moved[:, None, :], ref.points[None, :, :], L)
    return np.where(gap <= Bw, d2, np.inf).min(axis=1)


@settings(max_examples=200, deadline=None)
@given(
    steps=st.lists(
        st.one_of(st.floats(1e-9, 1e-6), st.floats(1e-3, 0.1), st.floats(0.1, 3.0)),
        min_size=0,
        max_size=60,
    ),
    start=st.floats(-10.0, 10.0),
    at=st.lists(st.integers(0, 59), max_size=8),
    queries=st.lists(st.floats(-20.0, 20.0), max_size=20),
)
def test_the_bearing_lookup_finds_what_a_bisection_finds(steps, start, at, queries):
    """``first_at_least`` through its bins equals ``np.searchsorted`` on bearings spread evenly,
    bunched nanoradians apart (a damaged scan) or with wide gaps, for queries outside them, on
    them exactly, between them, and NaN."""
    b = np.unique(start + np.cumsum([0.0, *steps]))  # strictly increasing, as a scan's are
    asked = [*queries, *(b[i % len(b)] for i in at), math.nan]
    bins = run(bearing_bins, b)
    for a in asked:
        for strict in (False, True):
            expected = 0 if math.isnan(a) else np.searchsorted(b, a, "right" if strict else "left")
            assert first_at_least(b, bins, a, strict) == expected, (a, strict)


@settings(max_examples=300, deadline=None)
@given(
    m=st.one_of(st.just(2 * math.pi), st.floats(1e-6, 1e6)),
    fraction=st.one_of(
        st.floats(-3.0, 3.0), st.sampled_from([-2.0, -1.0, -0.0, 0.0, 1.0, 2.0, 3.0])
    ),
    nudge=st.sampled_from([-1, 0, 1]),
    special=st.sampled_from([None, math.nan, math.inf, -math.inf, 5e-324, -5e-324]),
)
def test_the_turns_modulo_is_pythons(m, fraction, nudge, special):
    """``turn_mod`` gives the very float Python's ``%`` gives (its sign too), within its fast
    range (-m, 2m), at its edges and an ulp either side, and outside it."""
    x = special if special is not None else fraction * m
    if special is None and nudge:
        x = math.nextafter(x, math.copysign(math.inf, nudge))
    got, expected = turn_mod(x, m), x % m
    if math.isnan(expected):
        assert math.isnan(got)
    else:
        assert got == expected and math.copysign(1.0, got) == math.copysign(1.0, expected), x


@pytest.fixture(scope="module")
def scans():
    return {
        "intel": read_log(
            DATA.parent.parent / "mbicp_viz" / "examples" / "intel-excerpt.log.gz"
        ).scans[:30],
        "laserazos": read_log(DATA / "laserazosSM3-40.log").scans[:30],
        "stallo2 (360 deg)": read_log(DATA / "stallo2.jsonl").scans,
    }


@settings(max_examples=60, deadline=None)
@given(
    which=st.sampled_from(["intel", "laserazos", "stallo2 (360 deg)"]),
    k=st.integers(0, 29),
    x=st.floats(-0.5, 0.5),
    y=st.floats(-0.5, 0.5),
    t=st.floats(-0.8, 0.8),
    Bw_deg=st.floats(1.0, 180.0),
    Br=st.floats(0.05, 3.0),
    L=st.floats(0.3, 10.0),
)
def test_nearest_equals_the_brute_force_window_search(scans, which, k, x, y, t, Bw_deg, Br, L):
    """The narrowed search finds exactly MbICP's metric-nearest point for every pair within Br."""
    ref_scan = scans[which][k % len(scans[which])]
    obj_scan = scans[which][(k + 1) % len(scans[which])]
    ref = ReferenceIndex.build(ref_scan, L)
    moved = Pose2(x, y, t).apply(obj_scan.points())
    Bw = math.radians(Bw_deg)
    idx, d2 = run(nearest, moved, *polar(moved), ref, Bw, Br, L)
    # a beam exactly at +/-Bw is in or out by round-off: bracket the answer between both windows
    inner, outer = (
        brute_force_nearest(ref, moved, Bw - 1e-9, L),
        brute_force_nearest(ref, moved, Bw + 1e-9, L),
    )
    tol = 1e-9 * np.maximum(np.where(np.isfinite(outer), outer, 0.0), 1.0)
    within = outer <= Br * Br
    assert np.all(d2[within] >= outer[within] - tol[within]) and np.all(
        d2[within] <= inner[within] + tol[within]
    )
    # the reported point is the one at that distance
    got = metric_distance_sq(moved[within], ref.points[idx[within]], L)
    np.testing.assert_allclose(got, d2[within], rtol=1e-9, atol=1e-12)
    # beyond Br a point may report a candidate (rejected later), never a closer one than exists
    assert np.all(d2[~within] >= outer[~within] - tol[~within])


@settings(max_examples=40, deadline=None)
@given(
    which=st.sampled_from(["intel", "laserazos", "stallo2 (360 deg)"]),
    k=st.integers(0, 29),
    x=st.floats(-0.3, 0.3),
    y=st.floats(-0.3, 0.3),
    t=st.floats(-0.3, 0.3),
    max_len=st.floats(0.05, 1.0),
)
def test_point_line_pairs_follow_paper_000(scans, which, k, x, y, t, max_len):
    """§2.4.1 pair by pair: of the points sharing a metric-nearest reference point m_j the closest
    keeps it; each other one goes to the foot of its perpendicular on the segment from m_j to the
    scan neighbour metrically closer to it (clamped), unless that segment is longer than max_len."""
    ref_scan = scans[which][k % len(scans[which])]
    ref = ReferenceIndex.build(ref_scan, 3.0)
    moved = Pose2(x, y, t).apply(scans[which][(k + 1) % len(scans[which])].points())
    Bw = math.radians(45)
    obj, target, kind, ref_index, pair_d2 = run(
        candidates, True, moved, *polar(moved), ref, Bw, 1.0, 3.0, max_len
    )
    dist = np.sqrt(np.maximum(pair_d2, 0.0))
    idx, d2 = run(nearest, moved, *polar(moved), ref, Bw, 1.0, 3.0)
    np.testing.assert_array_equal(obj, np.flatnonzero(idx >= 0))
    np.testing.assert_array_equal(ref_index[:, 0], idx[idx >= 0])
    for j in np.unique(ref_index[:, 0]):
        group = np.flatnonzero(ref_index[:, 0] == j)
        keeper = group[np.argmin(d2[obj[group]])]
        a = ref.points[j]
        for g in group:
            p = moved[obj[g]]
            if g == keeper:
                assert kind[g] == PairKind.POINT and np.array_equal(target[g], a)
                continue
            nbs = [n for n in ref.neighbours[j] if n >= 0]
            d_nb = [metric_distance_sq(p, ref.points[n], 3.0) for n in nbs]
            second = nbs[int(np.argmin(d_nb))] if nbs else -1
            if second < 0 or np.linalg.norm(ref.points[second] - a) > max_len:
                assert kind[g] == PairKind.POINT and np.array_equal(target[g], a)
                assert dist[g] == pytest.approx(math.sqrt(d2[obj[g]]))
                continue
            e = ref.points[second] - a
            foot = a + np.clip(np.dot(p - a, e) / np.dot(e, e), 0.0, 1.0) * e
            assert kind[g] == PairKind.INTERPOLATED and ref_index[g, 1] == second
            np.testing.assert_allclose(target[g], foot, atol=1e-12)
            assert dist[g] == pytest.approx(
                math.sqrt(max(metric_distance_sq(p, foot, 3.0), 0.0)), abs=1e-12
            )


def test_rejection_floor_shrinks_from_br_to_the_floor():
    p = ImprovedParams(Br=1.0, mad_floor=0.1, mad_anneal=0.5)
    assert [rejection_floor(p.Br, p.mad_floor, p.mad_anneal, i) for i in range(1, 6)] == [
        1.0,
        0.5,
        0.25,
        0.125,
        0.1,
    ]
    assert rejection_floor(p.Br, p.mad_floor, 0.0, 1) == 0.1  # as published: MAD from the start


def test_annealed_rejection_widens_the_basin(intel):
    """Paper 000's protocol on Intel scans (0.5 m, 0.5 m, 15 deg; random removal): with MAD from
    the first iteration the scan slides into the corridor's local minimum (§2.4.2); with the
    floor shrinking from Br it comes home."""

    def successes(params):
        ok = 0
        for i in (10, 30):
            scan = intel.scan(i)
            for c in make_cases([scan], [1.0, 0.8, 0.6], 6, "random", 1, 0.5, math.radians(15)):
                r = match(*case_pair(scan, c), Pose2(), params)
                et, er = pose_error(r.pose, c.truth)
                ok += et <= 0.1 and er <= math.radians(3.14)
        return ok / 36

    published, annealed = successes(ImprovedParams()), successes(ImprovedParams(mad_anneal=0.9))
    assert annealed >= 0.95 and published < 0.6
