"""ROS 1 and ROS 2 bags (sqlite3 as Humble's recorder writes it, or MCAP) written with rosbags'
own writers, message by message: a robot's scan topics, the laser's mount on ``/tf_static`` and
its base's odometry on ``/odom`` or ``/tf``.

The bag is written as it is generated (memory does not grow with its length) and renamed into
place only once whole (``outputs.written``). The base's poses are the odometry; the laser sits on
the base at ``mount`` (T_base_laser, possibly upside down).
"""

from __future__ import annotations

import dataclasses
import math
import re
import sqlite3
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from mbicp_viz.core import Pose2, Scan
from mbicp_viz.errors import InputError

KINDS = ("ros1", "humble", "mcap")
SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"


@dataclasses.dataclass
class Topic:
    name: str
    frame_id: str
    scans: Sequence[Scan]
    upside_down: bool = False  # write the scans as a laser whose z axis points down sees them
    increments: list[float] | None = None  # per scan angle_increment (default: the scan's own)
    time_increment: float = 0.0  # [s] between two beams (0: the driver does not say)


@dataclasses.dataclass
class Robot:
    topics: list[Topic]
    stamps: Sequence[float]  # [s], increasing
    mount: Pose2 | None = None  # T_base_laser of the first topic's frame
    upside_down: bool = False
    odometry: Sequence[Pose2] | None = None  # base poses at the stamps
    odometry_from: int = 0  # the first stamp with an odometry message (a driver that starts late)
    odometry_on: str = "/odom"  # "/odom" (nav_msgs/Odometry) or "/tf" (odom -> base_link)
    mount_on: str = "/tf_static"
    mount_again: Pose2 | None = None  # a second static publisher of the mount, with this value


def write(path: Path, robot: Robot, kind: str, chunk_bytes: int = 768 * 1024) -> Path:
    """Write ``robot`` as a ROS 1 bag (``ros1``, chunks of about ``chunk_bytes``: rosbag's own
    768 KB by default), a ROS 2 sqlite3 bag as Humble's recorder writes it, without message
    definitions (``humble``), or a ROS 2 MCAP bag (``mcap``)."""
    if kind not in KINDS:
        raise ValueError(f"unknown bag kind {kind!r}; known: {', '.join(KINDS)}")
    ts = _typestore(kind == "ros1")
    messages = _Messages(ts, kind == "ros1").of(robot)
    if kind == "ros1":
        return _write_ros1(path, ts, messages, chunk_bytes)
    return _write_ros2(path, ts, messages, kind)


def _typestore(ros1: bool):
    from rosbags.typesys import Stores, get_typestore

    return ros1_typestore() if ros1 else get_typestore(Stores.ROS2_HUMBLE)


