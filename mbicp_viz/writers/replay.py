"""A long recording made of a short real one: its scans played forwards, then backwards, then
forwards again, as long as asked, as a robot driving to and fro along the recorded path would see
them. Nothing is invented: every scan is a real one (resampled to another beam count when asked,
each new beam reading the real beam nearest its bearing), every interval between two stamps is a
real one (scaled to another rate when asked), and the odometry is the recording's own, played
along. Benchmarks and tests use it to write an hour-long bag without shipping one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from mbicp_viz.core import Pose2, Scan, bearing_layout
from mbicp_viz.readers import ScanLog

from .bag import Robot, Topic


def resampled(scan: Scan, beams: int) -> Scan:
    """``scan`` with ``beams`` evenly spaced beams over its own field of view, each reading the
    real beam nearest its bearing (no range is interpolated: a new beam between a wall and the
    background would read a point on neither)."""
    b = scan.bearings
    # one array for the scans resampled alike, as a reader's scans of one laser share theirs
    bearings = bearing_layout(np.linspace(b[0], b[-1], beams)).given
    nearest = np.clip(np.searchsorted(b, bearings), 1, len(b) - 1)
    nearest -= bearings - b[nearest - 1] < b[nearest] - bearings
    return replace(
        scan,
        ranges=scan.ranges[nearest],
        bearings=bearings,
        valid=scan.valid[nearest],
        beam_times=None,
    )


@dataclass(frozen=True)
class Replay(Sequence):
    """Step ``k`` of a to-and-fro play of ``n`` items: 0, 1, ..., n-1, n-2, ..., 0, 1, ..."""

    n: int
    steps: int

    def __len__(self) -> int:
        return self.steps

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(self.steps))]
        if not -self.steps <= k < self.steps:
            raise IndexError(k)
        k %= self.steps
        if self.n == 1:
            return 0
        k %= 2 * (self.n - 1)
        return k if k < self.n else 2 * (self.n - 1) - k


class _Mapped(Sequence):
    def __init__(self, replay: Replay, items: Sequence):
        self.replay, self.items = replay, items

    def __len__(self) -> int:
        return len(self.replay)

    def __getitem__(self, k):
        return self.items[self.replay[k]]


class _Stamps(Sequence):
    """Each step's stamp: the first real stamp, then the real intervals of the steps played
    (an interval played backwards is the same interval), times ``scale``; kept as one running
    sum per period of the play so that any step is found without summing from the start."""

    def __init__(self, replay: Replay, stamps: np.ndarray, scale: float):
        self.replay, self.t0 = replay, float(stamps[0])
        dt = np.diff(stamps) * scale
        period = np.concatenate([dt, dt[::-1]])  # forwards, then back
        self.sums = np.concatenate([[0.0], np.cumsum(period)])

    def __len__(self) -> int:
        return len(self.replay)

    def __getitem__(self, k):
        if not -len(self) <= k < len(self):
            raise IndexError(k)
        k %= len(self)
        per = len(self.sums) - 1
        if per == 0:
            return self.t0
        return self.t0 + (k // per) * self.sums[-1] + self.sums[k % per]


def replayed(
    log: ScanLog,
    seconds: float,
    beams: int | None = None,
    rate_hz: float | None = None,
    topic: str = "/scan",
) -> Robot:
    """A robot recording ``seconds`` of ``log`` played to and fro: its scans (resampled to
    ``beams``), its stamps' intervals (scaled to ``rate_hz`` on average), its laser's mount and its
    odometry (the base's poses) when it has them."""
    scans = log.scans
    stamps = np.array([s.stamp for s in scans], dtype=float)
    if len(scans) < 2 or not np.all(np.isfinite(stamps)) or np.any(np.diff(stamps) <= 0):
        raise ValueError(f"{log.path}: needs two or more scans with increasing stamps to replay")
    mean_dt = float(np.mean(np.diff(stamps)))
    scale = 1.0 if rate_hz is None else 1.0 / (rate_hz * mean_dt)
    steps = max(2, int(seconds / (mean_dt * scale)) + 1)
    play = Replay(len(scans), steps)
    if beams is not None:
        scans = [resampled(s, beams) for s in scans]
    mount = log.frames.mount if log.frames.mount_source is not None else None
    odometry = None
    if all(s.odometry is not None for s in scans):
        inverse = (mount or Pose2()).inverse()
        odometry = _Mapped(play, [s.odometry @ inverse for s in scans])  # the base's poses
    return Robot(
        [Topic(topic, log.frames.frame_id or "laser", _Mapped(play, scans))],
        _Stamps(play, stamps, scale),
        mount,
        odometry=odometry,
    )
