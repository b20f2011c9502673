"""Minguez's ``.off`` files (the MbICP data set).

Two layouts exist: ``laserazosSM3.off`` starts with ``n_scans n_rays`` and then, per scan,
``n_rays`` lines of one range each and one line ``x y theta`` (odometry); ``datos.off`` holds
one scan per line. Both are 180-degree scans starting at -90 degrees.
"""

from __future__ import annotations

import math

import numpy as np

from core import Pose2, ScanError, ScanSource, make_scan, uniform_bearings

from ..errors import InputError
from .carmen import NO_RETURN_CODES_M
from .log import ScanLog
from .text import open_text


def _floats(tokens, path, line_no, field):
    try:
        return [float(t) for t in tokens]
    except ValueError:
        bad = next(t for t in tokens if not _ok(t))
        raise InputError(f"expected a number, got {bad[:40]!r}", path, line_no, field) from None


def _ok(t):
    try:
        float(t)
        return True
    except ValueError:
        return False


def _scan(path, index, line_no, ranges, odometry=None):
    n = len(ranges)
    bearings = uniform_bearings(n, -math.pi / 2, math.pi / (n - 1) if n > 1 else 0.0)
    try:
        return make_scan(ranges, bearings, invalid_values=NO_RETURN_CODES_M, odometry=odometry,
                         source=ScanSource(str(path), index, line_no))
    except ScanError as e:
        raise InputError(e.reason, path, line_no, "ranges") from None


def read_off(path: str) -> ScanLog:
    with open_text(path) as f:
        lines = [(i, ln.split()) for i, ln in enumerate(f, start=1)]
    lines = [(i, t) for i, t in lines if t]
    if not lines:
        raise InputError("empty file", path)
    first_no, first = lines[0]
    if len(first) == 2 and all(t.isdigit() for t in first):
        return _read_blocks(path, lines)
    width = len(first)
    scans = []
    for k, (i, toks) in enumerate(lines):
        if len(toks) != width:
            raise InputError(f"{len(toks)} ranges where the first scan has {width}", path, i, "ranges")
        scans.append(_scan(path, k, i, np.array(_floats(toks, path, i, "range"))))
    return ScanLog(str(path), scans)


def _read_blocks(path, lines) -> ScanLog:
    n_scans, n_rays = (int(t) for t in lines[0][1])
    if n_scans <= 0 or n_rays <= 1:
        raise InputError(f"header announces {n_scans} scans of {n_rays} rays", path, lines[0][0], "header")
    body = lines[1:]
    per = n_rays + 1
    if len(body) != n_scans * per:
        raise InputError(f"header announces {n_scans} scans x ({n_rays} ranges + 1 pose line) = "
                         f"{n_scans * per} lines, the file has {len(body)}", path, lines[0][0], "header")
    scans = []
    for k in range(n_scans):
        block = body[k * per:(k + 1) * per]
        for i, toks in block[:-1]:
            if len(toks) != 1:
                raise InputError(f"expected one range, got {len(toks)} fields", path, i, "range")
        ranges = np.array([_floats(t, path, i, "range")[0] for i, t in block[:-1]])
        i, pose_toks = block[-1]
        if len(pose_toks) != 3:
            raise InputError(f"expected 'x y theta', got {len(pose_toks)} fields", path, i, "pose")
        x, y, th = _floats(pose_toks, path, i, "pose")
        if not all(map(math.isfinite, (x, y, th))):
            raise InputError("pose is not finite", path, i, "pose")
        scans.append(_scan(path, k, block[0][0], ranges, Pose2(x, y, th)))
    return ScanLog(str(path), scans)
