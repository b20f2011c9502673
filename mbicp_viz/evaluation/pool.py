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
import multiprocessing.connection
import os
import queue
import signal
import sys
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager

POLL_S = 0.1  # how often a waiting parent looks at the flag: a stop takes effect within this
# Chunks sent and not yet taken, per worker: each has the next while the parent takes results
IN_FLIGHT_PER_WORKER = 3
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


def _serve(fn: Callable, tasks, results, parents_ends: list) -> None:
    """A worker's life: run ``fn`` on every job of each chunk received, send back the results (or
    the exception, which the parent raises as a run on one process would). ``parents_ends`` are
    the parent's ends of this worker's pipes and of those before it, which a fork copied: held
    here, they would keep the pipes open when the parent dies."""
    ignore_interrupts()
    for end in parents_ends:
        end.close()
    while True:
        try:
            jobs = tasks.recv()
        except EOFError:  # the parent is gone (killed): nothing is left to do
            return
        try:
            out = (True, [fn(j) for j in jobs])
        except Exception as e:
            out = (False, e)
        try:
            results.send(out)
        except OSError:  # the parent is gone (killed)
            return
        except Exception as e:  # pickling failed: nothing of it was sent
            results.send((False, RuntimeError(f"a worker could not send its result back: {e!r}")))


class _Worker:
    """One process running ``fn`` on the chunks sent through its own pipe, and a thread sending
    them: a chunk of scans outgrows the pipe, and the parent must go on taking results meanwhile.

    Ended by killing its process, whose pipe then breaks under the sending thread: nothing waits
    on anything that can no longer come. ``multiprocessing.Pool.terminate`` cannot promise that:
    its task thread, caught writing a chunk just as the pool stops, waits forever on a pipe no
    worker reads any more, and ``terminate`` waits on that thread (CPython issues 73945 and 96995;
    a Ctrl-C hung a run that way)."""

    def __init__(self, ctx, fn: Callable, before: list[_Worker]):
        tasks_in, self._tasks = ctx.Pipe(duplex=False)
        self.results, results_out = ctx.Pipe(duplex=False)
        ends = [e for w in (*before, self) for e in (w._tasks, w.results)]
        args = (fn, tasks_in, results_out, ends)
        self.process = ctx.Process(target=_serve, args=args, daemon=True)
        self.process.start()
        # The worker's ends, closed here (before the next worker is forked): each pipe has one
        # process at either end, so either's death is seen at once by the other, as a closed pipe.
        tasks_in.close()
        results_out.close()
        self.held: deque[int] = deque()  # numbers of the chunks sent it, in the order they return
        self._outbox: queue.SimpleQueue = queue.SimpleQueue()
        self._sender = threading.Thread(target=self._send_all, daemon=True)

    def start_sending(self) -> None:
        # once every worker is forked: a fork copies the locks a running thread may hold, held
        # for ever in the child
        self._sender.start()

    def _send_all(self) -> None:
        while (chunk := self._outbox.get()) is not None:
            try:
                self._tasks.send(chunk)
            except OSError:  # the worker was ended
                return

    def send(self, number: int, chunk: list) -> None:
        self.held.append(number)
        self._outbox.put(chunk)

    def take(self) -> tuple[int, tuple[bool, list | Exception]]:
        """The number of the oldest chunk sent, with its results (True, [...]) or the exception
        a job raised (False, e), once they have arrived."""
        try:
            outcome = self.results.recv()
        except EOFError:  # killed (out of memory?): never a result of the run, never a hang
            self.process.join(1.0)
            code = self.process.exitcode
            raise RuntimeError(f"a worker process ended in a run (exit code {code})") from None
        return self.held.popleft(), outcome

    def end(self) -> None:
        self.process.terminate()  # signals the sender's blocked write (EPIPE) too
        self.process.join()
        self._outbox.put(None)
        if self._sender.is_alive():
            self._sender.join()
        self._tasks.close()
        self.results.close()


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
        pool: list[_Worker] = []
        finished: dict[int, tuple] = {}  # chunks that came back before an earlier one
        first, sent = 0, 0  # numbers of the next chunk whose results are taken, and to be sent

        def send_more() -> None:
            """Chunks to the least busy workers, up to ``IN_FLIGHT_PER_WORKER`` each on average
            counted from the oldest not yet taken: jobs are made as they are needed, and a worker
            slow on one chunk holds back no more results than that."""
            nonlocal sent
            while sent - first < IN_FLIGHT_PER_WORKER * workers:
                chunk = next(chunks, None)
                if chunk is None:
                    return
                min(pool, key=lambda w: len(w.held)).send(sent, chunk)
                sent += 1

        try:
            ctx = multiprocessing.get_context()
            for _ in range(workers):
                pool.append(_Worker(ctx, fn, pool))
            for w in pool:
                w.start_sending()
            send_more()
            by_pipe = {w.results: w for w in pool}
            while not stop.is_set() and (busy := [w.results for w in pool if w.held]):
                for pipe in multiprocessing.connection.wait(busy, timeout=POLL_S):
                    number, outcome = by_pipe[pipe].take()
                    finished[number] = outcome
                while first in finished:  # what has come back in order is kept, stopped or not
                    ok, results = finished.pop(first)
                    if not ok:  # the first error in the jobs' order, as one process meets it
                        raise results
                    for r in results:
                        take(r)
                    first += 1
                if not stop.is_set():
                    send_more()
        finally:
            for w in pool:  # a stop ends the jobs under way; their results are not waited for
                w.end()
    return out
