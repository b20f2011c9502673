"""The event stream: what the observer receives is consistent with the result and the geometry."""

import numpy as np
import pytest

import mbicp_viz.core.mbicp
from mbicp_viz.core import (
    MATCHERS,
    FinishEvent,
    ImprovedParams,
    IterationEvent,
    PairKind,
    PairStatus,
    Pose2,
    Recorder,
    StartEvent,
    match,
)


@pytest.mark.parametrize("algo", list(MATCHERS))
def test_stream_is_start_iterations_finish(algo, intel):
    rec = Recorder()
    r = match(intel.scans[11], intel.scans[12], Pose2(), algorithm=algo, observer=rec)
    ev = rec.events
    assert isinstance(ev[0], StartEvent) and isinstance(ev[-1], FinishEvent)
    its = rec.iterations
    assert len(its) == len(ev) - 2 == r.iterations
    assert [e.iteration for e in its] == list(range(1, r.iterations + 1))
    assert ev[-1].result is r


@pytest.mark.parametrize("algo", list(MATCHERS))
def test_iterations_chain_and_moved_points(algo, intel):
    rec = Recorder()
    guess = Pose2(0.05, -0.02, 0.1)
    r = match(intel.scans[30], intel.scans[31], guess, algorithm=algo, observer=rec)
    start = rec.start
    est = guess
    kept_run = None  # ICP and PL-ICP after restarts: the last iteration of the run they keep
    for e in rec.iterations:
        if e.note.startswith("restart"):  # ICP and PL-ICP restart from their result, moved (CSM)
            est = e.estimate_before
        assert e.estimate_before == est
        after = e.increment @ e.estimate_before
        assert np.allclose(after.as_array(), e.estimate_after.as_array())
        np.testing.assert_allclose(
            e.moved_points, e.estimate_before.apply(start.obj_points[start.used]), atol=1e-12
        )
        p = e.pairs
        assert (
            len(
                {
                    len(p.obj_index),
                    len(p.target),
                    len(p.kind),
                    len(p.ref_index),
                    len(p.distance),
                    len(p.status),
                }
            )
            == 1
        )
        # point pairs sit exactly on their reference point
        pt = p.kind == PairKind.POINT
        np.testing.assert_allclose(p.target[pt], start.ref_points[p.ref_index[pt, 0]])
        assert np.all(p.ref_index[pt, 1] == -1)
        est = e.estimate_after
        if e.note.startswith("the run kept"):
            kept_run = e
    assert r.pose == (kept_run.estimate_after if kept_run else est)
    # the result describes the last system that was solved (a final TOO_FEW_PAIRS event solves none)
    last = (kept_run or [e for e in rec.iterations if np.isfinite(e.error)][-1]).pairs
    assert r.pairs_kept == last.count(status=PairStatus.KEPT)
    assert r.pairs_rejected == len(last.kind) - r.pairs_kept


def test_improved_events_show_interpolation_rejection_and_resampling(intel):
    rec = Recorder()
    match(intel.scans[11], intel.scans[12], Pose2(), ImprovedParams(), observer=rec)
    rs = rec.start.resampling
    assert rs is not None and len(rs.kept) < len(rec.start.obj_points)
    np.testing.assert_array_equal(rec.start.used, rs.kept)
    first = rec.iterations[0]
    p = first.pairs
    inter = p.kind == PairKind.INTERPOLATED
    assert inter.any()
    # interpolated targets lie on the segment between their two reference points
    a = rec.start.ref_points[p.ref_index[inter, 0]]
    b = rec.start.ref_points[p.ref_index[inter, 1]]
    t = p.target[inter]
    cross = (b - a)[:, 0] * (t - a)[:, 1] - (b - a)[:, 1] * (t - a)[:, 0]
    assert np.allclose(cross, 0.0, atol=1e-9)
    # the MAD threshold separates kept from MAD-rejected pairs
    assert first.threshold is not None
    assert np.all(p.distance[p.status == PairStatus.MAD] > first.threshold)
    assert np.all(p.distance[p.status == PairStatus.KEPT] <= first.threshold)


def shared_point_targets(pairs) -> int:
    """How many POINT pairs share their reference point with another POINT pair."""
    j = pairs.ref_index[pairs.kind == PairKind.POINT, 0]
    _, counts = np.unique(j, return_counts=True)
    return int(counts[counts > 1].sum())


def test_point_line_resolves_shared_targets(intel):
    """Paper 000 §2.4.1: where object points share a reference point, only the closest keeps it."""
    runs = {}
    for pl in (True, False):
        rec = Recorder()
        match(
            intel.scans[11], intel.scans[12], Pose2(), ImprovedParams(point_line=pl), observer=rec
        )
        runs[pl] = rec.iterations[0].pairs
    assert shared_point_targets(runs[False]) > 0
    # the only sharing left is where the segment to the second point is longer than MaxDistInter
    assert shared_point_targets(runs[True]) < shared_point_targets(runs[False]) / 2


def test_no_event_payload_is_built_without_observer(intel, monkeypatch):
    built = []
    for cls in (StartEvent, IterationEvent, FinishEvent):
        monkeypatch.setattr(
            mbicp_viz.core.mbicp,
            cls.__name__,
            lambda *a, _c=cls, **k: built.append(_c) or _c(*a, **k),
        )
    match(intel.scans[11], intel.scans[12], Pose2(), ImprovedParams())
    assert built == []
    match(intel.scans[11], intel.scans[12], Pose2(), ImprovedParams(), observer=Recorder())
    assert (
        built.count(StartEvent) == 1 and built.count(FinishEvent) == 1 and IterationEvent in built
    )
