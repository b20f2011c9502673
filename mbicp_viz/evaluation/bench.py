"""``bench``: time per match on consecutive pairs of a log, events off and with a recording
observer."""

from __future__ import annotations

import platform
import time
from dataclasses import dataclass

import numpy as np

from mbicp_viz.core import Params, Pose2, Recorder, match
from mbicp_viz.readers import ScanLog

from .pairs import stored_guess


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
        return (
            f"{self.label:<24} mean {np.mean(self.times_ms):7.2f} ms   median {self.median:7.2f} "
            "ms   "
            f"p90 {self.p90:7.2f} ms   "
            f"p95 {np.percentile(self.times_ms, 95):7.2f} ms   "
            f"{1000.0 / self.median:8.1f} {self.what}/s   ({len(self.times_ms)} {self.what})"
        )


def bench_guesses(
    log: ScanLog, pairs, perturb: tuple[float, float] | None, seed: int
) -> list[Pose2]:
    """The guess of each pair: the stored one, or moved uniformly within +/-perturb (metres in x
    and y, radians in theta) as the issues' comparisons with the original implementations do."""
    rng = np.random.default_rng(seed)
    out = []
    for i, j in pairs:
        g, _ = stored_guess(log.scan(i), log.scan(j))
        if perturb is not None:
            dx, dy, dth = rng.uniform(-1.0, 1.0, 3) * (perturb[0], perturb[0], perturb[1])
            g = Pose2(g.x + dx, g.y + dy, g.theta + dth)
        out.append(g)
    return out


def time_matches(
    log: ScanLog, params: Params, pairs, guesses, observe: bool, repeat: int
) -> np.ndarray:
    out = []
    for (i, j), guess in zip(pairs, guesses):
        ref, obj = log.scan(i), log.scan(j)
        for _ in range(repeat):
            obs = Recorder() if observe else None
            t0 = time.perf_counter()
            match(ref, obj, guess, params, obs)
            out.append(1000.0 * (time.perf_counter() - t0))
    return np.array(out)


def bench(
    log: ScanLog,
    params: Params,
    limit: int | None,
    repeat: int,
    perturb: tuple[float, float] | None = None,
    seed: int = 0,
) -> list[Timing]:
    pairs = log.consecutive_pairs(limit)
    guesses = bench_guesses(log, pairs, perturb, seed)
    time_matches(log, params, pairs[:3], guesses[:3], False, 1)  # warm caches and imports
    return [
        Timing("events off", time_matches(log, params, pairs, guesses, False, repeat)),
        Timing("recording observer", time_matches(log, params, pairs, guesses, True, repeat)),
    ]


def machine_line() -> str:
    import os

    return (
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}"
    )


def speed_probe_us() -> float:
    """Time of a fixed small numpy workload [us] (best of several): how fast the machine runs right
    now. Shared virtual machines drift by tens of percent from one minute to the next; printed
    beside a benchmark, it tells a slow minute from a slow matcher."""
    import timeit

    a = np.random.default_rng(0).normal(size=300)
    return (
        1e6
        * min(timeit.repeat(lambda: np.sort(a) + np.arctan2(a, a), number=2000, repeat=5))
        / 2000
    )


def probe_line(before: float, after: float) -> str:
    """The speed probe around a benchmark, in words: figures from a machine that drifted between
    the two are not to be compared."""
    return (
        f"machine speed probe    {before:.2f} us before, {after:.2f} us after (a fixed numpy "
        "workload; lower is faster)"
    )


def run_measured(
    args: list[str], env: dict | None = None, until_printed: bool = False
) -> tuple[float, float]:
    """Wall time [s] and peak resident memory [MB] of one process; an error if it fails. The time
    is from its launch to its end, or with ``until_printed`` to the ``time.monotonic()`` it printed
    last: a server's first result, which a person sees while the server goes on (its stop and the
    interpreter's exit, 0.7 s of the debugger's 2.3 s on an hour's sqlite3 bag, are no wait of
    theirs). Linux's monotonic clock is one for every process."""
    import os
    import subprocess
    import tempfile

    with tempfile.TemporaryFile() as out:
        t0 = time.monotonic()
        proc = subprocess.Popen(
            args,
            stdout=out if until_printed else subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            env=env,
        )
        _, status, usage = os.wait4(proc.pid, 0)
        took = time.monotonic() - t0
        err = proc.stderr.read().decode("utf-8", "replace")
        proc.stderr.close()
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(args)} failed: {err.strip()[-300:]}")
        if until_printed:
            out.seek(0)
            took = float(out.read().split()[-1]) - t0
    return took, usage.ru_maxrss / 1024.0


def _wait_background_compile(cache: str) -> None:
    """Until the compile that a first run started in the background (under ``cache``) has ended."""
    from pathlib import Path

    from mbicp_viz.core import tiers

    for lock in Path(cache).rglob(tiers.LOCK_NAME):
        tiers.wait_unlocked(lock)


def startup(
    commands: list[list[str]], match: list[str], debugger: list[str], repeat: int
) -> list[Timing]:
    """How soon the tool answers: ``--help`` of every command (``repeat`` runs each), the first
    match with numba's kernel cache empty (as after a fresh install: it runs interpreted while a
    background process compiles, core/tiers.py), how long that compile takes, the first match once
    cached, and the debugger's first result with an empty cache (server start, the first tab's
    match)."""
    import os
    import tempfile

    env = {k: v for k, v in os.environ.items() if k != "MBICP_VIZ_JIT"}  # the tiers a user gets
    helps = [run_measured(c)[0] for _ in range(repeat) for c in commands[:1]]
    each = [min(run_measured(c)[0] for _ in range(max(1, repeat // 3))) for c in commands[1:]]
    cold, compiled, warm, first_result = [], [], [], []
    for _ in range(max(1, repeat // 3)):
        with tempfile.TemporaryDirectory() as cache:
            t0 = time.perf_counter()
            cold.append(run_measured(match, env | {"NUMBA_CACHE_DIR": cache})[0])
            _wait_background_compile(cache)
            compiled.append(time.perf_counter() - t0)
            warm.append(run_measured(match, env | {"NUMBA_CACHE_DIR": cache})[0])
        with tempfile.TemporaryDirectory() as cache:
            first_result.append(
                run_measured(debugger, env | {"NUMBA_CACHE_DIR": cache}, until_printed=True)[0]
            )
            _wait_background_compile(cache)
    to_ms = lambda v: 1000.0 * np.array(v)  # noqa: E731
    return [
        Timing("mbicp-viz --help", to_ms(helps), "runs"),
        Timing("each command's --help", to_ms(each), "commands"),
        Timing("first match, empty cache", to_ms(cold), "runs"),
        Timing("background compile", to_ms(compiled), "runs"),
        Timing("first match, cached", to_ms(warm), "runs"),
        Timing("debugger first result", to_ms(first_result), "runs"),
    ]
