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
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from mbicp_viz.core import (
    Pose2,
    Scan,
    ScanError,
    ScanSource,
    UnusableScan,
    bearing_layout,
    make_scan,
)
from mbicp_viz.errors import InputError

if TYPE_CHECKING:
    from .bag_index import BagScans
    from .log_cache import CachedScans

# Records fewer than one in this many of those they span are read one by one, not front to back
# (a bag's scan by its index takes about 30 times as long as the next one in a pass).
SPARSE_READ = 30
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

    def laser_motion(self, motion: Pose2, base: bool) -> Pose2:
        """The laser's motion of a motion ``reported`` (its inverse)."""
        return self.mount.inverse().conjugate(motion) if self.reports_base(base) else motion


@dataclass
class ScanLog:
    """A file's scans. Read whole (``scans`` a list), or read when asked for (``store``: an indexed
    bag, ``bag_index.BagScans``, or a log kept in the cache, ``log_cache.CachedScans``):
    ``scan(record)`` then reads one record, and ``scans`` and ``unusable`` look at every
    record once, the first time a command needs them (``Survey``)."""

    path: str
    scans: Sequence[Scan]  # the usable scans, in file order
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
    store: BagScans | CachedScans | None = None

    def __post_init__(self):
        if self.store is None or isinstance(self.scans, _UsableScans):
            return
        if self.scans:  # given its scans (made whole: deskewed, thinned ...): read no more
            self.unusable, self.store = dict(self.unusable), None
        else:
            survey = Survey(self.store)
            self.scans, self.unusable = _UsableScans(survey), _Unusable(survey)

    def __len__(self) -> int:
        return len(self.scans)

    @property
    def records(self) -> int:
        """Scan records in the file, usable or not."""
        if self.store is not None:
            return self.store.records
        return len(self.scans) + len(self.unusable)

    def add(self, scan: Scan | UnusableScan) -> None:
        """The next scan record: a scan, or the error that makes it unusable."""
        if isinstance(scan, UnusableScan):
            self.unusable[self.records] = scan
        else:
            self.scans.append(scan)

    def scan(self, index: int, odometry: bool = True) -> Scan:
        """The scan of record ``index`` (negative: counted from the end; without ``odometry``, a
        lazily read log may leave its odometry unread)."""
        n = self.records
        if not -n <= index < n:
            raise InputError(
                f"scan index {index} out of range: the log holds {n} scans",
                self.path,
                field="index",
            )
        index %= n
        scan = (
            self.store.load(index, odometry) if self.store is not None else self.unusable.get(index)
        )
        if isinstance(scan, UnusableScan):
            raise InputError(
                f"scan {index} cannot be matched: {scan.reason}",
                self.path,
                scan.source.line,
                None if scan.source.line else "index",
            )
        if scan is not None:
            return scan
        return self.scans[index - bisect.bisect_left(sorted(self.unusable), index)]

    def scans_from(self, record: int, odometry: bool = True) -> Iterator[tuple[int, Scan]]:
        """(record, scan) of each usable scan from ``record`` on, in file order (a lazily read log
        is read front to back once, and learns its unusable records on the way; without
        ``odometry``, its scans' odometry is not read)."""
        if self.store is not None:
            survey = self.unusable.survey if isinstance(self.unusable, _Unusable) else None
            for r, scan in self.store.stream(record, odometry):
                if isinstance(scan, Scan):
                    yield r, scan
                elif survey is not None:
                    survey.saw(r, scan)
            return
        records = self.record_numbers()
        k = bisect.bisect_left(records, record)
        yield from zip(records[k:], self.scans[k:])

    def poses_of(self, records: list[int]) -> np.ndarray:
        """(n, 3) the stored poses of ``records``' scans (NaN where one has none); a lazily read
        log's store says them without making its scans."""
        if self.store is not None:
            return self.store.poses(records)
        none = (math.nan,) * 3
        scans = self.scans_of(records, odometry=False)
        return np.array([none if s.pose is None else s.pose.as_array() for s in scans]).reshape(
            -1, 3
        )

    def scans_of(self, records: list[int], odometry: bool = True) -> Iterator[Scan]:
        """The scans of ``records`` in their order, each read once: a lazily read log is read front
        to back once when they increase and lie close (a run's scans), else one by one (a map's
        every 1000th scan; without ``odometry``, its scans' odometry may be left unread)."""
        sparse = not records or len(records) * SPARSE_READ < records[-1] - records[0]
        one_by_one = self.store is None or self.store.random_access or sparse
        if one_by_one or any(b <= a for a, b in zip(records, records[1:])):
            yield from (self.scan(r, odometry) for r in records)
            return
        wanted = iter(records)
        r = next(wanted, None)
        for k, scan in self.scans_from(records[0], odometry):
            if k == r:
                yield scan
                r = next(wanted, None)
                if r is None:
                    return
        if r is not None:
            self.scan(r)  # not usable: its own error

    def record_numbers(self, first: int | None = None) -> list[int]:
        """The record number of each of ``scans`` (the ``first`` ones: a lazily read log not yet
        surveyed reads only as far as they go)."""
        if isinstance(self.scans, _UsableScans):
            return self.scans.survey.first(first)
        records = [r for r in range(self.records) if r not in self.unusable]
        return records if first is None else records[:first]

    def consecutive_pairs(self, limit: int | None = None) -> list[tuple[int, int]]:
        """Record numbers of each usable scan and the next usable one (the first ``limit``
        pairs)."""
        records = self.record_numbers(None if limit is None else limit + 1)
        if len(records) < 2:
            raise InputError("needs at least two usable scans", self.path)
        return list(zip(records[:-1], records[1:]))

    @property
    def surveyed(self) -> bool:
        """Whether the log knows its usable records without reading more of its file."""
        return not isinstance(self.scans, _UsableScans) or self.scans.survey.complete

    @property
    def known_unusable(self) -> Mapping[int, UnusableScan]:
        """The unusable records known without reading more of the file (a lazily read log knows
        them once a command has looked at every record)."""
        if isinstance(self.unusable, _Unusable):
            return self.unusable.survey.known
        return self.unusable

    def unusable_summary(self) -> str | None:
        """One line for the records skipped as unusable (those known), or None."""
        bad = self.known_unusable
        if not bad:
            return None
        first = min(bad)
        where = f", line {bad[first].source.line}" if bad[first].source.line else ""
        return (
            f"{self.path}: skipped {len(bad)} unusable scan(s) of {self.records} "
            f"(first: scan {first}{where}: {bad[first].reason})"
        )


