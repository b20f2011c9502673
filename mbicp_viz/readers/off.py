"""Minguez's ``.off`` files (the MbICP data set).

Two layouts exist: ``laserazosSM3.off`` starts with ``n_scans n_rays`` and then, per scan,
``n_rays`` lines of one range each and one line ``x y theta`` (odometry); ``datos.off`` holds
one scan per line. Both are 180-degree scans starting at -90 degrees.
"""

from __future__ import annotations

import math

from mbicp_viz.core import Pose2, ScanSource, uniform_bearings
from mbicp_viz.errors import InputError

from .carmen import NO_RETURN_CODES_M
from .log import ScanLog, scan_or_reason
from .text import Fields, token_lines


def _scan(fields: Fields, index: int, ranges, odometry=None):
    n = len(ranges)
    bearings = uniform_bearings(n, -math.pi / 2, math.pi / (n - 1) if n > 1 else 0.0)
    return scan_or_reason(
        ranges,
        bearings,
        fields.path,
        fields.line,
        "ranges",
        invalid_values=NO_RETURN_CODES_M,
        odometry=odometry,
        source=ScanSource(str(fields.path), index, fields.line),
    )


def read_off(path: str) -> ScanLog:
    records = token_lines(path, comment=None)
    first = next(records, None)
    if first is None:
        raise InputError("empty file", path)
    log = ScanLog(str(path), [])
    if len(first.t) == 2 and all(t.isdigit() for t in first.t):
        _read_blocks(first, records, log)
    else:
        width = len(first.t)
        for fields in (first, *records):
            if len(fields.t) != width:
                raise fields.error(
                    f"{len(fields.t)} ranges where the first scan has {width}", "ranges"
                )
            log.add(_scan(fields, log.records, fields.take_floats(width, "range")))
    return log


def _read_blocks(header: Fields, records, log: ScanLog) -> None:
    n_scans = header.take_int("n_scans", 1, 10**7)
    n_rays = header.take_int("n_rays", 2, 100_000)
    for k in range(n_scans):
        ranges, first = [], None
        for _ in range(n_rays):
            fields = next(records, None)
            if fields is None:
                raise header.error(
                    f"the header announces {n_scans} scans of {n_rays} ranges; the file ends in "
                    f"scan {k}",
                    "header",
                )
            first = first or fields
            ranges.append(fields.take("range", finite=False))
            fields.end("one range per line")
        pose_line = next(records, None)
        if pose_line is None:
            raise header.error(
                f"the header announces {n_scans} scans; the file ends before the pose of scan {k}",
                "header",
            )
        pose = Pose2(
            pose_line.take("pose_x"), pose_line.take("pose_y"), pose_line.take("pose_theta")
        )
        pose_line.end("x y theta")
        log.add(_scan(first, log.records, ranges, pose))
    extra = next(records, None)
    if extra is not None:
        raise extra.error(f"the header announces {n_scans} scans; more lines follow", "header")
