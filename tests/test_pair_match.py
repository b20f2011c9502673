"""One record of a pair's match: ``match --json``, a rows file and an ``.rrd`` of the same pair
hold the same record, and it reads back as it was written."""

import json
import math

import numpy as np
import pytest
from rerun.chunk import RrdReader
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.errors import InputError
from mbicp_viz.readers.pair_match import parse_pair_match
from mbicp_viz.readers.rows import read_rows

from .conftest import DATA, json_lines

LOG = DATA / "intel-relations.log"
TIMINGS = ("time_ms", "guess_ms", "interpreted")  # differ run to run: not in a recording


def untimed(record: dict) -> dict:
    return {k: v for k, v in record.items() if k not in TIMINGS}


def invoke(*args: str) -> str:
    res = CliRunner().invoke(app, list(args))
    assert res.exit_code == 0, res.output
    return res.stdout


@pytest.fixture(scope="module")
def three_records(tmp_path_factory):
    """The first pair of a real Intel piece from the identity, scored against its scan poses: as
    ``match --json`` prints it, as ``eval sequence`` writes it, as ``match --rrd`` records it."""
    tmp = tmp_path_factory.mktemp("record")
    printed = json.loads(invoke("match", str(LOG), "--guess", "identity", "--json"))
    rows = tmp / "rows.json"
    invoke(
        "eval", "sequence", str(LOG), "--guess", "identity", "--truth", "pose", "--limit", "1",
        "--out", str(rows),
    )  # fmt: skip
    rrd = tmp / "pair.rrd"
    invoke("match", str(LOG), "--guess", "identity", "--rrd", str(rrd))
    texts = [
        text
        for chunk in RrdReader(str(rrd)).stream().to_chunks()
        if chunk.entity_path == "/improved/record"
        for text in chunk.to_record_batch().column("TextDocument:text").to_pylist()
    ]
    assert len(texts) == 1
    return printed, json_lines(rows)[0], json.loads(texts[0][0]), rows


def test_match_json_a_rows_file_and_a_recording_hold_the_same_record(three_records):
    printed, row, recorded, _ = three_records
    assert untimed(printed) == untimed(row) == recorded
    # what the record says: the pair, the matcher and all its parameters, the guess, the answer
    assert (printed["ref"], printed["obj"], printed["algorithm"]) == (0, 1, "improved")
    assert printed["guess"] == "identity" and printed["guess_pose"] == [0.0, 0.0, 0.0]
    assert printed["truth"] == "the log's scan poses" and len(printed["truth_pose"]) == 3
    assert {"error_xy", "error_theta", "success", "params", "frame"} <= set(printed)
    assert all(k in printed for k in TIMINGS[:1]) and not set(TIMINGS) & set(recorded)


def test_a_record_reads_back_as_it_was_written(three_records):
    printed, _, _, rows = three_records
    again = parse_pair_match(printed, "match.json", 1).to_json()
    assert again == printed
    # a match that kept no pairs has no error: written as null, read back as NaN, written as null
    unknown = parse_pair_match(printed | {"error": None}, "match.json", 1)
    assert math.isnan(unknown.result.error) and unknown.to_json()["error"] is None
    (read,) = read_rows(rows)
    assert read.to_json() == json_lines(rows)[0] and read.line == 1
    assert read.matcher == "improved" and read.score is not None and read.events is None


@pytest.mark.parametrize(
    "change, field",
    [
        (lambda r: r.update(reason="tired"), "reason"),
        (lambda r: r.update(covariance=[[1.0, 0.0], [0.0, 1.0]]), "covariance"),
        (lambda r: r.update(truth_pose=[0.0, "x", 0.0]), "truth_pose"),
        (lambda r: r.pop("pairs_kept"), "pairs_kept"),
        (lambda r: r.update(success="yes"), "success"),
    ],
)
def test_a_damaged_record_names_its_field(three_records, change, field):
    printed = dict(three_records[0])
    change(printed)
    with pytest.raises(InputError) as e:
        parse_pair_match(printed, "match.json", 7)
    assert (e.value.line, e.value.field) == (7, field)


def test_a_record_sent_between_processes_comes_back_whole(intel):
    """A pool's rows are pickled by value (core/pickled.py): every field comes back."""
    import pickle

    from mbicp_viz.core import ImprovedParams
    from mbicp_viz.evaluation.single import Setup, match_pair

    m = match_pair(intel.scan(0), intel.scan(1), ImprovedParams(), Setup(), indices=(0, 1))
    back = pickle.loads(pickle.dumps(m))
    assert back.to_json() == m.to_json() and back.result.pose == m.result.pose
    assert np.array_equal(back.result.covariance, m.result.covariance)
