"""The command line end to end on real data."""

import json
import math
import re

import pytest
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import MATCHERS, field_specs
from mbicp_viz.readers.params_toml import make_params

from .conftest import DATA, HOKUYO_BAG, INTEL, LASERAZOS, json_lines

runner = CliRunner()
ROW_KEYS = {"ref", "obj", "x", "y", "theta", "iterations", "converged", "reason", "time_ms"}


def ok(*args):
    res = runner.invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res.output


def test_match_json_has_the_stable_keys():
    out = ok(
        "match",
        LASERAZOS,
        "--pair",
        5,
        6,
        "--algo",
        "mbicp",
        "--init",
        "0.08",
        "-0.01",
        "-1.5",
        "--json",
    )
    row = json.loads(out)
    assert ROW_KEYS <= set(row)
    assert (row["ref"], row["obj"]) == (5, 6) and row["converged"] is True
    assert row["reason"] == "converged" and row["iterations"] > 0
    # consecutive scans 0.1 s apart: most points land on the reference
    assert 0.9 < row["on_ref"] <= 1.0


def test_match_two_files_prints_every_iteration(tmp_path):
    out = ok("match", DATA / "datos.off", DATA / "datos.off", "--algo", "improved")
    assert "threshold_m" in out and "converged" in out
    assert "pose        (x=+0.0000 m, y=+0.0000 m, theta=+0.000 deg)" in out
    assert "on ref      100.0 % of the object points" in out  # a scan against itself


def test_demo_serves_the_bundled_pair_on_loopback():
    out = ok("demo", "--port", 0, "--for-seconds", 0.5)
    assert "open http://127.0.0.1:" in out


def test_eval_sequence_writes_one_row_per_pair(tmp_path):
    out_file = tmp_path / "seq.json"
    ok("eval", "sequence", LASERAZOS, "--algo", "improved", "--out", out_file, "--limit", 5)
    rows = json_lines(out_file)
    assert len(rows) == 5
    for k, r in enumerate(rows):
        assert ROW_KEYS <= set(r) and (r["ref"], r["obj"]) == (k, k + 1)
        assert r["guess"] == "scan poses"  # the CARMEN log stores a pose per scan
        assert r["converged"] and math.isfinite(r["x"]) and r["time_ms"] > 0


def test_bench_reports_median_p90_and_rate():
    out = ok("bench", "matches", LASERAZOS, "--algo", "icp", "--limit", 3, "--repeat", 1)
    assert "events off" in out and "recording observer" in out
    assert "median" in out and "p90" in out and "matches/s" in out
    probe = re.search(r"machine speed probe +([\d.]+) us before, ([\d.]+) us after", out)
    assert probe and 0 < float(probe.group(1)) < 1000 and 0 < float(probe.group(2)) < 1000


@pytest.mark.parametrize("algo", list(MATCHERS))
def test_params_file_round_trip(tmp_path, algo):
    path = tmp_path / "p.toml"
    ok("params", "--algo", algo, "--out", path)
    loaded = make_params(algo, str(path))
    defaults = MATCHERS[algo].params_type()
    for s in field_specs(type(defaults)):
        assert getattr(loaded, s.name) == pytest.approx(getattr(defaults, s.name), rel=1e-12), (
            s.name
        )
    # and --params reads it
    ok("match", INTEL, "--pair", 1, 2, "--algo", algo, "--params", path, "--json")


def test_failed_match_is_valid_json_with_its_reason():
    out = ok(
        "match", LASERAZOS, "--pair", 0, 1, "--algo", "mbicp", "--init", "40", "40", "0", "--json"
    )
    row = json.loads(out)  # strict: no NaN
    assert row["converged"] is False and row["reason"] == "too_few_pairs" and row["error"] is None


def test_eval_protocol_reports_the_success_rate():
    out = ok(
        "eval",
        "protocol",
        LASERAZOS,
        "--algo",
        "mbicp",
        "--params",
        "mbicp-protocol",
        "--cases",
        20,
        "--seed",
        3,
    )
    assert out.startswith("mbicp: 20/20 within 1 cm and 0.1 deg (100.0 %)")


def test_bench_gui_reports_step_and_change_latency():
    out = ok("bench", "gui")
    assert "iteration step redraw" in out and "parameter change" in out and "p95" in out


def test_eval_ceiling_separates_what_the_data_allows_from_the_matcher():
    out = ok("eval", "ceiling", INTEL, "--algos", "improved,psm")
    rows = re.findall(
        r"(\w+) started at the scan poses: (\d+)/59 .*; of the (\d+) it leaves, (\d+) lay more", out
    )
    hits = {name: int(n) for name, n, _, _ in rows}
    search = int(re.search(r"correlative search alone: (\d+)/59", out).group(1))
    # PSM walks off some
    assert hits["improved"] == 59 and hits["psm"] < hits["improved"] and search >= 53
    assert all(
        int(left) == 59 - int(n) and int(doubted) <= int(left) for _, n, left, doubted in rows
    )


def test_eval_ceiling_needs_scan_poses():
    res = runner.invoke(app, ["eval", "ceiling", str(HOKUYO_BAG), "--limit", "3"])
    assert (
        res.exit_code == 2
        and "no pose to score against" in res.output
        and "Traceback" not in res.output
    )
