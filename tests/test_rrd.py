"""The rerun front end: recordings read back carry the same data as the in-memory events."""

import subprocess
from collections import defaultdict

import numpy as np
import pytest
from rerun.chunk import RrdReader

from mbicp_viz.core import ImprovedParams, MbicpParams, PairKind, PairStatus
from mbicp_viz.evaluation.single import match_pair
from mbicp_viz.views.rrd import record

from .conftest import RERUN, free_port, viewer_screenshot, wait_for

ROOT = "improved"


def columns(path, timeline: str = "iteration"):
    """{entity path: {column: [(time on ``timeline``, value), ...]}} of a recording, data columns
    only."""
    out = defaultdict(lambda: defaultdict(list))
    for chunk in RrdReader(str(path)).stream().to_chunks():
        rb = chunk.to_record_batch()
        names = rb.schema.names
        its = rb.column(timeline).to_pylist() if timeline in names else [None] * rb.num_rows
        for name in names:
            if ":" in name:
                for it, v in zip(its, rb.column(name).to_pylist()):
                    out[chunk.entity_path][name].append((it, v))
    return out


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, intel):
    path = tmp_path_factory.mktemp("rrd") / "match.rrd"
    m = match_pair(intel.scans[11], intel.scans[12], ImprovedParams(), record=True)
    record([m], str(path), teaching=True)
    return path, m.events


def by_iteration(values):
    return {it: v for it, v in values}


def test_counts_by_kind_and_rejections_match_the_events(recorded):
    path, rec = recorded
    cols = columns(path)
    strips = {
        k: by_iteration(cols[f"/{ROOT}/scene/pairs/{k}"]["LineStrips2D:strips"])
        for k in ("point", "interpolated", "rejected")
    }
    for e in rec.iterations:
        p = e.pairs
        kept = p.status == PairStatus.KEPT
        assert len(strips["point"][e.iteration]) == np.count_nonzero(
            kept & (p.kind == PairKind.POINT)
        )
        assert len(strips["interpolated"][e.iteration]) == np.count_nonzero(
            kept & (p.kind == PairKind.INTERPOLATED)
        )
        assert len(strips["rejected"][e.iteration]) == np.count_nonzero(~kept)
    assert any(len(v) for v in strips["interpolated"].values())
    assert any(len(v) for v in strips["rejected"].values())


def test_threshold_error_and_final_pose_match(recorded):
    path, rec = recorded
    cols = columns(path)
    thr = by_iteration(cols[f"/{ROOT}/plots/threshold"]["Scalars:scalars"])
    err = by_iteration(cols[f"/{ROOT}/plots/error"]["Scalars:scalars"])
    for e in rec.iterations:
        assert thr[e.iteration][0] == pytest.approx(e.threshold)
        assert err[e.iteration][0] == pytest.approx(e.error)
    final = rec.finish.result.pose
    tr = cols[f"/{ROOT}/scene/estimate"]["Transform3D:translation"]
    last_it = max(it for it, _ in tr)
    xy = [v for it, v in tr if it == last_it][-1][0][:2]
    assert xy == pytest.approx([final.x, final.y], abs=1e-6)
    ref = cols[f"/{ROOT}/scene/reference"]["Points2D:positions"]
    assert ref[0][0] is None and len(ref[0][1]) == len(rec.start.ref_points)  # static
    logs = by_iteration(cols[f"/{ROOT}/log"]["TextLog:text"])
    assert all(e.iteration in logs for e in rec.iterations)


def test_resampling_grid_and_teaching_layers_are_recorded(recorded):
    path, rec = recorded
    cols = columns(path)
    boxes = cols[f"/{ROOT}/scene/resampling_grid"]["Boxes2D:centers"]
    assert len(boxes[0][1]) == len(rec.start.resampling.cells)
    ell = by_iteration(cols[f"/{ROOT}/scene/teaching/metric_isocurves"]["LineStrips2D:strips"])
    assert set(ell) == {e.iteration for e in rec.iterations}
    assert f"/{ROOT}/teaching/histogram/threshold" in cols


