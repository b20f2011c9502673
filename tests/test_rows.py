"""Rows files: written by ``eval sequence``, read back, and a failure reopened in the debugger
exactly as the evaluation ran it."""

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import MATCHERS
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.failures import failed, failure_reason, worst_first
from mbicp_viz.readers.rows import read_rows
from mbicp_viz.views.debugger import report
from mbicp_viz.views.debugger.sources import files_source
from mbicp_viz.views.debugger.state import DebugState

from .conftest import DATA, json_lines
from .test_readers import two_lasers

LOG = DATA / "intel-relations.log"


@pytest.fixture(scope="module")
def rows_file(tmp_path_factory):
    """A real evaluation of a real Intel piece, from the identity (so that some pairs fail)."""
    out = tmp_path_factory.mktemp("rows") / "rows.json"
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "sequence",
            str(LOG),
            "--guess",
            "identity",
            "--truth",
            "pose",
            "--out",
            str(out),
            "--workers",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    assert "worst failures of" in res.output and f"--rows {out}" in res.output
    return out


def test_rows_read_back_as_written(rows_file):
    written = json_lines(rows_file)
    rows = read_rows(rows_file)
    assert [(r.ref, r.obj) for r in rows] == [(w["ref"], w["obj"]) for w in written]
    for r, w in zip(rows, written):
        assert r.params.as_dict() == w["params"] and r.matcher == w["algorithm"] == "improved"
        assert [r.guess.x, r.guess.y, r.guess.theta] == w["guess_pose"] and r.score.success == w[
            "success"
        ]
        # the line it is on
        assert json.loads(rows_file.read_text().split("\n")[r.line - 1]) == w


def test_failures_worst_first_with_a_reason(rows_file):
    rows = read_rows(rows_file)
    bad = worst_first(rows)
    assert (
        bad and all(failed(r) for r in bad) and len(bad) == sum(not r.score.success for r in rows)
    )
    assert [r.score.error_xy for r in bad] == sorted((r.score.error_xy for r in bad), reverse=True)
    for r in bad:
        reason = failure_reason(r)
        if not r.result.converged:
            assert reason.startswith("stopped early")
        elif r.score.inliers_truth < 0.5:
            on = r.score.inliers_truth
            assert reason.startswith("low overlap") and f"{100 * on:.0f} %" in reason
        else:
            assert reason.split(" (")[0] in ("degenerate direction", "wrong basin")


def test_every_failure_reopens_exactly_as_it_failed(rows_file):
    """Each failure's own matcher, parameters and guess give back the evaluation's pose."""
    src = files_source(str(LOG), None, rows=str(rows_file))
    state = DebugState(src)
    assert state.rematch() is None
    first = src.failures[0]
    assert state.pair == (first.ref, first.obj) and state.guess == first.guess
    for row in src.failures:
        assert state.open_row(row) is None
        assert state.matchers == [row.matcher] and state.params[row.matcher] == row.params
        pose = state.runs[0].result.pose
        assert (
            math.hypot(pose.x - row.result.pose.x, pose.y - row.result.pose.y) < 1e-9
            and abs(pose.theta - row.result.pose.theta) < 1e-9
        )
        text = report.result_markdown(state)
        assert (
            f"line {row.line}" in text
            and "this run reproduces it" in text
            and failure_reason(row) in text
        )
    # change what the evaluation ran with: the page says the run no longer reproduces it
    assert state.set_params(row.matcher, {"MaxIter": "3"}) is None
    assert "this run differs from it" in report.result_markdown(state)


def test_rows_from_another_log_are_refused(rows_file, tmp_path):
    rows = json_lines(rows_file)
    rows[2]["obj"] = 5000
    bad = tmp_path / "other.json"
    bad.write_text(json.dumps(rows, indent=1))
    with pytest.raises(InputError) as e:
        files_source(str(LOG), None, rows=str(bad))
    line = read_rows(bad)[2].line
    assert e.value.line == line and e.value.field == "obj" and "another log" in e.value.message
    res = CliRunner().invoke(
        app, ["serve", str(LOG), "--rows", str(bad), "--port", "0", "--for-seconds", "0"]
    )
    assert (
        res.exit_code == 2
        and f"other.json:{line}: obj:" in res.output
        and "Traceback" not in res.output
    )


