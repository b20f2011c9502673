"""Logs read whole once, then read as a bag is: their scans kept in a cache folder as arrays that
are mapped from disk, each scan read when it is asked for.

A CARMEN, text or JSON log (compressed or not) has no index to seek in: its PARAM lines apply to
the scans after them, and its no-return ceiling and the mount its poses imply come from every
scan. So it is read whole the first time, as before, and what the reader made of it is written to
``cache_root()`` (never beside the input, which may be read-only): the scans' readings,
bearings and validity end to end, each scan's pose, odometry, stamp and line, the unusable
records' reasons, and the log's frames, odometry and notes. The next opening of the same file
(same path, size and modification time, same stream) maps those arrays and reads one scan at a
time, in memory bounded by the scans in view; a note says the cache was used. Logs under
``CACHED_RECORDS`` scan records are not cached: reading them whole takes well under a second.
The cache holds at most ``CACHE_BYTES``: writing an entry removes the least recently used ones
beyond it.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import threading
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from mbicp_viz.core import Pose2, Scan, ScanSource, UnusableScan

from .log import Frames, ScanLog

CACHED_RECORDS = 5_000  # logs with fewer scan records are read whole each time
CACHE_BYTES = 4_000_000_000  # entries beyond this, least recently used first, are removed
FORMAT = 1  # the layout of a cache entry; a new layout ignores the old entries


def cache_root() -> Path:
    """``MBICP_VIZ_CACHE``, else ``$XDG_CACHE_HOME/mbicp-viz``, else ``~/.cache/mbicp-viz``."""
    if given := os.environ.get("MBICP_VIZ_CACHE"):
        return Path(given)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "mbicp-viz"


def entry(path: str, reader: str, args: tuple) -> Path:
    """The cache folder of ``path`` as ``reader`` reads it with ``args``: named by the file's
    full path, size and modification time, so an edited or replaced file is read afresh."""
    st = Path(path).stat()
    what = [str(Path(path).resolve()), st.st_size, st.st_mtime_ns, reader, list(args), FORMAT]
    digest = hashlib.sha256(json.dumps(what).encode()).hexdigest()[:32]
    return cache_root() / "logs" / digest


def _pose(p: Pose2 | None) -> tuple[float, float, float]:
    return (np.nan,) * 3 if p is None else (p.x, p.y, p.theta)


def save(log: ScanLog, folder: Path) -> bool:
    """Write ``log`` (as its reader made it) to ``folder``, whole or not at all; False when it
    holds what the cache does not keep (scans with beam times or a raw scan), or the disk is
    full."""
    scans = list(log.scans)
    if any(s.beam_times is not None or s.raw is not None for s in scans):
        return False
    arrays = {
        "ranges": np.concatenate([s.ranges for s in scans]).astype(float),
        "bearings": np.concatenate([s.bearings for s in scans]).astype(float),
        "valid": np.concatenate([s.valid for s in scans]).astype(bool),
        "ends": np.cumsum([len(s.ranges) for s in scans]),
        "records": np.array(log.record_numbers(), dtype=np.int64),
        "poses": np.array([_pose(s.pose) for s in scans]).reshape(-1, 3),
        "odometry": np.array([_pose(s.odometry) for s in scans]).reshape(-1, 3),
        "stamps": np.array([np.nan if s.stamp is None else s.stamp for s in scans]),
        "lines": np.array([-1 if s.source.line is None else s.source.line for s in scans]),
        "log_odometry": np.array([(t, *_pose(p)) for t, p in log.odometry]).reshape(-1, 4),
    }
    f = log.frames
    meta = {
        "records": log.records,
        "unusable": {str(r): [u.reason, u.source.line] for r, u in log.unusable.items()},
        "frames": [*_pose(f.mount), f.mount_source, f.base_frame, f.frame_id],
        "skipped": log.skipped,
        "topic": log.topic,
        "scan_topics": log.scan_topics,
        "odometry_source": log.odometry_source,
        "notes": log.notes,
    }

    def fill(tmp: Path) -> None:
        for name, a in arrays.items():
            np.save(tmp / f"{name}.npy", a)

    try:
        write_entry(folder, fill, meta)
    except OSError:  # a full disk: read whole next time
        return False
    return True


def used(folder: Path) -> bool:
    """Whether the cache holds a whole entry in ``folder``: its ``meta.json``, written last into
    an entry moved in whole (``write_entry``). It is marked used (``prune`` removes the least
    recently used first)."""
    try:
        os.utime(folder / "meta.json")
    except OSError:
        return False
    return True


def write_entry(folder: Path, fill: Callable[[Path], None], meta: dict) -> None:
    """A cache entry, whole or not at all: ``fill`` writes its files into a folder that becomes
    ``folder``, then its ``meta.json``; then the entries least recently used beyond
    ``CACHE_BYTES`` are removed. When another process wrote the same entry meanwhile, its entry
    stays; an OSError otherwise (a full disk)."""
    from mbicp_viz.outputs import written_folder

    shutil.rmtree(folder, ignore_errors=True)  # an entry left incomplete, or damaged
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        with written_folder(folder) as tmp:
            tmp.mkdir()
            fill(tmp)
            (tmp / "meta.json").write_text(json.dumps(meta))
    except OSError:
        if used(folder):  # moved in by another process first
            return
        raise
    prune(folder.parent, CACHE_BYTES, keep=folder)


ARRAYS = ("ranges", "bearings", "valid", "ends", "records", "poses", "odometry", "stamps", "lines")


def mapped(folder: Path) -> dict[str, np.ndarray]:
    """A cache entry's scan arrays, mapped from disk (read when sliced)."""
    return {n: np.load(folder / f"{n}.npy", mmap_mode="r") for n in ARRAYS}


