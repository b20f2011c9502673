"""ROS 1 and ROS 2 bags (sqlite3 or MCAP) holding ``sensor_msgs/LaserScan``, decoded by rosbags.

What a robotics engineer's bag holds, read as the robot recorded it:

- **One scan topic**, chosen automatically when there is one; with several and none named, an
  error lists them (message count, frame id). Topics are never merged.
- **ROS 2 bags of any distro**: bags written without message definitions (``ros2 bag record`` up
  to Humble) are decoded with the named distro's types (``typestore``, default Humble).
- **The laser's mount** from ``/tf_static`` (or ``/tf``, as older robots publish it): base frame ->
  the scans' ``frame_id``; a laser mounted upside down is turned upright. Scans stay in the
  (upright) laser frame; ``ScanLog.frames.mount`` turns matches into the base's motion.
- **Odometry**, from a ``nav_msgs/Odometry`` topic or ``/tf`` (odom -> base), interpolated at each
  scan's stamp and given as each scan's ``odometry``: the pose of the laser in the odom frame.
- **Damage** is never a traceback: a bag cut short keeps the scans of its intact chunks with a
  warning naming what was lost, or is one error when none survive.

A ROS 1 bag is read through its own index by the project's reader (``ros1_index.py``: rosbags'
reader holds the index as one Python object per message and refuses the damaged index records of
``demo.bag`` of the Hokuyo data, which announce 20 bytes per entry where the format has 12). A bag
whose index is missing (a recording that was never closed) or damaged otherwise is read by walking
its records from the start (ROS bag format 2.0, ``ros1_format.py``), each message decoded with
rosbags.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mbicp_viz.choices import DEFAULT_TYPESTORE
from mbicp_viz.core import Pose2, Scan, ScanSource
from mbicp_viz.errors import InputError

from .log import Frames, ScanLog, scan_or_reason
from .ros1_format import (
    MAGIC,
    MAX_CHUNK_BYTES,
    OP_CHUNK,
    OP_CHUNK_INFO,
    OP_CONN,
    OP_HEADER,
    OP_INDEX,
    OP_MSG,
    CutShort,
    decompress,
    header,
    op_of,
    records,
    register,
    ros2_type,
)
from .tf import BASE_FRAMES, Mount, TfTree, interpolate

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"


@dataclass(frozen=True)
class Message:
    topic: str
    msgtype: str
    stamp: float  # [s] when it was recorded
    msg: object


def read_rosbag(
    path: str,
    topic: str | None = None,
    typestore: str = DEFAULT_TYPESTORE,
    mount: Pose2 | None = None,
) -> ScanLog:
    """The scans of one LaserScan topic, with the laser's mount from tf (``mount``, --mount, wins)
    and the odometry of the robot's base moved onto the laser through that mount. A bag is read
    through its index (a ROS 1 bag's by ``ros1_index.py``, a ROS 2 bag's by rosbags, its scans'
    stamps from its storage's own by ``ros2_index.py``), each scan when it is asked for
    (``bag_index.py``); a ROS 1 bag whose index is damaged or missing is walked and read whole."""
    p = Path(path)
    if not p.exists():
        raise InputError("no such file or folder", str(path))
    notes: list[str] = []
    try:
        reader = open_bag(p, typestore, notes)
    except InputError:
        raise
    except Exception as e:  # a damaged ROS 1 index, or rosbags refusing a ROS 2 bag
        reason = " ".join(str(a) for a in e.args) or type(e).__name__
        if _is_ros1(p):
            return _to_log(str(path), _walk_ros1(p, notes, reason), topic, notes, mount)
        raise InputError(f"not a readable ROS 1 or ROS 2 bag: {reason[:300]}", str(p)) from None
    return _indexed_log(str(path), reader, typestore, topic, notes, mount)


def _is_ros1(p: Path) -> bool:
    if not p.is_file():
        return False
    with p.open("rb") as f:
        return f.read(len(MAGIC)) == MAGIC


def open_bag(p: Path, typestore: str, notes: list[str] | None = None):
    """A reader on ``p``, its index read: the project's own for a ROS 1 bag, rosbags' for a ROS 2
    one (``_open_ros2``: ``notes`` is told where it was read from when not from ``p``). A bag
    without a LaserScan topic is refused here, before any message is decoded."""
    if _is_ros1(p):
        from .ros1_index import Ros1Bag

        reader = Ros1Bag(p, (LASER_SCAN, ODOMETRY, TF))
    else:
        reader, said = _open_ros2(p, typestore)
        if said is not None and notes is not None:
            notes.append(said)
    if not any(ros2_type(c.msgtype) == LASER_SCAN for c in reader.connections):
        has = "; ".join(
            f"{c.topic} ({c.msgtype}, {c.msgcount} messages)" for c in reader.connections
        )
        reader.close()
        raise InputError(f"no {LASER_SCAN} topic; the bag has: {has or 'none'}", str(p))
    return reader


def _open_ros2(p: Path, typestore: str):
    """rosbags' reader, open on the storage ``ros2_storage.py`` says ``p`` is read from (a
    compressed bag's, a folder's without metadata), or on the closed copy of an MCAP file cut
    short (``mcap_recovered.py``); and what to say of where it reads."""
    from rosbags.highlevel import AnyReader

    from .ros2_storage import storage_to_open

    bag, said = storage_to_open(p)
    reader = AnyReader([bag], default_typestore=typestore_named(typestore))
    try:
        reader.open()
    except Exception:  # rosbags refuses it: an MCAP file cut short is read to its cut
        from .mcap_recovered import cut_short, recovered

        if (cut := cut_short(bag)) is None:
            raise
        bag, also = recovered(cut)
        said = also if said is None else f"{said}; {also}"
        reader = AnyReader([bag], default_typestore=typestore_named(typestore))
        reader.open()
    return reader, said


def raw_messages(reader, path: str, connections, start: int | None = None, stop: int | None = None):
    """rosbags' (connection, record stamp [ns], raw bytes) of ``connections`` within [start, stop);
    damage rosbags meets on the way (a chunk or record its index points at wrongly, a sqlite3 row
    whose stamp is not a number) is one error naming the bag. No connections, no messages
    (rosbags reads every topic for none)."""
    if not connections:
        return
    try:
        for c, t, raw in reader.messages(connections, start, stop):
            if not isinstance(t, (int, np.integer)):
                raise InputError(f"a message of {c.topic} has no record stamp ({t!r})", path)
            yield c, t, raw
    except InputError:
        raise
    except Exception as e:
        raise InputError(
            f"the bag is damaged where its index points ({type(e).__name__}: {str(e)[:200]}); "
            "the messages before it were read",
            path,
        ) from None


def decoded_messages(reader, path: str, connections, start=None, stop=None):
    """(connection, record stamp [ns], decoded message) of ``raw_messages``."""
    p = Path(path)
    for c, t, raw in raw_messages(reader, path, connections, start, stop):
        yield c, t, decode(reader.deserialize, raw, c.msgtype, p, f"at {t} ns")


def typestore_named(name: str):
    from rosbags.typesys import Stores, get_typestore

    try:
        return get_typestore(Stores[name])
    except KeyError:
        known = ", ".join(s.name for s in Stores if s.name.startswith("ROS"))
        raise InputError(
            f"unknown ROS distro {name!r}; known: {known}", field="--typestore"
        ) from None


# The fields this reader reads of each type, and what each holds (f: a float, i: an integer, s: a
# string, F: floats). A bag carries its own definitions (MCAP's schemas, ROS 1's connection
# records) and rosbags decodes by them: a damaged one decodes into a message without the field, or
# with an integer where a float belongs, which must be said, not met later as a missing attribute
# or a wrong number.
_STAMPED = (("header.stamp.sec", "i"), ("header.stamp.nanosec", "i"), ("header.frame_id", "s"))
_SCAN_FIELDS = ("angle_min", "angle_increment", "time_increment", "range_min", "range_max")
_FIELDS = {
    LASER_SCAN: _STAMPED + tuple((f, "f") for f in _SCAN_FIELDS) + (("ranges", "F"),),
    ODOMETRY: _STAMPED
    + tuple((f"pose.pose.position.{c}", "f") for c in "xy")
    + tuple((f"pose.pose.orientation.{c}", "f") for c in "xyzw"),
    TF: (("transforms", "list"),),
}
_TRANSFORM_FIELDS = (
    _STAMPED
    + (("child_frame_id", "s"),)
    + tuple((f"transform.translation.{c}", "f") for c in "xyz")
    + tuple((f"transform.rotation.{c}", "f") for c in "xyzw")
)
_HOLDS = {"f": "a float", "i": "an integer", "s": "a string", "F": "floats", "list": "a list"}


def _holds(value, kind: str) -> bool:
    if kind == "F":
        return isinstance(value, np.ndarray) and value.dtype.kind == "f"
    types = {"f": (float, np.floating), "i": (int, np.integer), "s": str, "list": list}[kind]
    return isinstance(value, types) and not isinstance(value, bool)


def decode(deserialize, raw, msgtype: str, p: Path, n: int | str):
    try:
        msg = deserialize(raw, msgtype)
    except Exception as e:  # rosbags' serde errors: damaged message data
        raise InputError(
            f"message {n} ({msgtype}) cannot be decoded: {type(e).__name__}: {str(e)[:200]}", str(p)
        ) from None
    kind = ros2_type(msgtype)
    if type(msg) not in _CHECKED:
        _has_fields(msg, _FIELDS.get(kind, ()), f"message {n} ({msgtype})", p)
        if kind != TF:
            _CHECKED.add(type(msg))
    if kind == TF:
        for tr in msg.transforms:
            if type(tr) not in _CHECKED:
                _has_fields(tr, _TRANSFORM_FIELDS, f"message {n} ({msgtype}): a transform", p)
                _CHECKED.add(type(tr))
    return msg


# The message classes whose fields were found as this reader needs them: what a field holds is
# its class's (the definition rosbags built it from), so each class is checked once.
_CHECKED: set[type] = set()


def _has_fields(msg, fields, what: str, p: Path) -> None:
    for name, kind in fields:
        obj = msg
        for part in name.split("."):
            obj = getattr(obj, part, _has_fields)
            if obj is _has_fields:
                break
        if not _holds(obj, kind):
            got = "no such field" if obj is _has_fields else type(obj).__name__
            raise InputError(
                f"{what}: field {name!r} should hold {_HOLDS[kind]} ({got}): the bag's definition "
                "of its type is damaged",
                str(p),
                field=name,
            )


# ---- ROS 1 bags, walked record by record (rosbags refuses a damaged or missing index) ------------


def _walk_ros1(p: Path, notes: list[str], why: str):
    """Messages of a ROS 1 bag read chunk by chunk; a bag cut short keeps the messages before the
    cut (an uncompressed chunk cut in two keeps its first part) and says what was lost."""
    from rosbags.typesys import Stores, get_typestore

    buf = p.read_bytes()
    store = get_typestore(Stores.ROS1_NOETIC)
    conns: dict[int, tuple[str, str]] = {}
    out: list[Message] = []
    unknown = 0  # records of no kind the format has: their header was damaged
    try:
        for op, h, data in records(buf, len(MAGIC), p):
            if op == OP_HEADER and "index_pos" in h:
                index_pos = struct.unpack("<Q", h["index_pos"])[0]
                if index_pos == 0 or index_pos > len(buf):
                    notes.append(
                        f"{p}: the bag's index is missing (a recording never closed, or a file cut "
                        "short); "
                        "its chunks were read one by one"
                    )
            elif op == OP_CHUNK:
                size = struct.unpack("<I", h["size"])[0] if "size" in h else MAX_CHUNK_BYTES
                unknown += _chunk(
                    decompress(h.get("compression", b"none"), data, size, p), p, store, conns, out
                )
            elif op not in (OP_HEADER, OP_INDEX, OP_CHUNK_INFO, OP_CONN):
                unknown += 1
    except CutShort as cut:
        if (
            cut.header is not None
            and op_of(cut.header) == OP_CHUNK
            and cut.header.get("compression", b"none") == b"none"
        ):
            try:
                unknown += _chunk(cut.data, p, store, conns, out)
            except CutShort:
                pass
        notes.append(
            f"{p}: the bag ends inside a record at byte {cut.at} of {len(buf)} (cut short?): the "
            f"{len(out)} "
            "messages before the cut were read, the rest is lost"
        )
    except struct.error as e:
        raise InputError(f"a damaged record ({e}); rosbags: {why[:200]}", str(p)) from None
    if unknown:
        notes.append(
            f"{p}: passed over {unknown} damaged record{'s' * (unknown > 1)} (of no kind the "
            "format has): the messages in them are lost"
        )
    return out


def _chunk(data: bytes, p: Path, store, conns: dict, out: list) -> int:
    """The messages of one chunk's records (connections registered as they come); how many of
    its records are of no kind a chunk holds."""
    try:
        return _chunk_records(data, p, store, conns, out)
    except KeyError as e:
        raise InputError(f"a damaged record: its header has no {e} field", str(p)) from None


def _chunk_records(data: bytes, p: Path, store, conns: dict, out: list) -> int:
    unknown = 0
    for op, h, d in records(data, 0, p):
        if op == OP_CONN:
            conn = header(d, p)
            msgtype = ros2_type(conn["type"].decode("utf-8", "replace"))
            conns[struct.unpack("<I", h["conn"])[0]] = (
                h["topic"].decode("utf-8", "replace"),
                msgtype,
            )
            register(store, conn.get("message_definition", b""), msgtype, p)
        elif op == OP_MSG:
            conn_id = struct.unpack("<I", h["conn"])[0]
            if conn_id not in conns:
                raise InputError(f"message for unknown connection {conn_id}", str(p))
            topic, msgtype = conns[conn_id]
            if msgtype in (LASER_SCAN, ODOMETRY, TF):
                sec, nsec = struct.unpack("<II", h["time"]) if "time" in h else (0, 0)
                out.append(
                    Message(
                        topic,
                        msgtype,
                        sec + 1e-9 * nsec,
                        decode(store.deserialize_ros1, d, msgtype, p, len(out)),
                    )
                )
        else:
            unknown += 1
    return unknown


# ---- scans, topics, frames and odometry ---------------------------------------------------------


def _describe(count: int, frame_id: str) -> str:
    return f"{count} messages, frame_id {frame_id!r}"


def _scan_topics(messages: list[Message]) -> dict[str, str]:
    """Every LaserScan topic, described by its message count and frame id."""
    counts: dict[str, tuple[int, str]] = {}
    for m in messages:
        if m.msgtype == LASER_SCAN:
            n, frame = counts.get(m.topic, (0, m.msg.header.frame_id))
            counts[m.topic] = (n + 1, frame)
    return {t: _describe(n, f) for t, (n, f) in sorted(counts.items())}


def _scan_topic(topics: dict[str, str], others: list[str], topic: str | None, path: str) -> str:
    """The one scan topic to read: the one named, else the only one; several: an error listing
    them."""
    listing = "; ".join(f"{t} ({d})" for t, d in topics.items())
    if topic is not None:
        if topic not in topics:
            raise InputError(
                f"no LaserScan topic {topic!r}; the bag has: {listing or 'none'}",
                path,
                field="--topic",
            )
        return topic
    if not topics:
        raise InputError(
            f"no {LASER_SCAN} messages (topics read: {', '.join(others) or 'none'})", path
        )
    if len(topics) > 1:
        raise InputError(
            f"{len(topics)} LaserScan topics, choose one with --topic: {listing}",
            path,
            field="--topic",
        )
    return next(iter(topics))


def _odometry_topics(topics) -> list[str]:
    """The Odometry topics among ``topics`` (topic, type), ``/odom`` first."""
    return sorted({t for t, kind in topics if kind == ODOMETRY}, key=lambda t: (t != "/odom", t))


def _odometry(messages: list[Message], tf: TfTree, mount: Mount | None):
    """(source, stamps, base poses) from an Odometry topic (``/odom`` first), else from /tf: the
    track of the base the laser hangs from, or where tf does not link the laser, of the first
    base frame below odom."""
    topics = _odometry_topics((m.topic, m.msgtype) for m in messages)
    if topics:
        return (
            f"{topics[0]} (nav_msgs/Odometry)",
            *odometry_track([m.msg for m in messages if m.topic == topics[0]]),
        )
    base = tf_base(tf, mount)
    return None if base is None else tf.odometry_track(base)


def tf_base(tf: TfTree, mount: Mount | None) -> str | None:
    """The base frame whose track /tf gives (the one the laser hangs from, else the first below
    odom), or None."""
    for base in [mount.base_frame] if mount is not None else BASE_FRAMES:
        if tf.odometry_track(base) is not None:
            return base
    return None


def header_stamp(msg) -> float:
    """A ROS message's header stamp [s]."""
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def odometry_track(msgs: list) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, base poses (N, 3)) of Odometry messages, in stamp order."""
    stamps = np.array([header_stamp(o) for o in msgs])
    poses = np.array([planar(o.pose.pose) for o in msgs]).reshape(-1, 3)
    order = np.argsort(stamps, kind="stable")
    return stamps[order], poses[order]


def planar(pose) -> tuple[float, float, float]:
    q = pose.orientation
    return (
        pose.position.x,
        pose.position.y,
        float(np.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))),
    )


def _tf_tree(messages, notes: list[str]) -> TfTree:
    """The transforms of /tf and /tf_static among ``messages`` ((record stamp, topic, message))."""
    tf = TfTree()
    for stamp, topic, msg in messages:
        if topic.lstrip("/") in ("tf", "tf_static"):
            tf.add(msg, stamp, topic.lstrip("/") == "tf_static")
    for parent, child in sorted(tf.conflicts):
        notes.append(
            f"/tf_static gives {parent} -> {child} several different values: the last one "
            "published is used"
        )
    return tf


def _frames(
    tf: TfTree, frame_id: str, path: str, given: Pose2 | None, odometry: str | None, notes
) -> tuple[Frames, Mount | None]:
    """The scans' frames (the mount from tf, or ``given``: --mount wins) and the mount tf gives."""
    mount = tf.mount(frame_id, path) if frame_id else None
    frames = (
        Frames(mount.pose, mount.source, mount.base_frame, frame_id)
        if mount
        else Frames(frame_id=frame_id)
    )
    if given is not None:  # --mount: the laser's pose on the base, whatever tf says
        frames = replace(frames, mount=given, mount_source="--mount")
    elif mount is None and odometry is not None:
        notes.append(
            f"the odometry ({odometry}) is the robot base's and no mount of the laser "
            f"{frame_id!r} is known: the laser's odometry is taken as the base's (give --mount "
            "X Y THETA_DEG)"
        )
    return frames, mount


