"""CARMEN logs: FLASER, RAWLASER1-4, ROBOTLASER1, ODOM, PARAM (plain or .gz).

Formats as written by CARMEN's logger; CSM's ``laser_data_carmen.c`` is the reference for the
bearings of FLASER, which stores none: the scan spans 180 degrees from -90 degrees.
"""

from __future__ import annotations

import math
import re

import numpy as np

from core import Pose2, ScanError, ScanSource, make_scan, uniform_bearings

from ..errors import InputError
from .log import ScanLog
from .text import open_text

# No-return / max-range codes of real logs, masked, never points (see shared/data/README.md):
# SICK 80 m mode, the aces log's 50.00, SICK 8 m mode.
NO_RETURN_CODES_M = ((81.83, 81.91), (49.995, 50.005), (8.183, 8.191))
_MESSAGE = re.compile(r"^[A-Z][A-Z0-9_]*$")


class _Fields:
    """Tokens of one line, read left to right, with errors naming the line and the field."""

    def __init__(self, tokens, path, line_no):
        self.t, self.i, self.path, self.line = tokens, 1, path, line_no

    def take(self, name: str, kind=float):
        if self.i >= len(self.t):
            raise InputError(f"line ends before this field ({len(self.t)} fields)", self.path, self.line, name)
        tok = self.t[self.i]
        self.i += 1
        try:
            v = kind(tok)
        except ValueError:
            raise InputError(f"expected a number, got {tok!r}", self.path, self.line, name) from None
        if kind is float and math.isinf(v) and name not in ("range",):
            raise InputError(f"not finite: {tok!r}", self.path, self.line, name)
        if kind is float and math.isnan(v) and name != "range":
            raise InputError(f"not a number: {tok!r}", self.path, self.line, name)
        return v

    def take_count(self, name: str, max_count: int = 100000) -> int:
        n = self.take(name, int)
        if not 0 < n <= max_count:
            raise InputError(f"count {n} out of range 1..{max_count}", self.path, self.line, name)
        return n

    def take_ranges(self, n: int) -> np.ndarray:
        if self.i + n > len(self.t):
            raise InputError(f"{n} readings announced but only {len(self.t) - self.i} fields follow",
                             self.path, self.line, "num_readings")
        try:
            r = np.array(self.t[self.i:self.i + n], dtype=float)
        except ValueError:
            bad = next(k for k, tok in enumerate(self.t[self.i:self.i + n]) if not _is_float(tok))
            raise InputError(f"expected a number, got {self.t[self.i + bad]!r}", self.path, self.line,
                             f"range[{bad}]") from None
        self.i += n
        return r

    def take_pose(self, name: str) -> Pose2:
        return Pose2(self.take(f"{name}_x"), self.take(f"{name}_y"), self.take(f"{name}_theta"))


def _is_float(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def read_carmen(path: str) -> ScanLog:
    log = ScanLog(str(path), [])
    laser_offset = 0.0
    with open_text(path) as f:
        for line_no, line in enumerate(f, start=1):
            tokens = line.split()
            if not tokens or tokens[0].startswith("#"):
                continue
            kind = tokens[0]
            if not _MESSAGE.match(kind):
                raise InputError(f"not a CARMEN message name: {kind[:40]!r}", path, line_no, "message")
            fields = _Fields(tokens, path, line_no)
            if kind == "PARAM":
                if len(tokens) >= 3 and tokens[1] == "robot_frontlaser_offset":
                    fields.i = 2
                    laser_offset = fields.take("robot_frontlaser_offset")
                continue
            if kind == "ODOM":
                pose = fields.take_pose("odom")
                stamp = _stamp(tokens, 4 + 3, fields)
                log.odometry.append((stamp, pose))
                continue
            if kind == "FLASER":
                scan = _flaser(fields, len(log.scans), laser_offset)
            elif kind in ("ROBOTLASER1",) or re.fullmatch(r"RAWLASER[1-4]", kind):
                scan = _rawlaser(fields, len(log.scans), kind == "ROBOTLASER1")
            else:
                log.skipped[kind] = log.skipped.get(kind, 0) + 1
                continue
            log.scans.append(scan)
    if not log.scans:
        raise InputError("no laser scans (FLASER, RAWLASER1-4 or ROBOTLASER1 lines) in the file", path)
    return log


def _stamp(tokens, after: int, fields: _Fields) -> float | None:
    """The ipc timestamp after the message body (``ts host logger_ts``), if present."""
    fields.i = after
    if len(tokens) - after >= 1 and _is_float(tokens[after]):
        return float(tokens[after])
    return None


def _make(fields: _Fields, index: int, ranges, bearings, **kw):
    src = ScanSource(str(fields.path), index, fields.line)
    try:
        return make_scan(ranges, bearings, invalid_values=NO_RETURN_CODES_M, source=src, **kw)
    except ScanError as e:
        raise InputError(e.reason, fields.path, fields.line, "ranges") from None


def _flaser(fields: _Fields, index: int, laser_offset: float):
    n = fields.take_count("num_readings")
    ranges = fields.take_ranges(n)
    pose = fields.take_pose("laser_pose")
    odom = fields.take_pose("odom")
    stamp = _stamp(fields.t, fields.i, fields)
    if laser_offset:
        pose = pose @ Pose2(laser_offset, 0.0, 0.0)
        odom = odom @ Pose2(laser_offset, 0.0, 0.0)
    bearings = uniform_bearings(n, -math.pi / 2, math.pi / (n - 1) if n > 1 else 0.0)
    return _make(fields, index, ranges, bearings, pose=pose, odometry=odom, stamp=stamp)


def _rawlaser(fields: _Fields, index: int, robot: bool):
    fields.take("laser_type", int)
    start = fields.take("start_angle")
    fov = fields.take("field_of_view")
    res = fields.take("angular_resolution")
    max_range = fields.take("maximum_range")
    fields.take("accuracy")
    fields.take("remission_mode", int)
    n = fields.take_count("num_readings")
    ranges = fields.take_ranges(n)
    n_rem = fields.take("num_remissions", int)
    if n_rem < 0 or fields.i + n_rem > len(fields.t):
        raise InputError(f"{n_rem} remissions announced but fewer fields follow", fields.path, fields.line,
                         "num_remissions")
    fields.i += n_rem
    if not res > 0:
        raise InputError(f"must be positive, got {res}", fields.path, fields.line, "angular_resolution")
    if fov > 0 and abs((n - 1) * res - fov) > res + 1e-6 and abs(n * res - fov) > res + 1e-6:
        raise InputError(f"{n} readings at {res} rad do not cover the field of view {fov} rad",
                         fields.path, fields.line, "num_readings")
    pose = odom = None
    if robot:
        pose = fields.take_pose("laser_pose")
        odom = fields.take_pose("robot_pose")
        for name in ("tv", "rv", "forward_safety_dist", "side_safety_dist", "turn_axis"):
            fields.take(name)
    stamp = _stamp(fields.t, fields.i, fields)
    bearings = uniform_bearings(n, start, res)
    return _make(fields, index, ranges, bearings, range_max=max_range if max_range > 0 else math.inf,
                 pose=pose, odometry=odom, stamp=stamp)
