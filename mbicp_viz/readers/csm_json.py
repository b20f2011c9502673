"""CSM's JSON ``laser_data``: one object per line (``nrays``, ``theta``, ``readings``, ``valid``, poses)."""

from __future__ import annotations

import json
import math

import numpy as np

from core import Pose2, ScanError, ScanSource, make_scan

from ..errors import InputError
from .log import ScanLog
from .text import open_text


def _pose(obj, key, path, line_no):
    v = obj.get(key)
    if v is None or not isinstance(v, list) or any(c is None for c in v):
        return None
    if len(v) != 3 or not all(isinstance(c, (int, float)) and math.isfinite(c) for c in v):
        raise InputError(f"expected [x, y, theta], got {str(v)[:60]}", path, line_no, key)
    return Pose2(*map(float, v))


def _array(obj, key, n, path, line_no, allow_null=False):
    v = obj.get(key)
    if not isinstance(v, list) or len(v) != n:
        got = f"{len(v)} entries" if isinstance(v, list) else type(v).__name__
        raise InputError(f"expected a list of nrays={n} entries, got {got}", path, line_no, key)
    out = np.empty(n)
    for k, c in enumerate(v):
        if c is None and allow_null:
            out[k] = np.nan
        elif isinstance(c, (int, float)) and not isinstance(c, bool):
            out[k] = c
        else:
            raise InputError(f"entry {k} is {c!r}, not a number", path, line_no, key)
    return out


def read_csm_json(path: str) -> ScanLog:
    scans = []
    with open_text(path) as f:
        for line_no, line in enumerate(f, start=1):
            if not line.strip():
                continue
            try:
                obj = json.loads(line)
            except json.JSONDecodeError as e:
                raise InputError(f"invalid JSON ({e.msg}, column {e.colno})", path, line_no) from None
            if not isinstance(obj, dict):
                raise InputError("expected a JSON object (laser_data)", path, line_no)
            n = obj.get("nrays")
            if not isinstance(n, int) or isinstance(n, bool) or n <= 0:
                raise InputError(f"expected a positive integer, got {n!r}", path, line_no, "nrays")
            readings = _array(obj, "readings", n, path, line_no, allow_null=True)
            if "theta" in obj:
                theta = _array(obj, "theta", n, path, line_no)
            else:
                lo, hi = obj.get("min_theta"), obj.get("max_theta")
                if not all(isinstance(v, (int, float)) for v in (lo, hi)):
                    raise InputError("needs 'theta' or numeric 'min_theta' and 'max_theta'", path, line_no, "theta")
                theta = np.linspace(lo, hi, n)
            valid = _array(obj, "valid", n, path, line_no) != 0 if "valid" in obj else None
            pose = _pose(obj, "true_pose", path, line_no) or _pose(obj, "estimate", path, line_no)
            try:
                scans.append(make_scan(readings, theta, valid=valid, pose=pose,
                                       odometry=_pose(obj, "odometry", path, line_no),
                                       source=ScanSource(str(path), len(scans), line_no)))
            except ScanError as e:
                raise InputError(e.reason, path, line_no, "readings") from None
    if not scans:
        raise InputError("no laser_data objects in the file", path)
    return ScanLog(str(path), scans)
