"""A run's rows as the run view reads them: numpy columns of what it needs of every pair (the
pairs, the motions, the odometry, the health timeline, the ranking of flagged and failed pairs),
and each pair's whole record made only when it is asked for.

A rows file is read once, every row checked as ``read_rows`` checks it, and only its columns and
each row's place in the file are kept: an hour-long run's 144,000 records as objects took 261 MB,
its columns take about 20 MB. A long file's columns are kept in the cache folder, so its next
opening reads no row (``log_cache``'s folder and size limit). ``eval sequence`` makes the columns
as its rows arrive (``RunColumns``) and keeps none of its records. A run already in memory (a live
buffer) is wrapped as it is, its columns made from its records when first asked for.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import sys
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from mbicp_viz.core import Pose2, Termination
from mbicp_viz.errors import InputError
from mbicp_viz.readers import log_cache
from mbicp_viz.readers.pair_match import PairMatch, Suspicion
from mbicp_viz.readers.rows import belong, file_rows, gc_paused, parse_row

from .failures import failed
from .health import severity
from .pairs import missing_guess

NONE3 = (math.nan,) * 3

# each column: what it holds of one record (one definition, for a file's pass and a list alike)
COLUMNS: dict[str, Callable[[PairMatch], object]] = {
    "ref": lambda r: r.ref,
    "line": lambda r: r.line,
    "obj": lambda r: r.obj,
    "motion": lambda r: r.result.pose.as_array(),  # x, y [m], theta [rad]
    "odometry": lambda r: NONE3 if r.odometry is None else r.odometry.as_array(),  # NaN: none
    "overlap": lambda r: math.nan if r.overlap is None else r.overlap,  # share, NaN: not measured
    "error": lambda r: r.result.error,  # mean squared distance of the kept pairs [m^2]
    "odometry_xy": lambda r: math.nan if r.odometry_xy is None else r.odometry_xy,  # [m]
    "apart": lambda r: r.flags.get(Suspicion.DISAGREE, (0.0,))[0],  # from run B's [m]
    "flagged": lambda r: bool(r.flags),
    "severity": severity,
    "failed": failed,
    # a failed row's translation and rotation error against the truth (0: not scored)
    "error_xy": lambda r: r.score.error_xy if r.score is not None else 0.0,
    "error_theta": lambda r: r.score.error_theta if r.score is not None else 0.0,
    # what `eval sequence` sums up at its end
    "converged": lambda r: r.result.converged,
    "halted": lambda r: r.result.reason is Termination.HALTED,
    "success": lambda r: r.score is not None and r.score.success,
    "doubted": lambda r: r.score is not None and r.score.truth_doubted,
    "odometry_theta": lambda r: math.nan if r.odometry_theta is None else r.odometry_theta,  # [rad]
    "guess_missing": lambda r: missing_guess(r.guess_source),
}
CACHED_ROWS = 256  # records made again from the file, kept (a slider's neighbourhood)


class RunRows(Sequence[PairMatch]):
    """A run's rows: ``rows[k]`` is the k-th record, each column a numpy array over all of them.
    Its records are a list in memory (``rows``), or made again from a file when asked for
    (``fetch``, with every column already made)."""

    def __init__(
        self,
        first: PairMatch,
        rows: list[PairMatch] | None = None,
        fetch: Callable[[int], PairMatch] | None = None,
        columns: dict[str, np.ndarray] | None = None,
    ):
        self.first, self._rows, self._fetch = first, rows, fetch or rows.__getitem__
        self._columns = columns or {}
        self._n = len(rows) if rows is not None else len(self._columns["ref"])

    @staticmethod
    def of(rows: Sequence[PairMatch]) -> RunRows:
        """``rows`` as a RunRows (itself when it is one); a list's columns are made when asked."""
        if isinstance(rows, RunRows):
            return rows
        rows = list(rows)
        if not rows:
            raise ValueError("a run has rows")
        return RunRows(rows[0], rows)

    @staticmethod
    def renumbered(rows: list[PairMatch], ref: np.ndarray, obj: np.ndarray) -> RunRows:
        """``rows`` with their records numbered ``ref``, ``obj`` (a live buffer's, as the scans
        it still holds number them): each record renumbered only when it is read, every other
        column the rows' own (renumbering the whole buffer's records at each refresh of the live
        page took 40 % of it)."""

        def fetch(k: int) -> PairMatch:
            return replace(rows[k], ref=int(ref[k]), obj=int(obj[k]))

        return RunRows(fetch(0), rows, fetch, {"ref": ref, "obj": obj})

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self._fetch(i) for i in range(*k.indices(self._n))]
        if not -self._n <= k < self._n:
            raise IndexError(k)
        return self._fetch(k % self._n)

    def __iter__(self) -> Iterator[PairMatch]:
        return map(self._fetch, range(self._n))

    def column(self, name: str) -> np.ndarray:
        """A column (``COLUMNS``) over every row."""
        if name not in self._columns:
            self._columns[name] = np.array([COLUMNS[name](r) for r in self._rows])
        return self._columns[name]

    def poses(self, name: str) -> list[Pose2 | None]:
        """A pose column (``motion``, ``odometry``) as poses (None where it is NaN)."""
        return [None if math.isnan(p[0]) else Pose2(*p) for p in self.column(name).tolist()]

    def picked(self, keep: np.ndarray, *keys: np.ndarray) -> Sequence[PairMatch]:
        """The rows where ``keep`` holds, ordered by ``keys`` (each a value per row, smallest
        first; ties by the first key, then the next, then in the run's order), each made only
        when read."""
        idx = np.flatnonzero(keep)
        return _Picked(self, idx[np.lexsort([k[idx] for k in reversed(keys)])])

    def worst_first(self) -> Sequence[PairMatch]:
        """The failed rows: the largest translation error first, then rotation error."""
        c = self.column
        return self.picked(c("failed"), -c("error_xy"), -c("error_theta"))

    def ranked(self) -> Sequence[PairMatch]:
        """The flagged rows, the most suspicious first (then by their records)."""
        c = self.column
        return self.picked(c("flagged"), -c("severity"), c("ref"), c("obj"))


