"""CARMEN logs: FLASER, RAWLASER1-4, ROBOTLASER1, ODOM, PARAM (plain, .gz, .bz2 or .xz).

Layouts as written by CARMEN's logger (every message ends ``ipc_timestamp ipc_hostname
logger_timestamp``). FLASER stores no bearings: they are read as CARMEN's own reader reads them
(``carmen_laser_guess_angle_increment``), from -90 degrees in the log's stated step (``PARAM
laser_front_laser_resolution``, degrees) or else the SICK's step for its reading count — 1 degree
for 180 and 181 readings, 0.5 for 360 and 361 (the 180- and 360-reading scans lack the SICK's last
beam) — and 0.25 for 400 and 401 (the SICK's 100-degree mode, centred). Other counts than a SICK's
are read over 180 degrees from -90 with a note, as CSM's ``laser_data_carmen.c`` does, since the
file cannot say otherwise. A record must hold exactly the fields its counts announce.

No returns: a reading at or beyond the log's ``PARAM robot_front_laser_max`` (FLASER; RAWLASER and
ROBOTLASER1 state their ``maximum_range``) is no return, like SICK's codes (``NO_RETURN_CODES_M``)
and the code a log writes for its no returns where it states none: a spike of one value (or a band
of a few cm) at the top of the stream's readings, with nearly nothing above it (aces: 50.00 m;
``_ceiling``); a note names what was masked.

Each laser message type is a stream of its own: a log can hold two lasers (RAWLASER1 and
RAWLASER2) or one laser twice (FLASER from the robot module, RAWLASER1 from the laser module, at
the same instants), and a pair taken across two streams is no motion at all. A log with several is
read one stream at a time, chosen like a bag's topic (``--topic ROBOTLASER1``); unnamed, it is the
front laser (CARMEN's laser 1) as the robot module logs it, with its poses — ROBOTLASER1, which
states its field of view, else FLASER, else RAWLASER1 — and a note names the others. Without a
front laser there is nothing to prefer: the types are listed and one must be named. The mount
that ``PARAM robot_frontlaser_offset`` gives is the front laser's (FLASER, ROBOTLASER1, RAWLASER1):
the other lasers' scans are reported in their own frame.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import ClassVar

from mbicp_viz.core import Pose2, ScanSource, uniform_bearings
from mbicp_viz.errors import InputError

from .ceiling import mask_ceiling
from .log import Frames, ScanLog, scan_or_reason
from .text import Fields, token_lines

# No-return / max-range codes of SICK scanners, masked, never points (see shared/data/README.md):
# the 80 m mode's and the 8 m mode's (no real reading lies beyond those ranges).
NO_RETURN_CODES_M = ((81.83, 81.91), (8.183, 8.191))
_MESSAGE = re.compile(r"^[A-Z][A-Z0-9_]*$")
_RAWLASER = re.compile(r"RAWLASER[1-4]")
LASER_MESSAGES = "FLASER, RAWLASER1-4 or ROBOTLASER1"
TRAILER = 3  # ipc_timestamp ipc_hostname logger_timestamp
# FLASER reading counts of a SICK -> its step [deg] (CARMEN's carmen_laser_guess_angle_increment)
SICK_STEP_DEG = {180: 1.0, 181: 1.0, 360: 0.5, 361: 0.5, 400: 0.25, 401: 0.25}
SICK_100_DEG = (400, 401)  # the 100-degree mode, centred on the laser's axis
# CARMEN's laser 1, the front one, in the order read unnamed
FRONT_LASER = (
    "ROBOTLASER1",
    "FLASER",
    "RAWLASER1",
)


@dataclass
class FrontLaser:
    """What a log's PARAM lines say of its front laser, read as they come (a line applies to the
    scans after it): its offset on the robot [m], its maximum range [m] and, for FLASER, which
    stores no bearings, its step [deg]."""

    PARAMS: ClassVar = (
        "robot_frontlaser_offset",
        "robot_front_laser_max",
        "laser_front_laser_resolution",
    )
    offset: float = 0.0
    max_range: float = math.inf
    step_deg: float | None = None
    contradicted: set[int] = field(default_factory=set)  # counts the stated step cannot hold

    def read(self, fields: Fields) -> None:
        name = fields.t[1]
        fields.i = 2
        value = fields.take(name)
        if name == "robot_frontlaser_offset":
            self.offset = value
        elif not value > 0:
            raise fields.error(f"must be positive, got {value:g}", name)
        elif name == "robot_front_laser_max":
            self.max_range = value
        else:
            self.step_deg = value

    def bearings(self, n: int):
        """A FLASER scan's bearings: from -90 degrees in the stated step, else the SICK's for ``n``
        readings (the 100-degree mode from -50), else over 180 degrees as CSM reads them."""
        step = self.step_deg
        if step is not None and (n - 1) * step > 180.0 + 1e-9:
            self.contradicted.add(n)
            step = None
        start = -90.0
        if step is None and n in SICK_STEP_DEG:
            step = SICK_STEP_DEG[n]
            start = -50.0 if n in SICK_100_DEG else -90.0
        if step is None:
            step = 180.0 / (n - 1) if n > 1 else 0.0
        return uniform_bearings(n, math.radians(start), math.radians(step))

    def notes(self, beams: set[int], path: str) -> list[str]:
        """What was read otherwise than the log says, or guessed where it says nothing."""
        out = [
            f"{path}: PARAM laser_front_laser_resolution {self.step_deg:g} deg cannot hold {n} "
            "readings within 180 degrees: read at "
            + (f"the SICK's {SICK_STEP_DEG[n]:g} deg" if n in SICK_STEP_DEG else "180/(n-1)")
            for n in sorted(self.contradicted)
        ]
        guessed = sorted(n for n in beams if n not in SICK_STEP_DEG)
        if self.step_deg is None and guessed:
            out.append(
                f"{path}: FLASER stores no field of view, and {', '.join(map(str, guessed))} "
                "readings are not a SICK's: read over 180 degrees from -90, as CSM does"
            )
        return out


def read_carmen(path: str, message: str | None = None) -> ScanLog:
    """The scans of laser message type ``message`` (None: the log's only one, else its front
    laser's, with a note; see ``_stream``)."""
    log = ScanLog(str(path), [])  # odometry, frames and the messages read past
    streams: dict[str, ScanLog] = {}
    front = FrontLaser()
    mounts: list[Pose2] = []  # what each ROBOTLASER1 line's two poses imply
    for fields in token_lines(path, comment=None):
        kind = fields.t[0]
        if kind.startswith("#"):
            continue
        if not _MESSAGE.match(kind):
            raise fields.error(f"not a CARMEN message name: {kind[:40]!r}", "message")
        fields.i = 1
        if kind == "PARAM":
            if fields.left >= 2 and fields.t[1] in FrontLaser.PARAMS:
                front.read(fields)
                if fields.t[1] == "robot_frontlaser_offset":
                    log.frames = Frames(Pose2(front.offset, 0.0, 0.0), f"PARAM {fields.t[1]}")
        elif kind == "ODOM":
            pose = _pose(fields, "odom")
            for name in ("tv", "rv", "accel"):
                fields.take(name)
            log.odometry.append((_trailer(fields, "ODOM x y theta tv rv accel"), pose))
        elif kind == "FLASER":
            stream = streams.setdefault(kind, ScanLog(str(path), []))
            stream.add(_flaser(fields, stream.records, front))
        elif kind == "ROBOTLASER1" or _RAWLASER.fullmatch(kind):
            stream = streams.setdefault(kind, ScanLog(str(path), []))
            stream.add(_rawlaser(fields, stream.records, kind, mounts, front))
        else:
            log.skipped[kind] = log.skipped.get(kind, 0) + 1
    if not streams:
        seen = ", ".join(f"{k} ({n})" for k, n in sorted(log.skipped.items())) or "none"
        raise InputError(
            f"no laser scans ({LASER_MESSAGES} lines); message types seen: {seen}", path
        )
    kind = _stream(streams, message, path)
    if message is None and len(streams) > 1:
        others = "; ".join(f"{k} ({v.records} scans)" for k, v in streams.items() if k != kind)
        log.notes.append(
            f"{path}: read {kind} ({streams[kind].records} scans), the front laser"
            f"{' with its poses' if kind != 'RAWLASER1' else ''}; the log also has {others}: "
            "--topic (in the "
            "debugger: scan stream) reads another"
        )
    log.scans, log.unusable = streams[kind].scans, streams[kind].unusable
    if kind not in FRONT_LASER:  # robot_frontlaser_offset is not this laser's mount
        log.frames = Frames()
    if kind == "ROBOTLASER1" and mounts:
        log.frames, note = _implied_mount(mounts, log.frames, path)
        if note:
            log.notes.append(note)
    beams = {len(s.ranges) for s in log.scans}
    if kind == "FLASER":
        log.notes += front.notes(beams, path)
    log.notes += mask_ceiling(log)
    if len(streams) > 1:
        log.topic, log.scan_topics = kind, {k: f"{v.records} scans" for k, v in streams.items()}
    return log


def _implied_mount(mounts: list[Pose2], frames: Frames, path: str) -> tuple[Frames, str | None]:
    """The laser's mount that ROBOTLASER1's laser and robot poses imply (the first line's), and a
    note where the lines, or the log's PARAM, say otherwise."""
    first = mounts[0]
    implied = Frames(first, "ROBOTLASER1 laser_pose against robot_pose")
    spread = max(
        max(abs(d.x), abs(d.y), abs(d.theta)) for d in (first.inverse() @ m for m in mounts)
    )
    if spread > 1e-6:
        return implied, (
            f"{path}: ROBOTLASER1 lines imply laser mounts up to {spread:.3g} apart (m or rad): "
            "the first line's is used"
        )
    param = frames.mount if frames.mount_source else None
    if param is not None and max(abs(v) for v in (param.inverse() @ first).as_array()) > 1e-6:
        return implied, (
            f"{path}: PARAM robot_frontlaser_offset ({param.x:g} m) differs from the mount the "
            f"ROBOTLASER1 poses imply ({first.x:g} m, {first.y:g} m, "
            f"{math.degrees(first.theta):g} deg): the lines' is used"
        )
    return implied, None


def _stream(streams: dict[str, ScanLog], message: str | None, path: str) -> str:
    """The laser message type to read: the one named, else the only one, else the front laser's
    (``FRONT_LASER``'s order); several without a front laser: an error listing them."""
    listing = "; ".join(f"{k} ({v.records} scans)" for k, v in streams.items())
    if message is not None:
        if message not in streams:
            raise InputError(f"no {message!r} scans; the log has: {listing}", path, field="--topic")
        return message
    front = [k for k in FRONT_LASER if k in streams]
    if len(streams) > 1 and not front:
        raise InputError(
            f"{len(streams)} laser message types, choose one with --topic: {listing}",
            path,
            field="--topic",
        )
    return front[0] if front else next(iter(streams))


def _pose(fields: Fields, name: str) -> Pose2:
    return Pose2(fields.take(f"{name}_x"), fields.take(f"{name}_y"), fields.take(f"{name}_theta"))


def _trailer(fields: Fields, layout: str) -> float:
    """The ipc timestamp of the trailer every message ends with; checks the record's length."""
    stamp = fields.take("ipc_timestamp")
    fields.skip(TRAILER - 1, "ipc_hostname logger_timestamp")
    fields.end(f"{layout} ipc_timestamp ipc_hostname logger_timestamp")
    return stamp


def _make(fields: Fields, index: int, ranges, bearings, **kw):
    return scan_or_reason(
        ranges,
        bearings,
        fields.path,
        fields.line,
        "ranges",
        invalid_values=NO_RETURN_CODES_M,
        source=ScanSource(str(fields.path), index, fields.line),
        **kw,
    )


def _flaser(fields: Fields, index: int, front: FrontLaser):
    n = fields.take_int("num_readings", 1, 100_000)
    ranges = fields.take_floats(n, "range", "num_readings")
    pose = _pose(fields, "laser_pose")
    odom = _pose(fields, "odom")
    stamp = _trailer(
        fields, "FLASER num_readings range[num_readings] x y theta odom_x odom_y odom_theta"
    )
    # x y theta is the laser's pose (CARMEN's laser_pose: the offset is in it already), odom_* the
    # robot's: moved onto the laser
    if front.offset:
        odom = odom @ Pose2(front.offset, 0.0, 0.0)
    return _make(
        fields,
        index,
        ranges,
        front.bearings(n),
        range_max=front.max_range,
        pose=pose,
        odometry=odom,
        stamp=stamp,
    )


def _rawlaser(fields: Fields, index: int, kind: str, mounts: list[Pose2], front: FrontLaser):
    """A RAWLASER or ROBOTLASER1 scan; a ROBOTLASER1 line's laser and robot poses (both in the
    odometry frame) add the mount they imply to ``mounts``, and the laser's is its odometry. Its
    readings at or beyond its ``maximum_range`` are no return, and for the front laser's streams
    at or beyond ``PARAM robot_front_laser_max`` too."""
    robot = kind == "ROBOTLASER1"
    fields.take_int("laser_type", -1000, 1000)
    start = fields.take("start_angle")
    fov = fields.take("field_of_view")
    res = fields.take("angular_resolution")
    max_range = fields.take("maximum_range")
    fields.take("accuracy")
    fields.take_int("remission_mode", -1000, 1000)
    n = fields.take_int("num_readings", 1, 100_000)
    ranges = fields.take_floats(n, "range", "num_readings")
    n_rem = fields.take_int("num_remissions", 0, 100_000)
    fields.take_floats(n_rem, "remission", "num_remissions")
    if not res > 0:
        raise fields.error(f"must be positive, got {res}", "angular_resolution")
    if fov > 0 and abs((n - 1) * res - fov) > res + 1e-6 and abs(n * res - fov) > res + 1e-6:
        raise fields.error(
            f"{n} readings at {res} rad do not cover the field of view {fov} rad", "num_readings"
        )
    pose = odom = None
    layout = (
        f"{kind} laser_type start_angle field_of_view angular_resolution maximum_range accuracy "
        "remission_mode num_readings range[num_readings] num_remissions remission[num_remissions]"
    )
    if robot:
        pose = odom = _pose(fields, "laser_pose")
        mounts.append(_pose(fields, "robot_pose").inverse() @ pose)
        for name in ("tv", "rv", "forward_safety_dist", "side_safety_dist", "turn_axis"):
            fields.take(name)
        layout += " laser_pose robot_pose tv rv forward_safety_dist side_safety_dist turn_axis"
    stamp = _trailer(fields, layout)
    bearings = uniform_bearings(n, start, res)
    return _make(
        fields,
        index,
        ranges,
        bearings,
        range_max=min(
            max_range if max_range > 0 else math.inf,
            front.max_range if kind in FRONT_LASER else math.inf,
        ),
        pose=pose,
        odometry=odom,
        stamp=stamp,
    )
