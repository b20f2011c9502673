"""A stopping test every iterative matcher shares: the estimate caught in a cycle.

Pairs that flip in and out in turn (the projection filter hiding one point every other
iteration, a threshold admitting a pair every third, a range comparison that comes and goes)
make the estimate cycle by millimetres: no counted rule of the matchers ever fires, and the
match would run to MaxIter although nothing changes any more. A match that settles also returns
to where it was; the matchers test their own rule first, so this one only fires when that rule
cannot. A short cycle has settled; a long one swings between competing pairings and is a sign
that the match failed: it ends the match as early, but not as settled.
"""

from __future__ import annotations

import numpy as np

from .params import Params
from .result import Termination
from .se2 import Pose2
from .tiers import kernel, run

# Cycles of the estimate up to this period (in iterations) are recognised. Every improved MbICP
# match that ran to MaxIter on the Intel and ACES logs (1 in 682 and 3 in 738 pairs, one in 20 and
# one in 10 sampled) and on their scans resampled to 1081 beams cycled with a period of 5 to 7 over
# 1-5 mm and 0.01-0.06 deg; the margin costs nothing (a few comparisons an iteration).
CYCLE_PERIOD_MAX = 12
# A cycle up to this period has settled (Termination.CYCLE). Longer ones end the match unsettled
# (Termination.OSCILLATING): improved MbICP's long cycles on the corrected Intel and ACES logs
# were failures in 31 of 32 and 17 of 18 pairs (eval flags), and a key-frame run takes a new key
# frame after a failed match (counted as settled, they cost its Intel score 0.552 -> 0.587 m).
SETTLED_PERIOD_MAX = 4


@kernel
def returned(
    recent: np.ndarray, n: int, x: float, y: float, th: float, errx: float, erry: float, errt: float
) -> int:
    """The shortest period with which the estimate (x, y, th) returns to within the stopping
    thresholds of one of the ``n`` estimates in ``recent`` (rows x, y, theta, the latest first:
    the estimate two iterations back, then three ...), measured in that estimate's frame; 0 when
    it returns to none."""
    for k in range(n):
        ex, ey, et = recent[k, 0], recent[k, 1], recent[k, 2]
        dth = ((th - et) + np.pi) % (2.0 * np.pi) - np.pi
        if abs(dth) >= errt:  # the rotation first: most estimates fail there already
            continue
        c, s = np.cos(et), np.sin(et)
        dx, dy = c * (x - ex) + s * (y - ey), -s * (x - ex) + c * (y - ey)
        if abs(dx) < errx and abs(dy) < erry:
            return k + 2
    return 0


@kernel
def remember(recent: np.ndarray, n: int, x: float, y: float, th: float) -> int:
    """Push (x, y, th) in front of ``recent`` (the oldest falls off); the new count."""
    for k in range(len(recent) - 1, 0, -1):
        for c in range(3):  # element by element: a row assignment costs a second of compilation
            recent[k, c] = recent[k - 1, c]
    recent[0, 0], recent[0, 1], recent[0, 2] = x, y, th
    return n + 1 if n + 1 < len(recent) else len(recent)


# How a streak of returns ends a match (``streaks``): not yet, settled, or unsettled
NOT_YET, SETTLED, UNSETTLED = 0, 1, 2


@kernel
def streaks(short: int, any_: int, back: int, needed: int) -> tuple[int, int, int]:
    """The two streaks of steps that came back, once one more came back with period ``back`` (0:
    it did not) — of returns within SETTLED_PERIOD_MAX iterations, and of any — and how they end
    the match: SETTLED after ``needed`` short steps, UNSETTLED after CYCLE_PERIOD_MAX more of any
    (an estimate that comes back at a long period on its way into a short cycle has settled)."""
    short = short + 1 if 0 < back <= SETTLED_PERIOD_MAX else 0
    any_ = any_ + 1 if back else 0
    if short >= needed:
        return short, any_, SETTLED
    return short, any_, UNSETTLED if any_ >= needed + CYCLE_PERIOD_MAX else NOT_YET


class CycleWatch:
    """Counts the consecutive steps in which the estimate came back to where it was 2 to
    CYCLE_PERIOD_MAX iterations before, within the stopping thresholds (the Python matchers'
    form of ``returned`` and ``streaks``; the compiled loops call them directly)."""

    def __init__(self, params: Params):
        self.params = params
        self.recent = np.zeros((CYCLE_PERIOD_MAX - 1, 3))
        self.n = 0
        self.short = self.any = 0

    def step(self, before: Pose2, after: Pose2, needed: int) -> Termination | None:
        """Record one iteration's move from ``before`` to ``after``; how the match ends once a
        streak has come back long enough (``streaks``), else None."""
        p = self.params
        back = run(
            returned,
            self.recent,
            self.n,
            after.x,
            after.y,
            after.theta,
            p.errx_out,
            p.erry_out,
            p.errt_out,
        )
        self.n = run(remember, self.recent, self.n, before.x, before.y, before.theta)
        self.short, self.any, end = run(streaks, self.short, self.any, back, needed)
        return {SETTLED: Termination.CYCLE, UNSETTLED: Termination.OSCILLATING}.get(end)
