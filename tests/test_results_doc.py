"""docs/results.md: every table is what its command prints (numbers byte for byte, same seed)."""

import re
import shlex
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mbicp_viz.cli import app

DOC = Path(__file__).parent.parent / "docs" / "results.md"
SHARED = Path(__file__).parent.parent.parent / "shared" / "data"


def overlap_blocks():
    text = DOC.read_text()
    for m in re.finditer(r"```\n(mbicp-viz eval overlap [^\n]+)\n```\n\n(.*?)\n(?=###|What this shows)", text, re.S):
        yield m.group(1), m.group(2).strip()


def test_the_doc_has_both_overlap_tables():
    assert len(list(overlap_blocks())) == 2


@pytest.mark.parametrize("command, table", list(overlap_blocks()))
def test_overlap_tables_regenerate_exactly(command, table):
    if not SHARED.exists():
        pytest.fail("the results use the full logs in ../shared/data, beside the checkout")
    args = shlex.split(command)[1:]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    printed = res.stdout.strip() if hasattr(res, "stdout") else res.output
    assert table in printed
