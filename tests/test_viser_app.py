"""The viser debugger driven from Python: the real server, GUI handles and scene nodes, no browser.
The model (``DebugState``) is tested without any server."""

import contextlib
import math
import os
import re
import time
from types import SimpleNamespace

import numpy as np
import pytest
import viser

import mbicp_viz.views.debugger.state as st
from mbicp_viz.choices import Guess
from mbicp_viz.core import MATCHERS, Pose2, field_specs, pose_error
from mbicp_viz.readers import read_log
from mbicp_viz.views import scene
from mbicp_viz.views.debugger import panels, report
from mbicp_viz.views.debugger.camera import TopDownCamera
from mbicp_viz.views.debugger.session import Session
from mbicp_viz.views.debugger.sources import files_source, scenario_source
from mbicp_viz.views.debugger.state import DebugState, Source, parse_entry

from .conftest import EXAMPLES, INTEL, LASERAZOS, interpreted_kernels, wait_for

PAIR = EXAMPLES / "hokuyo-125-130.npz"


@pytest.fixture
def server():
    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


def test_the_debuggers_server_lights_a_top_down_view_without_shadows_or_reflections():
    """What every tab is sent first: the default lights casting no shadow and no environment map
    (a browser drawing WebGL in software spent most of a run view's slider step on them)."""
    from viser import _messages

    from mbicp_viz.views.debugger.app import stop_server, viser_server

    s = viser_server("127.0.0.1", 0)
    try:
        sent = list(s._websock_server._broadcast_buffer.message_from_id.values())
    finally:
        stop_server(s)
    (lights,) = [m for m in sent if isinstance(m, _messages.EnableLightsMessage)]
    (environment,) = [m for m in sent if isinstance(m, _messages.EnvironmentMapMessage)]
    assert lights.enabled and not lights.cast_shadow and environment.hdri_data is None


@pytest.fixture
def session(server):
    s = Session(server, Source("hokuyo pair", read_log(PAIR), guess=Pose2()))
    yield s
    s.close()


def submit(panel, **typed):
    """Type each value into its box and press Enter, as a user does."""
    for name, text in typed.items():
        panel.boxes[name].handle.value = f"{text}\n"


def test_opens_on_the_final_iteration_with_a_result(session):
    n = session.state.max_iteration()
    assert n > 5 and session.playback.slider.value == n and session.playback.slider.max == n
    content = session.h_result.content
    assert "improved" in content and "converged" in content and "condition number" in content
    on_ref = re.search(r"([0-9.]+) % of the object points lie within 5 cm", content)
    assert on_ref and 90.0 < float(on_ref.group(1)) <= 100.0  # the hand-held pair, matched
    assert "(motion of the laser frame" in content  # the frame the pose is in (no mount known here)


def test_each_iteration_draws_exactly_the_layers_of_its_own(session, server):
    """Back at the initial guess, the last iteration's pairs and step are gone from the scene (the
    legend dropped them, the scene kept them drawn), and they come back with their iteration."""
    n = session.state.max_iteration()
    at_end = set(session.nodes)
    assert "/improved/scene/pairs/point" in at_end
    session.playback.slider.value = 0
    own = {f"/improved/{ly.path}" for ly in report.layers(session.state, session.state.runs[0])}
    assert set(session.nodes) <= own and "/improved/scene/pairs/point" not in session.nodes
    gone = at_end - set(session.nodes)
    assert gone and not gone & set(server.scene._handle_from_node_name)  # removed from the scene
    session.playback.slider.value = n
    assert set(session.nodes) == at_end


def test_iteration_slider_redraws_without_rematching(session, monkeypatch):
    calls = []
    monkeypatch.setattr(st, "match_pair", lambda *a, **k: calls.append(a))
    run = session.state.runs[0]
    for k in (0, 1, 5, session.state.max_iteration()):
        session.playback.slider.value = k
        obj = session.nodes["/improved/scene/object"]
        expected = (
            run.start.initial_guess.apply(run.start.obj_points[run.start.used])
            if k == 0
            else run.iterations[k - 1].moved_points
        )
        np.testing.assert_allclose(obj.points[:, :2], expected, atol=1e-5)
        assert f"iteration {k}" in session.playback.text.content
    assert calls == []


