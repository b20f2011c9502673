"""core/agreement.py: judging a pose by the points alone."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import Pose2
from mbicp_viz.core.agreement import inlier_fraction
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