@pytest.mark.parametrize(
    "change, field",
    [
        (lambda r: r.pop("guess_pose"), "guess_pose"),
        (lambda r: r.update(params={**r["params"], "Bw": -1.0}), "params.Bw"),
        (lambda r: r.update(params={**r["params"], "nope": 1}), "params.nope"),
        (lambda r: r.update(algorithm="ransac"), "algorithm"),
        (lambda r: r.update(ref=1.5), "ref"),
        (lambda r: r.update(converged="yes"), "converged"),
        (lambda r: r.update(guess_pose=[0, 0]), "guess_pose"),
        (lambda r: r.update(error_xy=float("nan")), "error_xy"),
    ],
)
def test_a_bad_field_names_its_line(rows_file, tmp_path, change, field):
    rows = json_lines(rows_file)
    change(rows[3])
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(rows, indent=1))
    with pytest.raises(InputError) as e:
        read_rows(path)
    starts = [k + 1 for k, text in enumerate(path.read_text().split("\n")) if text == " {"]
    assert e.value.field == field and e.value.line == starts[3]


@settings(max_examples=60, deadline=None)
@given(cut=st.floats(0.0, 1.0), flip=st.tuples(st.floats(0.0, 1.0), st.integers(0, 255)))
def test_damaged_rows_files_end_in_one_line(tmp_path_factory, rows_file, cut, flip):
    data = bytearray(rows_file.read_bytes()[: max(1, int(cut * rows_file.stat().st_size))])
    data[int(flip[0] * (len(data) - 1))] = flip[1]
    path = tmp_path_factory.mktemp("fuzz") / "rows.json"
    path.write_bytes(bytes(data))
    try:
        rows = read_rows(path)
    except InputError as e:
        assert "\n" not in str(e) and "rows.json" in str(e)
    else:
        assert rows and all(r.matcher in MATCHERS for r in rows)


def test_rows_remember_the_scan_stream_and_reopen_only_on_it(tmp_path, intel):
    """Rows of one laser message type of a log that has several reopen on that type; read as
    another, the debugger refuses them instead of opening other scans under the same numbers."""
    log = two_lasers(tmp_path / "two.log", intel, 6)
    out = tmp_path / "rows.json"
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "sequence",
            str(log),
            "--topic",
            "RAWLASER2",
            "--guess",
            "identity",
            "--out",
            str(out),
            "--workers",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    assert {r.stream for r in read_rows(out)} == {"RAWLASER2"}
    from mbicp_viz.readers import ReadOptions

    state = DebugState(
        files_source(str(log), None, rows=str(out), options=ReadOptions(topic="RAWLASER2"))
    )
    assert state.rematch() is None and state.source.log.topic == "RAWLASER2"
    assert np.allclose(state.ref.points(), intel.scans[10 + state.pair[0]].points(), atol=1e-9)
    with pytest.raises(InputError) as e:
        files_source(str(log), None, rows=str(out), options=ReadOptions(topic="FLASER"))
    assert e.value.field == "stream" and "--topic RAWLASER2" in e.value.message
    # unnamed: the front laser, and the command says which it read and how to read another
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "sequence",
            str(log),
            "--guess",
            "identity",
            "--out",
            str(out),
            "--workers",
            "1",
            "--limit",
            "2",
        ],
    )
    assert res.exit_code == 0, res.output
    assert (
        "read FLASER (6 scans), the front laser with its poses; the log also has RAWLASER1 (6 "
        "scans); "
        "RAWLASER2 (6 scans): --topic (in the debugger: scan stream) reads another" in res.stderr
    )
    assert {r.stream for r in read_rows(out)} == {"FLASER"}


