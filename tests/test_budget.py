"""A match's time budget and the stop (core/budget.py): the loops stop at the end of an iteration
once the flag is raised, keep that iteration's estimate, record exactly the iterations run, and
say ``halted``; the command line takes ``--budget-s``."""

from __future__ import annotations

from dataclasses import replace

import pytest
from typer.testing import CliRunner

from mbicp_viz.cli import app as cli
from mbicp_viz.core import MATCHERS, Pose2, Recorder, Termination, match
from mbicp_viz.core.budget import Halt, limited
from mbicp_viz.readers import read_log

from .conftest import EXAMPLES, json_lines

PAIR = EXAMPLES / "hokuyo-125-130.npz"


@pytest.fixture(scope="module")
def scans():
    log = read_log(PAIR)
    return log.scan(0), log.scan(1)


def never_settles():
    """Improved MbICP that cannot converge (every stopping threshold 0): it runs to MaxIter."""
    p = MATCHERS["improved"].params_type()
    return replace(p, MaxIter=10000, errx_out=0.0, erry_out=0.0, errt_out=0.0, errorRatio=0.0)


@pytest.mark.parametrize("name", list(MATCHERS))
def test_a_raised_halt_stops_every_matcher_after_one_iteration_with_its_estimate(scans, name):
    ref, obj = scans
    params = MATCHERS[name].params_type()
    free = Recorder()
    whole = match(ref, obj, Pose2(), params, free)
    assert whole.iterations > 1 and whole.reason is not Termination.HALTED
    halt, seen = Halt(), Recorder()
    halt.stop("stopped by the test")
    with limited(None, halt):
        stopped = match(ref, obj, Pose2(), params, seen)
    assert stopped.reason is Termination.HALTED and not stopped.converged
    assert stopped.iterations == 1 and len(seen.iterations) == 1
    # the estimate of its one finished iteration, as the free run computed it
    first = free.iterations[0].estimate_after
    assert stopped.pose.x == pytest.approx(first.x, abs=1e-12)
    assert stopped.pose.theta == pytest.approx(first.theta, abs=1e-12)
    assert seen.iterations[0].estimate_after == free.iterations[0].estimate_after
    assert seen.finish.result.reason is Termination.HALTED


def test_the_budget_stops_a_match_that_would_run_on(scans):
    """The timer is another thread: it runs while the compiled loop does only because the kernels
    release the GIL (else the loop would end at MaxIter, not halted); so does the page's stop."""
    ref, obj = scans
    params = never_settles()
    with limited(0.05) as halt:
        r = match(ref, obj, Pose2(), params)
    assert r.reason is Termination.HALTED and 0 < r.iterations < params.MaxIter
    assert "0.05 s" in halt.why
    # outside the block nothing is limited any more: the same match runs to MaxIter
    assert match(ref, obj, Pose2(), replace(params, MaxIter=300)).iterations == 300


def test_match_budget_on_the_command_line(tmp_path):
    toml = tmp_path / "slow.toml"
    toml.write_text(
        "[improved]\nMaxIter = 10000\nerrx_out = 0.0\nerry_out = 0.0\nerrt_out = 0.0\n"
        "errorRatio = 0.0\n"
    )
    res = CliRunner().invoke(
        cli,
        ["match", str(PAIR), "--guess", "identity", "--params", str(toml), "--budget-s", "0.05"],
    )
    assert res.exit_code == 0, res.output
    assert "by its time budget of 0.05 s (--budget-s)" in res.output
    assert "NOT converged: halted" in res.output
    bad = CliRunner().invoke(cli, ["match", str(PAIR), "--budget-s", "-1"])
    assert bad.exit_code != 0 and "--budget-s" in bad.output and "Traceback" not in bad.output


def test_eval_sequence_counts_and_records_the_pairs_its_budget_stopped(tmp_path):
    toml, rows = tmp_path / "slow.toml", tmp_path / "rows.json"
    toml.write_text(
        "[improved]\nMaxIter = 10000\nerrx_out = 0.0\nerry_out = 0.0\nerrt_out = 0.0\n"
        "errorRatio = 0.0\n"
    )
    res = CliRunner().invoke(
        cli,
        ["eval", "sequence", str(PAIR), "--guess", "identity", "--params", str(toml)]
        + ["--budget-s", "0.05", "--out", str(rows), "--workers", "1"],
    )
    assert res.exit_code == 0, res.output
    # the pair runs to MaxIter in about a second without a budget (never_settles)
    assert "1 stopped by the time budget of 0.05 s (--budget-s)" in res.output
    assert [r["reason"] for r in json_lines(rows)] == ["halted"]
