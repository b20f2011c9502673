"""Rows files: what ``eval sequence --out`` (and ``tune``'s worst pairs) write, one JSON object per
matched pair, read back so that a pair reopens exactly as it ran (``serve LOG --rows FILE``).

Rows are JSON lines, one object per line, written as each pair finishes (``PartialRows``); files
of earlier versions, one JSON array, still read.

A row is a pair's record (``pair_match.PairMatch``): the pair (record numbers), the matcher and
every one of its parameters, the initial guess in the laser frame, and what came out. Each
object's line in the file is kept: an error names the file, the line and the field.
"""

from __future__ import annotations

import gc
import json
import os
import shutil
from array import array
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from mbicp_viz.errors import InputError
from mbicp_viz.outputs import written

from .pair_match import PairMatch, parse_pair_match
from .text import opening

MAX_FILE_BYTES = 512_000_000  # a rows file written as one JSON array is read whole
PARTIAL = ".partial"  # a stopped run's rows, beside the file they become


def parse_row(obj, path: str, line: int) -> PairMatch:
    """One row: a pair's record, of two different records of the log."""
    m = parse_pair_match(obj, path, line)
    if m.ref == m.obj:
        raise InputError(f"the same record as ref ({m.ref})", path, line, "obj")
    return m


def rows_text(rows: list[dict]) -> str:
    """Rows as JSON lines, in order."""
    return "".join(json.dumps(r) + "\n" for r in rows)


def _header(obj) -> dict | None:
    """The run a partial file's first line names, else None."""
    if isinstance(obj, dict) and len(obj) == 1 and isinstance(obj.get("partial"), dict):
        return obj["partial"]
    return None


def _decoded(line: str, path: str, n: int):
    try:
        return json.loads(line)
    except json.JSONDecodeError as e:
        raise InputError(f"invalid JSON ({e.msg}, column {e.colno})", path, n) from None
    except RecursionError:
        raise InputError("JSON nested too deeply", path, n) from None


def _lines(lines, path: str):
    """(line, its byte offset, object) for each non-empty line of JSON lines (``lines``: offset
    and text of each); a partial file's header is skipped."""
    for n, (offset, line) in enumerate(lines, 1):
        if line.strip():
            obj = _decoded(line, path, n)
            if n > 1 or _header(obj) is None:
                yield n, offset, obj


def _objects(text: str, path: str):
    """(line, object) for each element of the top-level JSON array, in order."""
    decoder, pos, line, n = json.JSONDecoder(), 0, 1, len(text)

    def skip(p: int) -> int:
        while p < n and text[p] in " \t\r\n":
            p += 1
        return p

    def line_at(p: int) -> int:
        nonlocal pos, line
        line += text.count("\n", pos, p)
        pos = p
        return line

    p = skip(0)
    if p >= n or text[p] != "[":
        raise InputError(
            "expected a JSON array of rows (the file `eval sequence --out` writes)",
            path,
            line_at(p),
        )
    p = skip(p + 1)
    if p < n and text[p] == "]":
        return
    while True:
        try:
            obj, end = decoder.raw_decode(text, p)
        except json.JSONDecodeError as e:
            raise InputError(f"invalid JSON ({e.msg}, column {e.colno})", path, e.lineno) from None
        except RecursionError:
            raise InputError("JSON nested too deeply", path, line_at(p)) from None
        yield line_at(p), obj
        p = skip(end)
        if p < n and text[p] == "]":
            if skip(p + 1) != n:
                raise InputError("text after the closing ']'", path, line_at(skip(p + 1)))
            return
        if p >= n or text[p] != ",":
            raise InputError(
                "expected ',' or ']' after a row (is the file cut short?)", path, line_at(min(p, n))
            )
        p = skip(p + 1)