def test_previous_next_and_play(session):
    import time

    session.playback.slider.value = 3
    session.playback.step(+1)
    assert session.state.iteration == 4
    session.playback.step(-1)
    session.playback.step(-1)
    assert session.state.iteration == 2
    session.playback.fps = 30.0
    session.playback.playing = True
    wait_for(lambda: session.state.iteration != 2, 10.0)
    assert session.state.iteration != 2  # the player advanced
    session.close()  # stops the player even while playing
    at = session.state.iteration
    time.sleep(0.2)
    assert session.state.iteration == at


def test_pairs_by_kind_match_the_events(session):
    k = 3
    session.playback.slider.value = k
    ev = session.state.runs[0].iterations[k - 1]
    kept = ev.pairs.status == 0
    n_inter = int(np.count_nonzero(kept & (ev.pairs.kind == 1)))
    n_rej = int(np.count_nonzero(~kept))
    assert len(session.nodes["/improved/scene/pairs/interpolated"].points) == max(n_inter, 1)
    assert len(session.nodes["/improved/scene/pairs/rejected"].points) == max(n_rej, 1)


def test_layer_toggles_hide_nodes_and_the_legend_lists_what_is_shown(session):
    label = scene.PAIR_REJECTED.label
    assert label in session.h_legend.content
    session.layers.boxes[label].value = False
    assert (
        session.nodes["/improved/scene/pairs/rejected"].visible is False
        and label not in session.h_legend.content
    )
    session.layers.boxes[label].value = True
    assert (
        session.nodes["/improved/scene/pairs/rejected"].visible is True
        and label in session.h_legend.content
    )
    assert scene.HIDDEN.label not in session.h_legend.content  # off by default


def test_typed_parameters_reach_the_matcher_exactly(session):
    panel = session.matchers.params
    submit(panel, errx_out="1e-5", MaxIter="1e2", Bw="12.5")
    p = session.state.params["improved"]
    assert p.errx_out == 1e-5 and p.MaxIter == 100 and p.Bw == pytest.approx(math.radians(12.5))
    assert session.state.runs[0].start.params is p  # the match that is shown ran with them
    # as typed
    assert panel.boxes["errx_out"].handle.value == "1e-5" and panel.message.content == ""


@pytest.mark.parametrize(
    "name, typed, why",
    [
        ("MaxIter", "2.5", "whole number"),
        ("Br", "-1", "below the minimum"),
        ("Bw", "500", "outside"),
        ("L", "nan", "finite"),
        ("L", "1e", "not a number"),
        ("resample", "yes", "true or false"),
    ],
)
def test_refused_entries_say_why_and_keep_the_last_result(session, name, typed, why):
    before = (session.h_result.content, session.state.params["improved"])
    submit(session.matchers.params, **{name: typed})
    assert (
        why in session.matchers.params.message.content
        and name in session.matchers.params.message.content
    )
    assert (session.h_result.content, session.state.params["improved"]) == before
    spec = next(s for s in field_specs(MATCHERS["improved"].params_type) if s.name == name)
    assert session.matchers.params.boxes[name].handle.value == st.shown_value(
        spec, getattr(before[1], name)
    )


def test_an_exception_inside_a_match_is_shown_and_the_server_keeps_serving(session, monkeypatch):
    good = session.h_result.content

    def broken(*a, **k):
        raise ValueError("boom")

    monkeypatch.setattr(st, "match_pair", broken)
    submit(session.matchers.params, Br="0.8")
    assert "boom" in session.h_status.content and session.h_result.content == good
    assert session.state.params["improved"].Br != 0.8  # the failed change is not kept
    monkeypatch.undo()
    submit(session.matchers.params, Br="0.8")
    assert session.state.params["improved"].Br == 0.8 and session.h_status.content == ""


def test_parameter_form_stays_in_place_and_follows_the_matcher(session):
    order = session.matchers.params.folder.order
    session.matchers.edit.value = "icp"
    assert (
        "Parameters: icp" in session.matchers.params.folder.label
        and session.matchers.params.folder.order == order
    )
    assert set(session.matchers.params.boxes) == {
        s.name for s in field_specs(MATCHERS["icp"].params_type)
    }


