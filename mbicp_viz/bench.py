"""``bench``: time per match on consecutive pairs of a log, events off and with a recording observer."""

from __future__ import annotations

import platform
import time
from dataclasses import dataclass

import numpy as np

from core import Params, Recorder, match

from .inputs import consecutive_pairs, stored_guess
from .readers import ScanLog


@dataclass(frozen=True)
class Timing:
    label: str
    times_ms: np.ndarray
    what: str = "matches"

    @property
    def median(self) -> float:
        return float(np.median(self.times_ms))

    @property
    def p90(self) -> float:
        return float(np.percentile(self.times_ms, 90))

    def line(self) -> str:
        return (f"{self.label:<22} median {self.median:7.2f} ms   p90 {self.p90:7.2f} ms   "
                f"p95 {np.percentile(self.times_ms, 95):7.2f} ms   "
                f"{1000.0 / self.median:8.1f} {self.what}/s   ({len(self.times_ms)} {self.what})")


def time_matches(log: ScanLog, params: Params, pairs, observe: bool, repeat: int) -> np.ndarray:
    out = []
    for i, j in pairs:
        ref, obj = log.scans[i], log.scans[j]
        guess, _ = stored_guess(ref, obj)
        for _ in range(repeat):
            obs = Recorder() if observe else None
            t0 = time.perf_counter()
            match(ref, obj, guess, params, obs)
            out.append(1000.0 * (time.perf_counter() - t0))
    return np.array(out)


def bench(log: ScanLog, params: Params, limit: int | None, repeat: int) -> list[Timing]:
    pairs = consecutive_pairs(log, limit)
    time_matches(log, params, pairs[:3], False, 1)  # warm caches and imports
    return [Timing("events off", time_matches(log, params, pairs, False, repeat)),
            Timing("recording observer", time_matches(log, params, pairs, True, repeat))]


def machine_line() -> str:
    import os

    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def speed_probe_us() -> float:
    """Time of a fixed small numpy workload [us] (best of several): how fast the machine runs right
    now. Shared virtual machines drift by tens of percent from one minute to the next; printed
    beside a benchmark, it tells a slow minute from a slow matcher."""
    import timeit

    a = np.random.default_rng(0).normal(size=300)
    return 1e6 * min(timeit.repeat(lambda: np.sort(a) + np.arctan2(a, a), number=2000, repeat=5)) / 2000


def time_recordings(log: ScanLog, params: Params, limit: int | None, repeat: int, teaching: bool):
    """Time for matching and writing each pair to an .rrd (rerun front end), and the file sizes [bytes]."""
    import os
    import tempfile

    from .rrd import Run, record

    pairs = consecutive_pairs(log, limit)
    times, sizes = [], []
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "bench.rrd")
        for i, j in pairs:
            ref, obj = log.scans[i], log.scans[j]
            guess, _ = stored_guess(ref, obj)
            for _ in range(repeat):
                t0 = time.perf_counter()
                record([Run("bench", ref, obj, guess, params)], path, teaching=teaching)
                times.append(1000.0 * (time.perf_counter() - t0))
                sizes.append(os.path.getsize(path))
    return Timing("recording to .rrd", np.array(times)), np.array(sizes)


def gui_latency(path: str, pair: tuple[int, int], steps: int = 3, changes: int = 40):
    """Server-side latency of the viser debugger on a real pair: iteration step -> redraw, and
    parameter change -> re-match -> redraw (a real ViserServer; no browser attached)."""
    import viser

    from core import Pose2

    from .readers import read_log
    from .viser_app import Session, Source

    log = read_log(path)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        s = Session(server, Source(path, log, pair=pair, guess=Pose2()))
        step_ms = []
        for _ in range(steps):
            for k in range(s.max_iteration() + 1):
                t0 = time.perf_counter()
                s.h_iter.value = k
                step_ms.append(1000.0 * (time.perf_counter() - t0))
        change_ms = []
        values = np.linspace(0.5, 1.5, changes)  # the radial window Br [m], a value a user drags
        for v in values:
            t0 = time.perf_counter()
            s.set_param("improved", "Br", float(v))
            change_ms.append(1000.0 * (time.perf_counter() - t0))
        return (Timing("iteration step redraw", np.array(step_ms), "steps"),
                Timing("parameter change", np.array(change_ms), "changes"))
    finally:
        server.stop()
