"""Errors of the core and where a scan came from (no numpy: the command line imports these at
once)."""

from __future__ import annotations

from dataclasses import dataclass


class ScanError(ValueError):
    """A scan that cannot be matched (empty, all invalid, inconsistent arrays)."""

    def __init__(self, source: ScanSource, reason: str):
        super().__init__(f"{source}: {reason}")
        self.source, self.reason = source, reason

    def __reduce__(self):  # worker processes send errors back pickled; keep the arguments
        return type(self), (self.source, self.reason)


class UnusableScan(ScanError):
    """A well-formed scan with nothing to match: no beams, or no valid reading. A log skips it."""


@dataclass(frozen=True)
class ScanSource:
    """Where a scan came from, so every message can name it."""

    path: str = "<memory>"
    index: int = 0
    line: int | None = None

    def __str__(self) -> str:
        where = f"{self.path}: scan {self.index}"
        return f"{where} (line {self.line})" if self.line is not None else where
