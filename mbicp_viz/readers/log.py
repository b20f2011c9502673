"""What every reader returns: the scans of a file, and the odometry it stores.

Scans are numbered by their record in the file (0 = the first scan message). A record that
cannot be matched — no beams, no valid reading — is kept as a reason, not as a scan: a long log
is not refused for one empty scan, the scans after it keep their numbers, and only asking for
that scan by its number is an error.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np

from mbicp_viz.core import Pose2, Scan, ScanError, UnusableScan, make_scan
from mbicp_viz.errors import InputError

# The finest 2-D scanners step by about 0.04 degrees; steps this small are damaged bearings.
MIN_BEARING_STEP_RAD = 1e-4


@dataclass
class ScanLog:
    path: str
    scans: list[Scan]  # the usable scans, in file order
    odometry: list[tuple[float, Pose2]] = field(default_factory=list)  # (stamp [s], pose) from ODOM lines
    skipped: dict[str, int] = field(default_factory=dict)  # message type -> records read past
    unusable: dict[int, UnusableScan] = field(default_factory=dict)  # scan record -> why it cannot be matched

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
            raise InputError(f"scan index {index} out of range: the log holds {n} scans", self.path, field="index")
        index %= n
        if index in self.unusable:
            bad = self.unusable[index]
            raise InputError(f"scan {index} cannot be matched: {bad.reason}", self.path, bad.source.line,
                             None if bad.source.line else "index")
        return self.scans[index - bisect.bisect_left(sorted(self.unusable), index)]

    def record_numbers(self) -> list[int]:
        """The record number of each of ``scans``."""
        return [r for r in range(self.records) if r not in self.unusable]

    def consecutive_pairs(self, limit: int | None = None) -> list[tuple[int, int]]:
        """Record numbers of each usable scan and the next usable one (the first ``limit`` pairs)."""
        n = len(self.scans) - 1 if limit is None else min(limit, len(self.scans) - 1)
        if n < 1:
            raise InputError("needs at least two usable scans", self.path)
        records = self.record_numbers()[:n + 1]
        return list(zip(records[:-1], records[1:]))

    def unusable_summary(self) -> str | None:
        """One line for the records skipped as unusable, or None."""
        if not self.unusable:
            return None
        first = min(self.unusable)
        where = f", line {self.unusable[first].source.line}" if self.unusable[first].source.line else ""
        return (f"{self.path}: skipped {len(self.unusable)} unusable scan(s) of {self.records} "
                f"(first: scan {first}{where}: {self.unusable[first].reason})")


def scan_or_reason(ranges, bearings, path: str, line: int | None, field: str, **kw) -> Scan | UnusableScan:
    """A reader's scan (``make_scan``'s keywords), or the reason it is unusable, which the log keeps
    and skips. Malformed beams are an error naming the file, line (or message) and field."""
    b = np.asarray(bearings, dtype=float)
    steps = np.abs(np.diff(b))
    if len(steps) and np.all(np.isfinite(steps)) and steps.min() < MIN_BEARING_STEP_RAD:
        raise InputError(f"bearings {steps.min():.3g} rad apart: below the finest scanner's step "
                         f"({MIN_BEARING_STEP_RAD} rad)", path, line, field)
    try:
        return make_scan(ranges, bearings, **kw)
    except UnusableScan as e:
        return e
    except ScanError as e:
        raise InputError(e.reason, path, line, field) from None