def test_blueprint_is_stored_and_verify_passes(recorded):
    path, _ = recorded
    assert RrdReader(str(path)).blueprints()  # a default blueprint travels with the file
    res = subprocess.run([RERUN, "rrd", "verify", str(path)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr


def test_two_generations_compare_equal(tmp_path, intel):
    paths = []
    for k in range(2):
        p = tmp_path / f"run{k}.rrd"
        record(
            [
                match_pair(intel.scans[20], intel.scans[21], p, record=True)
                for p in (MbicpParams(), ImprovedParams())
            ],
            str(p),
        )
        paths.append(str(p))
    res = subprocess.run(
        [RERUN, "rrd", "compare", "--unordered", *paths], capture_output=True, text=True
    )
    assert res.returncode == 0, res.stderr
    assert {"/mbicp/scene/reference", "/improved/scene/reference"} <= set(columns(paths[0]))


def test_eval_sequence_records_the_run_on_a_pair_timeline(tmp_path):
    """Each pair adds its step of the trajectory and the scan it placed (the run's view shows all
    up to the time cursor), and its match up close: the correspondences its last iteration kept,
    as many as its record says."""
    from typer.testing import CliRunner

    from mbicp_viz.cli import app
    from mbicp_viz.evaluation.trajectory import accumulate
    from mbicp_viz.readers.rows import read_rows

    from .conftest import LASERAZOS

    rrd, out = tmp_path / "seq.rrd", tmp_path / "s.json"
    args = [
        "eval",
        "sequence",
        str(LASERAZOS),
        "--out",
        str(out),
        "--limit",
        "6",
        "--rrd",
        str(rrd),
    ]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    rows = read_rows(out)
    poses = accumulate(rows)
    cols = columns(rrd, "pair")
    maps = cols["/sequence/sequence/map"]["Points2D:positions"]
    assert sorted(t for t, _ in maps) == list(range(7))  # scans 0..6, each placed once
    steps = sorted(cols["/sequence/sequence/trajectory"]["LineStrips2D:strips"])
    assert [t for t, _ in steps] == list(range(7))
    for (n, strips), before in zip(steps[1:], poses):
        (a, b), after = strips[0], poses[n]
        assert np.allclose([a, b], [[before.x, before.y], [after.x, after.y]], atol=1e-5)
    kept = defaultdict(int)
    for kind in ("point", "interpolated"):
        for n, strips in cols[f"/sequence/pair/scene/pairs/{kind}"]["LineStrips2D:strips"]:
            kept[n] += len(strips)
    assert [kept[n] for n in range(1, 7)] == [r.result.pairs_kept for r in rows]
    assert len(cols["/sequence/log"]["TextLog:text"]) == 6
    assert RrdReader(str(rrd)).blueprints()


def _listeners(port: int) -> set[str]:
    """Local addresses (hex, as in /proc/net/tcp) listening on ``port``."""
    out = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table) as f:
            for line in list(f)[1:]:
                local, state = line.split()[1], line.split()[3]
                addr, p = local.rsplit(":", 1)
                if state == "0A" and int(p, 16) == port:
                    out.add(addr)
    return out


def test_serve_binds_loopback_only(tmp_path):
    import os
    import signal
    import sys
    import urllib.request

    from .conftest import DATA

    port = free_port()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "mbicp_viz",
            "match",
            str(DATA / "datos.off"),
            str(DATA / "datos.off"),
            "--serve",
            "--port",
            str(port),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    try:
        wait_for(lambda: _listeners(port), 60.0)
        assert _listeners(port) == {"0100007F"}, _listeners(port)  # 127.0.0.1, never 0.0.0.0
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=10) as r:
            assert r.status == 200
        wait_for(lambda: _listeners(port + 1), 30.0)
        assert _listeners(port + 1) == {"0100007F"}
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=30)


