"""``bench throughput`` and ``bench open``: how a whole run keeps up with the robot, and how soon a
recording of any length opens.

A run's real-time factor is the recording's duration over the time ``eval sequence``'s matching
takes on it (every pair's record: the match, its covariance, overlap and signs), on one core and on
all of them. The runs are real scans played to and fro (``writers/replay.py``), resampled to each
beam count asked for, at the scan rate asked for.
"""

from __future__ import annotations

import statistics
import sys
import time
from dataclasses import dataclass, replace

from mbicp_viz.core import Params
from mbicp_viz.readers import ScanLog

from .bench import run_measured


@dataclass(frozen=True)
class Throughput:
    beams: int
    pairs: int
    seconds: float  # the recording's duration over the pairs matched
    walls_s: dict[int, list[float]]  # workers -> wall time of each run

    @property
    def wall_s(self) -> dict[int, float]:
        """Workers -> the median wall time of their runs."""
        return {w: statistics.median(t) for w, t in self.walls_s.items()}

    def line(self) -> str:
        wall = self.wall_s
        one = wall[1]
        runs = len(self.walls_s[1])
        cells = [
            f"{self.beams:5d} beams  {self.pairs} pairs over {self.seconds:.1f} s"
            + (f" (median of {runs} runs)" if runs > 1 else ""),
            f"{1000.0 * one / self.pairs:6.2f} ms/pair on 1 core",
        ]
        for w, t in sorted(wall.items()):
            cells.append(f"{self.seconds / t:6.1f}x real time on {w} core{'s' * (w > 1)}")
        if len(wall) > 1:
            most = max(wall)
            cells.append(f"scaling {one / wall[most]:.2f}x on {most}")
        return "   ".join(cells)


def replay_log(log: ScanLog, pairs: int, beams: int, rate_hz: float) -> ScanLog:
    """``pairs + 1`` scans of ``log`` played to and fro, resampled to ``beams``, at ``rate_hz``."""
    from mbicp_viz.writers.replay import replayed

    robot = replayed(log, (pairs + 1) / rate_hz, beams, rate_hz)
    scans, stamps = robot.topics[0].scans, robot.stamps
    mount = robot.mount
    odometry = robot.odometry
    out = []
    for k in range(pairs + 1):
        laser = None if odometry is None else odometry[k] @ mount if mount else odometry[k]
        out.append(replace(scans[k], stamp=stamps[k], odometry=laser, pose=None))
    return ScanLog(f"{log.path} at {beams} beams, {rate_hz:g} Hz", out, frames=log.frames)


def throughput(
    log: ScanLog,
    params: Params,
    beams: int,
    pairs: int,
    rate_hz: float,
    workers: list[int],
    repeat: int = 1,
) -> Throughput:
    """The wall time of matching ``pairs`` consecutive pairs of the replayed run, per count of
    ``workers``, ``repeat`` times: the counts alternate run by run, so a drift in the machine's
    speed (15 % within minutes here) falls on each alike."""
    from .sequence import match_sequence

    run = replay_log(log, pairs, beams, rate_hz)
    match_sequence(run, params, limit=3, workers=1)  # kernels loaded (forked workers share them)
    walls: dict[int, list[float]] = {w: [] for w in workers}
    for _ in range(repeat):
        for w in workers:
            t0 = time.perf_counter()
            rows = match_sequence(run, params, workers=w)
            walls[w].append(time.perf_counter() - t0)
            assert len(rows) == pairs
    seconds = run.scans[-1].stamp - run.scans[0].stamp
    return Throughput(beams, pairs, seconds, walls)


@dataclass(frozen=True)
class Opening:
    label: str
    wall_s: float
    peak_mb: float

    def line(self) -> str:
        return f"{self.label:<34} {self.wall_s:6.2f} s   peak RSS {self.peak_mb:6.0f} MB"


def opening(
    path: str, pair: tuple[int, int], repeat: int, topic: str | None = None
) -> list[Opening]:
    """Each a fresh process, best of ``repeat``: ``match PATH --pair I J``, and the debugger on
    ``PATH`` to its first tab's result."""
    exe = [sys.executable, "-m", "mbicp_viz"]
    match = exe + ["match", path, "--pair", str(pair[0]), str(pair[1]), "--json"]
    match += ["--topic", topic] if topic is not None else []
    debugger = [
        sys.executable,
        "-c",
        "from mbicp_viz.views.debugger.latency import first_result_ms; "
        f"first_result_ms({path!r}, {pair!r}, {topic!r})",
    ]
    out = []
    for label, args in (
        (f"match --pair {pair[0]} {pair[1]}", match),
        ("debugger first result", debugger),
    ):
        runs = [run_measured(args) for _ in range(repeat)]
        out.append(Opening(label, min(w for w, _ in runs), max(m for _, m in runs)))
    return out
