"""What every reader returns: the scans of a file, the odometry it stores, and the frames.

Scans are numbered by their record in the file (0 = the first scan message). A record that
cannot be matched — no beams, no valid reading — is kept as a reason, not as a scan: a long log
is not refused for one empty scan, the scans after it keep their numbers, and only asking for
that scan by its number is an error.

Frames: every scan is in its laser's (upright) frame, and its ``pose`` and ``odometry`` are poses
of that laser frame. ``frames.mount`` (T_base_laser) says where the laser sits on the robot, so
that a match (the laser's motion T) is the base's motion ``mount @ T @ mount.inverse()``.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

from mbicp_viz.core import Pose2, Scan, ScanError, ScanSource, UnusableScan, make_scan
from mbicp_viz.errors import InputError

# The finest 2-D scanners step by about 0.04 degrees; steps this small are damaged bearings.
MIN_BEARING_STEP_RAD = 1e-4


@dataclass(frozen=True)
class Frames:
    """The frames of a log's matches: the laser's mount on the robot (T_base_laser), where it came
    from (None: unknown, the laser frame stands for the base), and the frames' names."""

    mount: Pose2 = field(default_factory=Pose2)
    mount_source: str | None = None
    base_frame: str = "base"
    frame_id: str = ""  # the scans' frame, as the file names it

    def reports_base(self, base: bool) -> bool:
        """Whether matches are reported as the base's motion (asked for, and a mount is known)."""
        return base and self.mount_source is not None

    def frame_name(self, base: bool) -> str:
        return self.base_frame if self.reports_base(base) else "laser"

    def frame_text(self, base: bool = True) -> str:
        """Which frame a match's pose is given in, and why."""
        laser = f"the laser frame{f' {self.frame_id!r}' if self.frame_id else ''}"
        if not self.reports_base(base):
            return (
                laser
                if not base
                else f"{laser} (no mount known: give --mount X Y THETA_DEG for the base's motion)"
            )
        m = self.mount
        return (
            f"the robot's {self.base_frame} (laser mount ({m.x:g} m, {m.y:g} m, "
            f"{math.degrees(m.theta):g} deg) "
            f"from {self.mount_source})"
        )

    def reported(self, motion: Pose2, base: bool) -> Pose2:
        """A motion of the laser as reported: the base's motion when ``base`` and the mount is
        known."""
        return self.mount.conjugate(motion) if self.reports_base(base) else motion


@dataclass
class ScanLog:
    path: str
    scans: list[Scan]  # the usable scans, in file order
    # (stamp [s], pose) from ODOM lines
    odometry: list[tuple[float, Pose2]] = field(default_factory=list)
    skipped: dict[str, int] = field(default_factory=dict)  # message type -> records read past
    # scan record -> why it cannot be matched
    unusable: dict[int, UnusableScan] = field(default_factory=dict)
    frames: Frames = field(default_factory=Frames)
    topic: str | None = (
        None  # the scan stream read: a bag's topic, a CARMEN log's laser message type
    )
    # the file's scan streams -> their descriptions
    scan_topics: dict[str, str] = field(default_factory=dict)
    odometry_source: str | None = None
    notes: list[str] = field(default_factory=list)  # warnings for the user (a bag cut short ...)

    def __len__(self) -> int:
        return len(self.scans)

    @property
    def records(self) -> int:
        """Scan records in the file, usable or not."""
        return len(self.scans) + len(self.unusable)

    def add(self, scan: Scan | UnusableScan) -> None:
        """The next scan record: a scan, or the error that makes it unusable."""
        if isinstance(scan, UnusableScan):
            self.unusable[self.records] = scan
        else:
            self.scans.append(scan)

    def scan(self, index: int) -> Scan:
        """The scan of record ``index`` (negative: counted from the end)."""
        n = self.records
        if not -n <= index < n:
            raise InputError(
                f"scan index {index} out of range: the log holds {n} scans",
                self.path,
                field="index",
            )
        index %= n
        if index in self.unusable:
            bad = self.unusable[index]
            raise InputError(
                f"scan {index} cannot be matched: {bad.reason}",
                self.path,
                bad.source.line,
                None if bad.source.line else "index",
            )
        return self.scans[index - bisect.bisect_left(sorted(self.unusable), index)]

    def record_numbers(self) -> list[int]:
        """The record number of each of ``scans``."""
        return [r for r in range(self.records) if r not in self.unusable]

    def consecutive_pairs(self, limit: int | None = None) -> list[tuple[int, int]]:
        """Record numbers of each usable scan and the next usable one (the first ``limit``
        pairs)."""
        n = len(self.scans) - 1 if limit is None else min(limit, len(self.scans) - 1)
        if n < 1:
            raise InputError("needs at least two usable scans", self.path)
        records = self.record_numbers()[: n + 1]
        return list(zip(records[:-1], records[1:]))

    def unusable_summary(self) -> str | None:
        """One line for the records skipped as unusable, or None."""
        if not self.unusable:
            return None
        first = min(self.unusable)
        where = (
            f", line {self.unusable[first].source.line}" if self.unusable[first].source.line else ""
        )
        return (
            f"{self.path}: skipped {len(self.unusable)} unusable scan(s) of {self.records} "
            f"(first: scan {first}{where}: {self.unusable[first].reason})"
        )


def scan_or_reason(
    ranges, bearings, path: str, line: int | None, field: str, **kw
) -> Scan | UnusableScan:
    """A reader's scan (``make_scan``'s keywords), or the reason it is unusable, which the log keeps
    and skips: no valid reading, or bearings closer than any scanner steps (a scan of a log that
    writes its bearings unevenly). Malformed beams are an error naming the file, line (or message)
    and field."""
    b = np.asarray(bearings, dtype=float)
    steps = np.abs(np.diff(b))
    if len(steps) and np.all(np.isfinite(steps)) and steps.min() < MIN_BEARING_STEP_RAD:
        return UnusableScan(
            kw.get("source") or ScanSource(path, 0, line),
            f"bearings {steps.min():.3g} rad apart: below the finest scanner's step "
            f"({MIN_BEARING_STEP_RAD} rad)",
        )
    try:
        return make_scan(ranges, bearings, **kw)
    except UnusableScan as e:
        return e
    except ScanError as e:
        raise InputError(e.reason, path, line, field) from None


def mirrored(log: ScanLog) -> ScanLog:
    """The log of a laser mounted upside down, its scans turned upright (every bearing negated)."""
    from dataclasses import replace

    scans = [
        replace(
            s,
            ranges=s.ranges[::-1],
            bearings=-s.bearings[::-1],
            valid=s.valid[::-1],
            beam_times=None if s.beam_times is None else s.beam_times[::-1],
        )
        for s in log.scans
    ]
    source = f"{log.frames.mount_source or 'no mount given'}, the laser upside down"
    return replace(log, scans=scans, frames=replace(log.frames, mount_source=source))