def test_compare_chosen_matchers_each_in_its_colour(session):
    session.matchers.boxes["icp"].value = True
    assert [r.matcher for r in session.state.runs] == ["icp", "improved"]
    legend = session.h_legend.content
    for name in ("icp", "improved"):
        assert scene.run_style(name).label in legend
        colors = np.asarray(session.nodes[f"/{name}/scene/object"].colors)
        assert (colors == np.array(MATCHERS[name].colour)).all()
    assert (
        "**icp**" in session.playback.text.content
        and "**improved**" in session.playback.text.content
    )
    session.matchers.boxes["improved"].value = False
    session.matchers.boxes["icp"].value = False  # none: refused, the last choice stays
    assert [r.matcher for r in session.state.runs] == [
        "icp"
    ] and "choose at least one" in session.h_status.content


def test_initial_guess_by_numbers_and_by_gizmo(session):
    session.guess.boxes["theta"].handle.value = "-10\n"
    session.guess.boxes["x"].handle.value = "1e-3\n"
    assert (
        session.state.guess.theta == pytest.approx(math.radians(-10.0))
        and session.state.guess.x == 1e-3
    )
    assert session.state.runs[0].start.initial_guess == session.state.guess
    session.guess.gizmo.position = (0.3, -0.2, 0.0)
    session.guess._dragged()
    assert (session.state.guess.x, session.state.guess.y) == pytest.approx((0.3, -0.2))
    assert (
        float(session.guess.boxes["x"].text) == pytest.approx(0.3)
        and "dragged" in session.guess.info.content
    )


def test_the_servers_memory_stays_flat_over_many_exports(session):
    """rerun-sdk keeps ~2.5 MB of every recording stream in its process: 40 exports grew the
    server by ~100 MB when it recorded them itself."""
    from mbicp_viz.views import rrd

    def rss_mb() -> float:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20

    try:
        session.export_rrd()  # the recording process starts
        before = rss_mb()
        for _ in range(40):
            assert len(session.export_rrd()) > 100_000
        assert rss_mb() - before < 25, (before, rss_mb())
    finally:
        rrd.stop_recorder()
    assert rrd._recorder is None


def test_export_writes_a_readable_rrd_and_params(session, tmp_path):
    from rerun.chunk import RrdReader

    from mbicp_viz.readers.params_toml import make_params, read_params

    p = tmp_path / "s.rrd"
    p.write_bytes(session.export_rrd())
    paths = {c.entity_path for c in RrdReader(str(p)).stream().to_chunks()}
    assert "/improved/scene/pairs/point" in paths
    submit(session.guess.search, window_xy="0.75")
    f = tmp_path / "p.toml"
    f.write_text(session.export_params())
    assert make_params("improved", str(f)) == session.state.params["improved"]
    assert read_params(str(f), []).search.window_xy == 0.75


def test_log_source_picks_any_pair(server):
    s = Session(server, files_source(str(LASERAZOS), None))
    assert s.state.pair == (0, 1)
    s.scans.consecutive.value = False
    s.scans.ref.handle.value = "3\n"
    s.scans.obj.handle.value = "7\n"
    assert (
        s.state.pair == (3, 7) and s.state.runs[0].start.ref_points.shape[0] == s.state.ref.n_valid
    )
    s.scans.obj.handle.value = "999\n"
    assert "⚠" in s.h_status.content and s.state.pair == (3, 7) and s.scans.obj.text == "7"
    s.close()


def test_scenario_source_shows_its_note_and_teaching_layers(server):
    src = scenario_source("partial-overlap")
    assert src.truth is not None and src.matchers == ("mbicp", "improved") and src.teaching
    s = Session(server, src)
    assert s.state.visible[scene.ISO_METRIC.label]  # teaching = true: on from the start
    assert scene.TRUTH.label in s.h_legend.content
    s.close()


def test_clicking_a_point_shows_its_iso_distance_curves(session):
    session.playback.slider.value = 2
    run = session.state.runs[0]
    ev = run.iterations[1]
    j = 40
    target = ev.moved_points[j]
    # a ray straight down onto it
    chosen = session.layers.click((target[0], target[1], 10.0), (0.0, 0.0, -1.0))
    assert chosen == int(run.start.used[j])
    node = session.nodes["/improved/scene/teaching/metric_isocurves"]
    assert session.state.visible[scene.ISO_METRIC.label] and node.visible
    row = np.flatnonzero(ev.pairs.obj_index == chosen)[0]
    ellipse = node.points.reshape(-1, 3)[:, :2]
    # one ellipse, on its target
    np.testing.assert_allclose(ellipse.mean(axis=0), ev.pairs.target[row], atol=0.02)


