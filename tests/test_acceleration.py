"""Improved MbICP's ``extrapolate`` (Aitken, after Besl & McKay's accelerated ICP): a step that
follows the previous one and is shorter goes on by the rest of their geometric series; fewer
iterations to the same answers on real pairs, and every front end says which steps were
extrapolated."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mbicp_viz.core import ImprovedParams, Pose2, Recorder, match, pose_error
from mbicp_viz.core.mbicp import _extrapolate
from mbicp_viz.evaluation.bench import bench_guesses
from mbicp_viz.evaluation.pairs import stored_truth
from mbicp_viz.readers.params_toml import make_params
from mbicp_viz.views.text import iteration_text

from .conftest import DATA

L = 3.0


def _steps(x, y, th, ratio, dx, dy, dth):
    """Two increments of a linear convergence along one direction: d, then ratio * d (in x, y, L
    theta)."""
    d_prev = np.array([dx, dy, L * dth])
    # the second step from the pose the first one reached, composed as the loop composes it
    x1, y1, th1 = x + dx, y + dy, th + dth
    jx, jy, jth = ratio * dx, ratio * dy, ratio * dth
    c, s = math.cos(jth), math.sin(jth)
    ix, iy = x1 + jx - (c * x1 - s * y1), y1 + jy - (s * x1 + c * y1)  # moves (x1, y1) by (jx, jy)
    return (x1, y1, th1), (ix, iy, jth), d_prev


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-5, 5),
    st.floats(-5, 5),
    st.floats(-3, 3),
    st.floats(0.05, 0.74),
    st.floats(-0.3, 0.3),
    st.floats(-0.3, 0.3),
    st.floats(-0.2, 0.2),
)
def test_a_geometric_sequence_of_steps_lands_on_its_limit(x, y, th, ratio, dx, dy, dth):
    # the loop extrapolates no step below its stop thresholds (1e-4 m and rad by default); a
    # micrometre step composed at 5 m keeps only about 9 digits, too few for the 1e-9 below
    if math.hypot(dx, dy, L * dth) < 1e-4:
        return
    (x1, y1, th1), (ix, iy, ith), d_prev = _steps(x, y, th, ratio, dx, dy, dth)
    ex, ey, eth, factor = _extrapolate(x1, y1, th1, ix, iy, ith, d_prev, True, L, 3.0)
    assert math.isclose(factor, ratio / (1.0 - ratio), rel_tol=1e-9)
    # the composed increment takes the pose to the series' limit, x + d / (1 - ratio)
    c, s = math.cos(eth), math.sin(eth)
    end = (ex + c * x1 - s * y1, ey + s * x1 + c * y1, th1 + eth)
    limit = (x + dx / (1 - ratio), y + dy / (1 - ratio), th + dth / (1 - ratio))
    assert np.allclose(end, limit, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(st.floats(1.01, 5.0), st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), st.floats(-0.2, 0.2))
def test_no_extrapolation_when_the_step_grows_or_turns_back(ratio, dx, dy, dth):
    if math.hypot(dx, dy, L * dth) < 1e-6:
        return
    for r in (ratio, -1.0 / ratio):  # longer, or back the way it came
        (x1, y1, th1), (ix, iy, ith), d_prev = _steps(0.2, -0.1, 0.3, r, dx, dy, dth)
        assert _extrapolate(x1, y1, th1, ix, iy, ith, d_prev.copy(), True, L, 3.0) == (
            ix,
            iy,
            ith,
            0.0,
        )
    # and never before a previous step exists
    (x1, y1, th1), (ix, iy, ith), d_prev = _steps(0.2, -0.1, 0.3, 0.5, dx, dy, dth)
    assert _extrapolate(x1, y1, th1, ix, iy, ith, d_prev, False, L, 3.0)[3] == 0.0


def test_fewer_iterations_to_the_same_answers_on_real_pairs(laserazos):
    """The 40-scan laserazosSM3 excerpt (361 beams) from the baselines' poor guesses: the option
    file's improved MbICP succeeds as often with fewer iterations, and says which steps went on."""
    pairs = laserazos.consecutive_pairs(39)
    guesses = bench_guesses(laserazos, pairs, (0.3, math.radians(15.0)), 0)
    option = make_params("improved", "poor-guess")
    assert option.extrapolate > 0.0
    annealed = option.replace(extrapolate=0.0)
    counts = {"on": [0, 0], "off": [0, 0]}
    seen = []
    for (i, j), guess in zip(pairs, guesses):
        ref, obj = laserazos.scan(i), laserazos.scan(j)
        truth = stored_truth(ref, obj)
        rec = Recorder()
        for key, params in (("on", option), ("off", annealed)):
            r = match(ref, obj, guess, params, rec if key == "on" else None)
            e, t = pose_error(r.pose, truth)
            counts[key][0] += e < 0.1 and t < math.radians(3.14)
            counts[key][1] += r.iterations
        for ev in rec.iterations:
            # the events carry the composed step: after = increment @ before, extrapolated or not
            assert np.allclose(
                (ev.increment @ ev.estimate_before).as_array(),
                ev.estimate_after.as_array(),
                atol=1e-12,
            )
            if ev.extrapolated:
                assert 0.0 < ev.extrapolated <= option.extrapolate
                seen.append(iteration_text(ev))
    assert counts["on"][0] >= counts["off"][0] >= 35
    assert counts["on"][1] < 0.8 * counts["off"][1]
    assert seen and all("extrapolated" in text for text in seen)


def test_off_by_default_as_published(laserazos):
    assert ImprovedParams().extrapolate == 0.0
    rec = Recorder()
    match(laserazos.scan(0), laserazos.scan(1), Pose2(0.2, -0.1, 0.2), ImprovedParams(), rec)
    assert rec.iterations and not any(ev.extrapolated for ev in rec.iterations)


def test_match_and_the_debugger_say_which_steps_went_on(laserazos):
    """``match``'s iteration lines and the debugger's playback text (the recordings' text log is
    the same sentence) name the extrapolated steps and their factor."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app
    from mbicp_viz.views.debugger import report
    from mbicp_viz.views.debugger.state import DebugState, Source

    option = "poor-guess"
    res = CliRunner().invoke(
        app,
        [
            "match",
            str(DATA / "laserazosSM3-40.log"),
            "--pair",
            "5",
            "6",
            "--algo",
            "improved",
            "--params",
            option,
            "--init",
            "0.2",
            "-0.1",
            "10",
        ],
    )
    assert res.exit_code == 0, res.output
    marked = [line for line in res.stdout.splitlines() if "extrapolated x" in line]
    assert marked and all(float(line.rsplit("x", 1)[1]) > 1.0 for line in marked)

    params = make_params("improved", option)
    state = DebugState(
        Source(
            "laserazos",
            laserazos,
            guess=Pose2(0.2, -0.1, math.radians(10.0)),
            params={"improved": params},
        )
    )
    assert state.set_pair(5, 6) is None
    assert state.set_guess(Pose2(0.2, -0.1, math.radians(10.0))) is None
    texts = []
    for k in range(1, state.max_iteration() + 1):
        state.iteration = k
        ev = report.event(state, state.runs[0])
        texts.append((ev.extrapolated, report.iteration_text(state, state.runs[0])))
    assert any(f for f, _ in texts)
    assert all(("extrapolated" in t) == bool(f) for f, t in texts)
