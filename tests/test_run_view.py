"""The run view's model (views/debugger/run.py) on a real run, and ``eval sequence --serve``, which
opens it: the map is the scans up to the pair at the chained poses, in the first scan's frame; the
debugger answers and Ctrl-C ends it with no process left."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
import urllib.request

import numpy as np

from mbicp_viz.core import MATCHERS
from mbicp_viz.evaluation.sequence import match_sequence
from mbicp_viz.readers import read_log
from mbicp_viz.views.debugger.run import RunModel, is_chain

from .conftest import INTEL


def test_the_map_is_the_scans_up_to_the_pair_at_the_chained_poses():
    log = read_log(str(INTEL))
    rows = match_sequence(log, MATCHERS["improved"].params_type(), guess="odometry", workers=1)
    assert is_chain(rows) and not is_chain(rows[:3] + rows[4:])
    model = RunModel(log, rows)
    mount = log.frames.mount
    for n in (0, 17, len(rows) - 1):
        at = model.scene_at(n)
        # the pair's two scans where the chained matches put them (base pose @ mount: the laser)
        pose = model.poses[n + 1] @ mount
        assert np.allclose(at.obj_xy, pose.apply(log.scan(rows[n].obj).points()))
        expected = sum(log.scan(i).n_valid for i in [rows[0].ref, *(r.obj for r in rows[: n + 1])])
        assert len(at.map_xy) == expected
    # the log's own poses start where the run does: the first scan's frame
    first = model.stored[0]
    assert np.allclose([first.x, first.y, first.theta], 0.0, atol=1e-12)
    assert len(model.stored) == len(model.poses) == len(rows) + 1


def test_eval_sequence_serve_opens_the_run_and_stops_on_ctrl_c(tmp_path):
    cmd = [sys.executable, "-m", "mbicp_viz", "eval", "sequence", str(INTEL)]
    cmd += ["--out", str(tmp_path / "rows.jsonl"), "--serve", "--port", "0", "--workers", "1"]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
    )
    try:
        deadline, url = time.monotonic() + 120, None
        while url is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            m = re.search(r"open (http://127\.0\.0\.1:\d+) in a browser", line)
            url = m.group(1) if m else None
        assert url, "the debugger did not say where it listens"
        assert (tmp_path / "rows.jsonl").exists()  # the run is written before it is served
        with urllib.request.urlopen(url, timeout=30) as page:
            assert page.status == 200
        os.killpg(proc.pid, signal.SIGINT)
        # ended (as the server stops, or as any interrupted command: 130), without a traceback
        assert proc.wait(timeout=30) in (0, 130)
        assert "Traceback" not in proc.stdout.read()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
