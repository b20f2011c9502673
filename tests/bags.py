"""Real bags written with the project's bag writer (``writers/bag.py``) from its real scans.

A robot drives the Intel Research Lab: its laser's poses are the corrected log's scan poses; the
laser sits on the robot at ``mount`` (T_base_laser, possibly upside down), so the base's poses —
the odometry the bag records on ``/odom`` or on ``/tf`` — are ``laser_pose @ mount^-1``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from mbicp_viz.core import Pose2
from mbicp_viz.writers import bag
from mbicp_viz.writers.bag import Robot, Topic

__all__ = ["Robot", "Topic", "write", "intel_robot", "copy_bag"]


def write(path: Path, robot: Robot, kind: str) -> Path:
    """``writers.bag.write`` in chunks of 16 KB: several chunks even in a short bag, as a long
    recording has."""
    return bag.write(path, robot, kind, chunk_bytes=16 * 1024)


def intel_robot(
    intel,
    first: int,
    count: int,
    mount: Pose2 | None,
    upside_down: bool = False,
    period_s: float = 0.5,
    **kw,
) -> Robot:
    """Intel scans ``first`` .. ``first + count - 1`` driven by a robot whose laser sits at
    ``mount`` and scans every ``period_s`` from 100 s."""
    scans = [intel.scan(first + k) for k in range(count)]
    stamps = [100.0 + period_s * k for k in range(count)]
    odometry = None
    if mount is not None:
        odometry = [s.pose @ mount.inverse() for s in scans]  # the base's poses
    return Robot(
        [Topic("/scan", "laser", scans, upside_down=upside_down)],
        stamps,
        mount,
        upside_down,
        odometry,
        **kw,
    )


def copy_bag(src: Path, dst: Path) -> Path:
    (shutil.copytree if src.is_dir() else shutil.copy)(src, dst)
    return dst
