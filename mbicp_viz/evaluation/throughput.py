"""``bench throughput`` and ``bench open``: how a whole run keeps up with the robot, and how soon a
recording of any length opens.

A run's real-time factor is the recording's duration over the time ``eval sequence``'s matching
takes on it (every pair's record: the match, its covariance, overlap and signs), on one core and on
all of them. The runs are real scans played to and fro (``writers/replay.py``), resampled to each
beam count asked for, at the scan rate asked for.
"""

from __future__ import annotations

import re
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from mbicp_viz.core import Params
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ScanLog

from .bench import run_measured


@dataclass(frozen=True)
class Throughput:
    beams: int
    pairs: int
    seconds: float  # the recording's duration over the pairs matched
    walls_s: dict[int, list[float]]  # workers -> wall time of each run
    # the most workers' share of the pairs matched in as many processes at once, each on its own
    # (``apart``): the time of the slowest, per run
    apart_s: list[float] = field(default_factory=list)
    what: str = "matched in memory"  # what was timed

    @property
    def wall_s(self) -> dict[int, float]:
        """Workers -> the median wall time of their runs."""
        return {w: statistics.median(t) for w, t in self.walls_s.items()}

    def line(self) -> str:
        wall = self.wall_s
        one = wall[1]
        runs = len(self.walls_s[1])
        cells = [
            f"{self.beams:5d} beams  {self.pairs} pairs over {self.seconds:.1f} s, {self.what}"
            + (f" (median of {runs} runs)" if runs > 1 else ""),
            f"{1000.0 * one / self.pairs:6.2f} ms/pair on 1 core",
        ]
        for w, t in sorted(wall.items()):
            cells.append(f"{self.seconds / t:6.1f}x real time on {w} core{'s' * (w > 1)}")
        if len(wall) > 1:
            most = max(wall)
            cells.append(f"scaling {one / wall[most]:.2f}x on {most}")
            if self.apart_s:
                alone = one / statistics.median(self.apart_s)
                cells.append(f"(separate processes, nothing shared: {alone:.2f}x)")
        return "   ".join(cells)


def _robot(log: ScanLog, pairs: int, beams: int, rate_hz: float):
    """A robot driving to and fro along ``log``: ``pairs + 1`` scans resampled to ``beams``, at
    ``rate_hz`` (``writers/replay.py``)."""
    from mbicp_viz.writers.replay import replayed

    return replayed(log, (pairs + 1) / rate_hz, beams, rate_hz)


def replay_log(log: ScanLog, pairs: int, beams: int, rate_hz: float) -> ScanLog:
    """``pairs + 1`` scans of ``log`` played to and fro, resampled to ``beams``, at ``rate_hz``."""
    robot = _robot(log, pairs, beams, rate_hz)
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
    speed (15 % within minutes here) falls on each alike. With several workers, each run also
    times the pairs split between as many separate processes (``apart``): how far the cores
    themselves scale, whatever the run's pool does."""
    from mbicp_viz.core.warmup import load_kernels

    from .sequence import match_sequence

    run = replay_log(log, pairs, beams, rate_hz)
    load_kernels(params)  # start-up, out of the timed runs (forked workers share them)
    walls: dict[int, list[float]] = {w: [] for w in workers}
    most, apart_s = max(workers), []
    for _ in range(repeat):
        for w in workers:
            fresh = _fresh(run)
            t0 = time.perf_counter()
            rows = match_sequence(fresh, params, workers=w)
            walls[w].append(time.perf_counter() - t0)
            _raise_if_stopped()
            assert len(rows) == pairs
        if most > 1:
            apart_s.append(apart(run, params, most))
    seconds = run.scans[-1].stamp - run.scans[0].stamp
    return Throughput(beams, pairs, seconds, walls, apart_s)


def apart(run: ScanLog, params: Params, n: int) -> float:
    """The time ``n`` processes take to match the run's pairs split into ``n`` consecutive shares,
    all at once, each on its own (no parent sends them scans or takes their rows): the slowest
    one's time, from when each has its share. What ``n`` cores give to a run that needs nothing
    of the others; a pool's scaling below it is the pool's, at it the machine's."""
    from .pool import ordered_map

    times = ordered_map(_timed_run, [(s, params) for s in split(run, n)], workers=n)
    _raise_if_stopped()
    return max(times)