@contextmanager
def gc_paused():
    """Python's cycle collector held off: reading a run makes hundreds of thousands of objects
    that all live on, and each collection would walk them again (a fifth of an hour-long run's
    reading time)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def read_rows(path: str | Path) -> list[PairMatch]:
    """Every row of a rows file, in order; an empty file or array is refused."""
    with gc_paused():
        rows = [row for _, _, row in file_rows(path)]
    if not rows:
        raise InputError("no rows", str(path))
    return rows


def file_rows(path: str | Path) -> Iterator[tuple[int, int | None, PairMatch]]:
    """(line, byte offset, row) of each row of a rows file, in order, each checked. JSON lines
    (what `eval sequence` writes) are read one line at a time, an hour-long run's hundreds of MB
    never held whole; a JSON array (as written before) is read whole, up to ``MAX_FILE_BYTES``
    (its rows have no offset: None)."""
    path = str(path)
    p = Path(path)
    with opening(p), open(p, "rb") as f:
        start = f.read(64).lstrip()
        f.seek(0)
        if start.startswith(b"["):
            if p.stat().st_size > MAX_FILE_BYTES:
                raise InputError(
                    f"larger than {MAX_FILE_BYTES // 1_000_000} MB: not a rows file", path
                )
            objects = ((n, None, obj) for n, obj in _objects(_text(f.read(), path), path))
        else:
            objects = _lines(_offset_lines(f, path), path)
        for line, offset, obj in objects:
            yield line, offset, parse_row(obj, path, line)


MAX_LINE_BYTES = 1_000_000  # a row is a few kB


def _text(data: bytes, path: str, line: int | None = None) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"not UTF-8 text ({e.reason} at byte {e.start})", path, line) from None


def _offset_lines(f, path: str):
    """(byte offset, line) of each line of an open file, decoded, each at most
    ``MAX_LINE_BYTES``."""
    offset = f.tell()
    for n, data in enumerate(iter(lambda: f.readline(MAX_LINE_BYTES + 1), b""), 1):
        if len(data) > MAX_LINE_BYTES:
            raise InputError(f"a line longer than {MAX_LINE_BYTES} bytes: not a rows file", path, n)
        yield offset, _text(data, path, n)
        offset += len(data)


def _file_lines(f, path: str):
    """The lines of an open file, decoded, each at most ``MAX_LINE_BYTES``."""
    return (line for _, line in _offset_lines(f, path))


class PartialRows:
    """A run's rows as they finish: JSON lines in ``OUT.partial`` beside ``out`` (never over a
    complete earlier file), whose first line names the run; ``finish`` writes ``out`` whole and
    removes them. A stopped or killed run leaves them, and the same run started again resumes
    from them (``rows``: a list, or what ``rows`` given is, each appended); the rows of another
    run are refused, never mixed in. ``offsets()`` says where each row is in ``out``."""

    def __init__(self, out: Path, run: dict, decode=lambda row, path, line: row, rows=None):
        self.out = Path(out)
        self.path = self.out.with_name(self.out.name + PARTIAL)
        self.run = json.loads(json.dumps(run))  # as it reads back
        # the rows a stopped run left (``decode``-d from the file, path and line) and their pairs
        self.rows = [] if rows is None else rows
        self.pairs: list[tuple] = []
        self._good = 0  # bytes of the file up to its last whole row
        self._header = 0  # bytes of its first line, naming the run
        self._offsets = array("q")  # of each row's line in the file
        if self.path.exists():
            self._resume(decode)
        self.count = len(self.rows)
        self._file = None

    def _resume(self, decode) -> None:
        """The rows of the file, read a line at a time; a last line a kill cut short (no newline,
        or not JSON) is left out, and that pair is matched again."""
        path = str(self.path)
        with opening(self.path), open(self.path, "rb") as f:
            lines = _file_lines(f, path)
            first = next(lines, "")
            theirs = _header(_decoded(first, path, 1)) if first.strip() else None
            if theirs is None:
                raise InputError(
                    "not the rows of a stopped run (no first line naming it): delete it or give "
                    "another --out",
                    path,
                    1,
                )
            for key in sorted(set(theirs) | set(self.run)):
                if theirs.get(key) != self.run.get(key):
                    raise InputError(
                        f"rows of another run ({json.dumps(theirs.get(key))[:60]}; this run: "
                        f"{json.dumps(self.run.get(key))[:60]}): delete the file to start afresh, "
                        "or give another --out",
                        path,
                        1,
                        key,
                    )
            self._good = self._header = len(first.encode())
            cut = None
            for n, line in enumerate(lines, 2):
                if cut is not None:
                    raise InputError("invalid JSON: not a row this tool wrote", path, cut)
                try:
                    row = json.loads(line) if line.strip() else None
                except json.JSONDecodeError:
                    row = cut = n
                if not line.endswith("\n"):
                    cut = n
                if cut is None and row is not None:
                    self.pairs.append((row.get("ref"), row.get("obj")))
                    self.rows.append(decode(row, path, n))
                    self._offsets.append(self._good)
                if cut is None:
                    self._good += len(line.encode())

    def __enter__(self) -> PartialRows:
        if self.path.exists():
            os.truncate(self.path, self._good)  # without a line a kill cut short
        else:
            header = json.dumps({"partial": self.run}) + "\n"
            with written(self.path, say=False) as tmp:
                tmp.write_text(header)
            self._good = self._header = len(header.encode())
        self._file = open(self.path, "ab")
        return self

    def add(self, row: dict) -> None:
        """Append ``row``, on disk at once (a kill loses at most the row being written)."""
        line = (json.dumps(row) + "\n").encode()
        self._file.write(line)
        self._file.flush()
        self._offsets.append(self._good)
        self._good += len(line)
        self.count += 1

    def __exit__(self, exc_type, *exc) -> None:
        self._file.close()
        # a run refused or failed before its first row leaves no file: one naming only the run
        # would refuse the corrected command as "rows of another run" and keeps nothing
        if exc_type is not None and self.count == 0:
            self.path.unlink(missing_ok=True)

    def finish(self) -> None:
        """The run is complete: ``out`` written whole (the partial file's rows, copied line by
        line), the partial file gone."""
        with written(self.out) as tmp, open(self.path) as src, open(tmp, "w") as dst:
            src.readline()  # the line naming the run
            shutil.copyfileobj(src, dst)
        self.path.unlink()

    def offsets(self) -> np.ndarray:
        """The byte offset of each row's line in ``out`` once it is written (``finish``)."""
        return np.frombuffer(self._offsets, dtype=np.int64) - self._header


