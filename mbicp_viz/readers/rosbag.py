"""ROS 1 and ROS 2 bags holding ``sensor_msgs/LaserScan``, decoded by rosbags.

rosbags' reader refuses ROS 1 bags whose index records are damaged (``demo.bag`` of the Hokuyo
data: its index data records announce 20 bytes per entry where the format has 12). The chunks
themselves are intact, so such a bag is recovered by walking its records from the start
(ROS bag format 2.0) and handing each message to rosbags' own deserializer.
"""

from __future__ import annotations

import bz2
import struct
from pathlib import Path

import numpy as np

from mbicp_viz.core import ScanSource

from mbicp_viz.errors import InputError

from .log import ScanLog, scan_or_reason

LASER_SCAN = "sensor_msgs/msg/LaserScan"
_MAGIC = b"#ROSBAG V2.0\n"
_OP_MSG, _OP_INDEX, _OP_CHUNK, _OP_CONN = 2, 4, 5, 7


def read_rosbag(path: str, topic: str | None = None) -> ScanLog:
    p = Path(path)
    if not p.exists():
        raise InputError("no such file or directory", str(path))
    try:
        messages = list(_read_with_rosbags(p, topic))
    except InputError:
        raise
    except Exception:  # rosbags rejects the bag: recover ROS 1 bags by walking their chunks
        if not (p.is_file() and p.read_bytes()[: len(_MAGIC)] == _MAGIC):
            raise InputError("not a readable ROS 1 or ROS 2 bag", str(path)) from None
        messages = list(_walk_ros1(p, topic))
    return _to_log(str(path), messages)


def _typestore(ros1: bool):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


def _pick_topic(available: dict[str, str], topic: str | None, path) -> set[str]:
    """Topics to read: the requested one (which must carry LaserScan), else every LaserScan topic."""
    if topic is not None:
        if topic not in available:
            raise InputError(f"no topic {topic!r}; the bag has {sorted(available)}", str(path), field="topic")
        if available[topic] != LASER_SCAN:
            raise InputError(f"unknown message type {available[topic]!r} on {topic} (expected {LASER_SCAN})",
                             str(path), field="topic")
        return {topic}
    scans = {t for t, ty in available.items() if ty == LASER_SCAN}
    if not scans:
        raise InputError(f"no {LASER_SCAN} messages; topics: {available}", str(path))
    return scans


def _read_with_rosbags(p: Path, topic):
    from rosbags.highlevel import AnyReader

    with AnyReader([p]) as reader:
        available = {c.topic: _normalise(c.msgtype) for c in reader.connections}
        wanted = _pick_topic(available, topic, p)
        conns = [c for c in reader.connections if c.topic in wanted]
        for conn, _, raw in reader.messages(connections=conns):
            yield reader.deserialize(raw, conn.msgtype)


def _normalise(msgtype: str) -> str:
    """ROS 1 names types ``pkg/Type``; rosbags uses ``pkg/msg/Type``."""
    pkg, _, name = msgtype.rpartition("/")
    return msgtype if pkg.endswith("/msg") else f"{pkg}/msg/{name}"


def _header(buf: bytes, path) -> dict[str, bytes]:
    fields, i = {}, 0
    while i < len(buf):
        if i + 4 > len(buf):
            raise InputError("truncated record header", str(path))
        (n,) = struct.unpack_from("<I", buf, i)
        key, sep, value = buf[i + 4:i + 4 + n].partition(b"=")
        if not sep:
            raise InputError("malformed record header field", str(path))
        fields[key.decode("ascii", "replace")] = value
        i += 4 + n
    return fields


def _records(buf: bytes, start: int, path):
    """(header, data) of each record in ``buf`` from ``start`` (ROS bag 2.0 record layout)."""
    pos = start
    while pos + 4 <= len(buf):
        (hlen,) = struct.unpack_from("<I", buf, pos)
        if pos + 8 + hlen > len(buf):
            raise InputError(f"record at byte {pos} runs past the end of the data", str(path))
        h = _header(buf[pos + 4:pos + 4 + hlen], path)
        (dlen,) = struct.unpack_from("<I", buf, pos + 4 + hlen)
        data_at = pos + 8 + hlen
        op = h.get("op", b"\0")[0]
        if op == _OP_INDEX and "count" in h:
            # The length field of damaged index records is wrong; the count is not (12 bytes/entry).
            dlen = 12 * struct.unpack("<I", h["count"])[0]
        yield op, h, buf[data_at:data_at + dlen]
        pos = data_at + dlen


def _decompress(kind: bytes, data: bytes, path) -> bytes:
    if kind == b"none":
        return data
    if kind == b"bz2":
        return bz2.decompress(data)
    if kind == b"lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    raise InputError(f"unknown chunk compression {kind!r}", str(path))


def _walk_ros1(p: Path, topic):
    buf = p.read_bytes()
    store = _typestore(ros1=True)
    conns: dict[int, tuple[str, str]] = {}
    wanted = None
    for op, h, data in _records(buf, len(_MAGIC), p):
        if op != _OP_CHUNK:
            continue
        for op2, h2, d2 in _records(_decompress(h.get("compression", b"none"), data, p), 0, p):
            if op2 == _OP_CONN:
                conn_id = struct.unpack("<I", h2["conn"])[0]
                msgtype = _normalise(_header(d2, p)["type"].decode())
                conns[conn_id] = (h2["topic"].decode(), msgtype)
                wanted = None
            elif op2 == _OP_MSG:
                conn_id = struct.unpack("<I", h2["conn"])[0]
                if conn_id not in conns:
                    raise InputError(f"message for unknown connection {conn_id}", str(p))
                if wanted is None:
                    wanted = _pick_topic(dict(conns.values()), topic, p)
                t, msgtype = conns[conn_id]
                if t in wanted:
                    yield store.deserialize_ros1(d2, msgtype)


def _to_log(path: str, messages) -> ScanLog:
    log = ScanLog(path, [])
    for k, m in enumerate(messages):
        ranges = np.asarray(m.ranges, dtype=float)
        inc = float(m.angle_increment)
        bearings = float(m.angle_min) + inc * np.arange(len(ranges))
        if inc < 0:  # clockwise scanners: store bearings increasing
            ranges, bearings = ranges[::-1], bearings[::-1]
        stamp = m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
        log.add(scan_or_reason(ranges, bearings, path, None, f"message {k}", range_min=float(m.range_min),
                               range_max=float(m.range_max), stamp=stamp, source=ScanSource(path, k)))
    if not log.records:
        raise InputError("no LaserScan messages", path)
    return log
