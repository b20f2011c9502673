"""``bench originals``: this project's matchers beside the original C code, pair by pair.

The originals themselves (Player's MbICP, Censi's CSM) are built from GitHub by
tools/originals/build.sh, which this machine's tests cannot reach; their agreement with this project
is pinned in test_originals.py. Here stand-in drivers that speak the drivers' protocol (stdin: the
pairs; stdout: one pose per pair; stderr: seconds and count) check what the command does with it:
every pair and its guess reach the driver, the answers are scored against the log's stored poses,
and a missing or broken build is one line.
"""

import math
import stat
import sys

from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.evaluation.bench import bench_guesses
from mbicp_viz.evaluation.criteria import PAPER_000
from mbicp_viz.evaluation.pairs import stored_truth
from mbicp_viz.readers import read_log

from .conftest import HOKUYO_BAG, LASERAZOS
from .test_bad_input import assert_clean_error

# Reads the pairs as the C drivers do and answers each with its guess: what the command received.
ECHO_GUESS = """#!{python}
import sys
words = sys.stdin.read().split()
per_ray = {per_ray}
k = {header}
out = []
while k < len(words):
    n = int(words[k]); k += 1 + 2 * n * per_ray
    out.append("1 " + " ".join(words[k:k + 3])); k += 3
print("\\n".join(out[:len(out) - {drop}]))
sys.stderr.write({log!r})
print(0.001 * len(out), len(out), file=sys.stderr)
"""


def stand_ins(folder, drop=0, log=""):
    """The two stand-in drivers; ``log``: what they write on stderr before their time."""
    for name, per_ray, header in (("mbicp_pairs", 2, 15), ("csm_pairs", 3, 0)):
        exe = folder / name
        exe.write_text(
            ECHO_GUESS.format(
                python=sys.executable, per_ray=per_ray, header=header, drop=drop, log=log
            )
        )
        exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    return folder


def run(*args):
    res = CliRunner().invoke(app, ["bench", "originals", *(str(a) for a in args)])
    return res.exit_code, res.output


def test_every_pair_and_guess_reach_the_original_and_its_answers_are_scored(tmp_path):
    code, out = run(
        stand_ins(tmp_path), LASERAZOS, "--limit", 12, "--repeat", 1, "--perturb", 0.1, 4
    )
    assert code == 0, out
    log = read_log(LASERAZOS)
    pairs = log.consecutive_pairs(12)
    guesses = bench_guesses(log, pairs, (0.1, math.radians(4.0)), 0)
    truths = [stored_truth(log.scan(i), log.scan(j)) for i, j in pairs]
    by_guess = sum(PAPER_000.judge(g, t) for g, t in zip(guesses, truths))
    assert 0 < by_guess < 12  # the count below tells the guesses apart from the truth
    lines = out.splitlines()
    assert "12 pairs of 361 beams" in lines[0]
    for name in ("mbicp", "icp", "plicp"):
        row = next(line for line in lines if line.startswith(f"{name} "))
        assert f"successes original {by_guess}, ours " in row and "(ratio " in row, row
    # 1 ms per match by the stand-ins' clock, against this project's improved MbICP as published
    assert any(
        line.startswith("improved MbICP (as published)") and "against CSM's PL-ICP 1.000 ms" in line
        for line in lines
    ), out


def test_a_drivers_log_in_colour_before_its_time_is_read_past(tmp_path):
    """CSM logs to stderr in colour, its reset code not followed by a newline (seen at 1081
    beams): the time after it is still read."""
    drivers = stand_ins(tmp_path, log="\x1b[1;35;40m:sm_icp: some note\x1b[0m")
    code, out = run(drivers, LASERAZOS, "--limit", 3, "--repeat", 1)
    assert code == 0, out
    assert "against CSM's PL-ICP 1.000 ms" in out, out


def test_without_a_build_one_line_says_how_to_build(tmp_path):
    assert_clean_error(
        *run(tmp_path, LASERAZOS), str(tmp_path / "mbicp_pairs"), "tools/originals/build.sh"
    )


def test_a_driver_that_answers_too_few_pairs_ends_in_one_line(tmp_path):
    code, out = run(stand_ins(tmp_path, drop=1), LASERAZOS, "--limit", 3, "--repeat", 1)
    header, error = out.strip().splitlines()  # what runs, then why it stopped
    assert code == 2 and header.startswith(str(LASERAZOS)), out
    assert (
        error.startswith("mbicp-viz: error:")
        and "mbicp_pairs" in error
        and "2 poses for 3 pairs" in error
    )


def test_more_rays_than_the_c_mbicp_takes_skip_it_and_compare_the_rest(tmp_path):
    """The C MbICP takes at most 361 rays: on 681 it is not run (and the line says how to thin the
    scans); CSM's ICP and PL-ICP, and improved MbICP against PL-ICP, run at full resolution."""
    code, out = run(stand_ins(tmp_path), HOKUYO_BAG, "--limit", 2, "--repeat", 1)
    assert code == 0, out
    lines = out.splitlines()
    assert "2 pairs of 681 beams" in lines[0]
    assert (
        "mbicp  not compared: the original takes at most 361 rays and these scans have 681: "
        "--every 2 keeps "
        "one beam in 2" in lines
    )
    assert [line.split()[0] for line in lines[1:5]] == ["mbicp", "icp", "plicp", "improved"], out


def test_a_bad_perturbation_or_params_file_is_one_line(tmp_path):
    assert_clean_error(*run(stand_ins(tmp_path), LASERAZOS, "--perturb", -1, 3), "--perturb")
    bad = tmp_path / "bad.toml"
    bad.write_text("[improved]\nextrapolate = -1\n")
    assert_clean_error(*run(tmp_path, LASERAZOS, "--params", bad), "extrapolate")


def test_a_driver_that_never_answers_is_stopped_and_named(tmp_path, monkeypatch):
    from mbicp_viz.evaluation import originals

    stand_ins(tmp_path)
    (tmp_path / "mbicp_pairs").write_text(
        f"#!{sys.executable}\nimport signal, sys\nsys.stdin.read()\nsignal.pause()\n"
    )
    monkeypatch.setattr(originals, "DRIVER_TIMEOUT_S", 1)
    code, out = run(tmp_path, LASERAZOS, "--limit", 2, "--repeat", 1)
    error = out.strip().splitlines()[-1]
    assert code == 2 and "mbicp_pairs: no answer within 1 s for 2 pairs" in error, out


def test_a_log_without_stored_poses_says_so_instead_of_zero_successes(tmp_path):
    code, out = run(stand_ins(tmp_path), HOKUYO_BAG, "--every", 2, "--limit", 2, "--repeat", 1)
    assert code == 0, out
    rows = [
        line
        for line in out.splitlines()
        if line.startswith(("mbicp ", "icp ", "plicp ", "improved "))
    ]
    assert len(rows) == 4 and all(
        "no stored poses to count successes" in r and "successes " not in r for r in rows
    ), out
    assert "2 pairs of 341 beams" in out.splitlines()[0]
