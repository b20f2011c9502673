"""A log's scans corrected for the motion during each scan (``--deskew``; the geometry is
``core/deskew.py``). The sensor's velocity during scan k is taken as constant, from:

- ``odometry``: the log's odometry at scan k and at the next scan (the last scan: the one before),
  over the time between their stamps;
- ``velocity``: the motion between scan k and the next one as improved MbICP matches them as
  measured (from the odometry when the log has some, else the identity), over the time between
  their stamps: a constant-velocity model for logs without odometry (a hand-held scanner).

Only scans that say when each beam was measured can be corrected (a LaserScan's
``time_increment``); a log without beam times is an error, not a silent no-op.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mbicp_viz.choices import Deskew
from mbicp_viz.core import Pose2, Scan, ScanError, deskew, relative, twist
from mbicp_viz.errors import InputError

from .log import ScanLog

SWEEP_SLACK = (
    1.5  # a sweep may outlast the gap to the next stamp this much (stamps jitter), no more
)


def _check(log: ScanLog, mode: Deskew) -> None:
    if any(s.beam_times is None for s in log.scans):
        raise InputError(
            "its scans do not say when each beam was measured (a LaserScan's time_increment): "
            "nothing to correct the motion with",
            log.path,
            field="--deskew",
        )
    if any(s.stamp is None for s in log.scans):
        raise InputError("its scans have no time stamps", log.path, field="--deskew")
    for a, b in zip(log.scans[:-1], log.scans[1:]):  # a sweep ends before the next scan begins
        sweep, gap = float(np.max(a.beam_times)) - float(np.min(a.beam_times)), b.stamp - a.stamp
        if gap > 0 and sweep > SWEEP_SLACK * gap:
            raise InputError(
                f"scan message {a.source.index} sweeps for {sweep:.4g} s (its time_increment times "
                "its "
                f"beams) but the next scan comes {gap:.4g} s later: its beam times are wrong",
                log.path,
                field="--deskew",
            )
    if mode is Deskew.odometry and all(s.odometry is None for s in log.scans):
        raise InputError(
            "the log stores no odometry: use --deskew velocity (from the matches)",
            log.path,
            field="--deskew",
        )


def _motions(log: ScanLog, mode: Deskew) -> list[Pose2 | None]:
    """The motion from each scan to the next (None where it could not be had)."""
    from mbicp_viz.core import ImprovedParams, match

    out: list[Pose2 | None] = []
    for a, b in zip(log.scans[:-1], log.scans[1:]):
        if mode is Deskew.odometry:  # a scan without odometry is left as measured (counted)
            have = a.odometry is not None and b.odometry is not None
            out.append(relative(a.odometry, b.odometry) if have else None)
            continue
        guess = (
            relative(a.odometry, b.odometry)
            if a.odometry is not None and b.odometry is not None
            else Pose2()
        )
        try:
            out.append(match(a, b, guess, ImprovedParams()).pose)
        except (ScanError, ValueError, FloatingPointError, np.linalg.LinAlgError):
            out.append(None)
    return out


def velocities(log: ScanLog, mode: Deskew | str) -> list[np.ndarray | None]:
    """Each scan's velocity (vx, vy, omega) in its own frame: the motion to the next scan over the
    time between their stamps (the last scan: the pair before it); None where there is none."""
    mode = Deskew(mode)
    _check(log, mode)
    if len(log.scans) < 2:
        raise InputError("needs at least two scans to know the motion", log.path, field="--deskew")
    motions = _motions(log, mode)
    out: list[np.ndarray | None] = []
    for k in range(len(log.scans)):
        j = min(k, len(motions) - 1)
        dt = log.scans[j + 1].stamp - log.scans[j].stamp
        out.append(twist(motions[j], dt) if motions[j] is not None and dt > 0 else None)
    return out


def deskew_log(log: ScanLog, mode: Deskew | str) -> ScanLog:
    """``log`` with every scan corrected for the motion during it (each keeps the measured one as
    ``raw``); a note says how, and how many scans had no velocity (left as measured)."""
    mode = Deskew(mode)
    scans: list[Scan] = []
    for s, v in zip(log.scans, velocities(log, mode)):
        try:
            scans.append(s if v is None else deskew(s, v))
        except ScanError as e:
            raise InputError(
                e.reason, log.path, field=f"--deskew (scan message {s.source.index})"
            ) from None
    how = (
        "the odometry between consecutive scans"
        if mode is Deskew.odometry
        else "the motion improved MbICP finds between consecutive scans as measured"
    )
    note = f"corrected for motion during each scan (--deskew {mode.value}): the velocity from {how}"
    missing = sum(s.raw is None for s in scans)
    if missing:
        note += f"; {missing} scan(s) left as measured (no motion to the next scan)"
    return replace(log, scans=scans, notes=[*log.notes, note])