def _to_log(
    path: str, messages: list[Message], topic: str | None, notes: list[str], given: Pose2 | None
) -> ScanLog:
    """The log of a walked bag, every message decoded."""
    try:
        topics = _scan_topics(messages)
        chosen = _scan_topic(topics, sorted({m.topic for m in messages}), topic, path)
    except InputError as e:
        if not notes:
            raise
        raise InputError(
            f"{e.message}: {notes[-1].split(': ', 1)[-1]}", path, field=e.field
        ) from None
    tf = _tf_tree(((m.stamp, m.topic, m.msg) for m in messages if m.msgtype == TF), notes)
    scans = [m for m in messages if m.topic == chosen]
    frame_id = scans[0].msg.header.frame_id.lstrip("/")
    odometry = _odometry(messages, tf, tf.mount(frame_id, path) if frame_id else None)
    frames, mount = _frames(tf, frame_id, path, given, odometry[0] if odometry else None, notes)
    log = ScanLog(path, [], frames=frames, topic=chosen, scan_topics=topics, notes=notes)
    if odometry is not None:
        log.odometry_source = odometry[0]
    upside_down = mount is not None and mount.upside_down
    track = odometry[1:] if odometry is not None else None
    for k, m in enumerate(scans):
        log.add(laser_scan(m.msg, path, k, upside_down, track, frames.mount))
    return log


