"""Long evaluations spread over the machine's cores, interruptible without losing finished work.

Ctrl-C only sets a flag, read between two jobs (``stopping``): a KeyboardInterrupt raised inside a
compiled loop surfaces as numba's ``SystemError`` and loses the run, and one raised while a pool
shuts down leaves its workers behind. Every press is taken alike, so pressing it again does not
break the clean stop the first one started.
"""

from __future__ import annotations

import _thread
import itertools
import multiprocessing
import os
import signal
import sys
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager

POLL_S = 0.1  # how often a waiting parent looks at the flag: a stop takes effect within this
IN_FLIGHT_PER_WORKER = 3  # chunks sent ahead per worker: each busy while the parent takes results
# Jobs a chunk holds at most: each chunk wakes the parent's threads, which, with every core busy
# matching, run cold and take a worker's core. On two cores at 1081 beams (``bench throughput``'s
# run in memory, 4000 pairs, two alternations) chunks of 16 pairs cost the parent 0.135-0.155 ms
# of CPU a pair and scaled 1.48-1.50x; of 64, 0.094-0.100 ms and 1.62-1.68x; of 128, 0.08 ms and
# 1.56-1.60x. At ~1.4 ms a pair 64 are a tenth of a second of a worker's time: a Ctrl-C drops
# about half a second of the run's work (the chunks under way).
CHUNK_MAX = 64
# Set by Ctrl-C during a run: the run stops; within ``one_command`` later runs start no job (a
# command that runs several, one per matcher, ends instead of going on with the next).
INTERRUPTED = threading.Event()
_IN_COMMAND = threading.Event()
_TAKEN = threading.Event()  # the last Ctrl-C raised was taken by a handler
INSIST_S = 0.5  # a Ctrl-C not taken by then is raised again (``_insist``)


@contextmanager
def one_command() -> Iterator[threading.Event]:
    """A command's runs: a Ctrl-C during one stops the others too; yields ``INTERRUPTED``.
    Outside, every run starts afresh (a script calling the evaluations). In the main thread a
    Ctrl-C outside any run is a KeyboardInterrupt raised until something takes it (``_insist``)."""
    INTERRUPTED.clear()
    _IN_COMMAND.set()
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, _interrupt) if main else None
    try:
        yield INTERRUPTED
    finally:
        _IN_COMMAND.clear()
        _TAKEN.set()  # the command has ended: nothing to raise again, in it or in the next
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _interrupt(signum, frame) -> None:
    _TAKEN.clear()
    _insist_later()
    raise KeyboardInterrupt


def _insist_later() -> None:
    timer = threading.Timer(INSIST_S, _insist)
    timer.daemon = True
    timer.start()


def _insist() -> None:
    """A Ctrl-C nobody took is raised again: C code can swallow a KeyboardInterrupt raised inside
    it (an extension module's initialisation, as a lazy ``import numpy.random`` runs it), and the
    command then ran on to its end as if never interrupted. While the main thread still handles
    the interrupt (an ``except`` or ``finally`` on its way out) it is left to finish."""
    if _TAKEN.is_set() or not _IN_COMMAND.is_set():
        return
    handling = sys._current_exceptions().get(threading.main_thread().ident)
    if isinstance(handling, tuple):  # Python 3.11 gives exc_info's triple
        handling = handling[1]
    if from_interrupt(handling):
        _insist_later()
    else:
        _thread.interrupt_main()


def interrupt_taken() -> None:
    """A handler has taken the Ctrl-C (it stops the command its own way): not raised again."""
    _TAKEN.set()


def from_interrupt(e: BaseException | None) -> bool:
    """Whether a KeyboardInterrupt is ``e`` or among its causes (numba's SystemError: an
    interrupt inside compiled code)."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def ignore_interrupts() -> None:
    # Ctrl-C reaches every process of the terminal's group: only the parent should react to it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextmanager
def stopping(flag: threading.Event | None = None) -> Iterator[threading.Event]:
    """Within the block Ctrl-C sets ``flag`` (``INTERRUPTED`` by default) instead of raising;
    outside the main thread, where no handler can be set, the flag is only the caller's."""
    flag = flag if flag is not None else INTERRUPTED
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    previous = signal.signal(signal.SIGINT, lambda *_: flag.set())
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, previous)


def _chunk(job: tuple[Callable, list]) -> list:
    fn, jobs = job
    return [fn(j) for j in jobs]


def _chunks(jobs: Iterable, size: int) -> Iterator[list]:
    it = iter(jobs)
    while chunk := list(itertools.islice(it, size)):
        yield chunk


def chunk_size(total: int | None, workers: int) -> int:
    """Jobs a chunk sent to a worker holds: at least eight chunks per worker (a run's last chunks
    keep every core busy), at most ``CHUNK_MAX``."""
    return max(1, min(CHUNK_MAX, (total or CHUNK_MAX * 8 * workers) // (8 * workers)))


def ordered_map(
    fn: Callable,
    jobs: Iterable,
    workers: int | None = None,
    on_result: Callable | None = None,
    total: int | None = None,
    keep: bool = True,
) -> list:
    """``[fn(job) for job in jobs]``, in order, over ``workers`` processes (default: every core).

    ``jobs`` may be a generator (its ``total`` length, when known, sizes the chunks sent to a
    worker): a few chunks per worker are under way at a time, so a long run's jobs are made as
    they are needed, never all at once. ``on_result`` sees each result as it arrives (progress);
    without ``keep`` it alone takes them, none is kept and ``[]`` returned (a run of any length).
    Ctrl-C stops the run within one job (one process) or ``POLL_S`` (a pool, whose workers are
    ended) and returns the results finished so far, in order; ``fn`` and the jobs must pickle
    (module-level function, plain data).
    """
    workers = workers or os.cpu_count() or 1
    total = len(jobs) if total is None and hasattr(jobs, "__len__") else total
    out: list = []

    def take(r) -> None:
        if keep:
            out.append(r)
        if on_result is not None:
            on_result(r)

    if not _IN_COMMAND.is_set():
        INTERRUPTED.clear()
    with stopping() as stop:
        if stop.is_set():  # an earlier run of this command was stopped
            return out
        if workers == 1 or total is not None and total <= 1:
            for job in jobs:
                if stop.is_set():
                    break
                try:
                    take(fn(job))
                except KeyboardInterrupt:  # raised by the job itself (a handler of its own)
                    interrupt_taken()
                    stop.set()
                    break
            return out
        chunks = _chunks(jobs, chunk_size(total, workers))
        pool = multiprocessing.get_context().Pool(workers, initializer=ignore_interrupts)
        under_way: deque = deque()

        def send() -> None:
            chunk = next(chunks, None)
            if chunk is not None:
                under_way.append(pool.apply_async(_chunk, ((fn, chunk),)))

        try:
            for _ in range(IN_FLIGHT_PER_WORKER * workers):
                send()
            while under_way and not stop.is_set():
                try:
                    results = under_way[0].get(timeout=POLL_S)
                except multiprocessing.TimeoutError:
                    continue
                under_way.popleft()
                send()
                for r in results:
                    take(r)
        finally:
            pool.terminate()  # a stop ends the jobs under way; their results are not waited for
            pool.join()
    return out
