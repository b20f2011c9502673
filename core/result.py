"""The outcome of one match, and the degeneracy indicator of its final normal equations."""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass

import numpy as np

from .pickled import by_value
from .se2 import Pose2


class Termination(enum.Enum):
    CONVERGED = "converged"  # the algorithm's stopping rule held
    CYCLE = "cycle"  # the estimate returns within the stopping thresholds (stopping.py)
    OSCILLATING = "oscillating"  # it returns only after a long cycle: it swings between pairings
    MAX_ITERATIONS = "max_iterations"  # MaxIter reached first
    TOO_FEW_PAIRS = "too_few_pairs"  # fewer pairs than AsocError * points (or fewer than 3)
    SINGULAR = "singular"  # the normal equations could not be solved
    HALTED = "halted"  # its time budget ran out, or a person stopped it (core/budget.py)

    @property
    def converged(self) -> bool:
        """Whether the estimate settled: a short cycle below the thresholds settles as well as a
        fixed point."""
        return self in (Termination.CONVERGED, Termination.CYCLE)


@by_value
@dataclass(frozen=True, slots=True)
class Degeneracy:
    """How well the final pairs constrain the pose.

    Computed from the point-to-line information matrix sum_i J_i^T n_i n_i^T J_i of the kept
    pairs (n_i: the reference surface normal at the target), in the scaled coordinates
    (x, y, L*theta) so that the three axes share a unit. A corridor without frontal structure
    leaves the motion along its axis unconstrained (paper 000 §3.3): the condition number grows
    and ``weakest_direction`` points along the corridor.
    """

    condition_number: float
    weakest_direction: tuple[float, float, float]  # unit vector in (x, y, L*theta)
    eigenvalues: tuple[float, float, float]  # ascending
    length: float = 1.0  # L [m], the length that scales rotation in these coordinates

    @property
    def weakest_heading_deg(self) -> float:
        """Heading of the translational part of the weakest direction, degrees in (-90, 90]."""
        x, y, _ = self.weakest_direction
        a = np.degrees(np.arctan2(y, x))
        return float(a - 180.0 if a > 90.0 else a + 180.0 if a <= -90.0 else a)


@by_value
@dataclass(frozen=True, slots=True)
class MatchResult:
    """``pose`` is the pose of the object frame in the reference frame (maps object points into
    it)."""

    algorithm: str
    pose: Pose2
    converged: bool
    reason: Termination
    iterations: int
    error: float  # final mean squared Euclidean residual of the kept pairs [m^2]
    pairs_kept: int
    pairs_rejected: int
    # (3, 3) in (x [m], y [m], theta [rad]), sigma^2 * A^-1 of the final system
    covariance: np.ndarray | None
    degeneracy: Degeneracy | None

    def conjugated(self, mount: Pose2) -> MatchResult:
        """The same match seen as the motion of the frame the laser is mounted on (``mount`` =
        T_base_laser): pose ``mount @ pose @ mount^-1``; covariance and weakest direction carried
        by the mount's adjoint (the condition number stays that of the laser's constraints)."""
        if mount == Pose2():
            return self
        Ad = mount.adjoint()
        cov = Ad @ self.covariance @ Ad.T if self.covariance is not None else None
        deg = self.degeneracy
        if deg is not None:
            L = deg.length
            d = Ad @ (np.array(deg.weakest_direction) / [1.0, 1.0, L])
            d = d * [1.0, 1.0, L]
            deg = Degeneracy(
                deg.condition_number,
                tuple(float(v) for v in d / np.linalg.norm(d)),
                deg.eigenvalues,
                L,
            )
        return dataclasses.replace(
            self, pose=mount.conjugate(self.pose), covariance=cov, degeneracy=deg
        )

    def as_dict(self) -> dict:
        """Plain-JSON fields; the names are stable (scripts rely on them)."""
        d = {
            "x": self.pose.x,
            "y": self.pose.y,
            "theta": self.pose.theta,
            "iterations": self.iterations,
            "converged": self.converged,
            "reason": self.reason.value,
            "error": self.error if np.isfinite(self.error) else None,  # strict JSON has no NaN
            "pairs_kept": self.pairs_kept,
            "pairs_rejected": self.pairs_rejected,
            "algorithm": self.algorithm,
        }
        if self.covariance is not None:
            d["covariance"] = self.covariance.tolist()
        if self.degeneracy is not None:
            d["condition_number"] = self.degeneracy.condition_number
            d["weakest_direction"] = list(self.degeneracy.weakest_direction)
            d["eigenvalues"] = list(self.degeneracy.eigenvalues)
            d["degeneracy_length_m"] = self.degeneracy.length
        return d