def test_polar_cost_plot_follows_the_iteration(session):
    session.matchers.boxes["pmwn"].value = True
    session.matchers.boxes["improved"].value = False
    session.playback.slider.value = 1
    x, cost, fit = session.plots.cost.data
    np.testing.assert_allclose(cost, session.state.runs[0].iterations[0].polar.cost)
    assert np.isfinite(fit).sum() >= 2 and session.plots.cost.visible  # the V drawn at the minimum
    session.matchers.boxes["mbicp"].value = True
    session.matchers.boxes["pmwn"].value = False
    assert not session.plots.cost.visible  # no cost curve for the MbICP family


def test_search_button_finds_the_guess_a_corridor_needs(server):
    """Intel 12 -> 13: ~1 m along a corridor. From the identity improved MbICP shortens the motion;
    the search puts the guess (numbers and gizmo) near the truth and the match succeeds."""
    s = Session(
        server, Source("intel", read_log(INTEL), pair=(12, 13), pick_pair=True, guess=Pose2())
    )
    truth = s.state.truth()
    assert pose_error(s.state.runs[0].result.pose, truth)[0] > 0.5  # the failed match a user opens
    s.after_match(s.state.search_guess())
    found = s.state.guess
    assert pose_error(found, truth)[0] < 0.15 and "searched" in s.guess.info.content
    assert (float(s.guess.boxes["x"].text), float(s.guess.boxes["y"].text)) == pytest.approx(
        (found.x, found.y)
    )
    assert tuple(s.guess.gizmo.position[:2]) == pytest.approx((found.x, found.y))
    et, er = pose_error(s.state.runs[0].result.pose, truth)
    assert et < 0.05 and er < math.radians(1.0)
    s.close()


def test_picking_a_pair_puts_its_guess_in_the_fields(server):
    s = Session(server, Source("intel", read_log(INTEL), pick_pair=True))
    s.scans.ref.handle.value = (
        "12\n"  # consecutive: object 13; the guess comes from the stored poses
    )
    assert s.state.pair == (12, 13) and s.state.guess_source == "scan poses"
    assert float(s.guess.boxes["x"].text) == pytest.approx(s.state.guess.x)
    assert float(s.guess.boxes["theta"].text) == pytest.approx(math.degrees(s.state.guess.theta))
    s.close()


@pytest.mark.parametrize("name", list(MATCHERS))
def test_every_layer_of_every_matcher_has_a_place_in_both_front_ends(server, name, tmp_path):
    """An unknown layer is an error in both front ends: draw every layer of every iteration of
    every matcher in viser, and write them all to an .rrd."""
    from mbicp_viz.views import viser_draw
    from mbicp_viz.views.rrd import record

    log = read_log(LASERAZOS)
    state = DebugState(Source("laserazos", log, guess=Pose2(0.05, 0.0, 0.05), matchers=(name,)))
    assert state.rematch() is None
    drawn = set()
    for k in range(state.max_iteration() + 1):
        state.iteration = k
        for layer in report.layers(state, state.runs[0]):
            if viser_draw.in_scan_plane(layer):
                viser_draw.draw(server.scene, f"/t/{layer.path}", layer)
                drawn.add(layer.path)
    assert "scene/reference" in drawn and "scene/pairs/point" in drawn
    if name == "pmwn":
        assert "scene/polar/circle_points" in drawn
    record(state.runs, str(tmp_path / "all.rrd"), teaching=True)
    with pytest.raises(TypeError):
        viser_draw.in_scan_plane(
            scene.Points("elsewhere/points", np.zeros((1, 2)), scene.OBJECT, 0.1)
        )


