"""``eval basin``: the convergence atlas on a real pair, as numbers, PNG and .rrd."""

import numpy as np
from rerun.chunk import RrdReader
from typer.testing import CliRunner

from mbicp_viz.cli import app
from mbicp_viz.core import IcpParams, MbicpParams, Pose2
from mbicp_viz.evaluation.basin import CORRECT, basin
from mbicp_viz.readers import read_log

from .conftest import EXAMPLES


def test_atlas_outcomes_on_a_real_pair():
    ref, obj = read_log(EXAMPLES / "hokuyo-125-130.npz").scans
    # MbICP's angular window wide enough for 40 degrees and its iterations enough to get there
    # (Player's defaults, 30 degrees and 50 iterations, are not)
    wide = MbicpParams(Bw=np.radians(60), Br=1.0, MaxIter=100)
    atlas = basin(
        ref, obj, {"icp": IcpParams(), "mbicp": wide}, None, 0.3, 3, [0.0, np.radians(40)], 2
    )
    for o in atlas.outcome.values():
        assert o.shape == (2, 3, 3)
        assert o[0, 1, 1] == CORRECT  # from the answer itself, every matcher stays there
    # the metric pays off for large rotations: MbICP is right at least as often as ICP at 40 deg
    assert (atlas.outcome["mbicp"][1] == CORRECT).sum() >= (
        atlas.outcome["icp"][1] == CORRECT
    ).sum()


def test_cli_writes_png_and_rrd(tmp_path):
    res = CliRunner().invoke(
        app,
        [
            "eval",
            "basin",
            str(EXAMPLES / "hokuyo-125-130.npz"),
            "--pair",
            "0",
            "1",
            "--algos",
            "mbicp,psm",
            "--steps",
            "3",
            "--range-xy",
            "0.2",
            "--thetas-deg=-10,10",
            "--truth",
            "0.0741",
            "-0.0205",
            "-17.285",
            "--png",
            str(tmp_path / "b.png"),
            "--rrd",
            str(tmp_path / "b.rrd"),
        ],
    )
    assert res.exit_code == 0, res.output
    assert "mbicp" in res.output and "psm" in res.output and "correct from" in res.output
    assert (tmp_path / "b.png").read_bytes()[:4] == b"\x89PNG"
    paths = {c.entity_path for c in RrdReader(str(tmp_path / "b.rrd")).stream().to_chunks()}
    assert {"/basin/mbicp/outcome", "/basin/psm/outcome"} <= paths


def test_truth_is_the_reference_when_given():
    ref, obj = read_log(EXAMPLES / "hokuyo-125-130.npz").scans
    far = Pose2(5.0, 5.0, 0.0)  # a wrong "truth": nothing can be correct against it
    atlas = basin(ref, obj, {"mbicp": MbicpParams()}, far, 0.1, 2, [0.0], 1)
    assert atlas.answers["mbicp"] == far and not (atlas.outcome["mbicp"] == CORRECT).any()
