"""A scan's points: computed once and kept on the scan, equal to those computed afresh."""

import pickle
from dataclasses import replace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mbicp_viz.core import Scan
from mbicp_viz.core.points import valid_points

LIMITS = st.sampled_from([0.5, 2.0, 999.0, 1000.0, 1500.0, np.inf])


@settings(max_examples=60, deadline=None)
@given(
    ranges=st.lists(
        st.one_of(st.floats(0.1, 20.0), st.floats(990.0, 2000.0), st.just(np.nan)),
        min_size=1,
        max_size=30,
    ),
    limits=st.lists(LIMITS, min_size=1, max_size=8),
)
def test_a_scans_kept_points_equal_those_computed_afresh(ranges, limits):
    """Whatever the order of the limits asked for (a limit above every valid reading shares the
    limitless points), each answer is the computation's own; a pickled scan leaves them behind."""
    r = np.array(ranges)
    b = np.linspace(-1.0, 1.0, len(r))
    scan = Scan(r, b, np.isfinite(r))
    for limit in limits:
        pts, bearings = scan.points_and_bearings(limit)
        fresh = valid_points(r, b, np.isfinite(r), float(limit))
        assert np.array_equal(pts, fresh[0]) and np.array_equal(bearings, fresh[1])
    assert scan.points(limits[0]) is scan.points_and_bearings(limits[0])[0]
    assert "_memo" not in pickle.loads(pickle.dumps(scan)).__dict__
    assert "_memo" not in replace(scan).__dict__


def test_a_scan_says_whether_its_valid_readings_are_finite_points():
    b = np.array([0.0, 0.5, 1.0])
    assert Scan(np.array([1.0, np.nan, 2.0]), b, np.array([True, False, True])).has_finite_points()
    assert not Scan(np.array([1.0, np.inf, 2.0]), b, np.ones(3, bool)).has_finite_points()
    assert not Scan(np.array([1.0, 2.0, 3.0]), b, np.zeros(3, bool)).has_finite_points()
