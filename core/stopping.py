"""A stopping test every iterative matcher shares: the estimate caught in a short cycle."""

from __future__ import annotations

from collections import deque

from .params import Params
from .se2 import Pose2, relative, relative_theta

# Cycles of the estimate up to this period (in iterations) are recognised.
CYCLE_PERIOD_MAX = 4


class CycleWatch:
    """Counts the consecutive steps in which the estimate came back to where it was 2 to
    CYCLE_PERIOD_MAX iterations before, within the stopping thresholds.

    Pairs that flip in and out in turn (the projection filter hiding one point every other
    iteration, a threshold admitting a pair every third, a range comparison that comes and goes)
    make the estimate cycle by millimetres: no counted rule of the matchers ever fires, and the
    match would run to MaxIter although nothing changes any more. A match that settles also
    returns to where it was; the matchers test their own rule first, so this one only fires when
    that rule cannot.
    """

    def __init__(self, params: Params):
        self.params = params
        self.recent: deque[Pose2] = deque(maxlen=CYCLE_PERIOD_MAX - 1)
        self.count = 0

    def step(self, before: Pose2, after: Pose2) -> int:
        """Record one iteration's move from ``before`` to ``after``; the current count."""
        p = self.params
        # the rotation first (the same number relative() gives): most estimates fail there already
        returned = any(abs(relative_theta(e, after)) < p.errt_out and p.small(relative(e, after)) for e in self.recent)
        self.recent.appendleft(before)
        self.count = self.count + 1 if returned else 0
        return self.count