def test_parse_entry_is_exact():
    specs = {s.name: s for s in field_specs(MATCHERS["improved"].params_type)}
    assert parse_entry(specs["errx_out"], " 1e-5 ") == 1e-5
    assert parse_entry(specs["Bw"], "45") == pytest.approx(math.radians(45.0))
    assert parse_entry(specs["MaxIter"], "1e2") == 100 and isinstance(
        parse_entry(specs["MaxIter"], "1e2"), int
    )
    with pytest.raises(Exception, match="whole number"):
        parse_entry(specs["MaxIter"], "2.5")


def test_the_camera_is_put_back_top_down():
    assert TopDownCamera.is_top_down((1.0, 2.0, 10.0), (1.0, 2.0, 0.0), (0.0, 1.0, 0.0))
    # tilted
    assert not TopDownCamera.is_top_down((1.0, 5.0, 10.0), (1.0, 2.0, 0.0), (0.0, 1.0, 0.0))
    # turned
    assert not TopDownCamera.is_top_down((1.0, 2.0, 10.0), (1.0, 2.0, 0.0), (1.0, 0.2, 0.0))


class _Tab:
    """A tab's camera as the server sees it: what the tab last reported, or what was last sent
    (viser's handle keeps both in one state, as here)."""

    def __init__(self):
        self.client = SimpleNamespace(atomic=contextlib.nullcontext)
        self.position, self.look_at = np.array([0.0, 0.0, 10.0]), np.zeros(3)
        self.up_direction, self.fov, self.aspect, self.update_timestamp = (0, 1, 0), 1.0, 1.0, 1.0
        self.client.camera = self

    def report(self, position, look_at, up=(0.0, 1.0, 0.0)):
        self.position, self.look_at, self.up_direction = map(np.asarray, (position, look_at, up))


def test_a_framing_the_tab_overwrote_is_sent_again_and_a_view_of_its_own_is_kept(monkeypatch):
    """A loaded tab's own opening view can land after the view the server placed: once the
    placement has had time to settle, a tab still showing another view gets it again; a person's
    pan after the camera was levelled is theirs."""
    import mbicp_viz.views.debugger.camera as camera

    monkeypatch.setattr(camera, "SETTLE_S", 0.2)
    tab = _Tab()
    cam = TopDownCamera(tab.client)
    cam.fit(np.array([[4.0, 2.0], [6.0, 4.0]]))
    placed = np.array(tab.look_at)
    assert np.allclose(placed, [5.0, 3.0, 0.0])
    tab.report((0.0, 0.0, 10.0), (0.0, 0.0, 0.0))  # the tab's opening view, top-down at 0
    cam.level(tab)
    assert wait_for(lambda: np.allclose(tab.look_at, placed), 5)
    assert TopDownCamera.is_top_down(tab.position, tab.look_at, tab.up_direction)
    assert wait_for(lambda: time.monotonic() > cam.placed_at + camera.SETTLE_S)

    tab.report((1.0, 4.0, 10.0), (1.0, 1.0, 0.0))  # tilted by a drag: levelled where it looks
    cam.level(tab)
    assert wait_for(lambda: TopDownCamera.is_top_down(tab.position, tab.look_at, tab.up_direction))
    assert np.allclose(tab.look_at, [1.0, 1.0, 0.0])
    tab.report((2.0, 2.0, 10.0), (2.0, 2.0, 0.0))  # panned on at once: not pulled back
    cam.level(tab)
    settled = cam.placed_at + camera.SETTLE_S
    assert wait_for(lambda: time.monotonic() > settled + 0.2 and not cam.recheck.is_alive(), 5)
    assert np.allclose(tab.look_at, [2.0, 2.0, 0.0])


def test_guess_kind_of_the_source_and_where_it_came_from():
    state = DebugState(files_source(str(INTEL), None, (12, 13), Guess.identity))
    assert state.guess == Pose2() and state.guess_source == "identity"
    assert state.truth() is not None  # the log's scan poses judge a guess not taken from them


