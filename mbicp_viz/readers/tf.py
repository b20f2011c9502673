"""Transforms a bag records (``/tf_static``, ``/tf``, ``nav_msgs/Odometry``): the laser's mount on
the robot and the robot's odometry at each scan's time.

Frames follow ROS (REP 105): ``odom`` -> the robot's base (``base_link`` or ``base_footprint``) ->
the laser's ``frame_id``. A transform ``T_parent_child`` maps child-frame points into the parent
frame. A laser mounted upside down (its z axis pointing down) sees the world mirrored: its scans
are turned upright (bearings negated) and its mount is the upright frame's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mbicp_viz.core import Pose2
from mbicp_viz.errors import InputError

BASE_FRAMES = ("base_link", "base_footprint", "base")
ODOM_FRAMES = ("odom", "odom_combined")
UPRIGHT_TOLERANCE = math.cos(math.radians(5.0))  # a laser tilted more than this is no 2-D scanner


@dataclass(frozen=True)
class Transform3:
    """A rigid motion in 3-D: rotation matrix and translation (metres)."""

    R: np.ndarray  # (3, 3)
    t: np.ndarray  # (3,)

    @staticmethod
    def from_msg(translation, rotation) -> Transform3:
        x, y, z, w = rotation.x, rotation.y, rotation.z, rotation.w
        n = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
        x, y, z, w = x / n, y / n, z / n, w / n
        R = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        return Transform3(R, np.array([translation.x, translation.y, translation.z], dtype=float))

    def __matmul__(self, other: Transform3) -> Transform3:
        return Transform3(self.R @ other.R, self.R @ other.t + self.t)

    def planar(self) -> Pose2:
        """The motion in the plane (x, y, yaw), for transforms between upright frames."""
        return Pose2(float(self.t[0]), float(self.t[1]), math.atan2(self.R[1, 0], self.R[0, 0]))


@dataclass(frozen=True)
class Mount:
    """Where the laser sits on the robot: ``pose`` is T_base_laser in the plane (the laser frame
    turned upright when ``upside_down``), ``source`` says where it came from."""

    pose: Pose2
    upside_down: bool
    source: str
    base_frame: str


def mount_of(T: Transform3, source: str, base_frame: str, where: str) -> Mount:
    """A planar mount from a 3-D T_base_laser: upright, or upside down (z axis down); refuses a
    tilt."""
    z = T.R[2, 2]
    if z >= UPRIGHT_TOLERANCE:
        return Mount(T.planar(), False, source, base_frame)
    if z <= -UPRIGHT_TOLERANCE:  # turned about x: the upright laser frame is this one turned back
        flip = Transform3(np.diag([1.0, -1.0, -1.0]), np.zeros(3))
        return Mount((T @ flip).planar(), True, source, base_frame)
    raise InputError(
        f"the laser is tilted {math.degrees(math.acos(max(-1.0, min(1.0, z)))):.1f} deg from the "
        "vertical: not a 2-D scanner's mount",
        where,
        field="tf",
    )


@dataclass
class TfTree:
    """Every transform a bag publishes: static ones (latest wins, and ``conflicts`` names the
    edges published static with different values) and timed ones per edge."""

    static: dict[tuple[str, str], Transform3] = field(default_factory=dict)  # (parent, child) -> T
    timed: dict[tuple[str, str], list[tuple[float, Transform3]]] = field(default_factory=dict)
    conflicts: set[tuple[str, str]] = field(default_factory=set)

    def add(self, msg, stamp: float | None, is_static: bool) -> None:
        for tr in msg.transforms:
            key = (tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"))
            T = Transform3.from_msg(tr.transform.translation, tr.transform.rotation)
            if is_static:
                old = self.static.get(key)
                if old is not None and not (np.allclose(old.R, T.R) and np.allclose(old.t, T.t)):
                    self.conflicts.add(key)
                self.static[key] = T
            else:
                t = tr.header.stamp.sec + 1e-9 * tr.header.stamp.nanosec
                self.timed.setdefault(key, []).append((t if t > 0 else (stamp or 0.0), T))

    def drop_before(self, t: float) -> None:
        """Forget the timed transforms older than ``t`` [s] but the last one before it (what
        interpolating at ``t`` needs): a live run's tree stays the size of its last seconds."""
        for values in self.timed.values():
            k = 0
            while k + 1 < len(values) and values[k + 1][0] <= t:
                k += 1
            if k:
                del values[:k]

    def frames_only(self) -> TfTree:
        """The static transforms and the first value of each timed one (what ``constant`` reads):
        the tree a window of /tf messages is added to."""
        return TfTree(
            dict(self.static), {e: v[:1] for e, v in self.timed.items()}, set(self.conflicts)
        )

    def parents(self) -> dict[str, str]:
        out = {child: parent for parent, child in self.static}
        out.update({child: parent for parent, child in self.timed})
        return out

    def chain(self, ancestor: str, frame: str) -> list[tuple[str, str]] | None:
        """The edges from ``ancestor`` down to ``frame``, or None when ``frame`` does not hang
        below it."""
        parents, edges, f = self.parents(), [], frame
        while f != ancestor:
            if f not in parents or len(edges) > 64:
                return None
            edges.append((parents[f], f))
            f = parents[f]
        return edges[::-1]

    def constant(self, edges: list[tuple[str, str]]) -> Transform3:
        """The product along ``edges``, each static or its first timed value (a mount published on
        /tf)."""
        T = Transform3(np.eye(3), np.zeros(3))
        for e in edges:
            T = T @ (self.static[e] if e in self.static else self.timed[e][0][1])
        return T

    def mount(self, laser_frame: str, where: str) -> Mount | None:
        """The laser's mount below the first base frame it hangs from (None when it hangs below
        none)."""
        for base in BASE_FRAMES:
            edges = self.chain(base, laser_frame)
            if edges is not None:
                return mount_of(self.constant(edges), f"tf {base} -> {laser_frame}", base, where)
        return None

    def odometry_track(self, base: str) -> tuple[str, np.ndarray, np.ndarray] | None:
        """(source, stamps, poses (N, 3)) of the base in the odom frame from /tf, or None."""
        for odom in ODOM_FRAMES:
            edges = self.chain(odom, base)
            if edges is None or not any(e in self.timed for e in edges):
                continue
            moving = [e for e in edges if e in self.timed]
            if len(moving) > 1:
                continue  # several moving links: no single odometry stream
            stamps = np.array([t for t, _ in self.timed[moving[0]]])
            poses = []
            for _, T in self.timed[moving[0]]:
                full = Transform3(np.eye(3), np.zeros(3))
                for e in edges:
                    full = full @ (T if e == moving[0] else self.constant([e]))
                p = full.planar()
                poses.append((p.x, p.y, p.theta))
            order = np.argsort(stamps, kind="stable")
            return f"tf {odom} -> {base}", stamps[order], np.array(poses)[order]
        return None


def interpolate(
    stamps: np.ndarray, poses: np.ndarray, t: float, max_gap: float = 0.5
) -> Pose2 | None:
    """The pose at time ``t`` between the two recorded around it (linear in x, y and the shorter
    way round in theta); None outside the recording or across a gap longer than ``max_gap`` [s]."""
    if len(stamps) == 0 or not stamps[0] <= t <= stamps[-1]:
        return None
    k = int(np.searchsorted(stamps, t, side="right"))
    # Python floats: numpy scalars in a pose slow every step of a run that reads it (its
    # arithmetic, its pickling to the workers: 9 against 2 us a pose)
    if k >= len(stamps):
        return Pose2(*poses[-1].tolist())
    (ta, tb), (pa, pb) = stamps[k - 1 : k + 1].tolist(), poses[k - 1 : k + 1].tolist()
    dt = tb - ta
    if dt > max_gap:
        return None
    w = (t - ta) / dt if dt > 0 else 0.0
    dth = (pb[2] - pa[2] + math.pi) % (2 * math.pi) - math.pi
    return Pose2(pa[0] + w * (pb[0] - pa[0]), pa[1] + w * (pb[1] - pa[1]), pa[2] + w * dth)