def test_connect_streams_into_a_running_viewer_server(tmp_path):
    """A rerun server (no window) saving what it receives; --connect streams the run into it."""
    import os
    import signal
    import sys

    from .conftest import DATA

    port = free_port()
    saved = tmp_path / "received.rrd"
    server = subprocess.Popen(
        [RERUN, "--bind", "127.0.0.1", "--port", str(port), "--save", str(saved)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        wait_for(lambda: _listeners(port), 30.0)
        res = subprocess.run(
            [
                sys.executable,
                "-m",
                "mbicp_viz",
                "match",
                str(DATA / "datos.off"),
                str(DATA / "datos.off"),
                "--connect",
                f"rerun+http://127.0.0.1:{port}/proxy",
            ],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert res.returncode == 0, res.stderr
        # until the server has saved what the run streamed
        wait_for(lambda: WANTED <= _saved_paths(saved), 30.0)
    finally:
        os.killpg(server.pid, signal.SIGINT)
        server.wait(timeout=30)
    assert WANTED <= _saved_paths(saved)


WANTED = {"/improved/scene/reference", "/improved/scene/pairs/point", "/improved/log"}


def _saved_paths(path) -> set[str]:
    """Entity paths in a file a live server is still writing (no footer yet; maybe cut
    mid-chunk)."""
    import warnings

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return {c.entity_path for c in RrdReader(str(path)).stream().to_chunks()}
    except Exception:  # not written yet, or a chunk half written
        return set()


def test_rerun_viewer_shows_scenes_y_up_as_the_debugger(tmp_path, intel):
    """rerun's 2-D views put y down; a recording's views must not. A real scan split by the sign of
    y — the half ahead-left (y > 0) red, the other blue — rendered by rerun's own headless viewer:
    red above blue, as in the debugger."""
    import rerun.blueprint as rrb

    from mbicp_viz.views import scene
    from mbicp_viz.views.rrd import log_layer, log_y_up, new_stream, y_up_view

    pts = intel.scan(5).points()
    path, shot = tmp_path / "yup.rrd", tmp_path / "yup.png"
    stream = new_stream("mbicp-viz/y-up")
    stream.save(
        str(path),
        default_blueprint=rrb.Blueprint(y_up_view("/run/scene", "scans"), collapse_panels=True),
    )
    log_y_up(stream, "run/scene")
    log_layer(
        stream,
        "run",
        scene.Points("scene/left", pts[pts[:, 1] > 0.5], scene.REFERENCE, 0.15),
        static=True,
    )
    log_layer(
        stream,
        "run",
        scene.Points("scene/right", pts[pts[:, 1] < -0.5], scene.OBJECT, 0.15),
        static=True,
    )
    stream.flush()
    stream.disconnect()
    img = viewer_screenshot(path, shot, "900x700")
    img = img[:, : img.shape[1] // 2]  # the left half: away from the viewer's notifications
    rows = {
        name: np.flatnonzero(np.abs(img - np.array(s.color)).max(axis=2).min(axis=1) < 40)
        for name, s in (("red", scene.REFERENCE), ("blue", scene.OBJECT))
    }
    assert len(rows["red"]) > 5 and len(rows["blue"]) > 5
    assert rows["red"].mean() < rows["blue"].mean()  # image rows grow downwards: red is drawn above


def test_a_tests_viewer_leaves_no_process_behind():
    """rerun's wrapper starts the real viewer as a child: every viewer a test starts is ended."""
    from .conftest import rerun_viewer

    def viewers() -> set[str]:
        out = subprocess.run(["pgrep", "-f", "rerun --headless"], capture_output=True, text=True)
        return set(out.stdout.split())

    before = viewers()
    with rerun_viewer("320x240") as client:
        assert not client.get_state().loading
        assert viewers() - before  # the viewer runs
    assert wait_for(lambda: viewers() <= before, 10.0), viewers() - before