def ros1_typestore():
    """Noetic's message types, with tf2_msgs (which its store lacks; the definition is one
    line)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(
        get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
    )
    return ts


def ros1_as_cdr(payload: bytes, msgtype: str, ros1, ros2) -> bytes:
    """A ROS 1 message (``ros1``'s types) as the same ROS 2 message in CDR (``ros2``'s), field by
    field by name: ROS 1's header ``seq`` has no ROS 2 field and is left out. A type ROS 2 does not
    know is an ``InputError``."""
    try:
        msg = _as_ros2(ros1.deserialize_ros1(payload, msgtype), ros2)
    except KeyError as e:
        raise InputError(f"a ROS 1 {msgtype} has no ROS 2 type to be saved as ({e})") from None
    return bytes(ros2.serialize_cdr(msg, msgtype))


def _as_ros2(value, ros2):
    if isinstance(value, list):
        return [_as_ros2(v, ros2) for v in value]
    if not dataclasses.is_dataclass(value):  # a number, a string, an array of numbers
        return value
    cls = ros2.get_msgdef(value.__msgtype__).cls
    return cls(**{f.name: _as_ros2(getattr(value, f.name), ros2) for f in dataclasses.fields(cls)})


def _quat(yaw: float, roll: float = 0.0):
    # yaw about z after roll about x: q = q_z(yaw) * q_x(roll)
    cz, sz, cx, sx = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(roll / 2), math.sin(roll / 2)
    return cz * sx, sz * sx, sz * cx, cz * cx  # x, y, z, w


class _Messages:
    """A robot's messages as (topic, type, stamp [s], message), built in one typestore."""

    def __init__(self, ts, ros1: bool):
        self.T, self.ros1 = ts.types, ros1

    def of(self, robot: Robot) -> Iterator[tuple[str, str, float, object]]:
        """Every message in recording order: the mount just before the first stamp, then at each
        stamp its scans (topic by topic) and the base's odometry."""
        tf = self.T["tf2_msgs/msg/TFMessage"]
        t0 = robot.stamps[0]
        if robot.mount is not None:
            laser = robot.topics[0].frame_id
            roll = math.pi if robot.upside_down else 0.0
            tr = self.transform(t0, "base_link", laser, robot.mount, roll)
            yield robot.mount_on, TF, t0 - 1e-3, tf(transforms=[tr])
            if robot.mount_again is not None:
                again = self.transform(t0, "base_link", laser, robot.mount_again)
                yield robot.mount_on, TF, t0 - 5e-4, tf(transforms=[again])
        for k, t in enumerate(robot.stamps):
            for topic in robot.topics:
                inc = topic.increments[k] if topic.increments else None
                yield topic.name, SCAN, t, self.scan(t, topic, topic.scans[k], inc)
            if robot.odometry is not None and k >= robot.odometry_from:
                pose = robot.odometry[k]
                if robot.odometry_on == "/tf":
                    tr = self.transform(t, "odom", "base_link", pose)
                    yield "/tf", TF, t, tf(transforms=[tr])
                else:
                    yield "/odom", ODOMETRY, t, self.odometry(t, pose)

    def header(self, t: float, frame: str):
        T = self.T
        stamp = T["builtin_interfaces/msg/Time"](sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))
        if self.ros1:
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def transform(self, t: float, parent: str, child: str, pose: Pose2, roll: float = 0.0):
        T = self.T
        x, y, z, w = _quat(pose.theta, roll)
        return T["geometry_msgs/msg/TransformStamped"](
            header=self.header(t, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=pose.x, y=pose.y, z=0.2),
                rotation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
            ),
        )

    def scan(self, t: float, topic: Topic, scan: Scan, increment: float | None):
        r = np.where(scan.valid, scan.ranges, np.inf).astype(np.float32)
        b = scan.bearings
        if topic.upside_down:  # seen from a laser turned about x, the scan runs the other way round
            r, b = np.ascontiguousarray(r[::-1]), -b[::-1]
        inc = increment if increment is not None else float(np.median(np.diff(b)))
        return self.T["sensor_msgs/msg/LaserScan"](
            header=self.header(t, topic.frame_id),
            angle_min=float(b[0]),
            angle_max=float(b[0] + inc * (len(b) - 1)),
            angle_increment=inc,
            time_increment=topic.time_increment,
            scan_time=0.1,
            range_min=0.05,
            range_max=80.0,
            ranges=r,
            intensities=np.zeros(0, dtype=np.float32),
        )

    def odometry(self, t: float, pose: Pose2):
        T = self.T
        x, y, z, w = _quat(pose.theta)
        zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return T["nav_msgs/msg/Odometry"](
            header=self.header(t, "odom"),
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=pose.x, y=pose.y, z=0.0),
                    orientation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
                ),
                covariance=np.zeros(36),
            ),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero),
                covariance=np.zeros(36),
            ),
        )


def _write_ros1(path: Path, ts, messages, chunk_bytes: int) -> Path:
    from rosbags.rosbag1 import Writer

    w = Writer(path)
    w.chunk_threshold = chunk_bytes
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
