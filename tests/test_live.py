"""``mbicp-viz live`` against a real Foxglove SDK WebSocket server publishing real bags' messages
(CDR from a ROS 2 MCAP bag, ROS 1 from a ROS 1 bag) with their original stamps: the live poses are
``eval sequence``'s on the same bag, the buffer saves as a bag every command reads, a restarted
server is reconnected, and a wrong server is one line."""

from __future__ import annotations

import math
import re
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest

from mbicp_viz.core import ImprovedParams, Pose2
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.run_rows import RunRows
from mbicp_viz.evaluation.sequence import match_sequence
from mbicp_viz.live.publisher import FoxgloveRobot
from mbicp_viz.live.run import LiveRun
from mbicp_viz.readers import read_log

from . import bags
from .conftest import wait_for

SCANS = 40
TOPICS = ("/scan", "/odom", "/tf_static")


@pytest.fixture(scope="module", params=["mcap", "ros1"])
def bag(request, intel, tmp_path_factory):
    """A real bag of Intel scans (odometry on /odom, the laser's mount on /tf_static) and the file
    a Foxglove server publishes it from."""
    folder = tmp_path_factory.mktemp("live")
    kind = request.param
    path = folder / ("robot.bag" if kind == "ros1" else "robot")
    bags.write(path, bags.intel_robot(intel, 0, SCANS, Pose2(0.12, -0.03, 0.05)), kind)
    return path, path if kind == "ros1" else next(path.glob("*.mcap"))


def has(run) -> bool:
    """The run has the first message (subscriptions take effect a moment after they are seen)."""
    return run.snapshot()[0].buffer_bytes > 0


def caught_up(run, n: int) -> bool:
    """The run has received ``n`` scans and taken each (matched, or kept as the first)."""
    return run.snapshot()[0].scans >= n and run.wait_idle(0)


def same(a, b) -> bool:
    return (a.ref, a.obj, a.result.pose, a.result.iterations, a.guess, a.guess_source, a.frame) == (
        b.ref,
        b.obj,
        b.result.pose,
        b.result.iterations,
        b.guess,
        b.guess_source,
        b.frame,
    )


def lockstep_run(robot: FoxgloveRobot, path, topics=TOPICS, keyframes=None) -> tuple[LiveRun, list]:
    """Each scan sent once the one before it is matched (a robot slow enough for the matcher):
    every pair equals eval sequence's on the bag at ``path`` (with ``keyframes``, its key-frame
    run's); the run, still connected."""
    run = LiveRun(robot.url, ImprovedParams(), keyframes=keyframes)

    def before_scan(n: int) -> None:
        assert wait_for(lambda: caught_up(run, n), 60), run.snapshot()[0].line()

    robot.publish(topics, rate=10.0, before_scan=before_scan, received=lambda: has(run))
    assert wait_for(lambda: run.snapshot()[0].matched == SCANS - 1, 60)
    status, rows = run.snapshot()
    assert status.skipped == 0 and status.unusable == 0
    expected = match_sequence(read_log(path), ImprovedParams(), workers=1, keyframes=keyframes)
    assert len(rows) == len(expected) == SCANS - 1
    for m, e in zip(rows, expected):
        assert same(m, e), (m.ref, m.obj)
    assert rows[0].frame == "base_link" and rows[0].guess_source == "odometry"
    return run, rows


