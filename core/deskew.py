"""Motion distortion: a laser measures its beams one after another while the robot moves, so a
scan taken at speed is bent (a wall seen while turning is drawn rotated along the sweep, and a
360° scan does not close at its seam). Given when each beam was measured (``Scan.beam_times``,
from a LaserScan's ``time_increment``) and the sensor's velocity during the scan (a constant
twist: from odometry, or from the motion between two scans), every reading is moved to where the
sensor was at the scan's ``stamp`` (its first beam, as ROS stamps scans).
"""

from __future__ import annotations

import numpy as np

from .errors import ScanError
from .scan import Scan
from .se2 import Pose2


def twist(m: Pose2, dt: float) -> np.ndarray:
    """The constant velocity (vx [m/s], vy [m/s], omega [rad/s]), in the frame the motion ``m``
    starts from, that makes that motion in ``dt`` seconds (the SE(2) logarithm of ``m``, over
    ``dt``)."""
    th = m.theta
    s, c = (1.0, 0.0) if abs(th) < 1e-9 else (np.sin(th) / th, (1.0 - np.cos(th)) / th)
    vx, vy = np.array([[s, c], [-c, s]]) @ [m.x, m.y] / (s * s + c * c)
    return np.array([vx, vy, th]) / dt


def motion(v: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, theta) reached after moving at the constant twist ``v`` for each time in ``t`` (the
    SE(2) exponential)."""
    th = v[2] * t
    small = np.abs(th) < 1e-9
    w = np.where(small, 1.0, v[2])
    x = np.where(small, v[0] * t, (v[0] * np.sin(th) - v[1] * (1 - np.cos(th))) / w)
    y = np.where(small, v[1] * t, (v[0] * (1 - np.cos(th)) + v[1] * np.sin(th)) / w)
    return x, y, th


def deskew(scan: Scan, v: np.ndarray) -> Scan:
    """``scan`` as seen from the sensor's pose at its stamp, the sensor moving at twist ``v`` (in
    its frame at the stamp) while it measured; the measured scan is kept as ``raw``. Invalid
    beams keep their range and turn with the sensor, so that bearings stay in order."""
    if scan.beam_times is None:
        raise ScanError(
            scan.source, "no beam times (a LaserScan's time_increment): cannot correct for motion"
        )
    x, y, th = motion(np.asarray(v, float), scan.beam_times)
    r = np.where(scan.valid, scan.ranges, 0.0)  # an invalid beam's range may be anything (inf, NaN)
    px, py = r * np.cos(scan.bearings), r * np.sin(scan.bearings)
    qx = np.cos(th) * px - np.sin(th) * py + x
    qy = np.sin(th) * px + np.cos(th) * py + y
    turned = scan.bearings + th
    # the corrected bearing, near the beam's own direction turned with the sensor (no wrap-around
    # jump)
    bearings = np.where(
        scan.valid, turned + np.angle(np.exp(1j * (np.arctan2(qy, qx) - turned))), turned
    )
    ranges = np.where(scan.valid, np.hypot(qx, qy), scan.ranges)
    # a 360-degree sweep: beams turned past the first direction wrap round the seam
    if scan.is_full_circle():
        bearings = bearings[0] + np.mod(bearings - bearings[0], 2.0 * np.pi)
    order = np.argsort(bearings, kind="stable")
    if np.any(np.diff(bearings[order]) <= 0):
        raise ScanError(scan.source, "two beams fall on one bearing once corrected for motion")
    if bearings[order[-1]] - bearings[order[0]] >= 2.0 * np.pi:
        raise ScanError(
            scan.source,
            "corrected for motion, the scan would cover more than a full turn: the velocity "
            f"({v[0]:.3g} m/s, {v[1]:.3g} m/s, {v[2]:.3g} rad/s) is not plausible",
        )
    return Scan(
        ranges[order],
        bearings[order],
        scan.valid[order],
        scan.pose,
        scan.odometry,
        scan.stamp,
        scan.source,
        scan.beam_times[order],
        raw=scan,
    )
