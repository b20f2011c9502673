"""The viser debugger driven from Python: the real server, GUI handles and scene nodes, no browser."""

import math
import re

import numpy as np
import pytest
import viser

import mbicp_viz.viser_app as va
from core import Pose2
from mbicp_viz.readers import read_log
from mbicp_viz.rrd import Run  # noqa: F401  (the export path imports it lazily; fail early if broken)
from mbicp_viz.viser_app import COMPARE, Session, Source, source_for

from .conftest import EXAMPLES, LASERAZOS

PAIR = EXAMPLES / "hokuyo-125-130.npz"


@pytest.fixture
def server():
    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


@pytest.fixture
def session(server):
    s = Session(server, Source("hokuyo pair", read_log(PAIR), guess=Pose2()))
    yield s
    s.close()


def test_opens_on_the_final_iteration_with_a_result(session):
    n = session.max_iteration()
    assert n > 5 and session.h_iter.value == n and session.h_iter.max == n
    assert "improved" in session.h_result.content and "converged" in session.h_result.content
    assert "condition number" in session.h_result.content
    on_ref = re.search(r"within 5 cm of the reference: ([0-9.]+) %", session.h_result.content)
    assert on_ref and 90.0 < float(on_ref.group(1)) <= 100.0  # the hand-held pair, matched


def test_iteration_slider_redraws_without_rematching(session, monkeypatch):
    calls = []
    monkeypatch.setattr(va, "run_match", lambda *a, **k: calls.append(a))
    run = session.runs[0]
    for k in (0, 1, 5, session.max_iteration()):
        session.h_iter.value = k
        obj = session.nodes["/improved/scene/object"]
        if k == 0:
            expected = run.start.initial_guess.apply(run.start.obj_points[run.start.used])
        else:
            expected = run.iterations[k - 1].moved_points
        np.testing.assert_allclose(obj.points[:, :2], expected, atol=1e-5)
        assert f"iteration {k}" in session.h_iter_info.content
    assert calls == []


def test_previous_next_and_play(session):
    session.h_iter.value = 3
    session.step(+1)
    assert session.iteration == 4
    session.step(-1)
    session.step(-1)
    assert session.iteration == 2
    session.fps = 30.0
    session.playing = True
    import time

    time.sleep(0.5)
    session.playing = False
    assert session.iteration != 2  # the player advanced
    session.playing = True
    session.close()  # stops the player even while playing
    at = session.iteration
    time.sleep(0.2)
    assert session.iteration == at


def test_pairs_by_kind_match_the_events(session):
    k = 3
    session.h_iter.value = k
    ev = session.runs[0].iterations[k - 1]
    kept = ev.pairs.status == 0
    n_inter = int(np.count_nonzero(kept & (ev.pairs.kind == 1)))
    n_rej = int(np.count_nonzero(~kept))
    assert len(session.nodes["/improved/scene/pairs/interpolated"].points) == max(n_inter, 1)
    assert len(session.nodes["/improved/scene/pairs/rejected"].points) == max(n_rej, 1)


def test_layer_toggles_hide_nodes(session):
    session._on_layer("rejected pairs", False)
    assert session.nodes["/improved/scene/pairs/rejected"].visible is False
    session._on_layer("rejected pairs", True)
    assert session.nodes["/improved/scene/pairs/rejected"].visible is True


def test_parameter_change_rematches_and_updates_the_result(session):
    before = session.h_result.content
    assert session.set_param("improved", "MaxIter", 3)
    assert session.max_iteration() == 3 and "3 iterations" in session.h_result.content
    assert session.h_result.content != before


def test_invalid_entries_show_a_message_and_keep_the_last_result(session):
    before = (session.h_result.content, session.params["improved"])
    for name, value in (("Br", -1.0), ("L", float("nan")), ("Bw", 500.0), ("MaxIter", 2.5)):
        assert not session.set_param("improved", name, value)
        assert "⚠" in session.h_param_msg.content and name in session.h_param_msg.content
        assert (session.h_result.content, session.params["improved"]) == before


