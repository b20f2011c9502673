"""CSM's JSON ``laser_data``: one object per line (``nrays``, ``theta``, ``readings``, ``valid``,
poses)."""

from __future__ import annotations

import json
import math

import numpy as np

from mbicp_viz.core import Pose2, ScanSource
from mbicp_viz.errors import InputError

from .log import ScanLog, scan_or_reason
from .text import lines, open_text


def _number(c) -> float | None:
    """A JSON number as a finite-or-not float; None for anything else (bool, string, an integer
    beyond a float's range)."""
    if isinstance(c, bool) or not isinstance(c, (int, float)):
        return None
    try:
        return float(c)
    except OverflowError:
        return None


def _pose(obj, key, path, line_no):
    v = obj.get(key)
    if v is None or (isinstance(v, list) and any(c is None for c in v)):
        return None
    values = [_number(c) for c in v] if isinstance(v, list) else []
    if len(values) != 3 or not all(c is not None and math.isfinite(c) for c in values):
        raise InputError(
            f"expected [x, y, theta] of finite numbers, got {str(v)[:60]}", path, line_no, key
        )
    return Pose2(*values)


def _array(obj, key, n, path, line_no, allow_null=False):
    v = obj.get(key)
    if not isinstance(v, list) or len(v) != n:
        got = f"{len(v)} entries" if isinstance(v, list) else type(v).__name__
        raise InputError(f"expected a list of nrays={n} entries, got {got}", path, line_no, key)
    out = np.empty(n)
    for k, c in enumerate(v):
        x = np.nan if c is None and allow_null else _number(c)
        if x is None:
            raise InputError(
                f"entry {k} is {str(c)[:40]}, not a number a float can hold", path, line_no, key
            )
        out[k] = x
    return out


def _object(text: str, path, line_no) -> dict:
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"invalid JSON ({e.msg}, column {e.colno})", path, line_no) from None
    except RecursionError:
        raise InputError("JSON nested too deeply", path, line_no) from None
    if not isinstance(obj, dict):
        raise InputError("expected a JSON object (laser_data)", path, line_no)
    return obj


def _theta(obj, n, path, line_no) -> np.ndarray:
    if "theta" in obj:
        return _array(obj, "theta", n, path, line_no)
    lo, hi = _number(obj.get("min_theta")), _number(obj.get("max_theta"))
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        raise InputError(
            "needs 'theta' or finite 'min_theta' and 'max_theta'", path, line_no, "theta"
        )
    return np.linspace(lo, hi, n)


def read_csm_json(path: str) -> ScanLog:
    log = ScanLog(str(path), [])
    with open_text(path) as f:
        for line in lines(f, path):
            if not line.text.strip():
                continue
            obj = _object(line.text, path, line.number)
            n = obj.get("nrays")
            if not isinstance(n, int) or isinstance(n, bool) or not 0 < n <= 100_000:
                raise InputError(
                    f"expected a whole number 1..100000, got {str(n)[:40]}",
                    path,
                    line.number,
                    "nrays",
                )
            readings = _array(obj, "readings", n, path, line.number, allow_null=True)
            theta = _theta(obj, n, path, line.number)
            valid = _array(obj, "valid", n, path, line.number) != 0 if "valid" in obj else None
            pose = _pose(obj, "true_pose", path, line.number) or _pose(
                obj, "estimate", path, line.number
            )
            log.add(
                scan_or_reason(
                    readings,
                    theta,
                    path,
                    line.number,
                    "theta",
                    valid=valid,
                    pose=pose,
                    odometry=_pose(obj, "odometry", path, line.number),
                    source=ScanSource(str(path), log.records, line.number),
                )
            )
    if not log.records:
        raise InputError("no laser_data objects in the file", path)
    return log