class _Picked(Sequence[PairMatch]):
    """Some of a run's rows, in an order of their own, each made when read; ``index`` holds their
    places in the run."""

    def __init__(self, rows: RunRows, index: np.ndarray):
        self.rows, self.index = rows, index

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self.rows[int(i)] for i in self.index[k]]
        return self.rows[int(self.index[k])]


def run_of_log(path: str | Path, log) -> RunRows:
    """A rows file as a RunRows, checked to belong to ``log`` (``rows.belong``): read once, each
    row checked as ``read_rows`` does; its columns and each row's offset in the file kept, a row
    made again from its line when asked for (a JSON array, as written before, is kept whole).
    A file of ``CACHED_FROM`` rows or more has its columns kept in the cache folder for the next
    opening (``log_cache``: by its path, size and modification time, and the code that made
    them)."""
    path = str(path)
    run = _cached(_folder(path), path)
    if run is None:
        run = _read(path)
    belong(path, log, run.column("ref"), run.column("obj"), run.column("line"), run.first)
    return run


CACHED_FROM = 5_000  # rows files with fewer rows are read each time: well under a second


def _folder(path: str) -> Path:
    """Where the columns of the rows file ``path`` are cached (by its path, size and modification
    time, and the code that made them)."""
    return log_cache.entry(path, "rows", (_code_digest(),))


def _read(path: str) -> RunRows:
    """The rows file read once: its RunRows (its columns cached: ``RunColumns.over``)."""
    columns, offsets, rows = RunColumns(), [], []
    with gc_paused():
        for _, offset, row in file_rows(path):
            if offset is None:  # a JSON array's row has no line of its own
                rows.append(row)
                continue
            offsets.append(offset)
            columns.append(row)
    if rows:
        return RunRows(rows[0], rows)
    if not len(columns):
        raise InputError("no rows", path)
    return columns.over(path, np.array(offsets, dtype=np.int64))


