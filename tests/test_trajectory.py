"""Sequence trajectories: accumulation, the odometry Kalman filter, TUM export, the map plot."""

import numpy as np
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import ImprovedParams, MatchResult, Pose2, Termination, pose_error, relative
from mbicp_viz.evaluation.trajectory import accumulate, kalman
from mbicp_viz.readers import read_log
from mbicp_viz.readers.pair_match import PairMatch

from .conftest import INTEL, LASERAZOS


def row(k: int, motion: Pose2, converged: bool = True) -> PairMatch:
    reason = Termination.CONVERGED if converged else Termination.MAX_ITERATIONS
    result = MatchResult("improved", motion, converged, reason, 5, 0.0, 300, 0, None, None)
    return PairMatch(k, k + 1, ImprovedParams(), Pose2(), "identity", result, "laser")


def rows_from(poses, converged=True):
    return [
        row(k, relative(a, b), converged) for k, (a, b) in enumerate(zip(poses[:-1], poses[1:]))
    ]


def test_accumulated_increments_rebuild_the_log_trajectory():
    log = read_log(INTEL)
    poses = [relative(log.scans[0].pose, s.pose) for s in log.scans[:20]]
    rebuilt = accumulate(rows_from(poses))
    for a, b in zip(rebuilt, poses):
        assert pose_error(a, b)[0] < 1e-9


def test_kalman_agrees_when_both_sources_agree_and_follows_odometry_without_matches():
    log = read_log(INTEL)
    odo = [s.odometry for s in log.scans[:15]]
    truth = [relative(odo[0], o) for o in odo]
    fused = kalman(rows_from(truth), odo, (0.05, 0.05, 0.03), (0.02, 0.02, 0.01))
    assert max(pose_error(a, b)[0] for a, b in zip(fused, truth)) < 1e-9
    # matches that did not converge are ignored: the filter dead-reckons on odometry
    skipped = kalman(
        [row(k, Pose2(5.0, 0.0, 1.0), converged=False) for k in range(14)],
        odo,
        (0.05, 0.05, 0.03),
        (0.02, 0.02, 0.01),
    )
    assert max(pose_error(a, b)[0] for a, b in zip(skipped, truth)) < 1e-9


def test_kalman_weighs_the_sharper_source():
    odo = [Pose2(), Pose2(1.0, 0.0, 0.0)]
    fused = kalman(
        [row(0, Pose2(1.2, 0.0, 0.0))],
        odo,
        (0.2, 0.2, 0.1),
        (0.02, 0.02, 0.01),
    )
    assert 1.15 < fused[1].x < 1.2  # much closer to the matcher, whose noise is ten times smaller


def test_sequence_writes_tum_files_and_a_map(tmp_path):
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "sequence",
            str(LASERAZOS),
            "--out",
            str(tmp_path / "s.json"),
            "--limit",
            "8",
            "--tum",
            str(tmp_path / "est.tum"),
            "--tum-ref",
            str(tmp_path / "ref.tum"),
            "--png",
            str(tmp_path / "map.png"),
            "--kalman",
        ],
    )
    assert res.exit_code == 0, res.output
    est = [
        ln.split()
        for ln in (tmp_path / "est.tum").read_text().splitlines()
        if not ln.startswith("#")
    ]
    assert len(est) == 9 and all(len(r) == 8 for r in est)
    q = np.array([[float(v) for v in r[4:]] for r in est])
    # unit quaternions about z
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    assert (tmp_path / "map.png").read_bytes()[:4] == b"\x89PNG"
    ref = [
        ln.split()
        for ln in (tmp_path / "ref.tum").read_text().splitlines()
        if not ln.startswith("#")
    ]
    assert float(ref[0][1]) == 0.0 and len(ref) == 9


def test_kalman_without_odometry_is_a_clean_error(tmp_path):
    res = CliRunner().invoke(
        app, ["eval", "sequence", str(tmp_path.parent / "x"), "--out", "o.json"]
    )
    assert res.exit_code == 2
    from .conftest import DATA

    res = CliRunner().invoke(
        app,
        [
            "eval",
            "sequence",
            str(DATA / "stallo2.jsonl"),
            "--out",
            str(tmp_path / "o.json"),
            "--kalman",
        ],
    )
    # stallo2 stores odometry: fused fine
    assert res.exit_code == 0 and "1 pairs matched" in res.output
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "sequence",
            str(DATA / "datos.off"),
            "--out",
            str(tmp_path / "o.json"),
            "--kalman",
        ],
    )
    assert res.exit_code == 2 and "needs odometry" in res.output


def test_the_odometry_track_is_the_bases_when_the_rows_report_the_base(tmp_path, intel):
    """A laser mounted off the base's centre: the odometry chained from the rows is the base's
    track (the one the matches are chained in), not the laser's."""
    from mbicp_viz.evaluation.trajectory import odometry_chain
    from mbicp_viz.readers.rows import read_rows

    from .bags import intel_robot, write

    mount = Pose2(0.3, 0.1, 0.5)
    robot = intel_robot(intel, 0, 8, mount)
    path = write(tmp_path / "r.bag", robot, "ros1")
    out = tmp_path / "rows.json"
    args = ["eval", "sequence", str(path), "--out", str(out), "--workers", "1"]
    assert CliRunner().invoke(app, args).exit_code == 0
    rows = read_rows(out)
    assert rows[0].frame == "base_link"
    track = odometry_chain(read_log(path), rows)
    base = robot.odometry
    for k, pose in enumerate(track):
        assert max(pose_error(pose, relative(base[0], base[k]))) < 1e-6
