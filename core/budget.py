"""A match's time budget, and a stop a person can press while it runs.

numba has no clock in nopython mode, so the compiled loops cannot watch the time themselves:
they read a one-byte flag at the end of every iteration and stop when it is raised. A timer
thread raises it when the budget is used up, a front end when a person presses stop; the kernels
release the GIL (``core/tiers.kernel``) so that thread runs while they do. A stopped match keeps
the estimate of its last finished iteration and ends ``Termination.HALTED``. One watchdog thread per
process keeps every budget under way (a thread started per match cost a millisecond, as much as a
1081-beam match's own work).

The budget is a property of where a match runs (a debugger tab, a command), not of the matcher's
parameters: like numpy's ``errstate`` it is set around the calls, for this thread.
"""

from __future__ import annotations

import heapq
import itertools
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Halt:
    """The flag the loops read, and why it was raised."""

    flag: np.ndarray = field(default_factory=lambda: np.zeros(1, np.uint8))
    why: str = ""

    def stop(self, why: str) -> None:
        if not self.flag[0]:
            self.why = why
            self.flag[0] = 1

    @property
    def raised(self) -> bool:
        return bool(self.flag[0])


_HERE = threading.local()


def current() -> Halt:
    """The halt of the budget around this call (a never-raised one outside any)."""
    halt = getattr(_HERE, "halt", None)
    return halt if halt is not None else Halt()


class _Watchdog:
    """Raises each halt at its deadline: one thread, sleeping until the earliest one."""

    def __init__(self):
        self.pid = os.getpid()
        self.cv = threading.Condition()
        self.heap: list[list] = []  # [deadline, order, halt, why, live]
        self.order = itertools.count()
        threading.Thread(target=self._run, name="mbicp-viz budgets", daemon=True).start()

    def add(self, seconds: float, halt: Halt, why: str) -> list:
        entry = [time.monotonic() + seconds, next(self.order), halt, why, True]
        with self.cv:
            heapq.heappush(self.heap, entry)
            if self.heap[0] is entry:
                self.cv.notify()
        return entry

    def _run(self) -> None:
        with self.cv:
            while True:
                while self.heap and not self.heap[0][4]:  # budgets whose match has ended
                    heapq.heappop(self.heap)
                if not self.heap:
                    self.cv.wait()
                    continue
                wait = self.heap[0][0] - time.monotonic()
                if wait > 0:
                    self.cv.wait(wait)
                    continue
                _, _, halt, why, _ = heapq.heappop(self.heap)
                halt.stop(why)


_WATCHDOG: _Watchdog | None = None
_WATCHDOG_LOCK = threading.Lock()


def _watchdog() -> _Watchdog:
    """This process's watchdog (a forked worker starts its own: threads do not survive a fork)."""
    global _WATCHDOG
    with _WATCHDOG_LOCK:
        if _WATCHDOG is None or _WATCHDOG.pid != os.getpid():
            _WATCHDOG = _Watchdog()
        return _WATCHDOG


@contextmanager
def limited(seconds: float | None, halt: Halt | None = None) -> Iterator[Halt]:
    """Matches run in this block stop after ``seconds`` (None: no limit) or when ``halt`` is
    raised, whichever comes first."""
    halt = halt if halt is not None else Halt()
    entry = None
    if seconds is not None:
        entry = _watchdog().add(seconds, halt, f"its time budget of {seconds:g} s ran out")
    outer, _HERE.halt = getattr(_HERE, "halt", None), halt
    try:
        yield halt
    finally:
        _HERE.halt = outer
        if entry is not None:
            entry[4] = False  # the watchdog drops it when it comes to the top
