"""A scan's points and its bearings' layout: found once and kept, equal to those found afresh."""

import math
import pickle
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mbicp_viz.core import Pose2, Scan, ScanError, make_scan
from mbicp_viz.core.points import _cos_sin, directions, valid_points
from mbicp_viz.core.scan import _layout
from mbicp_viz.readers import read_log
from mbicp_viz.readers.rosbag import laser_scan

from .conftest import HOKUYO_BAG

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
        fresh = valid_points(r, b, *_cos_sin(b), np.isfinite(r), float(limit))
        assert np.array_equal(pts, fresh[0]) and np.array_equal(bearings, fresh[1])
        assert all(map(np.array_equal, scan.directions(limit), fresh[2:4]))
    assert scan.points(limits[0]) is scan.points_and_bearings(limits[0])[0]
    assert "_memo" not in pickle.loads(pickle.dumps(scan)).__dict__
    assert "_memo" not in replace(scan).__dict__


def test_a_scan_says_whether_its_valid_readings_are_finite_points():
    b = np.array([0.0, 0.5, 1.0])
    assert Scan(np.array([1.0, np.nan, 2.0]), b, np.array([True, False, True])).has_finite_points()
    assert not Scan(np.array([1.0, np.inf, 2.0]), b, np.ones(3, bool)).has_finite_points()
    assert not Scan(np.array([1.0, 2.0, 3.0]), b, np.zeros(3, bool)).has_finite_points()


