"""core/agreement.py: judging a pose by the points alone."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import Pose2, Scan
from mbicp_viz.core.agreement import SURFACE_GAP_BEAMS, agreement, inlier_fraction
from mbicp_viz.evaluation.pairs import seen_from
from mbicp_viz.readers import read_log
from mbicp_viz.readers.pair_match import Score

from .conftest import INTEL, json_lines

SCANS = read_log(INTEL).scans


@settings(max_examples=25, deadline=None)
@given(
    st.integers(0, len(SCANS) - 1), st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), st.floats(-0.3, 0.3)
)
def test_the_true_displacement_lays_every_point_on_the_reference(k, x, y, theta):
    ref = SCANS[k]
    truth = Pose2(x, y, theta)
    obj = seen_from(ref, truth)
    assert inlier_fraction(ref, obj, truth) > 0.95  # the points the displaced sensor still sees
    assert inlier_fraction(ref, obj, Pose2(x + 0.2, y + 0.2, theta + math.radians(15))) < 0.5


def exhaustive(ref, obj, pose, radius=0.05) -> tuple[float, float]:
    """``agreement`` as its definition reads, by trying every reference point for every object
    point (equal distances to the lower index)."""
    p, q = ref.points(), pose.apply(obj.points())
    idx = ref.valid_indices()
    r, b = ref.ranges[idx], ref.bearings[idx]
    d2 = (q[:, None, 0] - p[None, :, 0]) ** 2 + (q[:, None, 1] - p[None, :, 1]) ** 2
    nearest = d2.argmin(axis=1)
    to_point = np.sqrt(d2[np.arange(len(q)), nearest])
    ab = np.diff(p, axis=0)
    surface = np.hypot(*ab.T) <= SURFACE_GAP_BEAMS * np.maximum(r[:-1], r[1:]) * np.diff(b) + radius
    to_surface = to_point.copy()
    for i, j in enumerate(nearest):
        for s in (j - 1, j):
            if 0 <= s < len(ab) and surface[s]:
                t = np.dot(q[i] - p[s], ab[s]) / max(np.dot(ab[s], ab[s]), 1e-12)
                foot = p[s] + min(max(t, 0.0), 1.0) * ab[s]
                to_surface[i] = min(to_surface[i], math.hypot(*(q[i] - foot)))
    return float(np.mean(to_point <= radius)), float(np.mean(to_surface <= radius))


@settings(max_examples=60, deadline=None)
@given(
    k=st.integers(0, len(SCANS) - 1),
    truth=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-3.2, 3.2)),
    off=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-0.5, 0.5)),
    near=st.booleans(),
)
def test_agreement_is_what_trying_every_reference_point_gives(k, truth, off, near):
    """The search that stops where no nearer point can lie (any pose: on the surfaces or far
    off them; scans seen from anywhere around, their bearings wrapping at +/-pi) finds what
    trying every point finds."""
    ref = SCANS[k]
    obj = seen_from(ref, Pose2(*truth))
    pose = Pose2(*truth) if near else Pose2(*truth) @ Pose2(*off)
    assert agreement(ref, obj, pose) == exhaustive(ref, obj, pose)
    assert agreement(obj, ref, pose.inverse()) == exhaustive(obj, ref, pose.inverse())


def test_a_failure_is_doubted_only_when_the_points_side_with_the_matcher():
    assert Score(0.3, 0.1, False, inliers_match=0.74, inliers_truth=0.19).truth_doubted
    assert not Score(0.3, 0.1, False, inliers_match=0.19, inliers_truth=0.74).truth_doubted
    assert not Score(0.01, 0.001, True).truth_doubted


def test_eval_sequence_reports_failures_the_points_doubt(tmp_path):
    out = tmp_path / "rows.json"
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "sequence",
            str(INTEL),
            "--guess",
            "identity",
            "--truth",
            "pose",
            "--limit",
            "12",
            "--out",
            str(out),
            "--workers",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    rows = json_lines(out)
    failed = [r for r in rows if not r["success"]]
    assert failed and all(
        0.0 <= r["inliers_match"] <= 1.0 and 0.0 <= r["inliers_truth"] <= 1.0 for r in failed
    )
    # counted by hand from the written rows
    doubted = sum(r["inliers_match"] > r["inliers_truth"] for r in failed)
    assert f"than at the scan poses: {doubted} of {len(failed)}" in res.output


def test_a_hand_made_scans_valid_readings_that_make_no_point_are_left_out():
    """A scan made without ``make_scan`` may mark an infinite reading valid: its points leave it
    out, and so must the ranges the surface is judged by. Here it sits where the range jumps by
    12 cm, a gap wider than a surface seen at 1 m with 0.01 rad beams: the jump's midpoint lies on
    no surface (with the reading's range taken for its neighbour's, the gap counted as one)."""
    b = np.linspace(-0.5, 0.49, 100)
    r = np.where(np.arange(100) < 50, 1.0, 1.12)
    r[50] = np.inf
    loose, strict = Scan(r, b, np.ones(100, bool)), Scan(r, b, np.isfinite(r))
    p = loose.points()
    mid = 0.5 * (p[49] + p[50])
    obj = Scan(np.array([np.hypot(*mid)]), np.array([np.arctan2(mid[1], mid[0])]), np.ones(1, bool))
    assert agreement(strict, obj, Pose2()) == (0.0, 0.0)
    assert agreement(loose, obj, Pose2()) == (0.0, 0.0)
    assert agreement(loose, loose, Pose2()) == (1.0, 1.0)
