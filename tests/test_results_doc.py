"""docs/results.md: every table is what its command prints (numbers byte for byte, same seed).

These read the full logs of ../shared/data: they carry the ``shared`` marker, which the README's
test command leaves out and ``.ci/run`` runs as a step of its own where ../shared exists."""

import re
import shlex
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mbicp_viz.cli import app

ROOT = Path(__file__).parent.parent
DOC = ROOT / "docs" / "results.md"
pytestmark = pytest.mark.shared


def overlap_blocks():
    text = DOC.read_text()
    for m in re.finditer(
        r"```\n(mbicp-viz eval overlap [^\n]+)\n```\n\n(.*?)\n(?=###|What this shows)", text, re.S
    ):
        yield m.group(1), m.group(2).strip()


def console_blocks():
    """Each console block: its ($ command, the lines it printed), run in order (a later command
    may read what an earlier one wrote with --out)."""
    for block in re.findall(r"```console\n(.*?)```", DOC.read_text(), re.S):
        commands = []
        for line in block.splitlines():
            if line.startswith("$ "):
                commands.append((line[2:], []))
            elif commands:
                commands[-1][1].append(line)
        yield commands


def console_commands():
    """($ command, the lines it printed) from every console block."""
    for block in console_blocks():
        yield from block


def run(command: str, tmp_path=None) -> str:
    args = shlex.split(command)[1:]
    if tmp_path is not None:  # keep written files out of the checkout, and read them there
        if "--out" in args:
            k = args.index("--out") + 1
            args[k] = str(tmp_path / args[k])
        args = [
            str(tmp_path / a) if a[:1].isalnum() and (tmp_path / a).exists() else a for a in args
        ]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    return res.stdout


def test_the_doc_lists_every_evaluation():
    assert len(list(overlap_blocks())) == 7
    kinds = {shlex.split(c)[2] for c, _ in console_commands()}
    assert kinds == {
        "protocol",
        "sequence",
        "ceiling",
        "relations",
        "basin",
        "corridor",
        "covariance",
        "flags",
    }


@pytest.mark.parametrize("command, table", list(overlap_blocks()))
def test_overlap_tables_regenerate_exactly(command, table, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert table in run(command)


@pytest.mark.parametrize("block", list(console_blocks()), ids=lambda b: b[-1][0][:90])
def test_console_outputs_regenerate_exactly(block, monkeypatch, tmp_path):
    monkeypatch.chdir(ROOT)
    for command, lines in block:
        printed = run(command, tmp_path).replace(str(tmp_path) + "/", "")
        for line in lines:
            assert line in printed
