"""A key-frame run (eval sequence --keyframe-m): each scan matched against the last key frame, a new
one once the robot has moved far enough; its rows chain, score, resume and open like any run's."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import ImprovedParams, MatchResult, Pose2, Termination, pose_error, relative
from mbicp_viz.evaluation.keyframes import KeyFrames
from mbicp_viz.evaluation.trajectory import accumulate, is_run, off_the_run
from mbicp_viz.readers import read_log
from mbicp_viz.readers.pair_match import PairMatch
from mbicp_viz.readers.rows import rows_of_log
from mbicp_viz.views.debugger.sources import files_source

from .conftest import HOKUYO_BAG, json_lines
from .test_nothing_lost import interrupt_the_fourth_match

runner = CliRunner()
KEY_M, KEY_DEG = 0.05, 5.0  # the hand-held Hokuyo moves a few centimetres between key frames


def row(ref: int, obj: int, motion: Pose2, converged: bool = True) -> PairMatch:
    reason = Termination.CONVERGED if converged else Termination.MAX_ITERATIONS
    result = MatchResult("improved", motion, converged, reason, 5, 0.0, 300, 0, None, None)
    return PairMatch(ref, obj, ImprovedParams(), Pose2(), "identity", result, "laser")


poses = st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(-math.pi, math.pi)).map(
    lambda p: Pose2(*p)
)


@settings(max_examples=80)
@given(st.lists(poses, min_size=2, max_size=15), st.data())
def test_a_key_frame_runs_motions_place_every_scan_where_it_was(track, data):
    """Rows from any earlier scan (a key frame) rebuild the track, as consecutive rows do."""
    world = [relative(track[0], p) for p in track]
    rows = [
        row(ref, k, relative(world[ref], world[k]))
        for k in range(1, len(world))
        for ref in [data.draw(st.integers(0, k - 1))]
    ]
    assert is_run(rows)
    for a, b in zip(accumulate(rows), world):
        assert pose_error(a, b)[0] < 1e-6 and pose_error(a, b)[1] < 1e-9


def test_rows_that_start_from_a_scan_not_yet_placed_are_no_run():
    m = Pose2(0.1, 0.0, 0.0)
    assert off_the_run([row(0, 1, m), row(1, 2, m), row(0, 3, m)]) is None
    assert off_the_run([row(0, 1, m), row(2, 3, m)]) == 1  # scan 2 was never placed
    assert off_the_run([row(0, 1, m), row(0, 1, m)]) == 1  # scan 1 placed twice
    assert not is_run([])


def keyframe_run(tmp_path, name: str, *extra):
    out = tmp_path / name
    args = ["eval", "sequence", str(HOKUYO_BAG), "--out", str(out), "--limit", "80"]
    args += ["--keyframe-m", str(KEY_M), "--keyframe-deg", str(KEY_DEG), *map(str, extra)]
    return runner.invoke(app, args), out


def test_each_scan_is_matched_against_the_last_key_frame(tmp_path):
    res, out = keyframe_run(tmp_path, "kf.json")
    assert res.exit_code == 0, res.output
    rows = rows_of_log(str(out), read_log(str(HOKUYO_BAG)))
    assert [r.obj for r in rows] == list(range(1, 81)) and rows[0].ref == 0
    rule, key, keys = KeyFrames(KEY_M, math.radians(KEY_DEG)), 0, {0}
    for r in rows:
        assert r.ref == key  # the key frame the rows before made
        if rule.due(r):
            key = r.obj
            keys.add(key)
    assert 3 < len(keys) < 60  # the hand-held laser moves: some key frames, far fewer than scans
    assert any(r.obj - r.ref > 1 for r in rows)
    # the rows say how they were made, and eval relations / the run view take them as a run
    assert json_lines(out)[0]["ref"] == 0
    assert files_source(str(HOKUYO_BAG), None, rows=str(out)).run is not None


def test_a_stopped_key_frame_run_resumes_to_the_same_rows(tmp_path, monkeypatch):
    res, fresh = keyframe_run(tmp_path, "fresh.json")
    assert res.exit_code == 0, res.output
    with monkeypatch.context() as m:
        interrupt_the_fourth_match(m)
        res, out = keyframe_run(tmp_path, "kf.json", "--limit", "80")
    assert res.exit_code == 130, res.output
    res, out = keyframe_run(tmp_path, "kf.json")
    assert res.exit_code == 0 and "already matched" in res.stderr, res.output
    key = [(r["ref"], r["obj"], r["x"], r["y"], r["theta"]) for r in json_lines(fresh)]
    assert [(r["ref"], r["obj"], r["x"], r["y"], r["theta"]) for r in json_lines(out)] == key


def test_a_key_frame_runs_rows_are_not_resumed_as_a_consecutive_run(tmp_path, monkeypatch):
    with monkeypatch.context() as m:
        interrupt_the_fourth_match(m)
        res, out = keyframe_run(tmp_path, "kf.json")
    assert res.exit_code == 130
    args = ["eval", "sequence", str(HOKUYO_BAG), "--out", str(out), "--limit", "80"]
    res = runner.invoke(app, args)
    assert res.exit_code == 2 and "keyframes: rows of another run" in res.stderr, res.output