def rows_of_log(path: str | Path, log) -> list[PairMatch]:
    """``read_rows``, the rows checked to belong to ``log`` (``belong``)."""
    rows = read_rows(path)
    belong(
        str(path),
        log,
        np.array([r.ref for r in rows]),
        np.array([r.obj for r in rows]),
        np.array([r.line for r in rows]),
        rows[0],
    )
    return rows


def belong(
    path: str, log, refs: np.ndarray, objs: np.ndarray, lines: np.ndarray, first: PairMatch
) -> None:
    """Rows (their records ``refs`` and ``objs``, their ``lines``, the ``first``) checked to
    belong to ``log`` (a ``ScanLog``): its scan records, its scan stream and the frame its poses
    are in; the first row that does not is named."""
    beyond = np.flatnonzero((refs >= log.records) | (objs >= log.records))
    if len(beyond):
        k = beyond[0]
        key = "ref" if refs[k] >= log.records else "obj"
        raise InputError(
            f"record {refs[k] if key == 'ref' else objs[k]} is beyond the {log.records} records "
            f"of {log.path}: rows of another log?",
            path,
            int(lines[k]),
            key,
        )
    if first.stream != log.topic and first.stream is not None:
        raise InputError(
            f"written for the scans of {first.stream!r}, but {log.path} is read as "
            f"{log.topic or 'its only stream'!r}: open it with --topic {first.stream}",
            path,
            first.line,
            "stream",
        )
    frames = log.frames
    if first.frame not in (frames.frame_name(True), frames.frame_name(False)):
        raise InputError(
            f"written for poses in {first.frame!r}, but {log.path} reads as "
            f"{frames.frame_name(True)!r}: rows of another log, or read with other options?",
            path,
            first.line,
            "frame",
        )
