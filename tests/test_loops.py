"""Loop closures (evaluation/loops.py): the chain's uncertainty, candidates verified by real scan
matches, a pose graph on the real GTSAM that turns off a wrong closure, and the score with loops
closed on the command line."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import ImprovedParams, MatchResult, Pose2, Termination, relative
from mbicp_viz.evaluation.keyframes import KeyFrames
from mbicp_viz.evaluation.loops import (
    ChainUncertainty,
    Closure,
    LoopParams,
    LoopRun,
    PoseGraph,
    close_loops,
)
from mbicp_viz.readers import read_log
from mbicp_viz.readers.pair_match import PairMatch, Verdict
from mbicp_viz.readers.rows import rows_of_log
from mbicp_viz.views import scene

from .conftest import DATA, HOKUYO_BAG

runner = CliRunner()

steps = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-0.5, 0.5)).map(lambda s: Pose2(*s))
sigmas = st.tuples(st.floats(0.001, 0.1), st.floats(0.001, 0.1), st.floats(0.001, 0.05))


def chain(motions: list[Pose2]) -> list[Pose2]:
    out = [Pose2()]
    for m in motions:
        out.append(out[-1] @ m)
    return out


@settings(max_examples=40)
@given(st.lists(st.tuples(steps, sigmas), min_size=1, max_size=8), st.data())
def test_the_chain_uncertainty_is_the_first_order_propagation_of_its_edges(edges, data):
    """Against the Jacobian of the last position in every edge's noise, taken numerically."""
    motions = [m for m, _ in edges]
    covs = [np.diag(np.square(s)) for _, s in edges]
    poses = chain(motions)
    n = len(poses) - 1
    j = data.draw(st.integers(0, n - 1))
    h, jac = 1e-6, []
    for e in range(j, n):  # the edges between key frame j and n
        for axis in range(3):
            d = np.zeros(3)
            d[axis] = h
            # a match's covariance is on its motion's parameters (x, y in the frame it starts from);
            # central differences, so the Jacobian's own error (O(h^2)) is far below the tolerance
            ends = []
            for sign in (1, -1):
                moved = list(motions)
                moved[e] = Pose2(*(motions[e].as_array() + sign * d))
                q = relative(chain(moved)[j], chain(moved)[n])
                ends.append(np.array([q.x, q.y]))
            jac.append(((ends[0] - ends[1]) / (2 * h), covs[e][axis, axis]))
    # in the world frame: the relative position's covariance turned by key frame j's heading
    r = np.array(
        [
            [math.cos(poses[j].theta), -math.sin(poses[j].theta)],
            [math.sin(poses[j].theta), math.cos(poses[j].theta)],
        ]
    )
    expected = sum(var * r @ np.outer(g, g) @ r.T for g, var in jac)
    got = ChainUncertainty(poses, covs).position_covariances(n)[j]
    assert np.allclose(got, expected, rtol=1e-3, atol=1e-9)


def closure(old: int, key: int, motion: Pose2, judged: Verdict = Verdict.ACCEPTED) -> Closure:
    cov = np.diag(np.square([0.02, 0.02, math.radians(0.5)]))
    r = MatchResult("improved", motion, True, Termination.CONVERGED, 5, 0.0, 300, 0, cov, None)
    m = PairMatch(old, key, ImprovedParams(), Pose2(), "", r, "laser")
    return Closure(old, key, m, judged, judged, 0.1, None)


# A robot drives a 4 m square three times, its heading drifting 0.01 rad a step
LAP = ([Pose2(0.5, 0.0, 0.0)] * 7 + [Pose2(0.5, 0.0, math.pi / 2)]) * 4  # 32 steps
TRUTH = chain(LAP * 3)
DRIFT = [Pose2(m.x, m.y, m.theta + 0.01) for m in LAP * 3]
STEP_COV = np.diag(np.square([0.01, 0.01, math.radians(0.5)]))


