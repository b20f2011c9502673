"""Corridors (paper 000 §3.3): improved MbICP's ``hold_weak`` keeps the guess along a free axis,
says so in its events and both front ends draw it; ``eval corridor`` counts successes there."""

import math

import numpy as np
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import ImprovedParams, Pose2, Recorder, match
from mbicp_viz.evaluation.corridor import surface_condition
from mbicp_viz.evaluation.pairs import stored_truth
from mbicp_viz.evaluation.single import Setup, match_pair
from mbicp_viz.readers import read_log
from mbicp_viz.views import scene, viser_draw
from mbicp_viz.views.debugger import report
from mbicp_viz.views.debugger.state import DebugState, Source
from mbicp_viz.views.rrd import record
from mbicp_viz.views.text import iteration_text

from .conftest import DATA

ROOT = DATA.parent.parent


def corridor_pair():
    """The corridor scenario's real pair (Intel 187 -> 188, 1 m along a corridor) and its truth."""
    log = read_log(ROOT / "recordings" / "inputs" / "intel-corridor-187-188.log")
    return log, stored_truth(*log.scans)


def test_hold_keeps_the_guess_along_the_corridor_and_says_so():
    log, truth = corridor_pair()
    guess = Pose2(truth.x - 0.05, truth.y, truth.theta + math.radians(1.0))
    free = match(*log.scans, guess, ImprovedParams())
    rec = Recorder()
    held_run = match(*log.scans, guess, ImprovedParams(hold_weak=30.0), rec)
    held = [e.held for e in rec.iterations if e.held is not None]
    assert held and all(h.condition_number > 30.0 for h in held)
    u = np.array(
        [math.cos(math.radians(held[-1].heading_deg)), math.sin(math.radians(held[-1].heading_deg))]
    )
    assert abs(u[0]) > 0.95  # the corridor runs along the robot's x axis (it drove 1 m forward)
    along = lambda p: abs((np.array([p.x, p.y]) - [guess.x, guess.y]) @ u)  # noqa: E731
    # held: the estimate stays with the guess there
    assert along(held_run.pose) < 0.5 * along(free.pose)
    assert "held along heading" in iteration_text(rec.iterations[0])


def test_held_direction_is_drawn_in_both_front_ends(tmp_path):
    import viser

    log, truth = corridor_pair()
    assert surface_condition(*log.scans, truth) > 30.0  # the corridor scenario's pair is degenerate
    params = ImprovedParams(hold_weak=30.0)
    state = DebugState(
        Source(
            "corridor",
            log,
            guess=Pose2(truth.x + 0.05, truth.y, truth.theta),
            params={"improved": params},
        )
    )
    assert state.rematch() is None
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        drawn = []
        for k in range(1, state.max_iteration() + 1):
            state.iteration = k
            for layer in report.layers(state, state.runs[0]):
                if isinstance(layer, scene.Segments) and layer.style is scene.HELD:
                    viser_draw.draw(server.scene, f"/t/{k}", layer)
                    drawn.append(layer)
        assert drawn and all(np.linalg.norm(ly.ends - ly.starts) > 0 for ly in drawn)
    finally:
        server.stop()
    held = match_pair(state.ref, state.obj, params, Setup(state.guess), record=True)
    record([held], str(tmp_path / "held.rrd"))
    from rerun.chunk import RrdReader

    assert "/improved/scene/held" in {
        c.entity_path for c in RrdReader(str(tmp_path / "held.rrd")).stream().to_chunks()
    }


def test_eval_corridor_counts_degenerate_pairs_and_the_others():
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "corridor",
            str(DATA / "intel-relations.log"),
            "--algos",
            "icp,improved",
            "--perturb",
            "0.05",
            "2",
            "--condition",
            "1",
            "--workers",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    lines = res.stdout.strip().splitlines()
    n = int(lines[0].split()[0])
    # every pair is above 1
    assert lines[0].endswith("(surface condition number above 1)") and n == 11
    assert (
        lines[1].startswith("icp ") and lines[2].startswith("improved ") and f"/{n} (" in lines[1]
    )
    bad = CliRunner().invoke(
        app, ["eval", "corridor", str(DATA / "intel-relations.log"), "--perturb", "-1", "2"]
    )
    assert bad.exit_code == 2 and "--perturb" in bad.output
