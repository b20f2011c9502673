"""Long evaluations spread over the machine's cores, interruptible without losing finished work."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor


def ignore_interrupts() -> None:
    # Ctrl-C reaches every process of the terminal's group: only the parent should react to it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def ordered_map(
    fn: Callable, jobs: list, workers: int | None = None, on_result: Callable | None = None
) -> list:
    """``[fn(job) for job in jobs]``, in order, over ``workers`` processes (default: every core).

    ``on_result`` sees each result as it arrives (progress). Ctrl-C stops the run and returns the
    results finished so far; ``fn`` and the jobs must pickle (module-level function, plain data).
    """
    workers = workers or os.cpu_count() or 1
    out: list = []
    pool = None
    try:
        if workers == 1 or len(jobs) <= 1:
            results: Iterable = map(fn, jobs)
        else:
            pool = ProcessPoolExecutor(max_workers=workers, initializer=ignore_interrupts)
            results = pool.map(fn, jobs, chunksize=max(1, min(16, len(jobs) // (8 * workers))))
        for r in results:
            out.append(r)
            if on_result is not None:
                on_result(r)
    except KeyboardInterrupt:
        pass
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
    return out
