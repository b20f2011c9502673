"""The cycle stop shared by the iterative matchers, on real Intel pairs that cycle."""

import math

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
