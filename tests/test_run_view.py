"""The run view's model (views/debugger/run.py) on a real run, and ``eval sequence --serve``, which
opens it: the map is the scans up to the pair at the chained poses, in the first scan's frame; the
debugger answers and Ctrl-C ends it with no process left."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
import urllib.request
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mbicp_viz.core import MATCHERS, Pose2
from mbicp_viz.evaluation.loops import close_loops
from mbicp_viz.evaluation.sequence import match_sequence
from mbicp_viz.evaluation.trajectory import is_run
from mbicp_viz.readers import read_log
from mbicp_viz.views import scene
from mbicp_viz.views.debugger.run_model import MapAt, RunModel

from .conftest import HOKUYO_BAG, INTEL


@pytest.mark.parametrize("chunks", [100, 7])
def test_the_map_is_the_scans_up_to_the_pair_at_the_chained_poses(chunks, monkeypatch):
    """... with a chunk a scan (60 scans), or chunks of several whose last part follows the pair."""
    from mbicp_viz.views.debugger import run_model as run

    monkeypatch.setattr(run, "MAP_CHUNKS", chunks)
    log = read_log(str(INTEL))
    rows = match_sequence(log, MATCHERS["improved"].params_type(), guess="odometry", workers=1)
    assert is_run(rows) and not is_run(rows[:3] + rows[4:])
    model = RunModel(log, rows)
    mount = log.frames.mount
    for n in (0, 17, 30, len(rows) - 1):
        at = model.pair_at(n)
        # the pair's two scans where the chained matches put them (base pose @ mount: the laser)
        pose = model.poses[n + 1] @ mount
        assert np.allclose(at.obj_xy, pose.apply(log.scan(rows[n].obj).points()))
        # the map up to it: the whole chunks it has passed and the part since, every scan once
        ((_, last, _),) = at.maps
        shown = model.chunks(model.poses)[: model.whole_chunks(n)] + [last]
        expected = [
            (p @ mount).apply(log.scan(i).points()) for p, i in zip(model.poses, model.scans)
        ]
        assert np.allclose(np.concatenate(shown), np.concatenate(expected[: n + 2]))
    # the health timeline: one point per pair, each as its record says
    x, overlap, odo, flagged, residual = model.series
    assert list(x) == list(range(1, len(rows) + 1))
    assert np.allclose(overlap, [100 * r.overlap for r in rows])
    assert np.allclose(odo, [1000 * r.odometry_xy for r in rows])
    assert np.allclose(residual, [1000 * np.sqrt(r.result.error) for r in rows])
    assert [f > 0 for f in flagged] == [bool(r.flags) for r in rows]
    # the log's own poses start where the run does: the first scan's frame
    first = model.stored[0]
    assert np.allclose([first.x, first.y, first.theta], 0.0, atol=1e-12)
    assert len(model.stored) == len(model.poses) == len(rows) + 1
    # asked to, the map and the pair are drawn at the poses with the loops closed, or both maps
    chained_map = np.concatenate(model.chunks(model.poses))
    moved = Pose2(1.0, -2.0, 0.3)
    loops = close_loops(log, rows, rows[0].params)
    model.loops = replace(loops, optimised=[moved @ p for p in model.poses])
    for at_, styles in (
        (MapAt.LOOPS, [scene.RUN_LOOP_MAP]),
        (MapAt.BOTH, [scene.RUN_LOOP_MAP, scene.RUN_MAP]),
    ):
        model.map_at = at_
        assert [style for _, _, style in model.maps()] == styles
        assert np.allclose(np.concatenate(model.chunks(model.drawn)), moved.apply(chained_map))
        at = model.pair_at(17)
        obj = (moved @ model.poses[18] @ mount).apply(log.scan(18).points())
        assert np.allclose(at.obj_xy, obj)
        assert [style for _, _, style in at.maps] == styles


# a log read whole (its pairs listed first), and a bag read as the run goes
@pytest.mark.parametrize("log", [INTEL, HOKUYO_BAG], ids=["carmen", "bag"])
def test_eval_sequence_serve_opens_the_log_at_once_then_its_run_and_stops_on_ctrl_c(tmp_path, log):
    cmd = [sys.executable, "-m", "mbicp_viz", "eval", "sequence", str(log)]
    cmd += ["--out", str(tmp_path / "rows.jsonl"), "--serve", "--port", "0", "--workers", "1"]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
    )
    try:
        deadline, url = time.monotonic() + 120, None
        while url is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            m = re.search(r"open (http://127\.0\.0\.1:\d+) in a browser", line)
            url = m.group(1) if m else None
        assert url, "the debugger did not say where it listens"
        with urllib.request.urlopen(url, timeout=30) as page:  # while the run is matched
            assert page.status == 200
        said = []
        while not any("the run view is open" in x for x in said) and time.monotonic() < deadline:
            said.append(proc.stdout.readline())
        assert (tmp_path / "rows.jsonl").exists()  # the run is written before its view opens
        assert any("pairs matched with improved" in x for x in said)
        os.killpg(proc.pid, signal.SIGINT)
        # ended (as the server stops, or as any interrupted command: 130), without a traceback
        assert proc.wait(timeout=30) in (0, 130)
        assert "Traceback" not in proc.stdout.read()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def test_two_runs_side_by_side_count_as_a_person_would(tmp_path):
    """Improved MbICP and PL-ICP on the Intel excerpt from the identity, scored: where they end
    apart, who is right where the other is wrong, and each disagreeing pair flagged in both."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli
    from mbicp_viz.core import pose_error
    from mbicp_viz.errors import InputError
    from mbicp_viz.evaluation.criteria import CONSECUTIVE
    from mbicp_viz.evaluation.versus import versus
    from mbicp_viz.readers.pair_match import Suspicion
    from mbicp_viz.readers.rows import read_rows

    paths = {}
    for algo in ("improved", "plicp"):
        paths[algo] = tmp_path / f"{algo}.jsonl"
        res = CliRunner().invoke(
            cli,
            ["eval", "sequence", str(INTEL), "--algo", algo, "--guess", "identity"]
            + ["--truth", "pose", "--out", str(paths[algo]), "--workers", "1"],
        )
        assert res.exit_code == 0, res.output
    a, b = read_rows(paths["improved"]), read_rows(paths["plicp"])
    v = versus(a, b, "improved", "plicp")
    apart = [not CONSECUTIVE.judge(x.result.pose, y.result.pose) for x, y in zip(a, b)]
    assert v.differ == [k for k, d in enumerate(apart) if d] and v.differ
    assert all(Suspicion.DISAGREE in v.b[k].flags for k in v.differ)
    b_wins = sum(y.score.success and not x.score.success for x, y in zip(a, b))
    a_wins = sum(x.score.success and not y.score.success for x, y in zip(a, b))
    verdict = "\n".join(v.verdict())
    assert (
        f"B is right where A is wrong on {b_wins} pairs, A right where B is wrong on {a_wins}"
        in (verdict)
    )
    assert f"{len(v.differ)} of {len(a)} pairs end more than" in verdict
    far = v.differing()[0]
    assert far.flags[Suspicion.DISAGREE][0] == max(
        pose_error(x.result.pose, y.result.pose)[0] for x, y in zip(a, b)
    )
    # rows of another frame are refused in one line
    laser = tmp_path / "laser.jsonl"
    CliRunner().invoke(
        cli,
        ["eval", "sequence", str(INTEL), "--frame", "laser", "--limit", "3", "--out", str(laser)],
    )
    assert read_rows(laser)[0].frame != a[0].frame
    with pytest.raises(InputError) as e:
        versus(a, read_rows(laser), "a", str(laser))
    assert e.value.field == "frame" and str(laser) in str(e.value)