def test_a_foreign_origin_is_refused():
    """A page of another site opens the debugger's websocket: closed before any data flows."""
    import asyncio

    import viser
    import websockets
    from websockets.asyncio.client import connect

    async def attempt(origin):
        async with connect(
            f"ws://127.0.0.1:{app.port}",
            origin=origin,
            subprotocols=[f"viser-v{viser.__version__}"],
        ) as ws:
            try:
                await asyncio.wait_for(ws.recv(), timeout=10)
                return "data"
            except websockets.ConnectionClosed as e:
                return e.rcvd.code if e.rcvd else None

    from mbicp_viz.views.debugger.app import App

    app = App(Source("hokuyo pair", read_log(PAIR), guess=Pose2()), "127.0.0.1", 0)
    try:
        assert asyncio.run(attempt("http://evil.example")) == 1008
        assert "http://evil.example" in app.refused.values() and not app.sessions
        # the debugger's own page
        assert asyncio.run(attempt(f"http://127.0.0.1:{app.port}")) == "data"
    finally:
        app.stop()


def test_no_connection_is_accepted_before_the_origin_rule(monkeypatch):
    """A foreign page that connects in a loop from the moment the port opens, while the server is
    still starting, is refused every time: no window before the check is in place."""
    import asyncio
    import socket
    import threading
    import time

    import websockets
    from websockets.asyncio.client import connect

    from mbicp_viz.views.debugger.app import App

    with socket.socket() as s:  # a free port, known before the server opens it
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    connected, built, outcomes = threading.Event(), threading.Event(), []
    fit = TopDownCamera.fit

    def fit_once_a_probe_got_in(camera, points):  # a start slowed by a compile, deterministically
        assert connected.wait(60)
        return fit(camera, points)

    monkeypatch.setattr(TopDownCamera, "fit", fit_once_a_probe_got_in)

    async def probe():
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and not (built.is_set() and len(outcomes) >= 3):
            try:
                async with connect(
                    f"ws://127.0.0.1:{port}",
                    origin="http://evil.example",
                    subprotocols=[f"viser-v{viser.__version__}"],
                ) as ws:
                    try:
                        await asyncio.wait_for(ws.recv(), timeout=10)
                        outcomes.append("data")
                    except websockets.ConnectionClosed as e:
                        outcomes.append(e.rcvd.code if e.rcvd else None)
                connected.set()
            except OSError:  # not listening yet
                await asyncio.sleep(0)

    prober = threading.Thread(target=lambda: asyncio.run(probe()))
    prober.start()
    app = App(Source("hokuyo pair", read_log(PAIR), guess=Pose2()), "127.0.0.1", port)
    built.set()
    prober.join(120)
    try:
        assert len(outcomes) >= 3 and set(outcomes) == {1008}, outcomes
        assert not app.sessions
    finally:
        app.stop()


def test_a_tab_says_it_waits_for_the_kernels_then_shows_its_result(server):
    import threading

    from mbicp_viz.views.debugger.session import COMPILING

    ready = threading.Event()
    s = Session(server, Source("hokuyo pair", read_log(PAIR), guess=Pose2()), ready=ready)
    assert s.h_status.content == panels.warning(COMPILING) and not s.state.runs  # built, waiting
    ready.set()
    s.first_match(ready)
    assert s.state.runs and s.h_status.content == "" and "converged" in s.h_result.content
    s.close()


def test_while_the_kernels_compile_in_the_background_a_tab_matches_interpreted_and_says_so(server):
    from mbicp_viz.core import tiers
    from mbicp_viz.core.tiers import INTERPRETED

    source = Source("hokuyo pair", read_log(PAIR), guess=Pose2())
    compiled = Session(server, source).state.runs[0].result
    with interpreted_kernels():
        s = Session(server, source)
        assert (
            tiers.compiling()
            and s.h_status.content == panels.warning(INTERPRETED)
            and "converged" in s.h_result.content
        )
    assert (
        s.state.runs[0].result.pose == compiled.pose
        and s.state.runs[0].result.iterations == compiled.iterations
    )
    s.compiled()  # the background compile ended
    assert s.h_status.content == ""
    s.close()


