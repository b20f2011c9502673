"""``eval relations LOG RELATIONS --run ROWS``: a whole run scored as Kümmerle et al. 2009 score
SLAM (evaluation/run_score.py), checked against a scorer written here from the paper with
homogeneous matrices, on a real Intel run."""

from __future__ import annotations

import json
import math
import re

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from mbicp_viz.cli import app as cli
from mbicp_viz.core import Pose2
from mbicp_viz.evaluation.run_score import score_track
from mbicp_viz.readers.relations import Relation

from .conftest import DATA

LOG, RELATIONS, OFFSET = (
    DATA / "intel-relations.log",
    DATA / "intel-relations.relations",
    976052857.337,
)


def mat(x, y, th):
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def paper_errors(stamps, poses, relations, tol=0.025):
    """Kümmerle et al. eq. 2: e = d*^-1 d with d = P1^-1 P2, here in matrices."""
    et, er = [], []
    for t1, t2, x, y, _z, _r, _p, yaw in relations:
        i, j = np.argmin(abs(stamps - t1)), np.argmin(abs(stamps - t2))
        if abs(stamps[i] - t1) > tol or abs(stamps[j] - t2) > tol:
            continue
        d = np.linalg.inv(poses[i]) @ poses[j]
        e = np.linalg.inv(mat(x, y, yaw)) @ d
        et.append(math.hypot(e[0, 2], e[1, 2]))
        er.append(abs(math.atan2(e[1, 0], e[0, 0])))
    return np.array(et), np.array(er)


def test_a_run_scored_on_the_relations_equals_the_papers_measure(tmp_path):
    rows = tmp_path / "rows.json"
    run = CliRunner().invoke(
        cli,
        ["eval", "sequence", str(LOG), "--guess", "odometry", "--out", str(rows), "--workers", "1"],
    )
    assert run.exit_code == 0, run.output
    res = CliRunner().invoke(
        cli,
        [
            "eval",
            "relations",
            str(LOG),
            str(RELATIONS),
            "--run",
            str(rows),
            "--offset",
            str(OFFSET),
        ],
    )
    assert res.exit_code == 0, res.output
    # the scorer of this test: the chain composed from the rows, the stamps of the log's scans
    lines = [json.loads(x) for x in rows.read_text().splitlines() if x.strip()]
    chain = [np.eye(3)]
    for r in lines:
        chain.append(chain[-1] @ mat(r["x"], r["y"], r["theta"]))
    stamps = np.array(
        [float(x.split()[-3]) for x in LOG.read_text().splitlines() if x.startswith("FLASER")]
    )
    et, er = paper_errors(stamps + OFFSET, chain, np.loadtxt(RELATIONS, ndmin=2))
    assert len(et) == 8
    got = re.search(
        r"matches chained: translation ([\d.]+) ± ([\d.]+) m, rotation ([\d.]+) ± ([\d.]+) deg",
        res.output,
    )
    assert got, res.output
    t, ts, r, rs = (float(g) for g in got.groups())
    assert abs(t - et.mean()) <= 1e-3 and abs(ts - et.std(ddof=1)) <= 1e-3
    assert abs(r - math.degrees(er.mean())) <= 0.01
    assert abs(rs - math.degrees(er.std(ddof=1))) <= 0.01
    assert "raw odometry: translation" in res.output and "kalman (matcher + odometry)" in res.output
    assert "published (Kümmerle et al. 2009, intel): scan matching 0.220 ± 0.296 m" in res.output
    worst = int(np.argmax(et))  # the relations are in file order and all are covered
    assert (
        f"relation {worst + 1} ("
        in res.output.split("most (translational error):")[1].splitlines()[1]
    )


def test_rows_that_are_no_chain_are_refused_in_one_line(tmp_path):
    rows = tmp_path / "rows.json"
    run = CliRunner().invoke(
        cli,
        ["eval", "sequence", str(LOG), "--guess", "odometry", "--out", str(rows), "--workers", "1"],
    )
    assert run.exit_code == 0, run.output
    kept = rows.read_text().splitlines()
    rows.write_text("\n".join(kept[:3] + kept[4:]) + "\n")  # one pair taken out: a gap
    res = CliRunner().invoke(
        cli,
        [
            "eval",
            "relations",
            str(LOG),
            str(RELATIONS),
            "--run",
            str(rows),
            "--offset",
            str(OFFSET),
        ],
    )
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert f"{rows}:4: ref: the rows are no chain" in res.output


poses = st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-math.pi, math.pi)).map(
    lambda p: Pose2(*p)
)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(poses, min_size=3, max_size=12),
    poses,
    st.lists(st.tuples(st.integers(0, 11), st.integers(0, 11)), min_size=1, max_size=8),
)
def test_the_score_sees_only_motions(track, world, picks):
    """A run that is the truth scores zero in any world frame; the score of a run does not change
    when its whole trajectory is moved rigidly (only motions between stamps count)."""
    stamps = [float(k) for k in range(len(track))]
    rels = [
        Relation(float(i), float(j), track[i].inverse() @ track[j])
        for i, j in picks
        if i < len(track) and j < len(track) and i != j
    ]
    if not rels:
        return
    exact = score_track("truth", stamps, [world @ p for p in track], rels, 0.1)
    assert exact.relations == len(rels) and exact.trans[0] < 1e-9 and exact.rot[0] < 1e-9
    bent = [p @ Pose2(0.01 * k, 0.0, 0.002 * k) for k, p in enumerate(track)]
    a = score_track("bent", stamps, bent, rels, 0.1)
    b = score_track("bent, moved", stamps, [world @ p for p in bent], rels, 0.1)
    assert abs(a.trans[0] - b.trans[0]) < 1e-7 and abs(a.rot[0] - b.rot[0]) < 1e-9