def square_closures(judged: Verdict = Verdict.ACCEPTED) -> tuple[list[Closure], Closure]:
    """The square's right closures, lap to lap, and a wrong one (a place 3 m away taken for this
    one), judged ``judged`` by its match."""
    right = [closure(k, k + 32, relative(TRUTH[k], TRUTH[k + 32])) for k in range(2, 64, 5)]
    return right, closure(10, 42, relative(TRUTH[10], TRUTH[42]) @ Pose2(3.0, 0.0, 0.0), judged)


def off_at_home(poses: list[Pose2]) -> float:
    return math.hypot(poses[-1].x - TRUTH[-1].x, poses[-1].y - TRUTH[-1].y)


def test_graduated_non_convexity_turns_off_the_wrong_closure_of_a_square():
    """The right closures bring the robot home, the wrong one is turned off."""
    graph, estimate = PoseGraph(), chain(DRIFT)
    for n, m in enumerate(DRIFT, start=1):
        graph.add_step(m, STEP_COV, estimate[n])
    right, wrong = square_closures()
    for c in [*right, wrong]:
        graph.add_closure(c.old, c.key, c)
    graph.optimise()
    assert graph.turned_off() == [wrong]
    assert off_at_home([graph.pose(len(DRIFT))]) < 0.2
    assert off_at_home(chain(DRIFT)) > 2.0  # the chain alone


@pytest.mark.parametrize("judged", [Verdict.ACCEPTED, Verdict.LOW_OVERLAP])
def test_closures_decided_by_hand_solve_the_graph_again(judged):
    """The square as a run: the wrong closure forced in by hand stays in and bends the map
    (whether its match passed or not); the right ones rejected by hand leave the chain; no
    decision gives the run back."""
    right, wrong = square_closures(judged)
    n = len(DRIFT) + 1
    edges = [(m, STEP_COV) for m in DRIFT]
    drifted = chain(DRIFT)
    run = LoopRun(
        list(range(n)), list(range(n)), edges, [*right, wrong], drifted, drifted, [0.0]
    ).decided({})
    expected = Verdict.INCONSISTENT if judged is Verdict.ACCEPTED else judged
    assert [c.verdict for c in run.closures] == [Verdict.ACCEPTED] * len(right) + [expected]
    assert off_at_home(run.optimised) < 0.2
    assert run.moved(run.decided({})).max() < 1e-6
    # a key frame a lap on without a candidate says where the nearest old one lies (10 m or more
    # back along the run: key frames 0 to 13 for key frame 33, 16.5 m along)
    here = run.optimised[33]
    near = min(
        range(14), key=lambda j: math.dist(run.optimised[j].as_array()[:2], [here.x, here.y])
    )
    said = run.around(33)
    old = "no loop candidate; the nearest old key frame (10 m or more back along the run)"
    assert f"{old} is scan {near}," in said
    a, b = run.optimised[33], run.optimised[near]
    assert f"{math.hypot(a.x - b.x, a.y - b.y):.2f} m away" in said

    forced = run.decided({len(right): True})
    c = forced.closures[-1]
    assert c.accepted and c.by_hand and c.says() == f"accepted by hand (its match: {judged})"
    assert off_at_home(forced.optimised) > 0.5 and run.moved(forced).max() > 0.5

    none = run.decided({k: False for k in range(len(right) + 1)})
    assert all(c.verdict is Verdict.SET_ASIDE and c.by_hand for c in none.closures)
    assert none.closures[0].says() == "rejected by hand (its match: accepted)"
    assert max(np.hypot(a.x - b.x, a.y - b.y) for a, b in zip(none.optimised, drifted)) < 1e-6


# the hand-held Hokuyo as a key-frame run a few centimetres apart, its loops looked for 0.3 m back
HAND_HELD = ["--limit", "300", "--keyframe-m", "0.05", "--keyframe-deg", "5"]
HAND_HELD_LOOPS = LoopParams(keyframes=KeyFrames(0.05, math.radians(5.0)), min_path_m=0.3)