def test_an_exception_inside_a_match_is_shown_and_the_server_keeps_serving(session, monkeypatch):
    good = session.h_result.content

    def broken(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(va, "run_match", broken)
    assert not session.set_param("improved", "Br", 0.8)
    assert "boom" in session.h_status.content and session.h_result.content == good
    assert session.params["improved"].Br != 0.8  # the failed change is not kept
    monkeypatch.undo()
    assert session.set_param("improved", "Br", 0.8) and session.h_status.content == ""


def test_algorithm_dropdown_and_compare(session):
    session.h_algo.value = "icp"
    assert [r.name for r in session.runs] == ["icp"] and "Parameters: icp" in session.param_folder.label
    session.h_algo.value = COMPARE
    assert [r.name for r in session.runs] == ["icp", "mbicp", "improved", "psm", "pmwn"]
    assert "/mbicp/scene/object" in session.nodes and "/icp/scene/object" in session.nodes


def test_initial_guess_by_numbers_and_by_gizmo(session):
    session.h_gt.value = -10.0
    assert session.guess.theta == pytest.approx(math.radians(-10.0))
    assert session.runs[0].start.initial_guess == session.guess
    session.gizmo.position = (0.3, -0.2, 0.0)
    session._on_gizmo()
    assert (session.guess.x, session.guess.y) == pytest.approx((0.3, -0.2))
    assert session.h_gx.value == pytest.approx(0.3)


def test_export_writes_a_readable_rrd_and_params(session, tmp_path):
    from rerun.chunk import RrdReader

    data = session.export_rrd()
    p = tmp_path / "s.rrd"
    p.write_bytes(data)
    paths = {c.entity_path for c in RrdReader(str(p)).stream().to_chunks()}
    assert "/improved/scene/pairs/point" in paths
    text = session.export_params()
    f = tmp_path / "p.toml"
    f.write_text(text)
    from mbicp_viz.params_io import load_params

    assert load_params(str(f), "improved") == session.params["improved"]


def test_log_source_picks_any_pair(server):
    s = Session(server, source_for(str(LASERAZOS), None, None))
    assert s.pair == (0, 1)
    s.h_consecutive.value = False
    s.h_ref.value = 3
    s.h_obj.value = 7
    assert s.pair == (3, 7) and s.runs[0].start.ref_points.shape[0] == s.ref.n_valid
    s.h_obj.value = 999
    assert "⚠" in s.h_status.content and s.pair == (3, 7)


def test_scenario_source():
    src = source_for(None, None, "partial-overlap")
    assert src.truth is not None and set(src.params) == {"mbicp", "improved"}


def test_clicking_a_point_shows_its_iso_distance_curves(session):
    session.h_iter.value = 2
    run = session.runs[0]
    ev = run.iterations[1]
    j = 40
    target = ev.moved_points[j]
    # a view ray from above, straight down onto that point
    chosen = session.click((target[0], target[1], 10.0), (0.0, 0.0, -1.0))
    assert chosen == int(run.start.used[j])
    assert session.visible["iso-distance curves"] and session.nodes["/improved/scene/teaching/metric_isocurves"].visible
    row = np.flatnonzero(ev.pairs.obj_index == chosen)[0]
    ellipse = session.nodes["/improved/scene/teaching/metric_isocurves"].points.reshape(-1, 3)[:, :2]
    # one ellipse, centred on that point's target
    np.testing.assert_allclose(ellipse.mean(axis=0), ev.pairs.target[row], atol=0.02)


def test_polar_cost_plot_follows_the_iteration(session):
    session.h_algo.value = "pmwn"
    session.h_iter.value = 1
    x, cost, fit = session.h_cost.data
    polar = session.runs[0].iterations[0].polar
    np.testing.assert_allclose(cost, polar.cost)
    assert np.isfinite(fit).sum() >= 2  # the V drawn at the minimum
    session.h_algo.value = "mbicp"
    assert len(session.h_cost.data[0]) == 1  # no cost curve for the MbICP family


def test_search_button_finds_the_guess_a_corridor_needs(server):
    """Intel 12 -> 13: ~1 m along a corridor. From the identity improved MbICP shortens the motion;
    the search button puts the guess (numbers and gizmo) near the truth and the match succeeds."""
    from core import pose_error

    from .conftest import INTEL

    s = Session(server, Source("intel", read_log(INTEL), pair=(12, 13), pick_pair=True, guess=Pose2()))
    truth = s.truth()
    assert pose_error(s.runs[0].result.pose, truth)[0] > 0.5  # the failed match a user opens
    found = s.search_guess()
    assert pose_error(found, truth)[0] < 0.15
    assert (s.h_gx.value, s.h_gy.value) == pytest.approx((found.x, found.y))
    assert tuple(s.gizmo.position[:2]) == pytest.approx((found.x, found.y))
    et, er = pose_error(s.runs[0].result.pose, truth)
    assert et < 0.05 and er < math.radians(1.0) and "searched around the guess" in s.h_status.content


def test_picking_a_pair_puts_its_guess_in_the_fields(server):
    s = Session(server, Source("intel", read_log(EXAMPLES / "intel-excerpt.log.gz"), pick_pair=True))
    s.h_ref.value = 12  # consecutive: object 13; the guess comes from the stored poses
    assert s.pair == (12, 13)
    assert (s.h_gx.value, s.h_gy.value) == pytest.approx((s.guess.x, s.guess.y))
    assert s.h_gt.value == pytest.approx(math.degrees(s.guess.theta))