def _indexed_log(
    path: str, reader, typestore: str, topic: str | None, notes: list[str], given: Pose2 | None
) -> ScanLog:
    """The log of a bag rosbags opened: frames and topics from the messages that name them, the
    scans read when asked for (``bag_index.BagScans``)."""
    from .bag_index import TF_AT_OPEN_S, BagScans, OdometrySource, records_with_stamps

    by_topic: dict[str, list] = {}
    for c in reader.connections:
        by_topic.setdefault(c.topic, []).append(c)
    kinds = {t: ros2_type(cs[0].msgtype) for t, cs in by_topic.items()}

    def first(t: str):
        """The topic's first message; None when it has none."""
        return next((m for _, _, m in decoded_messages(reader, path, by_topic[t])), None)

    firsts = {t: first(t) for t, k in kinds.items() if k == LASER_SCAN}
    frames_of = {t: m.header.frame_id for t, m in firsts.items() if m is not None}
    if not frames_of:
        raise InputError(
            f"no message on its {LASER_SCAN} topics: {', '.join(sorted(firsts))}", path
        )
    topics = {
        t: _describe(sum(c.msgcount for c in by_topic[t]), frames_of[t]) for t in sorted(frames_of)
    }
    chosen = _scan_topic(topics, sorted(by_topic), topic, path)
    tf_conns = [c for t, cs in by_topic.items() if kinds[t] == TF for c in cs]
    statics = [c for c in tf_conns if c.topic.lstrip("/") == "tf_static"]
    first_seconds = reader.start_time + int(TF_AT_OPEN_S * 1e9)
    timed = [c for c in tf_conns if c not in statics]
    opening = [*decoded_messages(reader, path, statics)]
    opening += decoded_messages(reader, path, timed, stop=first_seconds)
    tf = _tf_tree(((t * 1e-9, c.topic, m) for c, t, m in opening), notes)
    frame_id = frames_of[chosen].lstrip("/")
    laser_mount = tf.mount(frame_id, path) if frame_id else None
    odometry, source = None, None
    if odom_topics := _odometry_topics(kinds.items()):
        odometry, source = OdometrySource(odom_topics[0]), f"{odom_topics[0]} (nav_msgs/Odometry)"
    elif (base := tf_base(tf, laser_mount)) is not None:
        odometry, source = OdometrySource("/tf", base), tf.odometry_track(base)[0]
    frames, mount = _frames(tf, frame_id, path, given, source, notes)
    store = BagScans(
        path,
        typestore,
        chosen,
        records_with_stamps(reader, chosen, by_topic[chosen], path),
        tf,
        odometry,
        mount is not None and mount.upside_down,
        frames.mount,
    )
    store.adopt(reader)
    return ScanLog(
        path,
        [],
        frames=frames,
        topic=chosen,
        scan_topics=topics,
        odometry_source=source,
        notes=notes,
        store=store,
    )