def hand_held_run(out, *extra):
    """``eval sequence`` of the hand-held bag into ``out`` with ``HAND_HELD`` (and ``extra``)."""
    args = ["eval", "sequence", str(HOKUYO_BAG), "--out", str(out), *HAND_HELD, *map(str, extra)]
    return runner.invoke(app, args)


@pytest.fixture(scope="module")
def hand_held(tmp_path_factory):
    """The rows file of the hand-held key-frame run."""
    out = tmp_path_factory.mktemp("hand-held") / "rows.json"
    res = hand_held_run(out)
    assert res.exit_code == 0, res.output
    return out


def test_a_hand_held_run_closes_its_loops_with_real_matches(hand_held):
    """The hand-held Hokuyo sweeps the same room back and forth: key frames see old ones again."""
    log = read_log(str(HOKUYO_BAG))
    rows = rows_of_log(str(hand_held), log)
    p = HAND_HELD_LOOPS
    closed = close_loops(log, rows, ImprovedParams(), p)
    accepted = [c for c in closed.closures if c.verdict is Verdict.ACCEPTED]
    assert accepted and len(closed.optimised) == len(closed.chained) == len(rows) + 1
    for c in accepted:  # each judged on its own real match
        assert c.match.result.converged and c.match.overlap >= p.min_overlap
        assert c.peak_ratio < p.peak_ratio and (c.old, c.key) == (c.match.ref, c.match.obj)
    assert any(
        math.hypot(a.x - b.x, a.y - b.y) > 1e-3 for a, b in zip(closed.chained, closed.optimised)
    )
    assert closed.summary()[0].startswith(f"loops: {len(closed.keys)} key frames")
    # what happened at a key frame, in words: its candidates, or why none
    position = {k: n for n, k in enumerate(closed.scans)}
    c = accepted[0]
    assert f"candidate scan {c.old}: accepted" in closed.around(position[c.key])
    assert "no key frame 0.3 m or more back" in closed.around(0)


def test_a_scan_from_elsewhere_is_not_taken_for_a_loop(hand_held):
    log = read_log(str(HOKUYO_BAG))
    rows = rows_of_log(str(hand_held), log)
    p = HAND_HELD_LOOPS
    honest = close_loops(log, rows, ImprovedParams(), p)
    key = max(honest.closures, key=lambda c: c.verdict is Verdict.ACCEPTED).key
    elsewhere = read_log(str(DATA / "laserazosSM3-40.log")).scan(20)  # another robot's building
    real = log.scan

    def scan(k):
        return elsewhere if k == key else real(k)

    log.scan = scan
    swapped = close_loops(log, rows, ImprovedParams(), p)
    assert [c for c in swapped.closures if c.key == key]
    assert all(c.verdict is not Verdict.ACCEPTED for c in swapped.closures if c.key == key)


def test_the_run_score_with_loops_closed_on_a_log_without_loops_says_so(tmp_path):
    log, relations = DATA / "intel-relations.log", DATA / "intel-relations.relations"
    rows = tmp_path / "rows.json"
    res = runner.invoke(
        app, ["eval", "sequence", str(log), "--guess", "odometry", "--out", str(rows)]
    )
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app,
        [
            "eval",
            "relations",
            str(log),
            str(relations),
            "--run",
            str(rows),
            "--offset",
            "976052857.337",
            "--close-loops",
        ],
    )
    assert res.exit_code == 0, res.output
    assert "no loop closed: the optimised run is the chained one" in res.stderr
    chained = next(x for x in res.stdout.splitlines() if "matches chained:" in x)
    closed = next(x for x in res.stdout.splitlines() if "pose graph (loops closed):" in x)
    assert chained.split(":", 1)[1] == closed.split(":", 1)[1]
    res = runner.invoke(app, ["eval", "relations", str(log), str(relations), "--close-loops"])
    assert res.exit_code == 2 and "--close-loops closes the loops of a run" in res.stderr


