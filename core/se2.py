"""SE(2) poses: rigid motions of the plane.

A ``Pose2`` ``T_a_b`` maps points given in frame ``b`` into frame ``a``:
``p_a = R(theta) p_b + (x, y)``. Composition follows the frame names,
``T_a_c = T_a_b @ T_b_c``. Metres and radians throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .pickled import by_value


def wrap_angle(theta: float | np.ndarray) -> float | np.ndarray:
    """Angle(s) wrapped into [-pi, pi)."""
    return (theta + np.pi) % (2.0 * np.pi) - np.pi


@by_value
@dataclass(frozen=True, slots=True)
class Pose2:
    """Rigid motion (x [m], y [m], theta [rad]) mapping child-frame points into the parent frame."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    @staticmethod
    def identity() -> Pose2:
        return Pose2(0.0, 0.0, 0.0)

    @staticmethod
    def from_array(v) -> Pose2:
        x, y, t = np.asarray(v, dtype=float).tolist()
        return Pose2(x, y, wrap_angle(t))

    def as_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.theta])

    def rotation(self) -> np.ndarray:
        c, s = np.cos(self.theta), np.sin(self.theta)
        return np.array([[c, -s], [s, c]])

    def __matmul__(self, other: Pose2) -> Pose2:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            wrap_angle(self.theta + other.theta),
        )

    def inverse(self) -> Pose2:
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose2(-c * self.x - s * self.y, s * self.x - c * self.y, wrap_angle(-self.theta))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Map an (N, 2) array of child-frame points into the parent frame."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return points @ np.array([[c, s], [-s, c]]) + np.array([self.x, self.y])

    def adjoint(self) -> np.ndarray:
        """3x3 matrix taking a small motion (dx, dy, dtheta) applied on the left in this pose's
        child frame to the same motion seen from its parent frame: ``self @ exp(d) @ self^-1 =
        exp(Ad d)``."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return np.array([[c, -s, self.y], [s, c, -self.x], [0.0, 0.0, 1.0]])

    def conjugate(self, motion: Pose2) -> Pose2:
        """``self @ motion @ self^-1``: a motion of the child frame as the motion of the parent
        frame (a laser's motion as its robot's, with ``self`` the laser's mount T_base_laser)."""
        return self @ motion @ self.inverse()

    def translation_norm(self) -> float:
        return float(np.hypot(self.x, self.y))

    def __str__(self) -> str:
        return f"(x={self.x:+.4f} m, y={self.y:+.4f} m, theta={np.degrees(self.theta):+.3f} deg)"


def relative(a: Pose2, b: Pose2) -> Pose2:
    """``a^-1 @ b``: pose of frame ``b`` seen from frame ``a`` when both are given in a common
    frame."""
    return a.inverse() @ b


def pose_error(estimate: Pose2, truth: Pose2) -> tuple[float, float]:
    """Translation error [m] and absolute rotation error [rad] of ``estimate`` against ``truth``."""
    d = relative(truth, estimate)
    return d.translation_norm(), abs(d.theta)