def _bearings(kind: str, n: int) -> np.ndarray:
    """Bearings a reader may give: a laser's, a full turn with its closing beams, one nudged by an
    ulp in its middle (its ends, and so its key, the same), not increasing, not numbers."""
    b = np.linspace(-2.0, 2.0, n)
    if kind == "turn":
        b = -math.pi + 2.0 * math.pi / (n - 2) * np.arange(n)
    elif kind == "nudged":
        b[n // 2] = math.nextafter(b[n // 2], math.inf)
    elif kind == "backwards":
        b[n // 2] = b[n // 2 - 1]
    elif kind == "nan":
        b[n // 2] = math.nan
    return b


@settings(max_examples=80, deadline=None)
@given(
    stream=st.lists(
        st.tuples(
            st.sampled_from(["laser", "turn", "nudged", "backwards", "nan"]),
            st.sampled_from([5, 6, 361]),
        ),
        min_size=1,
        max_size=25,
    )
)
def test_a_scans_bearings_are_those_found_afresh_and_shared_when_equal(stream):
    """Scans made one after another, their bearings alike or not (the same ends, an ulp apart in
    the middle): each scan's bearings and kept beams, or its error, are what the bearings alone
    give; a scan whose bearings equal the last scan's shares its array (a stream's scans), which
    is C-contiguous and writable."""
    last = last_made = None
    for kind, n in stream:
        b = _bearings(kind, n)
        fresh = _layout(b.copy())
        r = np.linspace(1.0, 2.0, n)
        if fresh.error is not None:
            with pytest.raises(ScanError, match=fresh.error.split(":")[0]):
                make_scan(r, b)
            last = None
            continue
        scan = make_scan(r, b)
        assert np.array_equal(scan.bearings, fresh.bearings)
        assert len(scan.ranges) == len(fresh.bearings)
        assert scan.bearings.flags.c_contiguous and scan.bearings.flags.writeable
        if last is not None and np.array_equal(last, b):
            assert scan.bearings is last_made
        last, last_made = b, scan.bearings


def test_bearings_of_more_beams_than_any_laser_has_are_checked_but_not_kept():
    """A damaged file's scan of 70,000 beams is made as any other, its layout not kept (the
    layouts kept stay a few megabytes whatever a file holds)."""
    from mbicp_viz.core import scan as scan_module

    n = scan_module.KEPT_BEAMS_MAX + 1
    b = np.linspace(-2.0, 2.0, n)
    first, second = make_scan(np.ones(n), b), make_scan(np.ones(n), b)
    assert np.array_equal(first.bearings, b) and first.bearings is not second.bearings
    assert all(len(layout.given) <= scan_module.KEPT_BEAMS_MAX for layout in scan_module._LAYOUTS)


def test_scans_sharing_bearings_share_their_cosines_and_sines():
    """A stream's scans, and a worker's chunk of them unpickled, have equal bearings and so share
    one computation of their cosines and sines (numba's, as a scan's points take them), found by
    the bearings' bytes: new bearings written into an earlier scan's array, or a zero of the other
    sign, get their own; bearings of more beams than a laser has are never kept."""
    from mbicp_viz.core import scan as scan_module

    b = np.linspace(-2.0, 2.0, 361)
    stream = [make_scan(np.full(361, 1.0 + k), b) for k in range(3)]
    c, s = directions(stream[0].bearings)
    assert all(directions(scan.bearings)[0] is c for scan in stream)
    assert all(map(np.array_equal, (c, s), _cos_sin(b.copy())))
    assert np.allclose(c, np.cos(b), rtol=0, atol=1e-15)
    chunk = pickle.loads(pickle.dumps(stream))
    assert chunk[0].bearings is not stream[0].bearings
    assert directions(chunk[0].bearings)[0] is c
    assert np.array_equal(chunk[1].points(), stream[1].points())

    buffer = np.linspace(-1.0, 1.0, 5)
    first = Scan(np.ones(5), buffer, np.ones(5, bool))
    assert np.allclose(first.points()[:, 1], np.sin(buffer))
    buffer += 0.5  # a caller's buffer, filled anew for the next scan
    second = Scan(np.ones(5), buffer, np.ones(5, bool))
    assert np.allclose(second.points()[:, 1], np.sin(buffer))
    zero = np.array([-1.0, 0.0, 1.0])
    assert math.copysign(1.0, directions(zero)[1][1]) == 1.0
    assert math.copysign(1.0, directions(-zero[::-1].copy())[1][1]) == -1.0

    big = np.linspace(-2.0, 2.0, scan_module.KEPT_BEAMS_MAX + 1)
    assert directions(big)[0] is not directions(big)[0]


def test_a_bags_scans_share_their_first_scans_bearings_known_without_a_comparison(monkeypatch):
    """A bag's stream makes its bearings once: every scan after the first is given the first's
    array (``readers/rosbag._beams``), whose layout is its own, found without comparing the
    bearings; an equal array of a caller's is compared, and gets the same layout."""
    log = read_log(str(HOKUYO_BAG))
    scans = log.scans_from(0)
    _, first = next(scans)
    compared = []
    equal = np.array_equal
    monkeypatch.setattr(np, "array_equal", lambda *a, **k: compared.append(1) or equal(*a, **k))
    later = [scan for _, (_, scan) in zip(range(20), scans)]
    assert len(later) == 20 and all(s.bearings is first.bearings for s in later) and not compared
    again = make_scan(np.ones(len(first.ranges)), first.bearings.copy())
    assert again.bearings is first.bearings and compared


@settings(max_examples=150, deadline=None)
@given(
    stream=st.lists(
        st.tuples(
            st.sampled_from([0.0, -0.0, -1.5707963705062866, 2.0]),
            st.sampled_from([0.002892721677199006, -0.002892721677199006, 0.0174533, -0.0174533]),
            st.sampled_from([0.0, 1e-4, math.nan]),
            st.sampled_from([5, 361]),
            st.booleans(),
        ),
        min_size=1,
        max_size=12,
    )
)
def test_a_bags_scans_get_the_bearings_and_beam_times_their_message_gives(stream):
    """However a bag's messages alternate their geometry (a zero of either sign, clockwise or not,
    upside down or not), each scan's bearings and beam times are, bit for bit, those its message
    gives, though a stream's are made once (``readers/rosbag._beams``)."""
    for k, (angle_min, inc, dt, n, upside_down) in enumerate(stream):
        stamp = SimpleNamespace(sec=k, nanosec=0)
        m = SimpleNamespace(
            header=SimpleNamespace(stamp=stamp, frame_id="laser"),
            ranges=np.linspace(1.0, 2.0, n).astype(np.float32),
            angle_min=angle_min,
            angle_increment=inc,
            time_increment=dt,
            range_min=0.1,
            range_max=30.0,
        )
        scan = laser_scan(m, "test.bag", k, upside_down, None, Pose2())
        b = (angle_min + inc * np.arange(n)) * (-1.0 if upside_down else 1.0)
        t = dt * np.arange(n) if dt > 0 else None
        if b[1] < b[0]:
            b, t = b[::-1], None if t is None else t[::-1]
        fresh = _layout(b.copy())  # a full turn's closing beams dropped
        kept = slice(None) if fresh.keep is None else fresh.keep
        assert scan.bearings.tobytes() == fresh.bearings.tobytes()
        assert (scan.beam_times is None) == (t is None)
        assert t is None or scan.beam_times.tobytes() == t[kept].tobytes()
        assert scan.ranges[0] == (1.0 if inc * (1 - 2 * upside_down) > 0 else 2.0)
