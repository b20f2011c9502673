"""Motion correction (``--deskew``): the geometry inverts the motion exactly, bags carry each
beam's time to it, the velocity comes from the bag's odometry or from the matches, and a log that
cannot be corrected says so in one line."""

import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mbicp_viz.core import Pose2, Scan, deskew, make_scan, relative, twist
from mbicp_viz.core.deskew import motion
from mbicp_viz.readers import ReadOptions, read_log

from .bags import Robot, Topic, intel_robot, write
from .conftest import DATA, EXAMPLES

HOKUYO_DT = 0.06640625 / 680  # a URG-04LX's time between two beams (demo.bag's time_increment)
speed = st.floats(-2.0, 2.0)
turn = st.floats(-3.0, 3.0)


@settings(max_examples=40, deadline=None)
@given(speed, speed, turn, st.floats(0.01, 1.0))
def test_the_twist_between_two_poses_takes_one_onto_the_other(vx, vy, w, dt):
    """(Between two scans the sensor turns less than half a turn: |w dt| < pi.)"""
    a = Pose2(1.0, -2.0, 0.3)
    x, y, th = motion(np.array([vx, vy, w]), np.array([dt]))
    b = a @ Pose2(float(x[0]), float(y[0]), float(th[0]))
    assert twist(relative(a, b), dt) == pytest.approx([vx, vy, w], abs=1e-9)


def distorted(scan: Scan, v: np.ndarray) -> Scan:
    """What a sensor moving at twist ``v`` measures of ``scan``'s points (each beam at its time):
    the inverse of the correction, point by point."""
    x, y, th = motion(v, scan.beam_times)
    p = scan.points()
    t = scan.beam_times[scan.valid]
    x, y, th = x[scan.valid], y[scan.valid], th[scan.valid]
    dx, dy = p[:, 0] - x, p[:, 1] - y
    mx, my = np.cos(th) * dx + np.sin(th) * dy, -np.sin(th) * dx + np.cos(th) * dy
    b = np.arctan2(my, mx)
    order = np.argsort(b)
    return make_scan(np.hypot(mx, my)[order], b[order], beam_times=t[order], stamp=0.0)


