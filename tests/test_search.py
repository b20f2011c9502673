"""The correlative search that gives the local matchers a guess when there is none."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import ImprovedParams, Pose2, match, pose_error, relative
from mbicp_viz.core.search import SearchParams, correlative_search, likelihood_field
from mbicp_viz.evaluation.criteria import CONSECUTIVE
from mbicp_viz.evaluation.pairs import seen_from
from mbicp_viz.readers import read_log

from .conftest import EXAMPLES, INTEL, json_lines


def success(pose: Pose2, truth: Pose2) -> bool:
    return CONSECUTIVE.judge(pose, truth)


@settings(max_examples=12, deadline=None)
@given(
    x=st.floats(-1.2, 1.2),
    y=st.floats(-1.2, 1.2),
    theta_deg=st.floats(-35.0, 35.0),
    k=st.integers(0, 59),
)
def test_search_finds_a_large_known_displacement(intel, x, y, theta_deg, k):
    """A real scan seen from a pose up to 1.2 m and 35 deg away (far outside any local matcher's
    basin): the coarse pass lands within a grid step of the truth, the fine pass within a few of its
    own (2 cm, 0.25 deg)."""
    scan = intel.scan(k)
    truth = Pose2(x, y, math.radians(theta_deg))
    found = correlative_search(scan, seen_from(scan, truth))
    et, er = pose_error(found.coarse, truth)
    assert et <= 0.15 and er <= math.radians(1.5)
    et, er = pose_error(found.pose, truth)
    assert et <= 0.03 and er <= math.radians(0.3)


def test_search_stays_inside_its_window(intel):
    ref, obj = intel.scan(12), intel.scan(13)  # the truth is ~1 m ahead
    guess = Pose2(-0.5, 0.2, 0.1)
    p = SearchParams(window_xy=0.3, window_theta=math.radians(5.0))
    found = correlative_search(ref, obj, guess, p)
    d = relative(guess, found.coarse)
    assert (
        abs(found.coarse.x - guess.x) <= 0.3 + 1e-9 and abs(found.coarse.y - guess.y) <= 0.3 + 1e-9
    )
    assert abs(d.theta) <= math.radians(5.0) + 1e-9
    assert len(found.angles) == 11 and found.score == found.best_per_angle.max()
    # the fine pass looks within 1.5 coarse cells (in whole fine cells) and 2 coarse angle steps of
    # the coarse best
    d = relative(found.coarse, found.pose)
    reach = round(1.5 * p.cell / p.fine_cell) * p.fine_cell + 1e-9
    assert (
        abs(found.pose.x - found.coarse.x) <= reach and abs(found.pose.y - found.coarse.y) <= reach
    )
    assert abs(d.theta) <= math.radians(2.0) + 1e-9


def test_without_the_fine_pass_the_search_stops_at_the_coarse_grid(intel):
    ref, obj = intel.scan(12), intel.scan(13)
    coarse_only = correlative_search(ref, obj, params=SearchParams(refine=False))
    both = correlative_search(ref, obj)
    assert coarse_only.pose == coarse_only.coarse == both.coarse
    assert both.pose != both.coarse


def test_search_gives_improved_mbicp_the_basin_it_lacks(intel):
    """Consecutive Intel scans are seconds apart (up to ~1 m and 35 deg): from the identity,
    improved MbICP shortens the motion along corridors (paper 000 §3.3); from the searched guess it
    succeeds on nearly every pair of the excerpt."""
    pairs = [(intel.scan(i), intel.scan(i + 1)) for i in range(len(intel.scans) - 1)]
    truths = [relative(a.pose, b.pose) for a, b in pairs]
    from_identity = sum(
        success(match(a, b, Pose2(), ImprovedParams()).pose, t) for (a, b), t in zip(pairs, truths)
    )
    from_search = sum(
        success(match(a, b, correlative_search(a, b).pose, ImprovedParams()).pose, t)
        for (a, b), t in zip(pairs, truths)
    )
    assert from_search >= 0.93 * len(pairs) and from_identity <= 0.5 * len(pairs)


def test_eval_sequence_with_a_searched_guess(tmp_path):
    out = tmp_path / "rows.json"
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "sequence",
            str(INTEL),
            "--guess",
            "search",
            "--truth",
            "pose",
            "--limit",
            "6",
            "--out",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    rows = json_lines(out)
    assert len(rows) == 6 and all(r["guess"] == "search" and r["guess_ms"] > 0 for r in rows)
    assert sum(r["success"] for r in rows) >= 5


def test_the_likelihood_field_peaks_at_the_points_and_ignores_those_outside():
    """1 at a point's cell, exp(-(d / sigma)^2) beside it; a point outside the grid (the fine pass
    crops it to where the object can land) adds nothing, and none inside leaves the field at 0."""
    origin, cell, sigma = np.array([0.0, 0.0]), 0.1, 0.2
    field = likelihood_field(np.array([[0.5, 0.5], [5.0, 5.0]]), origin, (11, 11), cell, sigma)
    assert field[5, 5] == 1.0 and math.isclose(field[5, 7], math.exp(-((0.2 / sigma) ** 2)))
    assert math.isclose(field[0, 10], math.exp(-((math.hypot(0.5, 0.5) / sigma) ** 2)))
    assert not likelihood_field(np.array([[5.0, 5.0]]), origin, (11, 11), cell, sigma).any()


def test_a_field_built_tile_by_tile_finds_what_the_whole_field_finds(monkeypatch):
    """The tiled field (long-range scans) against the dense one on real pairs: the same poses, the
    same scores but for the order of the sums."""
    import mbicp_viz.core.search as search

    log = read_log(INTEL)
    pairs = [(log.scan(i), log.scan(j)) for i, j in log.consecutive_pairs(8)]
    dense = [correlative_search(a, b) for a, b in pairs]
    monkeypatch.setattr(search, "DENSE_CELLS", 0)
    monkeypatch.setattr(search, "TILE", 64)  # many tiles, windows across their borders
    for (a, b), d in zip(pairs, dense):
        t = correlative_search(a, b)
        assert t.pose == d.pose and t.coarse == d.coarse
        assert np.allclose(t.best_per_angle, d.best_per_angle, rtol=1e-12, atol=0)


def test_the_search_memory_is_bounded_whatever_the_range():
    """A real scan pair stretched to 150 m (the guess search held 4.3 GB at that range)."""
    import subprocess
    import sys

    code = (
        "import resource, numpy as np\n"
        "from mbicp_viz.core import make_scan\n"
        "from mbicp_viz.core.search import correlative_search\n"
        "from mbicp_viz.readers import read_log\n"
        f"log = read_log({str(EXAMPLES / 'hokuyo-125-130.npz')!r})\n"
        "a, b = log.scan(0), log.scan(1)\n"
        "k = 150.0 / np.nanmax(a.ranges[a.valid])\n"
        "far = [make_scan(s.ranges * k, s.bearings, valid=s.valid) for s in (a, b)]\n"
        "correlative_search(a, b)\n"  # kernels compiled (or loaded) first: their memory is numba's
        "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "correlative_search(*far)\n"
        "print(before, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    before, after = (int(v) for v in out.stdout.split()[-2:])  # peak resident sets [kB]
    assert after - before < 1_000_000, (before, after)  # the search itself: under 1 GB