def _raise_if_stopped() -> None:
    """A run Ctrl-C stopped kept what it had finished (``pool.ordered_map``); a timing of a part
    of it would be wrong, so the bench ends as any command Ctrl-C stops."""
    from .pool import INTERRUPTED

    if INTERRUPTED.is_set():
        raise KeyboardInterrupt


def split(run: ScanLog, n: int) -> list[ScanLog]:
    """The run's consecutive pairs in ``n`` runs of consecutive scans, each pair in one of them
    (a share's last scan is the next one's first)."""
    cut = [round(k * (len(run.scans) - 1) / n) for k in range(n + 1)]
    return [replace(run, scans=run.scans[a : b + 1]) for a, b in zip(cut, cut[1:])]


def _timed_run(job: tuple[ScanLog, Params]) -> float:
    from .sequence import match_sequence

    share, params = job
    t0 = time.perf_counter()
    match_sequence(share, params, workers=1)
    return time.perf_counter() - t0


def from_bag(
    log: ScanLog,
    cli_params: list[str],
    beams: int,
    pairs: int,
    rate_hz: float,
    workers: list[int],
    repeat: int = 1,
) -> Throughput:
    """``eval sequence`` itself on a ROS 1 bag written from the run ``throughput`` replays: each
    run a process of its own (``--algo``/``--params`` as ``cli_params`` say), reading the bag
    through its index and writing its rows as it goes; its time is the pace it prints, from
    finding its pairs to its rows written whole. What a person running it on a recording gets."""
    import tempfile

    from mbicp_viz.writers.bag import write

    robot = _robot(log, pairs, beams, rate_hz)
    walls: dict[int, list[float]] = {w: [] for w in workers}
    with tempfile.TemporaryDirectory(prefix="mbicp-viz-bench-") as tmp:
        bag = write(Path(tmp) / "run.bag", robot, "ros1")
        for k in range(repeat):
            for w in workers:
                rows = Path(tmp) / f"rows-{k}-{w}.jsonl"
                walls[w].append(pairs / eval_sequence_rate(bag, pairs, w, cli_params, rows))
    seconds = float(robot.stamps[pairs] - robot.stamps[0])
    return Throughput(beams, pairs, seconds, walls, what="eval sequence on a ROS 1 bag")


def eval_sequence_rate(bag: Path, pairs: int, workers: int, cli_params: list[str], out: Path):
    """The pairs a second ``mbicp-viz eval sequence`` prints for the first ``pairs`` of ``bag``."""
    args = [sys.executable, "-m", "mbicp_viz", "eval", "sequence", str(bag), "--limit", str(pairs)]
    args += ["--workers", str(workers), "--out", str(out), *cli_params]
    done = subprocess.run(args, capture_output=True, text=True, check=False)
    pace = re.search(r"(\d+) pairs matched in [\d.]+ s \(([\d.]+)/s", done.stderr)
    if done.returncode != 0 or pace is None or int(pace[1]) != pairs:
        said = done.stderr.strip().splitlines() or ["nothing said"]
        raise InputError(f"eval sequence on the bench's bag failed: {said[-1]}")
    return float(pace[2])


def _fresh(log: ScanLog) -> ScanLog:
    """``log`` with new scan objects: a scan keeps its points once computed (``Scan.points``), and
    a run of a recording meets each scan anew."""
    return replace(log, scans=[replace(s) for s in log.scans])


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
    """Each a fresh process, best of ``repeat``: ``match PATH --pair I J`` to its end, and the
    debugger on ``PATH`` from its launch to its first tab's result."""
    exe = [sys.executable, "-m", "mbicp_viz"]
    match = exe + ["match", path, "--pair", str(pair[0]), str(pair[1]), "--json"]
    match += ["--topic", topic] if topic is not None else []
    debugger = [
        sys.executable,
        "-c",
        "from mbicp_viz.views.debugger.latency import first_result_at; "
        f"print(first_result_at({path!r}, {pair!r}, {topic!r}))",
    ]
    out = []
    for label, args in (
        (f"match --pair {pair[0]} {pair[1]}", match),
        ("debugger first result", debugger),
    ):
        runs = [run_measured(args, until_printed=args is debugger) for _ in range(repeat)]
        out.append(Opening(label, min(w for w, _ in runs), max(m for _, m in runs)))
    return out
