"""The Python API (``import mbicp_viz as mv``): its page's examples run as written, its functions
give what the commands give, its errors are the commands' one error, and the examples/ scripts
run."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import mbicp_viz as mv
from mbicp_viz.cli import app as cli

from .conftest import DATA

ROOT = Path(__file__).resolve().parent.parent
API_DOC = ROOT / "docs" / "api.md"
BAG = DATA / "hokuyo-demo.bag"
INTEL_REL, RELATIONS, OFFSET = (
    DATA / "intel-relations.log",
    DATA / "intel-relations.relations",
    976052857.337,
)


def _run(args, cwd) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=600
    )


@pytest.fixture
def folder(tmp_path):
    """The folder the API page's examples run in: its robot.bag and Intel files."""
    shutil.copy(BAG, tmp_path / "robot.bag")
    shutil.copy(INTEL_REL, tmp_path / "intel.log")
    shutil.copy(RELATIONS, tmp_path / "intel.relations")
    return tmp_path


def test_the_api_pages_examples_run_as_written(folder):
    blocks = re.findall(r"```python\n(.*?)```", API_DOC.read_text(), re.S)
    assert len(blocks) >= 8
    (folder / "page.py").write_text("\n".join(blocks))
    res = _run(["page.py"], folder)
    assert res.returncode == 0, res.stderr
    out = res.stdout
    assert "360 scan records; /scan" in out
    assert "11 rows read back" in out
    assert "matches chained: translation" in out and "raw odometry: translation" in out
    assert "improved.mad_k:" in out  # the error, as the command line prints it
    assert "no loop closed" in out and "pose graph (loops closed): translation" in out
    assert re.search(r"open http://127\.0\.0\.1:\d+", out)
    for rrd in ("pair.rrd", "run.rrd", "loops.rrd"):
        res = subprocess.run(
            [str(Path(sys.executable).parent / "rerun"), "rrd", "verify", str(folder / rrd)],
            capture_output=True,
            text=True,
        )
        assert res.returncode == 0, res.stderr


def _cli_json(args) -> dict:
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("matcher, preset", [("improved", "poor-guess"), ("icp", None)])
def test_a_match_is_the_commands_match(matcher, preset):
    log = mv.read_log(BAG)
    m = mv.match(log, 200, 201, mv.params(matcher, preset))
    args = ["match", str(BAG), "--pair", "200", "201", "--algo", matcher, "--json"]
    got = _cli_json(args + (["--params", preset] if preset else []))
    assert (got["x"], got["y"], got["theta"]) == pytest.approx(
        (m.result.pose.x, m.result.pose.y, m.result.pose.theta), abs=1e-12
    )
    assert got["iterations"] == m.result.iterations == len(m.iterations)
    assert got["frame"] == m.frame and got["guess"] == m.guess_source


def test_a_run_is_the_commands_run_and_its_score_the_commands_score(tmp_path):
    log = mv.read_log(INTEL_REL)
    rows = mv.run(log, "mbicp", guess="odometry", workers=1)
    out = tmp_path / "rows.jsonl"
    res = CliRunner().invoke(
        cli,
        ["eval", "sequence", str(INTEL_REL), "--algo", "mbicp", "--guess", "odometry"]
        + ["--out", str(out), "--workers", "1"],
    )
    assert res.exit_code == 0, res.output
    theirs = mv.read_rows(out, log)
    assert [(r.ref, r.obj) for r in rows] == [(r.ref, r.obj) for r in theirs]
    for a, b in zip(rows, theirs):
        assert (a.result.pose.x, a.result.pose.y, a.result.pose.theta) == pytest.approx(
            (b.result.pose.x, b.result.pose.y, b.result.pose.theta), abs=1e-9
        )
    scores = mv.score_run(log, rows, RELATIONS, offset=OFFSET)
    res = CliRunner().invoke(
        cli,
        ["eval", "relations", str(INTEL_REL), str(RELATIONS), "--run", str(out)]
        + ["--offset", str(OFFSET)],
    )
    assert res.exit_code == 0, res.output
    for s in scores:
        assert s.line() in res.output
    # rows written from the API open as the command's do
    mine = tmp_path / "mine.jsonl"
    mv.write_rows(rows, mine)
    assert [r.result.pose for r in mv.read_rows(mine, log)] == [r.result.pose for r in rows]


def test_scans_from_arrays_match_a_known_turn():
    bearings = np.radians(np.arange(-120.0, 120.5, 0.5))
    walls = np.minimum(4.0 / np.abs(np.cos(bearings)), 6.0 / np.abs(np.sin(bearings) + 1e-9))
    ref = mv.scan(walls, bearings)
    obj = mv.scan(walls, angle_min=bearings[0] + np.radians(3.0), angle_increment=np.radians(0.5))
    m = mv.match_scans(ref, obj, "mbicp", guess="identity", truth=mv.pose_deg(0, 0, -3.0))
    assert m.score is not None and m.score.success
    assert np.degrees(m.result.pose.theta) == pytest.approx(-3.0, abs=0.05)


