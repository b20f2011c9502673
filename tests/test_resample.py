"""Grid resampling (paper 000 §2.3) on real scans and on hand-made grids."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from mbicp_viz.core.resample import grid_resample, regular_pick


def test_real_scan_thins_near_cells_and_keeps_far_ones(laserazos):
    pts = laserazos.scans[0].points()
    rs = grid_resample(pts, 0.1)
    assert 0 < len(rs.kept) < len(pts)
    np.testing.assert_array_equal(rs.kept, np.unique(rs.kept))  # scan order, no repeats
    assert rs.ratio.max() == 1.0 and rs.ratio.min() >= 0.0
    # n' = ceil(n * eta) per cell, and the farthest cell keeps all its points
    np.testing.assert_array_equal(rs.kept_count, np.ceil(rs.count * rs.ratio - 1e-9).astype(int))
    far = np.argmax(rs.ratio)
    assert rs.kept_count[far] == rs.count[far]
    assert rs.kept_count.sum() == len(rs.kept)
    # points near the sensor are thinned more than far ones
    r = np.hypot(*pts.T)
    near, farther = r < np.percentile(r, 25), r > np.percentile(r, 75)
    kept = np.zeros(len(pts), bool)
    kept[rs.kept] = True
    assert kept[near].mean() < kept[farther].mean()


def test_first_and_last_point_of_a_cell_are_kept():
    # one cell far away with 10 points in scan order, one cell at the sensor's row/col distance 1
    far = np.column_stack((np.full(10, 1.0) + np.linspace(0, 0.09, 10), np.full(10, 1.0)))
    near = np.array([[0.5, 1.0]])
    pts = np.vstack((near, far))
    rs = grid_resample(pts, 0.1)
    kept = set(rs.kept.tolist())
    cell_far = np.argmax(rs.ratio)
    if rs.kept_count[cell_far] >= 2:
        assert {1, 10} <= kept


@given(st.integers(1, 60), st.data())
def test_regular_picks_are_first_last_and_evenly_spaced(n, data):
    k = data.draw(st.integers(0, n))
    rank = np.arange(n)
    picked = np.array([r for r in rank if regular_pick(n, k, r)])
    assert len(picked) == k
    if k >= 1:
        assert picked[0] == 0
    if k >= 2:
        assert picked[-1] == n - 1
        gaps = np.diff(picked)
        assert gaps.max() - gaps.min() <= 1


def test_no_points_no_cells(laserazos):
    """An object scan with nothing within the matcher's range: no cells, and the match ends as one
    with too few pairs (no traceback, no undefined sensor cell)."""
    import dataclasses

    from mbicp_viz.core import ImprovedParams, Pose2, Recorder, Termination, match

    rs = grid_resample(np.zeros((0, 2)), 0.1)
    assert len(rs.cells) == 0 and len(rs.kept) == 0 and rs.sensor_cell.tolist() == [0, 0]
    far = dataclasses.replace(laserazos.scan(1), ranges=laserazos.scan(1).ranges + 50.0)
    rec = Recorder()
    r = match(laserazos.scan(0), far, Pose2(), ImprovedParams(max_range=20.0), rec)
    assert r.reason is Termination.TOO_FEW_PAIRS and not r.converged
    assert len(rec.start.resampling.kept) == 0
