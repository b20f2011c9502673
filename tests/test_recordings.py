"""Curated scenarios: regenerated recordings equal the committed ones; the viewer renders them."""

import subprocess

import numpy as np
import pytest
from rerun.chunk import RrdReader
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.evaluation.scenarios import load_scenario, recordings_dir, scenario_paths
from mbicp_viz.views.scene import OBJECT, REFERENCE

from .conftest import RERUN, viewer_screenshot

RECORDINGS = recordings_dir()

NAMES = [p.stem for p in scenario_paths()]


def test_the_five_curated_scenarios_exist():
    assert set(NAMES) == {
        "partial-overlap",
        "large-rotation",
        "corridor",
        "csm-stallo2",
        "hokuyo-handheld",
    }
    for p in scenario_paths():
        s = load_scenario(p)
        assert s.note.strip() and s.params
        assert (RECORDINGS / f"{p.stem}.rrd").exists(), f"run: mbicp-viz record {p.stem}"


@pytest.fixture(scope="module")
def regenerated(tmp_path_factory):
    out = tmp_path_factory.mktemp("recordings")
    res = CliRunner().invoke(app, ["record", "--out-dir", str(out)])
    assert res.exit_code == 0, res.output
    return out


@pytest.mark.parametrize("name", NAMES)
def test_regenerated_recording_equals_the_committed_one(regenerated, name):
    res = subprocess.run(
        [
            RERUN,
            "rrd",
            "compare",
            "--unordered",
            str(RECORDINGS / f"{name}.rrd"),
            str(regenerated / f"{name}.rrd"),
        ],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]


def summary(name, out_dir) -> dict[str, str]:
    out = CliRunner().invoke(app, ["record", name, "--out-dir", str(out_dir)]).output
    return {ln.split(":")[0].strip(): ln for ln in out.splitlines() if ln.startswith("    ")}


def test_scenarios_show_what_their_notes_promise(tmp_path):
    partial = summary("partial-overlap", tmp_path)
    error_mm = {m: float(partial[m].split("; ")[1].split(" mm")[0]) for m in ("mbicp", "improved")}
    # improved lands, standard does not
    assert error_mm["improved"] < 2.0 and error_mm["mbicp"] > 100.0
    rotation = summary("large-rotation", tmp_path)
    assert "1950.0 mm, 61.248 deg from the known answer" in rotation["icp"]
    assert "; 0.0 mm, 0.001 deg from the known answer" in rotation["mbicp"]


def test_corridor_degeneracy_points_along_the_corridor():
    s = load_scenario(RECORDINGS / "scenarios" / "corridor.toml")
    from mbicp_viz.core import match

    r = match(s.ref, s.obj, s.guess, s.params["improved"])
    assert r.degeneracy.condition_number > 100
    assert abs(r.degeneracy.weakest_heading_deg) < 15  # the corridor runs along the robot's x axis
    assert abs(s.truth.x) > 0.9 and abs(r.pose.x) < 0.2  # ... and the match shortened it


def test_every_recording_has_a_blueprint_and_a_note():
    for name in NAMES:
        reader = RrdReader(str(RECORDINGS / f"{name}.rrd"))
        assert reader.blueprints()
        paths = {c.entity_path for c in reader.stream().to_chunks()}
        assert "/about" in paths


def test_rerun_viewer_renders_a_curated_recording(tmp_path):
    img = viewer_screenshot(RECORDINGS / "partial-overlap.rrd", tmp_path / "shot.png", "1200x800")
    near = lambda rgb: int(np.count_nonzero(np.abs(img - np.array(rgb)).max(axis=2) < 40))  # noqa: E731
    assert near(REFERENCE.color) > 50 and near(OBJECT.color) > 50


def test_a_scenario_thins_the_copy_it_names(tmp_path):
    """``thin`` picks the copy that loses the block; a wrong value is refused naming the field."""
    import shutil

    from mbicp_viz.errors import InputError

    (tmp_path / "scenarios").mkdir()
    shutil.copytree(RECORDINGS / "inputs", tmp_path / "inputs")
    text = (RECORDINGS / "scenarios" / "partial-overlap.toml").read_text()
    sizes = {}
    for thin in ("reference", "object"):
        path = tmp_path / "scenarios" / f"{thin}.toml"
        path.write_text(text.replace('thin = "reference"', f'thin = "{thin}"'))
        s = load_scenario(path)
        sizes[thin] = (s.ref.n_valid, s.obj.n_valid)
    (n, m), (n2, m2) = sizes["reference"], sizes["object"]
    assert m == n2 and n == m2 and n < m  # the same block, taken from the other copy
    bad = tmp_path / "scenarios" / "bad.toml"
    bad.write_text(text.replace('thin = "reference"', 'thin = "both"'))
    with pytest.raises(InputError, match="thin"):
        load_scenario(bad)
