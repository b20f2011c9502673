"""Real bags written with rosbags' own writers from the project's real scans (tests only).

A robot drives the Intel Research Lab: its laser's poses are the corrected log's scan poses; the
laser sits on the robot at ``mount`` (T_base_laser, possibly upside down), so the base's poses —
the odometry the bag records on ``/odom`` or on ``/tf`` — are ``laser_pose @ mount^-1``.
"""

from __future__ import annotations

import math
import re
import shutil
import sqlite3
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mbicp_viz.core import Pose2, Scan


@dataclass
class Topic:
    name: str
    frame_id: str
    scans: list[Scan]
    upside_down: bool = False  # write the scans as a laser whose z axis points down sees them
    increments: list[float] | None = None  # per scan angle_increment (default: the scan's own)
    time_increment: float = 0.0  # [s] between two beams (0: the driver does not say)


@dataclass
class Robot:
    topics: list[Topic]
    stamps: list[float]
    mount: Pose2 | None = None  # T_base_laser of the first topic's frame
    upside_down: bool = False
    odometry: list[Pose2] | None = None  # base poses at the stamps
    odometry_from: int = 0  # the first stamp with an odometry message (a driver that starts late)
    odometry_on: str = "/odom"  # "/odom" (nav_msgs/Odometry) or "/tf" (odom -> base_link)
    mount_on: str = "/tf_static"
    mount_again: Pose2 | None = None  # a second static publisher of the mount, with this value


def _quat(yaw: float, roll: float = 0.0):
    # yaw about z after roll about x: q = q_z(yaw) * q_x(roll)
    cz, sz, cx, sx = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(roll / 2), math.sin(roll / 2)
    return cz * sx, sz * sx, sz * cx, cz * cx  # x, y, z, w


def write(path: Path, robot: Robot, kind: str) -> Path:
    """Write ``robot`` as a ROS 1 bag (``ros1``), a ROS 2 sqlite3 bag as Humble's recorder writes
    it, without message definitions (``humble``), or a ROS 2 MCAP bag (``mcap``)."""
    from rosbags.typesys import Stores, get_typestore

    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if ros1:  # Noetic's store lacks tf2_msgs; its definition is one line
        from rosbags.typesys import get_types_from_msg

        ts.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
    T = ts.types
    Time = T["builtin_interfaces/msg/Time"]

    def header(t, frame):
        stamp = Time(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))
        return (
            T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
            if ros1
            else T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)
        )

    def transform(t, parent, child, pose: Pose2, roll=0.0):
        x, y, z, w = _quat(pose.theta, roll)
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(t, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=pose.x, y=pose.y, z=0.2),
                rotation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
            ),
        )

    def scan_msg(t, frame, scan: Scan, upside_down: bool, increment: float | None, dt: float):
        r = np.where(scan.valid, scan.ranges, np.inf).astype(np.float32)
        b = scan.bearings
        if upside_down:  # seen from a laser turned about x, the scan runs the other way round
            r, b = np.ascontiguousarray(r[::-1]), -b[::-1]
        inc = increment if increment is not None else float(np.median(np.diff(b)))
        return T["sensor_msgs/msg/LaserScan"](
            header=header(t, frame),
            angle_min=float(b[0]),
            angle_max=float(b[0] + inc * (len(b) - 1)),
            angle_increment=inc,
            time_increment=dt,
            scan_time=0.1,
            range_min=0.05,
            range_max=80.0,
            ranges=r,
            intensities=np.zeros(0, dtype=np.float32),
        )

    out = []  # (topic, msgtype, t, msg)
    for topic in robot.topics:
        for k, (t, scan) in enumerate(zip(robot.stamps, topic.scans)):
            inc = topic.increments[k] if topic.increments else None
            out.append(
                (
                    topic.name,
                    "sensor_msgs/msg/LaserScan",
                    t,
                    scan_msg(t, topic.frame_id, scan, topic.upside_down, inc, topic.time_increment),
                )
            )
    tf = T["tf2_msgs/msg/TFMessage"]
    if robot.mount is not None:
        laser = robot.topics[0].frame_id
        tr = transform(
            robot.stamps[0], "base_link", laser, robot.mount, math.pi if robot.upside_down else 0.0
        )
        out.append(
            (robot.mount_on, "tf2_msgs/msg/TFMessage", robot.stamps[0] - 1e-3, tf(transforms=[tr]))
        )
        if robot.mount_again is not None:
            again = transform(robot.stamps[0], "base_link", laser, robot.mount_again)
            out.append(
                (
                    robot.mount_on,
                    "tf2_msgs/msg/TFMessage",
                    robot.stamps[0] - 5e-4,
                    tf(transforms=[again]),
                )
            )
    for t, pose in list(zip(robot.stamps, robot.odometry or []))[robot.odometry_from :]:
        if robot.odometry_on == "/tf":
            out.append(
                (
                    "/tf",
                    "tf2_msgs/msg/TFMessage",
                    t,
                    tf(transforms=[transform(t, "odom", "base_link", pose)]),
                )
            )
        else:
            x, y, z, w = _quat(pose.theta)
            pwc = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=pose.x, y=pose.y, z=0.0),
                    orientation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
                ),
                covariance=np.zeros(36),
            )
            twc = T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](
                    linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                    angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                ),
                covariance=np.zeros(36),
            )
            out.append(
                (
                    "/odom",
                    "nav_msgs/msg/Odometry",
                    t,
                    T["nav_msgs/msg/Odometry"](
                        header=header(t, "odom"), child_frame_id="base_link", pose=pwc, twist=twc
                    ),
                )
            )
    out.sort(key=lambda m: m[2])
    if ros1:
        return _write_ros1(path, ts, out)
    return _write_ros2(path, ts, out, kind)


def _write_ros1(path: Path, ts, messages) -> Path:
    from rosbags.rosbag1 import Writer

    w = Writer(path)
    w.chunk_threshold = 16 * 1024  # several chunks, as a long recording has (rosbag's own: 768 KB)
    with w:
        conns = {}
        for topic, msgtype, t, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
            w.write(conns[topic], int(t * 1e9), ts.serialize_ros1(msg, msgtype))
    return path


def _write_ros2(path: Path, ts, messages, kind: str) -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as w:
        conns = {}
        for topic, msgtype, t, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
            w.write(conns[topic], int(t * 1e9), ts.serialize_cdr(msg, msgtype))
    if kind == "humble":
        _as_humble(path)
    return path


def _as_humble(path: Path) -> None:
    """What ``ros2 bag record`` wrote up to Humble: sqlite schema 3, metadata version 5, and no
    message definitions stored anywhere."""
    db = next(path.glob("*.db3"))
    with sqlite3.connect(db) as c:
        c.execute("DROP TABLE message_definitions")
        c.execute("UPDATE schema SET schema_version = 3")
    meta = path / "metadata.yaml"
    text = re.sub(r"\n\s*type_description_hash:\s*\n?\s*RIHS01_\w+", "", meta.read_text())
    meta.write_text(text.replace("version: 8", "version: 5"))


def intel_robot(
    intel, first: int, count: int, mount: Pose2 | None, upside_down: bool = False, **kw
) -> Robot:
    """Intel scans ``first`` .. ``first + count - 1`` driven by a robot whose laser sits at
    ``mount``."""
    scans = [intel.scan(first + k) for k in range(count)]
    stamps = [100.0 + 0.5 * k for k in range(count)]
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
