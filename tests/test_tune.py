"""``tune``: a real Optuna study on real scans (SQLite), resumed, interrupted, distributed over two
processes on a real PostgreSQL server, its outputs read back."""

import glob
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
from contextlib import closing
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.readers.params_toml import make_params
from mbicp_viz.readers.rows import read_rows
from mbicp_viz.views.debugger.sources import files_source

from .conftest import DATA, free_port, wait_for

LOG, HOLDOUT = str(DATA / "intel-relations.log"), str(DATA / "aces-10.log.gz")


def tune(tmp_path, *args):
    return CliRunner().invoke(
        app,
        [
            "tune",
            LOG,
            "--storage",
            f"sqlite:///{tmp_path / 'tune.db'}",
            "--workers",
            "1",
            "--out",
            str(tmp_path / "tuned.toml"),
            *args,
        ],
    )


def test_a_study_against_the_scan_poses_with_a_holdout(tmp_path):
    res = tune(
        tmp_path,
        "--trials",
        "6",
        "--holdout",
        HOLDOUT,
        "--png-dir",
        str(tmp_path / "png"),
        "--rows-dir",
        str(tmp_path / "rows"),
    )
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    train = next(ln for ln in lines if ln.startswith("training (11 pairs)"))
    held = next(ln for ln in lines if ln.startswith("holdout (9 pairs)"))
    successes = lambda ln: [int(part.split("/")[0]) for part in ln.split()[2:] if "/" in part]  # noqa: E731
    # defaults are trial 0
    assert len(successes(train)) == 2 and successes(train)[1] >= successes(train)[0]
    assert len(successes(held)) == 2
    best = make_params("improved", tmp_path / "tuned.toml")  # the TOML reads back
    assert any(f"L {best.L:.4g}" in ln for ln in lines)
    for png in ("history.png", "importance.png"):
        assert (tmp_path / "png" / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = tmp_path / "rows" / "intel-relations-rows.json"
    assert (
        len(read_rows(rows)) == 11 and files_source(LOG, None, rows=str(rows)).failures is not None
    )
    assert f"--rows {rows}" in res.stdout


def test_a_study_resumes_by_name(tmp_path):
    assert tune(tmp_path, "--trials", "2", "--study", "s").exit_code == 0
    res = tune(tmp_path, "--trials", "3", "--study", "s")
    assert (
        res.exit_code == 0
        and "(2 trials before)" in res.stdout
        and "3 trials ran now, 5 in the study" in res.stdout
    )


def test_ctrl_c_keeps_the_finished_trials(tmp_path):
    db = tmp_path / "tune.db"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "mbicp_viz",
            "tune",
            LOG,
            "--trials",
            "100000",
            "--workers",
            "1",
            "--storage",
            f"sqlite:///{db}",
            "--out",
            str(tmp_path / "tuned.toml"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )

    def finished() -> int:
        try:
            with closing(sqlite3.connect(db)) as con:
                return con.execute(
                    "select count(*) from trials where state = 'COMPLETE'"
                ).fetchall()[0][0]
        except sqlite3.Error:
            return 0

    wait_for(lambda: finished() >= 3, 120.0)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert finished() >= 3 and "trials ran now" in out and (tmp_path / "tuned.toml").exists()


@pytest.mark.parametrize(
    "other, field",
    [
        (["--limit", "4"], "--limit"),
        (["--perturb", "0.2", "10"], "--perturb"),
        (["--fields", "L"], "--fields"),
    ],
)
def test_a_study_refuses_to_resume_on_another_objective(tmp_path, other, field):
    assert tune(tmp_path, "--trials", "1", "--study", "s", "--limit", "3").exit_code == 0
    res = tune(tmp_path, "--trials", "1", "--study", "s", "--limit", "3", *other)
    assert res.exit_code == 2 and f"{field}: study 's' was scored with" in res.stderr, res.output
    assert "would mix objectives" in res.stderr and "Traceback" not in res.output


def test_a_trial_killed_mid_run_is_failed_on_resume_and_the_defaults_are_scored(tmp_path):
    db = tmp_path / "tune.db"
    cmd = [sys.executable, "-m", "mbicp_viz", "tune", LOG, "--trials", "100000", "--workers", "1"]
    cmd += ["--storage", f"sqlite:///{db}", "--out", str(tmp_path / "tuned.toml")]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def states() -> list[str]:
        try:
            with closing(sqlite3.connect(db)) as con:
                return [r[0] for r in con.execute("select state from trials order by number")]
        except sqlite3.Error:
            return []

    def scoring() -> bool:  # the first trial (the defaults) is under way, its worker recorded
        try:
            with closing(sqlite3.connect(db)) as con:
                attrs = con.execute("select key from trial_user_attributes").fetchall()
        except sqlite3.Error:
            return False
        return states() == ["RUNNING"] and ("worker",) in attrs

    try:  # kill -9 while the defaults are scored
        assert wait_for(scoring, 120.0), states()
    finally:
        proc.kill()
        proc.wait()
    res = tune(tmp_path, "--trials", "1")
    assert res.exit_code == 0, res.output
    assert "1 trial(s) left running by a stopped run marked failed" in res.stderr
    assert "the defaults were never scored in this study" in res.stderr
    assert states() == ["FAIL", "COMPLETE"]
    train = next(ln for ln in res.stdout.splitlines() if ln.startswith("training"))
    assert train.split()[3:11] == train.split()[11:19]  # the best is the defaults, scored


@pytest.mark.parametrize(
    "args, field",
    [
        (["--fields", "nope"], "--fields"),
        (["--truth", "x"], "--truth"),
        (["--guess", "pose"], "--guess"),
        (["--perturb", "-1", "2"], "--perturb"),
        (["--storage", "postgresql://127.0.0.1:1/none"], "--storage"),
    ],
)
def test_wrong_options_are_one_line(tmp_path, args, field):
    res = tune(tmp_path, "--trials", "1", *args)
    assert res.exit_code == 2 and field in res.output and "Traceback" not in res.output


@pytest.fixture(scope="module")
def postgres_url():
    """A real PostgreSQL server: the one MBICP_VIZ_POSTGRES_URL names, else a throwaway cluster
    started here from Debian's server binaries (as the postgres user when run as root)."""
    if os.environ.get("MBICP_VIZ_POSTGRES_URL"):
        yield os.environ["MBICP_VIZ_POSTGRES_URL"]
        return
    found = shutil.which("pg_ctl") or next(
        iter(sorted(glob.glob("/usr/lib/postgresql/*/bin/pg_ctl"))), None
    )
    assert found, "the PostgreSQL server (Debian: postgresql) is needed; .ci/run installs it"
    bindir = Path(found).resolve().parent
    as_user = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []
    root = Path(tempfile.mkdtemp(prefix="mbicp-viz-pg-"))
    root.chmod(0o755)
    if as_user:
        shutil.chown(root, "postgres")
    data, port = root / "data", free_port()
    subprocess.run(
        as_user + [str(bindir / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres"],
        check=True,
        capture_output=True,
    )
    subprocess.run(
        as_user
        + [
            str(bindir / "pg_ctl"),
            "-D",
            str(data),
            "-l",
            str(root / "log"),
            "-w",
            "-o",
            f"-p {port} -k {root} -c listen_addresses=127.0.0.1",
            "start",
        ],
        check=True,
        capture_output=True,
    )
    try:
        yield f"postgresql://postgres@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run(
            as_user + [str(bindir / "pg_ctl"), "-D", str(data), "-m", "immediate", "stop"],
            capture_output=True,
        )
        shutil.rmtree(root, ignore_errors=True)


def test_two_workers_share_one_study_on_postgresql(postgres_url, tmp_path):
    """Optuna's documented way to distribute: every worker runs `tune` on the same study."""
    import optuna

    study = f"shared-{os.getpid()}"
    cmd = [
        sys.executable,
        "-m",
        "mbicp_viz",
        "tune",
        LOG,
        "--trials",
        "3",
        "--workers",
        "1",
        "--storage",
        postgres_url,
        "--study",
        study,
    ]
    procs = [
        subprocess.Popen(
            cmd + ["--out", str(tmp_path / f"w{k}.toml")],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for k in range(2)
    ]
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
    storage = "postgresql+psycopg://" + postgres_url.split("://", 1)[1]
    trials = optuna.load_study(study_name=study, storage=storage).trials
    workers = {
        t.user_attrs["worker"] for t in trials if t.state == optuna.trial.TrialState.COMPLETE
    }
    assert (
        len([t for t in trials if t.state == optuna.trial.TrialState.COMPLETE]) >= 6
        and len(workers) == 2
    )
