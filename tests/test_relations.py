"""``eval relations``: Kümmerle et al. 2009 relations against real Intel scans."""

import pytest
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.errors import InputError
from mbicp_viz.readers.relations import read_relations

from .conftest import DATA, json_lines

OFFSET = "976052857.337"


def test_relations_are_matched_and_scored(tmp_path):
    out = tmp_path / "rel.json"
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "relations",
            str(DATA / "intel-relations.log"),
            str(DATA / "intel-relations.relations"),
            "--offset",
            OFFSET,
            "--algo",
            "psm",
            "--out",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    assert "8 relations matched" in res.output and "median" in res.output
    rows = json_lines(out)
    assert len(rows) == 8 and all(r["ref"] != r["obj"] for r in rows)
    # these are mostly in-place turns: the matcher gets most of them within a few centimetres
    assert sorted(r["error_xy"] for r in rows)[4] < 0.05
    # the log's corrected poses are judged by the same relations (a frame mix-up would put them
    # tens of centimetres off): how good a truth `eval sequence --truth pose` scores against
    assert "the log's scan poses against the same relations" in res.output
    assert sorted(r["stored_error_xy"] for r in rows)[4] < 0.1


def test_without_the_offset_nothing_matches():
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "relations",
            str(DATA / "intel-relations.log"),
            str(DATA / "intel-relations.relations"),
        ],
    )
    assert res.exit_code == 0 and "no relation had a scan at both ends" in res.output


def test_malformed_relations_name_the_line(tmp_path):
    p = tmp_path / "bad.relations"
    p.write_text("1 2 0 0 0 0 0 0.1\n1 2 x 0 0 0 0 0\n")
    with pytest.raises(InputError, match="bad.relations:2.*'x'"):
        read_relations(str(p))
    p.write_text("1 2 3\n")
    res = CliRunner().invoke(app, ["eval", "relations", str(DATA / "intel-relations.log"), str(p)])
    assert res.exit_code == 2 and "bad.relations:1" in res.output