def test_bench_run_times_the_run_view(tmp_path):
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli

    rows = tmp_path / "rows.jsonl"
    res = CliRunner().invoke(cli, ["eval", "sequence", str(INTEL), "--out", str(rows)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(cli, ["bench", "run", str(INTEL), str(rows), "--steps", "4"])
    assert res.exit_code == 0, res.output
    steps = next(x for x in res.output.splitlines() if x.startswith("run slider step redraw"))
    assert "(4 steps)" in steps and "open the run" in res.output
    assert "viser" not in res.stdout  # its banner and farewell are no data of the command


def test_bench_page_times_the_run_view_from_the_command_to_the_page(tmp_path):
    """bench page starts `serve LOG --rows ROWS` as a command and loads its page in a headless
    Chromium: listening, page loaded and run view shown come in that order, then steps of the
    run's slider are timed by the page, one right after another and from the page at rest, and
    as many on a bare viser page (this browser's floor), under the name of the renderer that
    drew; the server is ended after each opening (Ctrl-C); a server that cannot open says why in
    one line."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli

    rows = tmp_path / "rows.jsonl"
    res = CliRunner().invoke(cli, ["eval", "sequence", str(INTEL), "--out", str(rows)])
    assert res.exit_code == 0, res.output
    args = ["bench", "page", str(INTEL), str(rows), "--repeat", "2", "--steps", "3"]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    steps = [
        f"{view} step, {how}"
        for view in ("run view", "bare page")
        for how in ("in a row", "at rest")
    ]
    medians = {
        name: float(re.search(rf"^{name}\s+mean\s+\S+ ms\s+median\s+(\S+) ms", res.output, re.M)[1])
        for name in ["listening", "page loaded", "run view shown", *steps]
    }
    assert 0 < medians["listening"] < medians["page loaded"] < medians["run view shown"]
    assert "(2 opens)" in res.output
    # three steps of each kind at each opening, each timed to its pair's words on the page: no
    # step is done before two frames are drawn after its words (60 Hz: 16.7 ms apart)
    assert res.output.count("(6 steps)") == 4
    assert all(medians[name] > 15 for name in steps), medians
    assert re.search(r"^WebGL drawn by \S", res.output, re.M)  # the renderer's name
    left = subprocess.run(["pgrep", "-f", str(rows)], capture_output=True, text=True).stdout
    assert left == "", left  # no server left behind
    res = CliRunner().invoke(cli, ["bench", "page", str(INTEL), str(tmp_path / "none.jsonl")])
    assert res.exit_code == 2 and "serve did not open a page" in res.output
    assert "none.jsonl" in res.output and "Traceback" not in res.output
    res = CliRunner().invoke(  # a browser named is that one, or none
        cli, ["bench", "page", str(INTEL), str(rows), "--browser", str(tmp_path / "no-browser")]
    )
    assert res.exit_code == 2 and "--browser: no browser to run at" in res.output


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 3000),
    most=st.integers(2, 500),
    seed=st.integers(0, 2**32 - 1),
)
def test_a_long_health_timeline_keeps_every_spike(n, most, seed):
    """Thinned for the page, each point is the worst of the pairs it covers (the lowest overlap,
    the largest of the distances) at its first pair: the worst pair of the run stays on the plot;
    the flag line is the share of its pairs flagged."""
    from mbicp_viz.views.debugger.panels import worst_of_each

    rng = np.random.default_rng(seed)
    x = np.arange(1.0, n + 1)
    lines = [rng.uniform(0, 100, n) for _ in range(4)]
    lines[0][rng.random(n) < 0.1] = np.nan  # pairs whose overlap was not measured
    lines[2] = np.where(rng.random(n) < rng.random(), 100.0, 0.0)  # flagged or not
    (tx, *thin), each = worst_of_each((x, *lines), most)
    assert len(tx) <= most and each == max(1, -(-n // most))
    for k, start in enumerate(tx.astype(int) - 1):
        cover = slice(start, start + each)
        overlap = lines[0][cover]
        if np.isfinite(overlap).any():
            assert thin[0][k] == np.nanmin(overlap)
        else:
            assert np.isnan(thin[0][k])
        for i in (1, 3):
            assert thin[i][k] == lines[i][cover].max()
        assert thin[2][k] == pytest.approx(100.0 * np.mean(lines[2][cover] > 0))
    # the run's worst pair of each line is on the plot, and a flag anywhere is
    assert all(thin[i].max() == lines[i].max() for i in (1, 3))
    assert (thin[2] > 0).sum() == sum(lines[2][s : s + each].any() for s in range(0, n, each))
    if np.isfinite(lines[0]).any():
        assert np.nanmin(thin[0]) == np.nanmin(lines[0])


def test_a_slider_step_moves_the_pairs_nodes_in_place(tmp_path):
    """A step of the run's slider sends the new pair's geometry into the nodes already on the page
    (the same handles, their points now the new pair's scans in the world frame, as float32 goes
    over the wire) instead of building the nodes anew."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli
    from mbicp_viz.views.debugger.app import viser_server
    from mbicp_viz.views.debugger.latency import stop_server
    from mbicp_viz.views.debugger.session import Session
    from mbicp_viz.views.debugger.sources import files_source

    rows = tmp_path / "rows.jsonl"
    res = CliRunner().invoke(
        cli, ["eval", "sequence", str(INTEL), "--limit", "12", "--out", str(rows), "--workers", "1"]
    )
    assert res.exit_code == 0, res.output
    server = viser_server("127.0.0.1", 0)
    s = Session(server, files_source(str(INTEL), None, rows=str(rows)))
    try:
        run = s.run
        if not run.active:
            run.switch()
        run.slider.value = 3
        before = dict(run.pair_nodes)
        assert {"/run/reference", "/run/object", "/run/robot"} <= before.keys()
        run.slider.value = 8
        assert all(run.pair_nodes[name] is handle for name, handle in before.items())
        pair = run.model.pair_at(7)
        for name, xy in (("/run/reference", pair.ref_xy), ("/run/object", pair.obj_xy)):
            sent = run.pair_nodes[name].points
            assert sent.dtype == np.float32 and sent.shape == (len(xy), 3)
            np.testing.assert_allclose(sent[:, :2], xy, atol=1e-5)
        robot = run.pair_nodes["/run/robot"]
        np.testing.assert_allclose(robot.position[:2], [pair.pose.x, pair.pose.y], atol=1e-9)
    finally:
        s.close()
        stop_server(server)


def test_a_frame_redrawn_in_place_takes_its_new_size_whole():
    """A frame drawn again at another length keeps its node, and its axes and origin sphere are
    those a frame of that length is drawn with anew (viser sizes the origin from the axes only
    when the node is added)."""
    from mbicp_viz.views import viser_draw
    from mbicp_viz.views.debugger.app import viser_server
    from mbicp_viz.views.debugger.latency import stop_server

    server = viser_server("127.0.0.1", 0)
    try:
        small = scene.Frame(f"{scene.RUN}/robot", Pose2(1.0, 2.0, 0.3), length=0.2)
        nodes = viser_draw.draw_nodes(server.scene, {}, [("/robot", small, True)])
        big = scene.Frame(f"{scene.RUN}/robot", Pose2(-1.0, 0.5, -0.4), length=0.8)
        again = viser_draw.draw_nodes(server.scene, nodes, [("/robot", big, True)])
        fresh = viser_draw.draw(server.scene, "/fresh", big)
        handle = again["/robot"]
        assert handle is nodes["/robot"]
        for prop in ("axes_length", "axes_radius", "origin_radius"):
            assert getattr(handle, prop) == pytest.approx(getattr(fresh, prop))
        np.testing.assert_allclose(handle.position[:2], [-1.0, 0.5])
        np.testing.assert_allclose(handle.wxyz, fresh.wxyz)
    finally:
        stop_server(server)