@settings(max_examples=30, deadline=None)
@given(speed, speed, st.floats(-1.5, 1.5))
def test_correction_undoes_the_motion_on_a_real_scan(hokuyo, vx, vy, w):
    real = hokuyo.scan(0)
    real = replace(real, beam_times=HOKUYO_DT * np.arange(len(real.ranges)))
    v = np.array([vx, vy, w])
    measured = distorted(real, v)
    corrected = deskew(measured, v)
    assert corrected.raw is measured
    got, want = corrected.points(), real.points()
    assert len(got) == len(want)
    # the same points (compared as sets: the correction sorts beams by their corrected bearing)
    d = np.hypot(*(got[:, None, :] - want[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    assert d.max() < 1e-9


def test_bags_carry_beam_times_and_odometry_corrects_them(tmp_path, intel):
    robot = intel_robot(intel, 20, 5, Pose2(), odometry_on="/odom")
    robot.topics[0].time_increment = 1e-4
    path = write(tmp_path / "r.bag", robot, "ros1")
    log = read_log(path)
    s = log.scans[0]
    assert s.beam_times == pytest.approx(1e-4 * np.arange(len(s.ranges)))
    fixed = read_log(path, ReadOptions(deskew="odometry"))
    assert any("--deskew odometry" in n for n in fixed.notes)
    # each scan corrected by the odometry's velocity to the next one
    for k, c in enumerate(fixed.scans):
        j = min(k, len(log.scans) - 2)
        a, b = log.scans[j], log.scans[j + 1]
        expected = deskew(log.scans[k], twist(relative(a.odometry, b.odometry), b.stamp - a.stamp))
        assert c.raw is not None and np.allclose(c.points(), expected.points())
        # the correction moved something
        assert np.abs(c.points() - log.scans[k].points()).max() > 1e-4


def test_a_scan_without_odometry_is_left_as_measured_and_counted(tmp_path, intel):
    robot = intel_robot(intel, 20, 5, Pose2(), odometry_on="/odom", odometry_from=1)
    robot.topics[0].time_increment = 1e-4
    fixed = read_log(write(tmp_path / "r.bag", robot, "ros1"), ReadOptions(deskew="odometry"))
    assert fixed.scans[0].raw is None and all(s.raw is not None for s in fixed.scans[1:])
    assert any("1 scan(s) left as measured" in n for n in fixed.notes)


def test_velocity_from_the_matches_without_odometry(tmp_path, hokuyo):
    scans = [hokuyo.scan(0), hokuyo.scan(1)]
    path = write(
        tmp_path / "h",
        Robot([Topic("/scan", "laser", scans, time_increment=HOKUYO_DT)], [10.0, 10.5]),
        "humble",
    )
    log = read_log(path, ReadOptions(deskew="velocity"))
    assert all(s.raw is not None for s in log.scans)
    turned = [np.median(s.bearings[s.valid] - s.raw.bearings[s.raw.valid]) for s in log.scans]
    # a hand-held scanner turning about -17 deg in half a second turns about -2.3 deg during one
    # sweep
    assert all(-0.5 < math.degrees(t) < 0 for t in turned)


@pytest.mark.parametrize(
    "args,why",
    [
        ([str(EXAMPLES / "intel-excerpt.log.gz"), "--deskew", "odometry"], "time_increment"),
    ],
)
def test_a_log_that_cannot_be_corrected_says_so_in_one_line(args, why):
    res = subprocess.run(
        [sys.executable, "-m", "mbicp_viz", "match", *args, "--pair", "0", "1"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 2 and why in res.stderr and "--deskew" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr


def test_odometry_correction_needs_odometry(tmp_path, hokuyo):
    path = write(
        tmp_path / "h",
        Robot(
            [Topic("/scan", "laser", [hokuyo.scan(0), hokuyo.scan(1)], time_increment=HOKUYO_DT)],
            [10.0, 10.5],
        ),
        "humble",
    )
    res = subprocess.run(
        [sys.executable, "-m", "mbicp_viz", "match", str(path), "--deskew", "odometry"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 2 and "use --deskew velocity" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_the_debugger_shows_the_scans_as_measured_and_the_seam(tmp_path, hokuyo):
    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger import report
    from mbicp_viz.views.debugger.state import DebugState, Source

    path = write(
        tmp_path / "h",
        Robot(
            [Topic("/scan", "laser", [hokuyo.scan(0), hokuyo.scan(1)], time_increment=HOKUYO_DT)],
            [10.0, 10.5],
        ),
        "humble",
    )
    log = read_log(path, ReadOptions(deskew="velocity"))
    state = DebugState(Source("deskewed", log, guess=Pose2()))
    assert state.rematch() is None
    layers = {getattr(ly, "style", None): ly for ly in report.layers(state, state.runs[0])}
    raw = layers[scene.RAW]
    assert len(raw.xy) == log.scans[0].raw.n_valid + log.scans[1].raw.n_valid
    assert scene.SEAM not in layers  # a 239-degree scan has no seam

    stallo = read_log(DATA.parent.parent / "recordings" / "inputs" / "stallo2.jsonl")
    state = DebugState(Source("360", stallo, guess=Pose2()))
    assert state.rematch() is None
    seam = {getattr(ly, "style", None): ly for ly in report.layers(state, state.runs[0])}[
        scene.SEAM
    ]
    assert np.allclose(seam.ends, stallo.scans[0].points()[[0, -1]])


def test_on_a_real_hand_held_recording_the_correction_makes_scans_agree(hokuyo):
    """The Hokuyo bag (hand-held, 66 ms sweeps, no odometry): corrected with the velocity from the
    matches, scans three apart (whose velocities differ) agree better than as measured, and
    corrected with the opposite velocity, worse: the correction goes the right way."""
    from mbicp_viz.core import ImprovedParams, match
    from mbicp_viz.readers.deskew import velocities

    v = velocities(hokuyo, "velocity")
    assert all(x is not None for x in v)
    fixed, backwards = ([deskew(s, sign * x) for s, x in zip(hokuyo.scans, v)] for sign in (1, -1))

    def residual(scans, k):
        return match(scans[k], scans[k + 3], Pose2(), ImprovedParams()).error

    ks = range(0, len(hokuyo.scans) - 3, 2)
    raw, good, bad = (
        np.median([residual(scans, k) for k in ks]) for scans in (hokuyo.scans, fixed, backwards)
    )
    assert good < raw < bad


def test_beam_times_longer_than_the_gap_between_scans_are_refused(tmp_path, hokuyo):
    """A driver's time_increment that makes a sweep outlast the time to the next scan is wrong: the
    correction would move the points by whatever it says, so it is refused in one line."""
    path = write(
        tmp_path / "h",
        Robot(
            [Topic("/scan", "laser", [hokuyo.scan(0), hokuyo.scan(1)], time_increment=0.01)],
            [10.0, 10.5],
        ),
        "humble",
    )
    res = subprocess.run(
        [sys.executable, "-m", "mbicp_viz", "match", str(path), "--deskew", "velocity"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 2 and "beam times are wrong" in res.stderr and "--deskew" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("w", [-2.0, 2.0])
def test_a_360_degree_scan_wraps_round_its_seam(w):
    """A 360-degree lidar turning while it sweeps: corrected beams past the first direction wrap
    round the seam, and the scan still covers less than a full turn, bearings increasing."""
    stallo = read_log(DATA.parent.parent / "recordings" / "inputs" / "stallo2.jsonl").scans[0]
    assert stallo.is_full_circle()
    s = replace(stallo, beam_times=np.linspace(0.0, 0.1, len(stallo.ranges)))
    c = deskew(s, np.array([0.5, 0.0, w]))
    assert np.all(np.diff(c.bearings) > 0) and c.bearings[-1] - c.bearings[0] < 2 * np.pi
    assert c.n_valid == s.n_valid
