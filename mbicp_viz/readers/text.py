"""Text files, plain or compressed, read line by line into fields: the one parsing loop of the
text formats (CARMEN, ``.off``, plain scans, relations, CSM JSON lines).

Every error names the file, the line and the field. Reading is bounded by the file: a line longer
than ``MAX_LINE_CHARS`` is refused instead of being read whole (a file that never ends a line,
such as a link to ``/dev/zero``, would otherwise fill the memory).
"""

from __future__ import annotations

import bz2
import gzip
import io
import lzma
import math
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from mbicp_viz.errors import InputError

# A CARMEN line of 100 000 readings is under 1 MB; nothing real comes near this.
MAX_LINE_CHARS = 8_000_000
_MAGIC = ((b"\x1f\x8b", gzip.open), (b"BZh", bz2.open), (b"\xfd7zXZ\x00", lzma.open))
# What a damaged compressed stream raises while it is read.
_CORRUPT = (OSError, EOFError, zlib.error, lzma.LZMAError)


@contextmanager
def opening(path):
    """The ways a file cannot be opened, each as one InputError naming it."""
    try:
        yield
    except FileNotFoundError:
        raise InputError("no such file", str(path)) from None
    except IsADirectoryError:
        raise InputError("is a folder, not a file", str(path)) from None
    except PermissionError:
        raise InputError("permission denied", str(path)) from None


@contextmanager
def open_binary(path: str):
    """A file's bytes, decompressed when it starts with a gzip, bzip2 or xz header."""
    with opening(path):
        with open(path, "rb") as raw:
            magic = raw.read(6)
        opener = next((op for m, op in _MAGIC if magic.startswith(m)), open)
        stream = opener(path, "rb")
    with stream:
        try:
            yield stream
        except InputError:
            raise
        except _CORRUPT as e:
            raise InputError(
                f"cannot read: damaged or truncated data ({type(e).__name__}: {e})", str(path)
            ) from None


@contextmanager
def open_text(path: str):
    """A text stream (UTF-8) over ``open_binary``; decoding errors are InputErrors."""
    with open_binary(path) as stream:
        text = io.TextIOWrapper(stream, encoding="utf-8", errors="strict")
        try:
            yield text
        except UnicodeDecodeError as e:
            raise InputError(f"not UTF-8 text ({e.reason})", str(path)) from None


@dataclass(frozen=True)
class Line:
    number: int  # 1-based
    text: str  # without the line break


def lines(stream, path: str) -> Iterator[Line]:
    """The lines of a text stream, each at most ``MAX_LINE_CHARS`` long.

    A last line without a line break is refused: a file cut short ends mid-record, and a record
    whose length the format does not store (a ``.off`` scan, a plain scan line) would otherwise
    be read shortened without a word.
    """
    number = 0
    while True:
        text = stream.readline(MAX_LINE_CHARS + 1)
        if not text:
            return
        number += 1
        if len(text) > MAX_LINE_CHARS:
            raise InputError(f"line longer than {MAX_LINE_CHARS} characters", path, number)
        if not text.endswith("\n"):
            if text.strip():
                raise InputError(
                    "the file ends in the middle of this line (cut short?); a complete file ends "
                    "with a line break",
                    path,
                    number,
                )
            return
        yield Line(number, text.rstrip("\r\n"))


def token_lines(path: str, comment: str | None = "#") -> Iterator[Fields]:
    """``Fields`` of every line of a text file that has tokens once ``comment`` and what follows
    are cut."""
    with open_text(path) as f:
        for line in lines(f, path):
            text = line.text.split(comment, 1)[0] if comment else line.text
            tokens = text.split()
            if tokens:
                yield Fields(tokens, path, line.number)


def parse_float(token: str) -> float | None:
    try:
        return float(token)
    except ValueError:
        return None


class Fields:
    """The tokens of one record, read left to right; errors name the file, line and field.

    ``end()`` checks that the record holds exactly the fields its layout announces: a count that
    disagrees with the fields after it would otherwise shift every later field into the wrong one.
    """

    def __init__(self, tokens: list[str], path: str, line: int, start: int = 0):
        self.t, self.i, self.path, self.line = tokens, start, path, line

    def error(self, message: str, field: str | None = None) -> InputError:
        return InputError(message, self.path, self.line, field)

    @property
    def left(self) -> int:
        return len(self.t) - self.i

    def take_token(self, name: str) -> str:
        if self.i >= len(self.t):
            raise self.error(f"the record ends before this field ({len(self.t)} fields)", name)
        self.i += 1
        return self.t[self.i - 1]

    def take(self, name: str, finite: bool = True) -> float:
        tok = self.take_token(name)
        v = parse_float(tok)
        if v is None:
            raise self.error(f"expected a number, got {tok[:40]!r}", name)
        if finite and not math.isfinite(v):
            raise self.error(f"not a finite number: {tok[:40]!r}", name)
        return v

    def take_int(self, name: str, lo: int = 0, hi: int = 10**9) -> int:
        tok = self.take_token(name)
        try:
            v = int(tok)
        except ValueError:
            raise self.error(f"expected a whole number, got {tok[:40]!r}", name) from None
        if not lo <= v <= hi:
            raise self.error(f"{v} is out of range {lo}..{hi}", name)
        return v

    def take_floats(self, n: int, name: str, count_field: str | None = None) -> np.ndarray:
        """``n`` numbers (NaN and inf allowed: readings with no return); ``count_field`` names the
        field that announced ``n``, blamed when fewer fields follow."""
        if self.left < n:
            raise self.error(
                f"{n} {name}s announced but only {self.left} fields follow", count_field or name
            )
        toks = self.t[self.i : self.i + n]
        try:
            values = np.array(toks, dtype=float)
        except ValueError:
            k = next(k for k, tok in enumerate(toks) if parse_float(tok) is None)
            raise self.error(f"expected a number, got {toks[k][:40]!r}", f"{name}[{k}]") from None
        self.i += n
        return values

    def skip(self, n: int, name: str) -> None:
        if self.left < n:
            raise self.error(f"{n} values announced but only {self.left} fields follow", name)
        self.i += n

    def end(self, layout: str) -> None:
        if self.left:
            raise self.error(
                f"{self.left} more field(s) than the layout '{layout}' holds: the record's counts "
                "disagree with its fields",
                "fields",
            )
