"""A live channel's messages decoded as a bag's are (``readers/rosbag.py``): ROS 2 (CDR) with the
chosen distro's types, ROS 1 with Noetic's; only the kinds the matcher reads: LaserScan, Odometry
and tf."""

from __future__ import annotations

import functools
from pathlib import Path

from mbicp_viz.readers.rosbag import LASER_SCAN, ODOMETRY, TF, decode, ros2_type, typestore_named

from .client import Channel

KINDS = (LASER_SCAN, ODOMETRY, TF)
ENCODINGS = ("cdr", "ros1")


def kind(channel: Channel) -> str | None:
    """The message type a channel carries, when it is one the matcher reads in an encoding this
    decodes."""
    msgtype = ros2_type(channel.schema_name)
    return msgtype if msgtype in KINDS and channel.encoding in ENCODINGS else None


@functools.cache
def _ros1_store():
    from mbicp_viz.writers.bag import ros1_typestore

    return ros1_typestore()


class Decoder:
    """Decodes a channel's payloads; ``typestore`` names the ROS 2 distro (``--typestore``)."""

    def __init__(self, url: str, typestore: str):
        self.where, self.ros2 = Path(url), typestore_named(typestore)

    def warm(self) -> None:
        """Make each kind's decoder, in both encodings, before the first message: rosbags
        generates it at its first use (the first Odometry took 70 ms, and the scans that arrived
        meanwhile came together: the oldest were skipped)."""
        for msgtype in KINDS:
            self.ros2.get_msgdef(msgtype)
            _ros1_store().get_msgdef(msgtype)

    def __call__(self, channel: Channel, payload: bytes, n: int):
        """The message, or an ``InputError`` naming the channel and message ``n``."""
        msgtype = ros2_type(channel.schema_name)
        if channel.encoding == "ros1":
            deserialize = _ros1_store().deserialize_ros1
        else:
            deserialize = self.ros2.deserialize_cdr
        return decode(deserialize, payload, msgtype, self.where, f"{n} on {channel.topic}")