def test_a_bad_field_of_a_json_lines_file_names_its_line(rows_file, tmp_path):
    rows = json_lines(rows_file)
    rows[3]["converged"] = "yes"
    path = tmp_path / "bad.json"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    with pytest.raises(InputError) as e:
        read_rows(path)
    assert (e.value.line, e.value.field) == (4, "converged")
    rows[3]["converged"] = True
    path.write_text("".join(json.dumps(r) + "\n" for r in rows)[:-30])  # cut short
    with pytest.raises(InputError) as e:
        read_rows(path)
    assert e.value.line == len(rows) and "invalid JSON" in e.value.message


def test_a_parameter_set_seen_before_is_not_trusted_on_another_line(rows_file, tmp_path):
    """Rows repeat one parameter set, which is checked once; a later row whose set differs by one
    bad value is still refused, naming its own line."""
    rows = [r for r in json_lines(rows_file) if "ref" in r]
    bad = json.loads(json.dumps(rows[2]))
    key = next(k for k, v in bad["params"].items() if isinstance(v, float))
    bad["params"][key] = float("nan")
    path = tmp_path / "rows.jsonl"
    path.write_text("\n".join(json.dumps(r) for r in [rows[0], rows[1], bad]) + "\n")
    with pytest.raises(InputError) as e:
        read_rows(path)
    assert e.value.line == 3 and key in str(e.value)


def _long_run(rows_file, path, n):
    """A real run's rows repeated into a run of ``n`` pairs (records renumbered 0 -> 1 -> ...),
    as JSON lines: the size of an hour's run without matching one."""
    real = json_lines(rows_file)
    with open(path, "w") as f:
        for k in range(n):
            f.write(json.dumps(real[k % len(real)] | {"ref": k, "obj": k + 1}) + "\n")
    return path


def key(r):
    """What tells records apart (a record's covariance is an array: no ``==``)."""
    return (r.line, r.ref, r.obj, r.result.pose, r.result.error, r.flags, r.score, r.params)


def keys(rows):
    return [key(r) for r in rows]


def test_a_run_read_as_columns_is_its_rows(rows_file, tmp_path, monkeypatch):
    """The run view's rows (``run_of_log``): every column equals what the records say, a record
    asked for equals ``read_rows``', the failures and flagged pairs come in their order; the
    columns are kept in the cache for the next opening, which reads no row again, and a damaged
    entry is read afresh."""
    from mbicp_viz.evaluation import run_rows
    from mbicp_viz.evaluation.health import severity
    from mbicp_viz.readers import ScanLog, read_log

    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    n = run_rows.CACHED_FROM + 7
    path = _long_run(rows_file, tmp_path / "long.jsonl", n)
    scan = read_log(LOG).scan(0)
    log = ScanLog("many", [scan] * (n + 1))
    run = run_rows.run_of_log(path, log)
    rows = read_rows(path)
    assert len(run) == n and key(run.first) == key(rows[0])
    for k in (0, 1, 17, n - 1, -1):
        assert key(run[k]) == key(rows[k])
    for name, of in run_rows.COLUMNS.items():
        np.testing.assert_array_equal(run.column(name), np.array([of(r) for r in rows]))
    m = run.column("motion")[9]
    assert (m[0], m[1], m[2]) == (
        rows[9].result.pose.x,
        rows[9].result.pose.y,
        rows[9].result.pose.theta,
    )
    bad = sorted(
        (r for r in rows if failed(r)),
        key=lambda r: (-r.score.error_xy, -r.score.error_theta, r.line),
    )
    assert keys(run.worst_first()) == keys(bad) == keys(worst_first(rows))
    flagged = sorted((r for r in rows if r.flags), key=lambda r: (-severity(r), r.ref, r.obj))
    assert flagged and keys(run.ranked()) == keys(flagged)
    assert keys(run.ranked()[:3]) == keys(flagged[:3])
    # the next opening reads the cached columns: no row is read again but those asked for
    monkeypatch.setattr(run_rows, "file_rows", None)
    again = run_rows.run_of_log(path, log)
    assert len(again) == n and key(again[n - 1]) == key(rows[n - 1])
    np.testing.assert_array_equal(again.column("severity"), run.column("severity"))
    # a damaged entry is removed and the file read again
    folder = run_rows.log_cache.entry(str(path), "rows", (run_rows._code_digest(),))
    (folder / "motion.npy").write_bytes(b"not an array")
    monkeypatch.undo()
    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    np.testing.assert_array_equal(
        run_rows.run_of_log(path, log).column("motion"), run.column("motion")
    )
    # rows of another log are refused as ``rows_of_log`` refuses them
    with pytest.raises(InputError) as e:
        run_rows.run_of_log(path, ScanLog("few", [scan] * 10))
    assert e.value.field == "obj" and e.value.line == 10 and "another log" in e.value.message


