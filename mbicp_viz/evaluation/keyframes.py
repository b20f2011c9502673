"""A key-frame run: each scan is matched against the last key frame rather than the scan before it,
and becomes the next key frame once the robot has moved far enough from it (or its match failed).

Matching against a key frame a few tenths of a metre back, instead of chaining every pair, keeps a
robot that stands still or creeps from summing the millimetres each match reports (issue 34: 521
such pairs on Intel, 2,730 on ACES) and halves the number of motions composed along a run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mbicp_viz.core import Pose2
from mbicp_viz.readers.pair_match import PairMatch


@dataclass(frozen=True)
class KeyFrames:
    """When a scan becomes the next key frame: its match from the key frame moved at least
    ``distance_m`` [m] or turned at least ``angle`` [rad], or did not converge (the scans after
    it would be matched across the gap it left)."""

    # the best of 0.3 m/15 deg, 0.4/20, 0.6/30 and 1.0/30 on the full Intel and ACES logs with
    # improved MbICP (docs/results.md, "A whole run")
    distance_m: float = 0.6
    angle: float = math.radians(30.0)

    def moved(self, motion: Pose2) -> bool:
        """Whether ``motion`` from the key frame is far enough for a new one."""
        return motion.translation_norm() >= self.distance_m or abs(motion.theta) >= self.angle

    def due(self, row: PairMatch) -> bool:
        """Whether ``row``'s scan is the next key frame."""
        return not row.result.converged or self.moved(row.result.pose)

    def key_after(self, last: PairMatch) -> int:
        """The key frame after a key-frame run's ``last`` row: its scan when it is due, else the
        key frame it was matched against (its reference)."""
        return last.obj if self.due(last) else last.ref

    def as_dict(self) -> dict:
        return {"distance_m": self.distance_m, "angle_deg": math.degrees(self.angle)}
