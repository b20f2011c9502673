"""Jupyter: the lesson's notebooks (``lesson --notebooks DIR``) executed headless by nbclient hold
the lesson's own numbers, and ``mv.show`` feeds rerun's notebook widget the recording the
``.rrd`` holds, blueprint included."""

from __future__ import annotations

import base64
import shutil
from collections import defaultdict

import nbformat
import pytest
from nbclient import NotebookClient
from rerun.chunk import RrdReader
from typer.testing import CliRunner

import mbicp_viz as mv
from mbicp_viz.cli import app as cli
from mbicp_viz.views.lesson.steps import lesson_dir, load_lesson

from .conftest import DATA

STEPS = load_lesson()
WIDGET = "application/vnd.jupyter.widget-view+json"


@pytest.fixture(scope="module")
def notebooks(tmp_path_factory):
    out = tmp_path_factory.mktemp("lesson") / "notebooks"
    res = CliRunner().invoke(cli, ["lesson", "--notebooks", str(out)])
    assert res.exit_code == 0, res.output
    return out


def execute(path, cwd):
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    client = NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(cwd)}}
    )
    client.execute()
    return nb


def outputs(nb, mime: str) -> list:
    """Each code cell's outputs of type ``mime`` (printed text: "stream"), in cell order."""
    found = []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for o in cell.outputs:
            if mime == "stream" and o.output_type == "stream":
                found.append(o.text)
            elif mime in o.get("data", {}):
                found.append(o.data[mime])
    return found


def test_one_notebook_per_step(notebooks):
    names = sorted(p.name for p in notebooks.glob("*.ipynb"))
    assert len(names) == len(STEPS)
    assert [n[:7] for n in names] == [f"step-{s.number:02d}" for s in STEPS]


@pytest.mark.parametrize("step", STEPS, ids=lambda s: s.path.stem)
def test_each_notebook_runs_top_to_bottom_with_the_lessons_numbers(notebooks, step, tmp_path):
    path = next(notebooks.glob(f"step-{step.number:02d}-*.ipynb"))
    nb = execute(path, tmp_path)
    done = mv.run_lesson_step(step)
    # the text and the "Try" with the numbers of the step's own run, as the lesson shows them
    assert outputs(nb, "text/markdown") == [done.text, done.try_text]
    assert any(ch.isdigit() for ch in done.text)
    # its picture
    (png,) = outputs(nb, "image/png")
    assert base64.b64decode(png) == mv.lesson_picture(done)
    # its iterations in rerun's notebook viewer
    assert outputs(nb, WIDGET)
    # the exercise, run as written, repeats the step's matches
    printed = "".join(outputs(nb, "stream"))
    for run in done.runs:
        pose = next(ln for ln in mv.report(run).splitlines() if ln.startswith("pose"))
        status = next(ln for ln in mv.report(run).splitlines() if ln.startswith("status"))
        assert pose in printed and status in printed, run.matcher


def test_a_lesson_of_ones_own_runs_from_its_folder(tmp_path):
    own = tmp_path / "my-lesson"
    own.mkdir()
    shutil.copy(lesson_dir() / "04-mbicp-iterations.toml", own / "01-first.toml")
    # a step names its input relative to the recordings folder: give it an absolute one
    text = (own / "01-first.toml").read_text()
    inputs = lesson_dir().parent / "inputs"
    (own / "01-first.toml").write_text(text.replace('input = "inputs/', f'input = "{inputs}/'))
    out = tmp_path / "nb"
    res = CliRunner().invoke(cli, ["lesson", "--dir", str(own), "--notebooks", str(out)])
    assert res.exit_code == 0, res.output
    (path,) = out.glob("*.ipynb")
    assert f"directory={str(own.resolve())!r}" in path.read_text().replace('\\"', '"')
    nb = execute(path, tmp_path)
    step = mv.lesson_step(1, directory=own)
    assert outputs(nb, "text/markdown")[0] == mv.run_lesson_step(step).text


def test_notebooks_and_export_together_or_onto_a_file_are_refused(tmp_path):
    f = tmp_path / "file"
    f.write_text("keep")
    for args in (
        ["--notebooks", str(f)],
        ["--notebooks", str(tmp_path / "a"), "--export", str(tmp_path / "b")],
    ):
        res = CliRunner().invoke(cli, ["lesson", *args])
        assert res.exit_code == 2 and "--notebooks" in res.output, res.output
    assert f.read_text() == "keep"


# --- mv.show: the widget gets what the .rrd holds ------------------------------------------------


def widget_pieces(viewer, folder) -> list:
    """What the widget was sent to show (queued until a page takes it), each message as a file."""
    paths = []
    for k, (event, buffers) in enumerate(viewer._viewer._event_queue):
        assert event == {"type": "rrd"}
        paths.append(folder / f"piece-{k}.rrd")
        paths[-1].write_bytes(b"".join(bytes(b) for b in buffers))
    return paths


def contents(paths) -> tuple[dict, set]:
    """{entity: {column: sorted values}} of the recordings' data, and the blueprint's views
    (name, origin)."""
    data = defaultdict(lambda: defaultdict(list))
    views = set()
    for path in paths:
        reader = RrdReader(str(path))
        for store in reader.recordings():
            for chunk in reader.stream(store=store).to_chunks():
                rb = chunk.to_record_batch()
                for name in rb.schema.names:
                    if ":" in name:
                        data[chunk.entity_path][name] += map(repr, rb.column(name).to_pylist())
        for store in reader.blueprints():
            for chunk in reader.stream(store=store).to_chunks():
                rb = chunk.to_record_batch()
                cols = {
                    n.split(":")[-1]: rb.column(n).to_pylist()
                    for n in rb.schema.names
                    if n.endswith((":display_name", ":space_origin"))
                }
                if "display_name" in cols:
                    origins = cols.get("space_origin", [None] * rb.num_rows)
                    views |= {
                        (repr(n), repr(o)) for n, o in zip(cols["display_name"], origins) if n
                    }
    return {e: {c: sorted(v) for c, v in cols.items()} for e, cols in data.items()}, views


@pytest.mark.parametrize("what", ["pair", "run"])
def test_show_feeds_the_widget_the_recording_the_rrd_holds(what, tmp_path):
    log = mv.read_log(DATA / "intel-relations.log")
    if what == "pair":
        matches = [mv.match(log, 3, 4, "mbicp"), mv.match(log, 3, 4)]
        viewer = mv.show(matches, teaching=True)
        mv.write_rrd(matches, tmp_path / "file.rrd", teaching=True)
    else:
        rows = mv.run(log, workers=1)
        viewer = mv.show(rows, log=log)
        mv.write_rrd(rows, tmp_path / "file.rrd", log=log)
    shown, shown_views = contents(widget_pieces(viewer, tmp_path))
    saved, saved_views = contents([tmp_path / "file.rrd"])
    assert shown == saved and len(saved) > 5
    assert shown_views == saved_views and len(saved_views) >= 3