class CachedScans:
    """A cached log's scans, mapped from disk (``ScanLog.store``). It pickles as its folder."""

    random_access = True  # any scan is read as fast as the next one

    def __init__(self, folder: Path, path: str, records: int, unusable: dict, upside_down=False):
        self.folder, self.path, self.upside_down = folder, path, upside_down
        self._records, self._unusable = records, unusable
        self._arrays = None
        self._lock = threading.Lock()

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in ("_arrays", "_lock")}

    def __setstate__(self, state):
        self.__dict__.update(state, _arrays=None, _lock=threading.Lock())

    @property
    def records(self) -> int:
        return self._records

    def _mapped(self) -> dict[str, np.ndarray]:
        with self._lock:
            if self._arrays is None:
                self._arrays = mapped(self.folder)
                self._index = {int(r): k for k, r in enumerate(self._arrays["records"])}
            return self._arrays

    def load(self, record: int, odometry: bool = True) -> Scan | UnusableScan:
        """Record ``record`` (stored with its odometry: ``odometry`` is moot)."""
        if record in self._unusable:
            reason, line = self._unusable[record]
            return UnusableScan(ScanSource(self.path, record, line), reason)
        a = self._mapped()
        k = self._index[record]
        lo, hi = (int(a["ends"][k - 1]) if k else 0), int(a["ends"][k])
        ranges, bearings, valid = (np.array(a[n][lo:hi]) for n in ("ranges", "bearings", "valid"))
        if self.upside_down:
            ranges, bearings, valid = ranges[::-1].copy(), -bearings[::-1], valid[::-1].copy()
        line = int(a["lines"][k])

        def pose(name: str) -> Pose2 | None:
            p = a[name][k]
            return None if np.isnan(p[0]) else Pose2(float(p[0]), float(p[1]), float(p[2]))

        stamp = float(a["stamps"][k])
        return Scan(
            ranges,
            bearings,
            valid,
            pose=pose("poses"),
            odometry=pose("odometry"),
            stamp=None if np.isnan(stamp) else stamp,
            source=ScanSource(self.path, record, None if line < 0 else line),
        )

    def poses(self, records: list[int]) -> np.ndarray:
        """(n, 3) the stored poses of ``records`` (NaN where one has none), read at once: no scan
        is made."""
        a = self._mapped()
        return np.asarray(a["poses"][[self._index[r] for r in records]], dtype=float)

    def stream(
        self, start: int = 0, odometry: bool = True
    ) -> Iterator[tuple[int, Scan | UnusableScan]]:
        """Records ``start`` ... in order (each stored with its odometry: ``odometry`` is moot)."""
        for r in range(start, self._records):
            yield r, self.load(r)

    def mirrored(self) -> CachedScans:
        return CachedScans(
            self.folder, self.path, self._records, self._unusable, not self.upside_down
        )


def cached_log(folder: Path, path: str) -> ScanLog | None:
    """The log a cache folder holds, its scans read when asked for; None when there is none (or
    it cannot be read: the file is then read whole again)."""
    if not folder.is_dir():
        return None
    try:
        meta = json.loads((folder / "meta.json").read_text())
        odometry = np.load(folder / "log_odometry.npy")
        arrays = mapped(folder)
        if len(arrays["records"]) + len(meta["unusable"]) != meta["records"]:
            raise ValueError("records")
    except (OSError, ValueError, KeyError, TypeError):  # damaged: read the file whole again
        shutil.rmtree(folder, ignore_errors=True)
        return None
    x, y, theta, source, base, frame_id = meta["frames"]
    unusable = {int(r): (reason, line) for r, (reason, line) in meta["unusable"].items()}
    store = CachedScans(folder, path, meta["records"], unusable)
    return ScanLog(
        path,
        [],
        odometry=[(float(t), Pose2(float(a), float(b), float(c))) for t, a, b, c in odometry],
        skipped=meta["skipped"],
        frames=Frames(Pose2(x, y, theta), source, base, frame_id),
        topic=meta["topic"],
        scan_topics=meta["scan_topics"],
        odometry_source=meta["odometry_source"],
        notes=[*meta["notes"], f"{path}: read from its cache {folder} (the file read whole once)"],
        store=store,
    )


def prune(logs: Path, limit: int, keep: Path) -> None:
    """Remove the entries of ``logs`` least recently used first while they hold more than
    ``limit`` bytes (``keep``, the one just written, stays)."""
    entries = []
    for folder in logs.iterdir():
        try:
            size = sum(f.stat().st_size for f in folder.iterdir())
            entries.append(((folder / "meta.json").stat().st_mtime_ns, size, folder))
        except OSError:  # another process removing it, or not an entry
            continue
    total = sum(size for _, size, _ in entries)
    for _, size, folder in sorted(entries):
        if total <= limit:
            return
        if folder != keep:
            shutil.rmtree(folder, ignore_errors=True)
            total -= size


def read_cached(path: str, reader: str, args: tuple, read) -> ScanLog:
    """``read()``'s log of ``path``, from the cache when it holds it; a log of ``CACHED_RECORDS``
    records or more read whole is cached for the next time."""
    folder = entry(path, reader, args)
    if (log := cached_log(folder, path)) is not None:
        used(folder)
        return log
    log = read()
    if log.records >= CACHED_RECORDS and save(log, folder):
        note = f"{path}: read whole, and cached in {folder}: the next opening reads it from there"
        return replace(log, notes=[*log.notes, note])
    return log