def test_lesson_mode_opens_each_step_and_refuses_a_forged_step(server):
    from mbicp_viz.views.debugger.lesson import step_source
    from mbicp_viz.views.lesson.steps import load_lesson

    steps = tuple(load_lesson())
    s = Session(server, step_source(steps[0], steps))
    assert s.lesson is not None and "Step 1 of" in s.lesson.heading.content
    s.lesson.open(5)
    assert (
        s.state.matchers == list(steps[5].scenario.params)
        and "Step 6 of" in s.lesson.heading.content
    )
    assert s.lesson.pick.value.startswith("6.")
    n = len(steps)
    s.lesson.open(n + 5)  # past the end: the last step
    assert f"Step {n} of {n}" in s.lesson.heading.content
    s.lesson.pick._impl.value = "no such step"  # what a forged browser message leaves in the box
    s.lesson._picked()
    assert "no such step" in s.h_status.content and f"Step {n} of {n}" in s.lesson.heading.content
    assert s.lesson.pick.value.startswith(f"{n}.")
    s.close()
    third = Session(server, step_source(steps[2], steps))  # `mbicp-viz lesson --step 3`
    assert (
        "Step 3 of" in third.lesson.heading.content and third.state.iteration == steps[2].iteration
    )
    third.close()


def test_lesson_mode_compiles_every_steps_matchers_while_the_server_starts(monkeypatch):
    """A later step must not stall on compilation: the warm-up runs every matcher of the lesson."""
    import mbicp_viz.views.debugger.app as app_module
    from mbicp_viz.core import matcher_for
    from mbicp_viz.views.debugger.lesson import step_source
    from mbicp_viz.views.lesson.steps import load_lesson

    warmed = []
    monkeypatch.setattr(
        app_module, "match", lambda ref, obj, guess, p: warmed.append(matcher_for(p).name)
    )
    steps = tuple(load_lesson())
    app = app_module.App(step_source(steps[0], steps), "127.0.0.1", 0)
    try:
        assert app.ready.wait(60)
        assert set(warmed) == {name for s in steps for name in s.scenario.params} and len(
            warmed
        ) == len(set(warmed))
    finally:
        app.stop()


def test_a_box_typed_without_enter_says_it_is_not_applied(session):
    panel = session.matchers.params
    before = session.state.params["improved"].Bw
    panel.boxes["Bw"].handle.value = "60"  # typed, no Enter
    assert panel.message.content == panels.warning(
        "Bw [deg]: '60' is not applied yet: Enter applies it"
    )
    assert session.state.params["improved"].Bw == before
    submit(panel, Bw="60")  # Enter
    assert "not applied" not in panel.message.content
    assert session.state.params["improved"].Bw == pytest.approx(math.radians(60))


def test_the_run_view_shows_its_map_up_to_the_pair_and_hides_the_pairs_plots(server, tmp_path):
    """The run opens on the whole run, never first on its pair's scene; the map's chunks are shown
    exactly when the pair in view has passed them, forwards and back. The pair's plots are hidden
    while the run is shown (they are the pair debugger's match, not in view), and back with the
    pair."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app as cli

    rows = tmp_path / "rows.jsonl"
    res = CliRunner().invoke(cli, ["eval", "sequence", str(INTEL), "--out", str(rows)])
    assert res.exit_code == 0, res.output
    s = Session(server, files_source(str(INTEL), None, rows=str(rows)))
    run = s.run
    assert run.active and not s.plots.folder.visible and s.nodes == {}
    n = len(run.model.rows)
    (chunks,) = run.chunk_nodes
    for k in (n, n // 2, 1):
        run.slider.value = k
        whole = run.model.whole_chunks(k - 1)
        assert [h.visible for h in chunks] == [c < whole for c in range(len(chunks))]
    assert 0 < run.model.whole_chunks(n // 2 - 1) < len(chunks)
    run.switch()  # back to the pair
    assert not run.active and run.chunk_nodes == [] and s.plots.folder.visible and s.nodes
    s.close()


def test_the_error_plot_reads_mm2_so_a_converged_match_keeps_its_tick_labels(session):
    """uPlot writes at most three decimals on a tick: the bundled pair's converged error in m²
    would read "0" at every tick of its axis. The page plots it in mm², and says so."""
    run = session.state.runs[0]
    errors = np.array([e.error for e in run.iterations])
    _, err, _ = session.plots.error.data
    np.testing.assert_allclose(err[: len(errors)], errors * 1e6)
    assert errors[-1] < 5e-4 <= err[len(errors) - 1]  # "0" in m², a number in mm²
    assert [a["label"] for a in session.plots.error.axes][1] == "error [mm²]"
    assert session.plots.error.series[1]["label"] == "improved: mean squared residual [mm²]"