def test_live_poses_are_eval_sequences_and_the_buffer_saves_as_a_bag(bag, tmp_path):
    path, served = bag
    robot = FoxgloveRobot(served)
    run = None
    try:
        run, _ = lockstep_run(robot, path)
        log = read_log(path)
        # the buffer, saved, is the bag again; a ROS 1 robot's saves as MCAP too (converted)
        outs = [tmp_path / ("saved.bag" if path.suffix == ".bag" else "saved")]
        outs += [tmp_path / "saved-mcap"] if path.suffix == ".bag" else []
        for out in outs:
            assert run.save(out) >= len(robot.messages)
            again = read_log(out)
            assert again.records == SCANS and again.frames.mount == log.frames.mount
            for k in (0, SCANS // 2, SCANS - 1):
                a, b = again.scan(k), log.scan(k)
                assert np.array_equal(a.ranges, b.ranges) and a.stamp == b.stamp
                assert a.odometry == b.odometry
    finally:
        if run is not None:
            run.stop()
        robot.stop()


def test_odometry_on_tf_is_the_guess_as_a_bags_is(intel, tmp_path):
    """A robot whose odometry is only odom -> base_link on /tf (a TurtleBot's): the live pairs
    equal eval sequence's on its bag, guessed from that odometry."""
    path = tmp_path / "robot"
    robot = bags.intel_robot(intel, 0, SCANS, Pose2(0.12, -0.03, 0.05), odometry_on="/tf")
    bags.write(path, robot, "mcap")
    server = FoxgloveRobot(next(path.glob("*.mcap")))
    assert "/odom" not in server.channels
    run = None
    try:
        run, rows = lockstep_run(server, path, ("/scan", "/tf", "/tf_static"))
        assert read_log(path).odometry_source.startswith("tf odom -> base_link")
    finally:
        if run is not None:
            run.stop()
        server.stop()


def test_a_key_frame_run_live_is_eval_sequences_key_frame_run(bag):
    """live --keyframe-m: each scan against the last key frame, as eval sequence --keyframe-m
    matches the bag; the live page's view of it is a run."""
    from mbicp_viz.evaluation.keyframes import KeyFrames
    from mbicp_viz.evaluation.trajectory import is_run

    path, served = bag
    robot = FoxgloveRobot(served)
    run = None
    try:
        run, rows = lockstep_run(robot, path, keyframes=KeyFrames(1.5, math.radians(45.0)))
        assert any(r.obj - r.ref > 1 for r in rows)  # some scans matched across a key frame
        _, log, viewed, _, _ = run.view()
        assert is_run(viewed) and len(viewed) == len(rows) and log.records == SCANS
    finally:
        if run is not None:
            run.stop()
        robot.stop()


def test_scans_that_arrive_two_at_once_are_both_matched(bag):
    """The network delivers scans two at a time, faster than the matcher: neither is skipped, and
    the run is eval sequence's."""
    path, served = bag
    robot = FoxgloveRobot(served)
    run = LiveRun(robot.url, ImprovedParams())
    try:

        def before_scan(n: int) -> None:  # scans 1 and 2, 3 and 4 ... sent together
            assert n % 2 == 0 or wait_for(lambda: caught_up(run, n), 60)

        robot.publish(TOPICS, rate=1e6, before_scan=before_scan, received=lambda: has(run))
        assert wait_for(lambda: run.snapshot()[0].scans == SCANS and run.wait_idle(0), 60)
        status, rows = run.snapshot()
        assert status.skipped == 0 and status.matched == SCANS - 1
        expected = match_sequence(read_log(path), ImprovedParams(), workers=1)
        assert all(same(m, e) for m, e in zip(rows, expected))
    finally:
        run.stop()
        robot.stop()


def test_a_matcher_behind_skips_the_scans_it_would_reach_late_and_says_how_many(intel, tmp_path):
    """A robot faster than any matcher (a scan every 0.5 ms): the scans it would reach more than
    a scan period after they came are skipped and counted; the newest is matched, the pairs still
    chain."""
    path = tmp_path / "fast"
    bags.write(path, bags.intel_robot(intel, 0, SCANS, None, period_s=0.0005), "mcap")
    robot = FoxgloveRobot(next(path.glob("*.mcap")))
    run = LiveRun(robot.url, ImprovedParams(), guess="identity")
    try:

        def before_scan(n: int) -> None:  # the first scan starts the chain, then the rest
            assert n != 1 or wait_for(lambda: caught_up(run, 1), 60)

        robot.publish(("/scan",), rate=1.0, before_scan=before_scan, received=lambda: has(run))
        assert wait_for(lambda: run.snapshot()[0].scans == SCANS, 60)
        assert wait_for(lambda: sum(_taken(run.snapshot()[0])) == SCANS)
        status, rows = run.snapshot()
        assert status.skipped > 0 and status.matched + 1 + status.skipped == SCANS
        assert rows[-1].obj == SCANS - 1  # the newest was matched
        assert all(b.ref == a.obj for a, b in zip(rows, rows[1:]))  # still a chain
        # the page's view numbers the scans it holds, which leave out those skipped: each pair
        # is still the pair of the same two scans, matched alike
        _, log, viewed, _, numbers = run.view()
        assert len(numbers) < SCANS and len(viewed) == len(rows) == log.records - 1
        for v, r in zip(viewed, rows):
            assert (numbers[v.ref], numbers[v.obj]) == (r.ref, r.obj)
            assert log.scan(v.obj).stamp == run.scans[v.obj][1].stamp and v.result == r.result
    finally:
        run.stop()
        robot.stop()


def _taken(s) -> tuple[int, int, int]:
    return s.matched + (s.scans > 0), s.skipped, s.unusable


def test_a_restarted_server_is_reconnected_and_the_buffer_kept(bag, tmp_path):
    _, served = bag
    robot = FoxgloveRobot(served)
    run = LiveRun(robot.url, ImprovedParams())
    half = len(robot.messages) // 2
    try:
        robot.publish(TOPICS, rate=20.0, count=half, received=lambda: has(run))
        assert wait_for(lambda: run.snapshot()[0].scans >= SCANS // 2 - 1)
        robot.stop()
        assert wait_for(lambda: not run.snapshot()[0].connected)
        robot = FoxgloveRobot(served, port=robot.port)  # the bridge comes back
        robot.publish(("/scan", "/odom"), rate=20.0, first=half)
        assert wait_for(lambda: run.snapshot()[0].scans >= SCANS - 1, 60)
        # the matcher goes on after the reconnection, to the last scans (it may still be a pair
        # or two behind when they arrive)
        assert wait_for(lambda: (rows := run.snapshot()[1]) and rows[-1].obj >= SCANS - 2, 60)
        status, rows = run.snapshot()
        assert status.connected and status.reconnects == 1
        assert any("reconnecting (the buffer is kept)" in n for n in status.notes)
        # both halves are in the buffer, the mount of the first half's /tf_static with them
        out = tmp_path / "both.bag" if served.suffix == ".bag" else tmp_path / "both"
        run.save(out)
        assert read_log(out).records >= SCANS - 1
    finally:
        run.stop()
        robot.stop()


def test_the_command_prints_each_pair_serves_the_page_and_ctrl_c_saves_the_buffer(bag, tmp_path):
    """``live URL --save BAG --rrd FILE --serve``: a line per pair on stdout, the live page served
    on 127.0.0.1 meanwhile, and on Ctrl-C the buffer saved as a bag and as a run's .rrd."""
    import urllib.request

    from rerun.chunk import RrdReader

    path, served = bag
    robot = FoxgloveRobot(served)
    out = tmp_path / ("live.bag" if path.suffix == ".bag" else "live")
    rrd = tmp_path / "live.rrd"
    cmd = [sys.executable, "-m", "mbicp_viz", "live", robot.url, "--save", str(out)]
    cmd += ["--rrd", str(rrd), "--serve", "--port", "0"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    said: list[str] = []
    readers = [
        threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True),
        threading.Thread(target=lambda: said.extend(proc.stderr), daemon=True),
    ]
    for r in readers:
        r.start()
    try:
        assert wait_for(lambda: any("the live page is at" in line for line in said), 60), said
        url = next(line for line in said if "the live page is at" in line).split()[-1]
        assert url.startswith("http://127.0.0.1:")
        with urllib.request.urlopen(url, timeout=30) as page:
            assert page.status == 200
        robot.publish(TOPICS, rate=10.0)
        assert wait_for(lambda: len(lines) >= SCANS // 2, 60), said
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 0, said
        for r in readers:
            r.join(10)
        expected = {
            (m.ref, m.obj): m for m in match_sequence(read_log(path), ImprovedParams(), workers=1)
        }
        checked = 0
        for line in lines:
            i, j = (int(v) for v in line.split(":")[0].split()[1::2])
            if j == i + 1:
                p = expected[(i, j)].result.pose
                assert line.startswith(f"scans {i} -> {j}: x {p.x:+.4f} m, y {p.y:+.4f} m, "), line
                checked += 1
        assert checked >= SCANS // 4
        assert any("saved the last" in line for line in said)
        assert read_log(out).records >= SCANS // 2
        saved = next(line for line in said if "saved the buffer's" in line)
        pairs = int(saved.split("buffer's ")[1].split()[0])
        assert pairs >= SCANS // 2 - 1 and not any("Traceback" in line for line in said)
        entities = {c.entity_path for c in RrdReader(str(rrd)).stream().to_chunks()}
        assert any(e.endswith("/trajectory") for e in entities), entities
    finally:
        if proc.poll() is None:
            proc.kill()
        robot.stop()


def test_a_server_that_is_not_a_foxglove_bridge_is_one_line(tmp_path):
    """An HTTP server answers the websocket handshake with a plain page: one line, exit 2."""
    page = subprocess.Popen(
        [sys.executable, "-m", "http.server", "0", "--bind", "127.0.0.1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        cwd=tmp_path,
    )
    try:
        first = page.stdout.readline()  # "Serving HTTP on 127.0.0.1 port N ..."
        port = int(first.split(" port ")[1].split()[0])
        res = subprocess.run(
            [sys.executable, "-m", "mbicp_viz", "live", f"ws://127.0.0.1:{port}"],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert res.returncode == 2 and "Traceback" not in res.stderr
        assert "not a Foxglove WebSocket server" in res.stderr
        assert len(res.stderr.strip().splitlines()) == 1
    finally:
        page.terminate()
        page.wait()


def test_a_server_without_a_scan_topic_is_refused_naming_what_it_offers(bag):
    _, served = bag
    robot = FoxgloveRobot(served)
    robot.channels.pop("/scan").close()  # the robot's laser driver is down
    try:
        run = LiveRun(robot.url, ImprovedParams())
        assert wait_for(lambda: run.error() is not None, 30)
        e = run.error()
        assert isinstance(e, InputError) and "offers no LaserScan topic" in str(e)
        assert "/odom (nav_msgs" in str(e)
        run.stop()
        with pytest.raises(InputError, match="does not offer the LaserScan topic /front"):
            run = LiveRun(robot.url, ImprovedParams(), topic="/front")
            assert wait_for(lambda: run.error() is not None, 30)
            raise run.error()
    finally:
        robot.stop()


def test_a_wrong_url_is_one_line():
    for url, what in (("http://robot:8765", "not a websocket URL"), ("ws://127.0.0.1:1", "cannot")):
        with pytest.raises(InputError, match=what):
            LiveRun(url, ImprovedParams())


def test_the_live_map_grows_by_the_new_scans_and_stays_where_it_was_drawn(bag, tmp_path):
    """The live page's world frame is the first scan it drew, carried along as the buffer drops
    its oldest scans: a scan's pose never moves between refreshes; each refresh adds the map of
    the scans new to it as one node and leaves the nodes drawn before untouched; the map of
    scans that left the buffer is removed."""
    from mbicp_viz.views.debugger.app import viser_server
    from mbicp_viz.views.debugger.live import LiveTab
    from mbicp_viz.views.debugger.run_model import RunModel

    _, served = bag
    robot = FoxgloveRobot(served)
    run = LiveRun(robot.url, ImprovedParams(), buffer_s=4.0)  # 8 scans of a 20 s drive
    server = viser_server("127.0.0.1", 0)
    tab = LiveTab(server, run, tmp_path, None)
    seen: dict[int, object] = {}  # each map node by its last scan's number
    moved, refreshed, removed = [], 0, set()

    def refresh() -> None:
        nonlocal refreshed
        before = dict(tab.world)
        tab._guarded(tab.refresh)
        refreshed += 1
        for g in before.keys() & tab.world.keys():  # placed once, never composed anew
            a, b = before[g].pose, tab.world[g].pose
            moved.append(max(abs(a.x - b.x), abs(a.y - b.y), abs(a.theta - b.theta)))
        parts = {last: node for last, node, _ in tab.map_parts}
        for last, node in parts.items():
            assert seen.setdefault(last, node) is node  # drawn once, kept as it was
        removed.update(seen.keys() - parts.keys())
        assert all(last >= min(tab.world) for last in parts)  # only scans still in the buffer

    def before_scan(n: int) -> None:
        assert wait_for(lambda: caught_up(run, n), 60), run.snapshot()[0].line()
        if n > 1:
            refresh()

    try:
        robot.publish(TOPICS, rate=10.0, before_scan=before_scan, received=lambda: has(run))
        assert wait_for(lambda: caught_up(run, SCANS), 60)
        refresh()
        # placed pair by pair, the page's run is the buffer's run chained whole, in the page's
        # world: its poses, its odometry and its health timeline
        _, log, rows, lags, numbers = run.view()
        model = RunModel(log, rows)
        chain = [tab.world[numbers[k]] for k in model.scans]
        for p, o, got in zip(model.poses, model.odometry, chain):
            for a, b in ((chain[0].pose @ p, got.pose), (chain[0].odometry @ o, got.odometry)):
                assert np.allclose(a.as_array(), b.as_array(), atol=1e-9)
        t = np.array([log.scan(r.obj).stamp for r in rows])
        series = (t - t[-1], *model.series[1:5])
        assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(tab.health.data, series))
        assert np.array_equal(tab.lateness.data[1], 1000 * np.asarray(lags))
    finally:
        tab.close()
        server.stop()
        run.stop()
        robot.stop()
    assert refreshed >= SCANS - 1 and max(moved) == 0.0, max(moved)
    assert min(tab.world) > SCANS // 2  # the buffer dropped its first scans: the frame went on
    assert removed and len(seen) > len(tab.map_parts)


def test_the_live_odometry_track_starts_again_where_odometry_came_back(bag, tmp_path):
    """A robot whose odometry stops for three scans: their pairs have none; the odometry drawn
    is chained from the last scan without it, at that scan's matched pose."""
    from mbicp_viz.evaluation.trajectory import odometry_placed
    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger.app import viser_server
    from mbicp_viz.views.debugger.live import LiveTab
    from mbicp_viz.views.debugger.run_model import RunModel

    _, served = bag
    robot = FoxgloveRobot(served)
    scans = [k for k, m in enumerate(robot.messages) if m[0] == "/scan"]
    lost = range(scans[20], scans[23])  # no odometry from scan 20 to scan 23
    robot.messages = [m for k, m in enumerate(robot.messages) if m[0] != "/odom" or k not in lost]
    run = LiveRun(robot.url, ImprovedParams())
    server = viser_server("127.0.0.1", 0)
    tab = LiveTab(server, run, tmp_path, None)

    def before_scan(n: int) -> None:
        assert wait_for(lambda: caught_up(run, n), 60), run.snapshot()[0].line()

    try:
        robot.publish(TOPICS, rate=10.0, before_scan=before_scan, received=lambda: has(run))
        assert wait_for(lambda: caught_up(run, SCANS), 60)
        tab._guarded(tab.refresh)
        _, log, rows, _, numbers = run.view()
        assert [r.obj for r in rows if r.odometry is None] == [20, 21, 22, 23]
        after = RunRows.of(rows[23:])  # the pairs from scan 23 on
        chain = odometry_placed(
            log, after.column("ref"), after.column("obj"), after.poses("odometry"), "base_link"
        )
        gap = tab.world[numbers[23]]
        for k, p in zip(after.column("obj"), chain[1:]):
            got = tab.world[numbers[k]].odometry
            assert np.allclose((gap.pose @ p).as_array(), got.as_array(), atol=1e-9)
        assert f"/{scene.RUN}/odometry" in tab.nodes
        assert len(RunModel(log, rows).poses) == len(tab.world)
    finally:
        tab.close()
        server.stop()
        run.stop()
        robot.stop()


def test_a_frozen_buffer_opens_in_the_debugger_with_its_pairs_as_matched_live(bag, tmp_path):
    """Freeze: the buffer's run view in a real headless Chromium; "open this pair" opens the pair
    debugger on the pair as it was matched live."""
    from playwright.sync_api import sync_playwright

    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger.app import App
    from mbicp_viz.views.debugger.sources import log_source

    from .test_browser import ARGS, CHROMIUM, open_tab

    _, served = bag
    robot = FoxgloveRobot(served)
    run = LiveRun(robot.url, ImprovedParams(), buffer_s=12.0)  # the last 12 s of a 20 s drive
    try:
        robot.publish(TOPICS, rate=10.0, received=lambda: has(run))
        assert wait_for(lambda: run.snapshot()[0].scans == SCANS, 60)
        assert wait_for(lambda: run.snapshot()[0].matched + run.snapshot()[0].skipped >= SCANS - 2)
        log, rows = run.freeze(tmp_path)
        _, live_rows = run.snapshot()
    finally:
        run.stop()
        robot.stop()
    assert 20 <= log.records <= 27  # 12 s of scans every 0.5 s, give or take the window's ends
    shift = SCANS - log.records
    assert rows[-1].result.pose == live_rows[-1].result.pose and rows[-1].obj + shift == SCANS - 1
    for r in rows:  # the frozen log's scans are the ones matched live
        assert log.scan(r.obj).stamp == pytest.approx(100.0 + 0.5 * (r.obj + shift))
    app = App(log_source("frozen", log, run=rows, rows_label="live"), "127.0.0.1", 0)
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            page, session = open_tab(browser, app)
            legend = page.locator(".mbicp-legend")
            legend.get_by_text(scene.RUN_MAP.label).wait_for(timeout=30000)
            page.screenshot(path=str(tmp_path / "frozen-run.png"))
            page.get_by_role("button", name="open this pair").click()
            row = rows[session.run.n]
            # the pair and its guess, set one after the other by the page's thread: both awaited
            opened = ((row.ref, row.obj), row.guess)
            assert wait_for(lambda: (session.state.pair, session.state.guess) == opened)
            legend.get_by_text(scene.REFERENCE.label, exact=True).wait_for(timeout=30000)
            page.screenshot(path=str(tmp_path / "frozen-pair.png"))
            browser.close()
    finally:
        app.stop()


def test_the_live_page_grows_with_the_run_freezes_opens_a_pair_and_resumes(bag, tmp_path):
    """The live page in a real headless Chromium while a robot drives: the status, the laser's
    mount and the run grow; "freeze" opens the buffer's run view, a pair of it opens as it was
    matched live; "resume" goes live again and follows the scans sent since."""
    from playwright.sync_api import sync_playwright

    from mbicp_viz.views import scene
    from mbicp_viz.views.debugger.app import App

    from .test_browser import ARGS, CHROMIUM

    _, served = bag
    robot = FoxgloveRobot(served)
    run = LiveRun(robot.url, ImprovedParams())
    app = App(None, "127.0.0.1", 0, live=run)
    half = len(robot.messages) // 2

    def lockstep(n: int) -> None:  # each scan sent once the one before is matched
        assert wait_for(lambda: caught_up(run, n), 60), run.snapshot()[0].line()

    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(f"http://127.0.0.1:{app.port}")
            page.get_by_text("Connected: 0 scans").wait_for(timeout=60000)  # before any scan
            robot.publish(TOPICS, 20.0, count=half, before_scan=lockstep, received=lambda: has(run))
            first = sum(m[0] == "/scan" for m in robot.messages[:half])
            assert wait_for(lambda: run.wait_idle(0) and run.snapshot()[0].scans == first)
            matched = run.snapshot()[0].matched
            assert matched == first - 1
            page.get_by_text(f"{matched} matched, 0 skipped to keep up").wait_for(timeout=30000)
            page.get_by_text("laser mount (").wait_for(timeout=30000)
            page.get_by_text("x +0.120 m, y -0.030 m, theta +2.86 deg in base_link").wait_for()
            legend = page.locator(".mbicp-legend")
            for style in (scene.RUN_TRAJECTORY, scene.RUN_MAP, scene.RUN_OBJECT):
                legend.get_by_text(style.label, exact=True).wait_for(timeout=30000)
            legend.get_by_text("the first scan this page drew (base_link)").wait_for()
            page.get_by_text("how far behind the robot").wait_for()
            page.screenshot(path=str(tmp_path / "live.png"))
            tab = next(iter(app.sessions.values()))
            assert wait_for(lambda: tab.drawn and tab.drawn[0] == len(run.view()[2]) == matched)

            page.get_by_role("button", name="freeze").click()
            page.get_by_role("button", name="resume").wait_for(timeout=60000)
            assert wait_for(lambda: tab.session is not None and tab.session.run is not None)
            frozen = tab.session.run.model.rows
            assert len(frozen) == matched
            assert frozen[-1].result.pose == run.snapshot()[1][-1].result.pose
            page.get_by_text(f"{matched} pairs matched with improved").wait_for(timeout=30000)
            page.get_by_role("button", name="open this pair").click()
            row = frozen[tab.session.run.n]
            assert wait_for(lambda: tab.session.state.pair == (row.ref, row.obj))
            legend.get_by_text(scene.REFERENCE.label, exact=True).wait_for(timeout=30000)
            page.screenshot(path=str(tmp_path / "frozen.png"))

            sent = run.snapshot()[0].scans
            then = lambda n: lockstep(n + sent)  # noqa: E731
            robot.publish(("/scan", "/odom"), 20.0, first=half, before_scan=then)
            assert wait_for(lambda: run.wait_idle(0) and run.snapshot()[0].scans == SCANS, 60)
            page.get_by_role("button", name="resume").click()
            page.get_by_role("button", name="freeze").wait_for(timeout=30000)
            matched = run.snapshot()[0].matched
            page.get_by_text(f"{matched} matched, 0 skipped").wait_for(timeout=30000)
            assert matched == SCANS - 1
            assert wait_for(lambda: tab.drawn[:2] == (matched, SCANS - 1))  # the newest pair
            page.screenshot(path=str(tmp_path / "resumed.png"))
            browser.close()
    finally:
        app.stop()
        run.stop()
        robot.stop()


def test_bench_live_reports_what_it_matched_and_how_late(tmp_path):
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli

    from .conftest import HOKUYO_BAG

    res = CliRunner().invoke(
        cli,
        ["bench", "live", "--from", str(HOKUYO_BAG), "--seconds", "2", "--rate-hz", "20", "--page"],
    )
    assert res.exit_code == 0, res.output
    assert "bench live: 41 scans of 1081 beams at 20 Hz over 2 s, improved" in res.output
    got = re.search(r"received (\d+), matched (\d+), skipped (\d+)", res.output)
    received, matched, skipped = (int(g) for g in got.groups())
    assert received == 41 and matched + skipped + 1 == received
    assert re.search(r"median [\d.]+ ms, 95th percentile [\d.]+ ms", res.output)
    assert re.search(r"the live page: [1-9]\d* refreshes, median [\d.]+ ms", res.output)