def test_the_whole_run_recording_holds_the_run_with_its_loops_closed(tmp_path):
    """eval sequence --close-loops --rrd: a space of its own, read back and drawn by rerun."""
    from .conftest import viewer_screenshot
    from .test_rrd import columns

    rrd, out = tmp_path / "run.rrd", tmp_path / "rows.json"
    res = hand_held_run(
        out, "--close-loops", "--loop-gap-m", HAND_HELD_LOOPS.min_path_m, "--rrd", rrd
    )
    assert res.exit_code == 0, res.output
    summary = next(x for x in res.stderr.splitlines() if x.startswith("loops: "))
    accepted = int(summary.split(" accepted")[0].rsplit(" ", 1)[1])
    assert accepted > 0
    cols = columns(rrd)
    (segments,) = [v for _, v in cols["/sequence/loops/accepted"]["LineStrips2D:strips"]]
    assert len(segments) == accepted and all(len(s) == 2 for s in segments)
    (track,) = [v for _, v in cols["/sequence/loops/trajectory"]["LineStrips2D:strips"]]
    assert len(track[0]) == 301  # every scan of the run, at its optimised pose
    img = viewer_screenshot(rrd, tmp_path / "run.png")
    left = img[:, : img.shape[1] // 2]
    green = np.flatnonzero(
        (np.abs(left - np.array(scene.CLOSURE[Verdict.ACCEPTED].color)).max(axis=2) < 40).sum(1)
    )
    assert len(green) > 5
    # the chained run's view above, the loops' below: accepted closures only in the lower one
    assert green.min() > img.shape[0] * 0.4


@given(st.floats(0.0, 50.0), st.integers(1, 200_000))
def test_a_candidates_search_stays_within_the_searchs_bounds(spread, points):
    from mbicp_viz.core.search import MAX_WORK
    from mbicp_viz.evaluation.loops import search_window

    p = LoopParams()
    w = search_window(spread, points, p)
    half = round(w.window_xy / w.cell)
    angles = 2 * round(w.window_theta / w.angle_step) + 1
    assert angles * points * (2 * half + 1) ** 2 <= MAX_WORK or half <= 1
    assert w.window_xy <= p.window_max_m and w.cell <= 1.0
    if points <= 361:  # a 180- or 361-beam laser: the window the spread asks for, on the usual grid
        assert w.window_xy == min(max(spread, 0.3), p.window_max_m) and w.cell == 0.1


def test_loops_found_once_are_read_from_the_cache_the_next_time(
    hand_held, tmp_path, monkeypatch, capsys
):
    """The same run's loops come back from the cache as they were found, and are solved again;
    a different run, or an entry that cannot be read, is looked for again."""
    from dataclasses import replace

    from mbicp_viz.cli.options import closed_run
    from mbicp_viz.evaluation.loop_cache import FOUND, entry

    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    log = read_log(str(HOKUYO_BAG))
    rows = rows_of_log(str(hand_held), log)
    p = HAND_HELD_LOOPS

    def closed(rows):
        run = closed_run(log, rows, p.min_path_m, p.keyframes)
        return run, "read from the cache" in capsys.readouterr().err

    found, cached = closed(rows)
    assert not cached and found.closures
    again, cached = closed(rows)
    assert cached
    assert [(c.old, c.key, c.verdict, c.peak_ratio) for c in again.closures] == [
        (c.old, c.key, c.verdict, c.peak_ratio) for c in found.closures
    ]
    for a, b in zip(again.closures, found.closures):
        assert a.match.result.pose == b.match.result.pose and a.guess == b.guess
        assert np.array_equal(a.search.best_per_angle, b.search.best_per_angle)
    assert found.moved(again).max() < 1e-9

    other = list(rows)
    r = other[40]
    other[40] = replace(r, result=replace(r.result, pose=r.result.pose @ Pose2(0.01, 0.0, 0.0)))
    assert not closed(other)[1]

    kept = entry(log, rows, p) / FOUND
    kept.write_text(kept.read_text()[:1000])  # cut short
    damaged, cached = closed(rows)
    assert not cached and found.moved(damaged).max() < 1e-9
    assert closed(rows)[1]  # kept anew
