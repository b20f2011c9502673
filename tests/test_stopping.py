"""The cycle stop shared by the iterative matchers, on real Intel pairs that cycle."""

import math

import numpy as np
import pytest

from mbicp_viz.core import (
    ImprovedParams,
    PmwnParams,
    PsmParams,
    Termination,
    match,
    pose_error,
    relative,
)
from mbicp_viz.core.events import IterationEvent
from mbicp_viz.evaluation.throughput import replay_log

# (params, the same with the matcher's own rule and the cycle stop out of reach, pair)
CYCLING = {
    # the projection filter hides a point every other iteration: two poses mm apart
    "improved": (ImprovedParams(), ImprovedParams(IterSmoothConv=100, MaxIter=100), 23),
    # range comparisons coming and going at the edge of the overlap
    "pmwn": (PmwnParams(), PmwnParams(stop_after=100, MaxIter=60), 13),
    "psm": (PsmParams(), PsmParams(stop_after=100, MaxIter=60), 6),
}


@pytest.mark.parametrize("algo", list(CYCLING))
def test_a_short_cycle_ends_the_match_as_settled(intel, algo):
    """From the corrected pose the estimate settles into a cycle of a few millimetres; the
    matcher's counted rule never fires. The cycle stop ends it early, where it cycles."""
    params, without, k = CYCLING[algo]
    ref, obj = intel.scan(k), intel.scan(k + 1)
    guess = relative(ref.pose, obj.pose)
    r = match(ref, obj, guess, params)
    assert r.reason is Termination.CYCLE and r.converged and r.iterations < 40
    long_run = match(ref, obj, guess, without)
    assert long_run.reason is Termination.MAX_ITERATIONS  # it really never settles on its own
    t, rot = pose_error(r.pose, long_run.pose)
    assert t < 0.01 and rot < math.radians(0.2)


def _period(estimates: np.ndarray) -> int:
    """The shortest period with which the last half of ``estimates`` (rows x, y, theta) repeats."""
    tail = len(estimates) // 2
    return next(
        p
        for p in range(1, tail)
        if np.allclose(estimates[-tail:], estimates[-tail - p : -p], rtol=0, atol=1e-6)
    )


def test_a_cycle_of_six_or_seven_iterations_ends_the_match_unsettled(intel):
    """Intel's scans resampled to 1081 beams (as a Hokuyo UTM-30LX): improved MbICP from odometry
    falls into cycles of 7 and 6 iterations over millimetres. With a cycle stop that knew
    periods up to 4 these ran to MaxIter (a fifth of a long replay's matching time); they end
    early now, but as oscillating, not converged (a sign of a failed match, as MaxIter was)."""
    run = replay_log(intel, 22, 1081, 40.0)
    periods = []
    for k in (18, 21):
        ref, obj = run.scans[k], run.scans[k + 1]
        guess = relative(ref.odometry, obj.odometry)
        r = match(ref, obj, guess, ImprovedParams())
        assert r.reason is Termination.OSCILLATING and not r.converged and r.iterations < 40
        events = []
        long_run = match(
            ref, obj, guess, ImprovedParams(IterSmoothConv=100, MaxIter=100), observer=events.append
        )
        assert long_run.reason is Termination.MAX_ITERATIONS
        estimates = [e.estimate_after for e in events if isinstance(e, IterationEvent)]
        periods.append(_period(np.array([[e.x, e.y, e.theta] for e in estimates])))
        t, rot = pose_error(r.pose, long_run.pose)
        assert t < 0.01 and rot < math.radians(0.2)
    assert min(periods) > 4