def laser_scan(m, path: str, k: int, upside_down: bool, track, mount: Pose2):
    """One LaserScan as a scan in the (upright) laser frame, bearings increasing; its odometry is
    the pose of the laser in the odom frame at the scan's stamp, from the base's ``track``
    (stamps, poses) when there is one."""
    # damaged numbers become invalid readings, silently
    with np.errstate(invalid="ignore", over="ignore"):
        ranges = np.asarray(m.ranges, dtype=float)
    # time_increment: between two beams [s]; 0 when the driver does not say
    angles = (float(m.angle_min), float(m.angle_increment), float(m.time_increment))
    key = (len(ranges), struct.pack("<3d", *angles), upside_down)  # a zero's sign counts
    bearings, times, clockwise = _BEAMS.get(key) or _beams(len(ranges), *angles, upside_down)
    if clockwise:  # clockwise in the upright frame: stored increasing
        ranges = ranges[::-1]
    stamp = header_stamp(m)
    odom = None
    if track is not None:
        base = interpolate(track[0], track[1], stamp)
        odom = base @ mount if base is not None else None
    range_max = float(m.range_max) if np.isfinite(m.range_max) and m.range_max > 0 else np.inf
    range_min = float(m.range_min) if np.isfinite(m.range_min) else 0.0
    scan = scan_or_reason(
        ranges,
        bearings,
        path,
        None,
        f"message {k}",
        range_min=range_min,
        range_max=range_max,
        stamp=stamp,
        odometry=odom,
        source=ScanSource(path, k),
        beam_times=times,
    )
    if isinstance(scan, Scan) and len(scan.bearings) == len(ranges):
        if len(_BEAMS) >= _BEAMS_KEPT and key not in _BEAMS:
            _BEAMS.clear()
        _BEAMS[key] = (scan.bearings, scan.beam_times, clockwise)
    return scan


# A stream's beams, as its first scan kept them: (beams, the bits of angle_min, angle_increment
# and time_increment, upside down) -> (its bearings, shared with their layout (core/scan.py), its
# beam times, whether the message's beams run clockwise). Making a 1081-beam scan's bearings and
# comparing them with their layout's was 11 of the 95 us that reading a scan from a bag took.
_BEAMS: dict[tuple, tuple] = {}
_BEAMS_KEPT = 8  # a few streams (a bag's lasers, the debugger's logs): bounded whatever the file


def _beams(n: int, angle_min: float, inc: float, dt: float, upside_down: bool):
    """The bearings (increasing), beam times (None: not given) and clockwise flag of a scan."""
    bearings = angle_min + inc * np.arange(n)
    times = dt * np.arange(n) if np.isfinite(dt) and dt > 0 else None
    if upside_down:  # the laser's z axis points down: seen upright, every bearing is mirrored
        bearings = -bearings
    clockwise = n > 1 and bearings[1] < bearings[0]
    if clockwise:
        bearings, times = bearings[::-1], None if times is None else times[::-1]
    return bearings, times, clockwise