@pytest.mark.parametrize(
    "call, where",
    [
        (lambda: mv.read_log(DATA / "no-such.bag"), "no-such.bag"),
        (lambda: mv.read_log(BAG, topic="/nope"), "/nope"),
        (lambda: mv.params("improved", Bw_deg=-3), "improved.Bw_deg"),
        (lambda: mv.params("improved", "no-such-preset"), "no-such-preset"),
        (lambda: mv.params("nope"), "--algo"),
        (lambda: mv.scan([1.0, 2.0], [0.2, 0.1]), "scan 0"),
        (lambda: mv.scan([1.0, 2.0]), "bearings"),
        (lambda: mv.match(mv.read_log(BAG), 0, 1, guess="sideways"), "guess"),
        (lambda: mv.match(mv.read_log(BAG), 0, 1, frame="world"), "frame"),
        (lambda: mv.match(mv.read_log(BAG), 0, 100000), "100000"),
        (lambda: mv.match(mv.read_log(BAG), 0, 1, params=3), "params"),
        (lambda: mv.lesson_step(99), "number"),
        (lambda: mv.run(mv.read_log(BAG), keyframe_m=float("nan")), "keyframe_m"),
        (lambda: mv.run(mv.read_log(BAG), keyframe_m=0.5, keyframe_deg=200), "keyframe_deg"),
        (lambda: mv.close_loops(mv.read_log(BAG), [], loop_gap_m=-1), "loop_gap_m"),
        (lambda: mv.close_loops(mv.read_log(BAG), []), "rows"),
    ],
)
def test_every_bad_input_is_the_one_error_naming_what_is_wrong(call, where):
    with pytest.raises(mv.InputError) as e:
        call()
    assert where in str(e.value)


def test_importing_the_package_loads_no_numpy_and_every_name_is_documented():
    res = _run(["-c", "import sys, mbicp_viz; print('numpy' in sys.modules)"], ROOT)
    assert res.stdout.strip() == "False", res.stderr
    from mbicp_viz import api

    doc = API_DOC.read_text()
    for name in api.__all__:
        obj = getattr(mv, name)
        assert obj.__doc__, name
        if callable(obj) and not isinstance(obj, type):
            assert f"mv.{name}(" in doc, f"docs/api.md does not show mv.{name}"
    with pytest.raises(AttributeError):
        mv.no_such_name  # noqa: B018


# --- examples/ -----------------------------------------------------------------------------------

EXAMPLE_SCRIPTS = sorted((ROOT / "examples").glob("*.py"))


def test_the_examples_are_short():
    assert len(EXAMPLE_SCRIPTS) >= 3
    for path in EXAMPLE_SCRIPTS:
        assert len(path.read_text().splitlines()) < 80, path.name


def test_match_two_scans_of_a_bag_and_record_them(tmp_path):
    script = ROOT / "examples" / "match_two_scans.py"
    res = _run([script, BAG, "200", "201", "--rrd", tmp_path / "pair.rrd"], tmp_path)
    assert res.returncode == 0, res.stderr
    m = mv.match(mv.read_log(BAG), 200, 201)
    p = m.result.pose
    assert f"x {p.x:+.4f} m, y {p.y:+.4f} m, {p.theta:+.5f} rad" in res.stdout
    rows = [ln.split() for ln in res.stdout.split("threshold [m]")[1].splitlines()[1:] if ln]
    for it, row in zip(m.iterations, rows):
        assert int(row[1]) == int(it.pairs.kept.sum())
    assert (tmp_path / "pair.rrd").stat().st_size > 0
    # the bundled pair by default; a bad file is one line
    assert _run([script], tmp_path).returncode == 0
    bad = _run([script, tmp_path / "nope.bag", "0", "1"], tmp_path)
    assert bad.returncode == 1 and "Traceback" not in bad.stderr and "nope.bag" in bad.stderr


def test_score_run_on_relations(tmp_path):
    script = ROOT / "examples" / "score_run.py"
    out = tmp_path / "rows.jsonl"
    args = [script, INTEL_REL, RELATIONS, "--offset", OFFSET, "--rows", out, "--workers", "1"]
    res = _run(args, tmp_path)
    assert res.returncode == 0, res.stderr
    log = mv.read_log(INTEL_REL)
    for s in mv.score_run(log, mv.read_rows(out, log), RELATIONS, offset=OFFSET):
        assert s.line() in res.stdout
    assert "the relations the chained run misses most:" in res.stdout


def test_tune_on_your_log_finds_settings_no_worse_than_the_defaults(tmp_path):
    script = ROOT / "examples" / "tune_on_your_log.py"
    args = [script, INTEL_REL, "--relations", RELATIONS, "--offset", OFFSET, "--trials", "4"]
    res = _run(args, tmp_path)
    assert res.returncode == 0, res.stderr
    default = float(re.search(r"defaults: translational error \[m\] ([\d.]+)", res.stdout)[1])
    best = float(re.search(r"best of 4: translational error \[m\] ([\d.]+)", res.stdout)[1])
    assert best <= default
    log = mv.read_log(INTEL_REL)
    rows = mv.run(log, "improved", workers=1)
    assert mv.score_run(log, rows, RELATIONS, offset=OFFSET)[0].trans[0] == pytest.approx(
        default, abs=5e-5
    )
    assert "[improved]\nmad_k = " in res.stdout


def test_parameters_from_a_toml_file_and_from_a_dataclass(tmp_path):
    """A file ``params --out`` wrote, edited, reads back with values over it; the dataclass itself
    is taken as it is."""
    out = tmp_path / "mine.toml"
    res = CliRunner().invoke(cli, ["params", "--algo", "mbicp", "--out", str(out)])
    assert res.exit_code == 0, res.output
    out.write_text(out.read_text().replace("Bw_deg = ", "Bw_deg = 12.5 #"))
    p = mv.params("mbicp", out, L=2.0)
    assert np.degrees(p.Bw) == pytest.approx(12.5) and p.L == 2.0
    from mbicp_viz.core import MbicpParams

    log = mv.read_log(BAG)
    assert mv.match(log, 10, 11, MbicpParams(L=2.0)).params == MbicpParams(L=2.0)
    with pytest.raises(mv.InputError, match=r"mine\.toml"):
        out.write_text("Bw_deg = 'wide'\n")
        mv.params("mbicp", out)
