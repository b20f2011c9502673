"""The parameter presets: shipped with the package, read by ``--params NAME``, and the ones the
README and docs/ run are the ones that exist, for the matchers they run them with."""

import fnmatch
import json
import re
import shlex
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.readers.params_toml import PRESETS, make_params, preset_names

from .conftest import LASERAZOS

ROOT = Path(__file__).parent.parent
DOCS = (ROOT / "README.md", ROOT / "docs" / "reference.md", ROOT / "docs" / "results.md")
runner = CliRunner()


def documented_runs():
    """(preset, matcher) of every command line in the docs that passes ``--params NAME``."""
    for doc in DOCS:
        text = doc.read_text().replace("\\\n", " ")
        for line in text.splitlines():
            command = line.split(" # ")[0]
            m = re.search(r"mbicp-viz .*--params ([a-z0-9-]+)(`|\s|$)", command)
            if m is None:
                continue
            args = shlex.split(command[command.index("mbicp-viz") :].split("`")[0])
            algos = ["improved"]
            for flag in ("--algo", "--algos"):
                if flag in args:
                    algos = args[args.index(flag) + 1].split(",")
            for algo in algos:
                # "--algo A": any matcher, stands for the lines that name one
                if not algo.isupper():
                    yield m.group(1), algo


def test_every_preset_the_docs_run_exists_and_loads_for_its_matchers():
    runs = set(documented_runs())
    assert {name for name, _ in runs} == set(preset_names())  # none missing, none undocumented
    for name, algo in runs:
        make_params(algo, name)  # raises on a key the matcher does not have


def test_the_presets_are_package_data():
    setup = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    patterns = setup["package-data"]["mbicp_viz.presets"]
    files = [p.name for p in PRESETS.iterdir()]
    assert "mbicp_viz.presets" in setup["packages"]
    assert files and all(any(fnmatch.fnmatch(f, g) for g in patterns) for f in files), (
        files,
        patterns,
    )


def run(*args):
    res = runner.invoke(app, [str(a) for a in args])
    return res.exit_code, res.output


def test_params_takes_a_preset_by_name_and_a_file_of_that_name_first(tmp_path, monkeypatch):
    code, listing = run("params", "--presets")
    assert code == 0 and [line.split()[0] for line in listing.splitlines()] == preset_names()
    match = ("match", LASERAZOS, "--pair", 5, 6, "--init", "0.2", "-0.1", "10", "--json")
    by_name = json.loads(run(*match, "--params", "poor-guess")[1])
    by_path = json.loads(run(*match, "--params", PRESETS / "poor-guess.toml")[1])
    published = json.loads(run(*match)[1])
    assert by_name["iterations"] == by_path["iterations"] != published["iterations"]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "poor-guess").write_text("[improved]\nMaxIter = 2\n")
    assert json.loads(run(*match, "--params", "poor-guess")[1])["iterations"] == 2


@pytest.mark.parametrize("name", ["poor-gues", "presets/poor-guess", "poor-guess.toml"])
def test_a_name_that_is_no_preset_and_no_file_is_one_line(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out = run("match", LASERAZOS, "--pair", 5, 6, "--params", name)
    lines = out.strip().splitlines()
    assert (
        code == 2
        and len(lines) == 1
        and lines[0].startswith("mbicp-viz: error:")
        and name in lines[0]
    ), out
    # a bare name lists the presets; a path is a path
    assert ("poor-guess, robust-polar" in lines[0]) == ("/" not in name and "." not in name), lines[
        0
    ]
