"""A match's time budget, and a stop a person can press while it runs.

numba has no clock in nopython mode, so the compiled loops cannot watch the time themselves:
they read a one-byte flag at the end of every iteration and stop when it is raised. A timer
thread raises it when the budget is used up, a front end when a person presses stop; the kernels
release the GIL (``core/tiers.kernel``) so that thread runs while they do. A stopped match keeps
the estimate of its last finished iteration and ends ``Termination.HALTED``.

The budget is a property of where a match runs (a debugger tab, a command), not of the matcher's
parameters: like numpy's ``errstate`` it is set around the calls, for this thread.
"""

from __future__ import annotations

import threading
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


@contextmanager
def limited(seconds: float | None, halt: Halt | None = None) -> Iterator[Halt]:
    """Matches run in this block stop after ``seconds`` (None: no limit) or when ``halt`` is
    raised, whichever comes first."""
    halt = halt if halt is not None else Halt()
    timer = None
    if seconds is not None:
        timer = threading.Timer(seconds, halt.stop, (f"its time budget of {seconds:g} s ran out",))
        timer.daemon = True
        timer.start()
    outer, _HERE.halt = getattr(_HERE, "halt", None), halt
    try:
        yield halt
    finally:
        _HERE.halt = outer
        if timer is not None:
            timer.cancel()