class RunColumns:
    """A run's columns (``COLUMNS``) made as its rows arrive, a block of arrays at a time; of
    the records only the first and the last two are kept (a resumed run goes on from them: its
    ``done``). An hour's 144,000 records took 261 MB as objects and about 700 bytes each as
    lists of values; as arrays about 20 MB. ``numbered``: each row's line is its place in the
    rows file to come (one row a line), not the line it was read from."""

    BLOCK = 4096  # rows a block

    def __init__(self, numbered: bool = False):
        self.numbered = numbered
        self._blocks: dict[str, list[np.ndarray]] = {name: [] for name in COLUMNS}
        self._open: dict[str, list] = {name: [] for name in COLUMNS}
        self._n, self.first, self._last = 0, None, []

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, k):
        """The last two rows (``done[-1]``, ``done[-2:]``); no other is kept."""
        kept = self._n - len(self._last)
        if isinstance(k, slice):
            start, stop, step = k.indices(self._n)
            if step != 1 or start < kept:
                raise IndexError("only the last two rows are kept")
            return self._last[start - kept : stop - kept]
        i = k + self._n if k < 0 else k
        if not kept <= i < self._n:
            raise IndexError("only the last two rows are kept")
        return self._last[i - kept]

    def append(self, row: PairMatch) -> None:
        for name, value in COLUMNS.items():
            self._open[name].append(value(row))
        if self.numbered:
            self._open["line"][-1] = self._n + 1
        self._n += 1
        self.first = self.first or row
        self._last = [*self._last[-1:], row]
        if len(self._open["ref"]) == self.BLOCK:
            self._close()

    def _close(self) -> None:
        for name, values in self._open.items():
            if values:
                self._blocks[name].append(np.array(values))
            self._open[name] = []

    def columns(self) -> dict[str, np.ndarray]:
        """Each column whole: its blocks joined one column at a time (all joined at once took
        twice the columns' memory)."""
        self._close()
        for blocks in self._blocks.values():
            if len(blocks) > 1:
                blocks[:] = [np.concatenate(blocks)]
        return {name: blocks[0] for name, blocks in self._blocks.items()}

    def over(self, path: str | Path, offsets: np.ndarray) -> RunRows:
        """The run as a RunRows whose records are made again from the complete rows file ``path``,
        row k at byte ``offsets[k]``; with ``CACHED_FROM`` rows or more its columns are kept in
        the cache for the file's next opening (``run_of_log``: ``serve --rows`` after ``eval
        sequence`` reads no row)."""
        if not self._n:
            raise ValueError("a run has rows")
        path, columns = str(path), self.columns()
        first = replace(self.first, line=int(columns["line"][0]))
        run = RunRows(first, None, _FileRows(path, offsets, columns["line"]), columns)
        if self._n >= CACHED_FROM:
            _save(_folder(path), run, offsets)
        return run


def _code_digest() -> str:
    """What makes the columns (the record's reader, the flags' ranking, the failures, this
    module): another version of it makes them afresh."""
    from mbicp_viz.readers import pair_match

    from . import failures, health

    digest = hashlib.sha256()
    for module in (pair_match, failures, health, sys.modules[__name__]):
        digest.update(Path(module.__file__).read_bytes())
    return digest.hexdigest()[:16]


def _save(folder: Path, run: RunRows, offsets: np.ndarray) -> None:
    """The columns and offsets written to ``folder``, whole or not at all."""
    from mbicp_viz.outputs import written_folder

    folder.parent.mkdir(parents=True, exist_ok=True)
    try:
        with written_folder(folder) as tmp:
            tmp.mkdir()
            for name in COLUMNS:
                np.save(tmp / f"{name}.npy", run.column(name))
            np.save(tmp / "offsets.npy", offsets)
            (tmp / "meta.json").write_text(json.dumps({"rows": len(run)}))
    except OSError:  # a full disk, or another process wrote it first: read the file next time
        return
    log_cache.prune(folder.parent, log_cache.CACHE_BYTES, keep=folder)


def _cached(folder: Path, path: str) -> RunRows | None:
    """The RunRows a cache folder holds (None: none, or damaged, and then removed)."""
    if not folder.is_dir():
        return None
    try:
        n = json.loads((folder / "meta.json").read_text())["rows"]
        arrays = {name: np.load(folder / f"{name}.npy") for name in COLUMNS}
        offsets = np.load(folder / "offsets.npy")
        if any(len(a) != n for a in (*arrays.values(), offsets)) or not n:
            raise ValueError("rows")
        fetch = _FileRows(path, offsets, arrays["line"])
        first = fetch(0)
    except (OSError, ValueError, KeyError, TypeError, InputError):
        shutil.rmtree(folder, ignore_errors=True)
        return None
    os.utime(folder / "meta.json")  # used: the last to be removed
    return RunRows(first, None, fetch, arrays)


class _FileRows:
    """A row made again from its line of the rows file (a few kept)."""

    def __init__(self, path: str, offsets: np.ndarray, lines: np.ndarray):
        self.path, self.offsets, self.lines = path, offsets, lines
        self._kept: OrderedDict[int, PairMatch] = OrderedDict()
        self._lock = threading.Lock()

    def __call__(self, k: int) -> PairMatch:
        with self._lock:
            if k in self._kept:
                self._kept.move_to_end(k)
                return self._kept[k]
        with open(self.path, "rb") as f:
            f.seek(int(self.offsets[k]))
            text = f.readline()
        line = int(self.lines[k])
        try:
            row = parse_row(json.loads(text), self.path, line)
        except (ValueError, InputError):  # checked when read: the file changed since
            raise InputError(
                "changed since it was opened: open it again", self.path, line
            ) from None
        with self._lock:
            self._kept[k] = row
            if len(self._kept) > CACHED_ROWS:
                self._kept.popitem(last=False)
        return row