def test_a_long_run_keeps_its_columns_not_its_records(rows_file, tmp_path, monkeypatch):
    """Memory: a run of 6,000 pairs as columns takes a tenth of its records as objects."""
    import tracemalloc

    from mbicp_viz.evaluation.run_rows import run_of_log
    from mbicp_viz.readers import ScanLog, read_log

    monkeypatch.setenv("MBICP_VIZ_CACHE", str(tmp_path / "cache"))
    n = 6000
    path = _long_run(rows_file, tmp_path / "long.jsonl", n)
    log = ScanLog("many", [read_log(LOG).scan(0)] * (n + 1))
    read_rows(path)  # the parameter sets met once, as both readers meet them
    held = {}
    for name, read in (("records", read_rows), ("columns", lambda p: run_of_log(p, log))):
        tracemalloc.start()
        kept = read(path)
        held[name] = tracemalloc.get_traced_memory()[0]
        tracemalloc.stop()
        assert len(kept) == n
        del kept
    assert held["columns"] < held["records"] / 10, held


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 40), block=st.integers(1, 9))
def test_a_runs_columns_made_as_its_rows_arrive_are_its_records_columns(rows_file, n, block):
    """RunColumns, a block of arrays at a time: every column as the records make it, whatever the
    blocks; of the records, the last two kept and no other."""
    from mbicp_viz.evaluation.run_rows import COLUMNS, RunColumns, RunRows

    records = read_rows(rows_file)
    rows = [records[k % len(records)] for k in range(n)]
    made = RunColumns(numbered=True)
    made.BLOCK = block
    for r in rows:
        made.append(r)
    columns, whole = made.columns(), RunRows.of(rows)
    for name in COLUMNS:
        expected = np.arange(1, n + 1) if name == "line" else whole.column(name)
        np.testing.assert_array_equal(columns[name], expected, err_msg=name)
    assert len(made) == n and made[-1] is rows[-1] and made[-2:] == rows[-2:]
    if n > 2:
        with pytest.raises(IndexError):
            made[n - 3]


def test_each_row_of_a_resumed_run_is_found_at_its_offset_in_the_finished_file(tmp_path):
    """PartialRows says where each row's line starts in OUT (the run view reads a record from
    there): the rows a stopped run left, past a line a kill cut short, and those added after."""
    from mbicp_viz.readers.rows import PartialRows

    out, run = tmp_path / "r.jsonl", {"command": "test", "log": "é"}
    with PartialRows(out, run) as rows:
        for k in range(3):
            rows.add({"k": k, "name": "ü" * k})
    rows.path.write_bytes(rows.path.read_bytes() + b'{"k": 3, "na')  # a kill while writing
    again = PartialRows(out, run)
    assert again.count == 3
    with again:
        for k in range(3, 6):
            again.add({"k": k})
    again.finish()
    data = out.read_bytes()
    offsets = again.offsets()
    assert len(offsets) == 6 and offsets[0] == 0
    for k, at in enumerate(offsets.tolist()):
        assert data[at - 1 : at] in (b"", b"\n") and json.loads(data[at:].split(b"\n")[0])["k"] == k