def no_usable_scan(path: str, unusable: Mapping[int, UnusableScan]):
    """The error of a file whose every scan record is unusable."""
    first = unusable[min(unusable)]
    raise InputError(
        f"no usable scan: all {len(unusable)} are unusable (scan {min(unusable)}: {first.reason})",
        path,
        first.source.line,
        "ranges",
    )


class Survey:
    """Every record's fate in a lazily read log, found by reading it front to back once, when
    first asked for: the usable records' numbers and the unusable ones' reasons."""

    def __init__(self, store: BagScans | CachedScans):
        self.store = store
        self._usable: list[int] | None = None
        self._unusable: dict[int, UnusableScan] = {}

    def _read(self, n: int | None) -> list[int]:
        """The first ``n`` usable records (None: all, and the survey is complete), read front to
        back only as far as they go."""
        out = []
        for r, scan in self.store.stream(odometry=False):
            if isinstance(scan, UnusableScan):
                self._unusable[r] = scan
            else:
                out.append(r)
                if len(out) == n:
                    return out
        if not out:
            no_usable_scan(self.store.path, self._unusable)
        self._usable = out
        return out

    @property
    def usable(self) -> list[int]:
        return self._usable if self._usable is not None else self._read(None)

    def first(self, n: int | None) -> list[int]:
        """The first ``n`` usable records (all: the survey)."""
        return self.usable[:n] if n is None or self._usable is not None else self._read(n)

    @property
    def unusable(self) -> dict[int, UnusableScan]:
        if self._usable is None:  # the survey finds them
            self._read(None)
        return self._unusable

    @property
    def known(self) -> dict[int, UnusableScan]:
        """The unusable records found so far (all of them once surveyed)."""
        return self._unusable

    @property
    def complete(self) -> bool:
        return self._usable is not None

    def saw(self, r: int, scan: UnusableScan) -> None:
        """Record ``r`` is unusable, as a pass over the log other than the survey's found."""
        self._unusable[r] = scan


class _UsableScans(Sequence):
    """The usable scans of a lazily read log, each read when asked for."""

    def __init__(self, survey: Survey):
        self.survey = survey

    def __len__(self) -> int:
        return len(self.survey.usable)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        return self.survey.store.load(self.survey.usable[k])

    def __iter__(self):
        """Front to back once (each scan by its own read would seek for every one)."""
        for _, scan in self.survey.store.stream():
            if isinstance(scan, Scan):
                yield scan


class _Unusable(Mapping):
    def __init__(self, survey: Survey):
        self.survey = survey

    def __getitem__(self, r: int) -> UnusableScan:
        return self.survey.unusable[r]

    def __iter__(self):
        return iter(self.survey.unusable)

    def __len__(self) -> int:
        return len(self.survey.unusable)


def scan_or_reason(
    ranges, bearings, path: str, line: int | None, field: str, **kw
) -> Scan | UnusableScan:
    """A reader's scan (``make_scan``'s keywords), or the reason it is unusable, which the log keeps
    and skips: no valid reading, or bearings closer than any scanner steps (a scan of a log that
    writes its bearings unevenly). Malformed beams are an error naming the file, line (or message)
    and field."""
    step = bearing_layout(bearings).min_step
    if step < MIN_BEARING_STEP_RAD:
        return UnusableScan(
            kw.get("source") or ScanSource(path, 0, line),
            f"bearings {step:.3g} rad apart: below the finest scanner's step "
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

    source = f"{log.frames.mount_source or 'no mount given'}, the laser upside down"
    frames = replace(log.frames, mount_source=source)
    if log.store is not None:
        return replace(log, scans=[], unusable={}, frames=frames, store=log.store.mirrored())

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
    return replace(log, scans=scans, frames=frames)
