"""A matcher is declared in one place: a matcher registered from one file of its own
(tests/extra_matcher.py) is a choice of the command line, a matcher of the debugger and a
recording's run, with no other file touched."""

import json
import subprocess
import sys
from pathlib import Path

from .conftest import LASERAZOS

ROOT = Path(__file__).parent.parent

PROBE = """
import json, sys
import viser
import tests.extra_matcher  # registers p2p: before the command line makes its choices
from rerun.chunk import RrdReader
from typer.testing import CliRunner
from mbicp_viz.cli import app
from mbicp_viz.core import Pose2
from mbicp_viz.readers import read_log
from mbicp_viz.views.debugger.session import Session
from mbicp_viz.views.debugger.state import Source

log, rrd = sys.argv[1], sys.argv[2]
run = CliRunner().invoke
out = {}
res = run(app, ["match", log, "--pair", "5", "6", "--algo", "p2p", "--json"])
out["match"] = (res.exit_code, json.loads(res.stdout) if res.exit_code == 0 else res.output)
res = run(app, ["params", "--algo", "p2p"])
out["params"] = res.stdout
res = run(app, ["match", log, "--pair", "5", "6", "--algo", "p2p", "--rrd", rrd])
out["rrd"] = sorted({c.entity_path for c in RrdReader(rrd).stream().to_chunks()})
server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
try:
    s = Session(server, Source("laserazos", read_log(log), pair=(5, 6), guess=Pose2(),
                               matchers=("p2p",)))
    s.first_match(None)
    out["debugger"] = (list(s.matchers.boxes), s.state.runs[0].result.reason.value)
    s.close()
finally:
    server.stop()
print(json.dumps(out))
"""


def test_a_matcher_registered_in_one_file_is_in_the_cli_the_debugger_and_a_recording(tmp_path):
    res = subprocess.run(
        [sys.executable, "-c", PROBE, str(LASERAZOS), str(tmp_path / "p2p.rrd")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    code, row = out["match"]
    assert code == 0 and row["algorithm"] == "p2p" and row["converged"], row
    assert "max_dist = 1.0" in out["params"]
    assert "/p2p/scene/pairs/point" in out["rrd"] and "/p2p/scene/reference" in out["rrd"]
    boxes, reason = out["debugger"]
    assert "p2p" in boxes and reason == "converged"
