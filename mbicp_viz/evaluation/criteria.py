"""When a match counts as correct: one criteria object, used by every evaluation and test."""

from __future__ import annotations

import math
from dataclasses import dataclass

from mbicp_viz.core import Pose2, pose_error


@dataclass(frozen=True)
class Criteria:
    """A match is correct when both its translation and its rotation error against the truth are
    within these tolerances (metres, radians)."""

    name: str
    max_error_m: float
    max_error_rad: float

    def correct(self, error_m: float, error_rad: float) -> bool:
        return bool(error_m <= self.max_error_m and error_rad <= self.max_error_rad)

    def judge(self, pose: Pose2, truth: Pose2) -> bool:
        return self.correct(*pose_error(pose, truth))

    def text(self) -> str:
        """How users read it: ``0.1 m and 3 deg``."""
        m = (
            f"{self.max_error_m * 100:g} cm"
            if self.max_error_m < 0.1
            else f"{self.max_error_m:g} m"
        )
        return f"{m} and {math.degrees(self.max_error_rad):g} deg"


# Paper 000 §3.1: a failure is an error above 0.1 m or 3.14 deg (partial-overlap protocol).
PAPER_000 = Criteria("paper 000 §3.1", 0.1, math.radians(3.14))
# Consecutive pairs of a log against its stored poses, the convergence atlas.
CONSECUTIVE = Criteria("consecutive pairs", 0.1, math.radians(3.0))
# MbICP's own protocol (T-RO 2006 §V): a scan against itself from a random guess.
MBICP_PROTOCOL = Criteria("MbICP protocol", 0.01, math.radians(0.1))
