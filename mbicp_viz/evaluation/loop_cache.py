"""Loops found once, kept between commands (issue 36).

Looking for a run's loops matches thousands of candidates: two minutes on the full Intel log.
Opening the same run again (``serve --rows R --close-loops`` after ``eval sequence
--close-loops``, or ``eval relations --close-loops``) reads what was found from the cache folder
(``cache_root()``, never beside the input) and only solves the graph again, in under a second.

An entry is named by everything the search depends on: the log (its path, size, modification
time, stream, mount and a few of its scans' readings), each row's motion and covariance, the
matcher and its parameters, and the loop parameters. It holds JSON, never a pickle; an entry that
cannot be read is looked for again. Entries beyond ``CACHE_BYTES`` go least recently used first.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import asdict
from pathlib import Path

import numpy as np

from mbicp_viz.core import Pose2
from mbicp_viz.core.search import SearchResult
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ScanLog
from mbicp_viz.readers.log_cache import cache_root, prune
from mbicp_viz.readers.pair_match import PairMatch, Verdict
from mbicp_viz.readers.rows import parse_row

from .loops import Closure, Found, LoopParams
from .trajectory import scan_indices

FORMAT = 1  # the layout of an entry; a new layout ignores the old entries
CACHE_BYTES = 1_000_000_000
FOUND = "closures.json"
META = "meta.json"  # what the entry is of; its modification time is its last use


def entry(log: ScanLog, rows: list[PairMatch], p: LoopParams) -> Path | None:
    """The cache folder of a run's loops (None: the log is no file, so nothing names it)."""
    try:
        st = Path(log.path).stat()
    except OSError:
        return None
    records = scan_indices(rows)
    first = rows[0]
    what = [
        str(Path(log.path).resolve()),
        st.st_size,
        st.st_mtime_ns,
        log.topic,
        log.frames.mount.as_array().tolist(),
        first.matcher,
        first.params.as_dict(),
        first.frame,
        asdict(p),
        FORMAT,
    ]
    digest = hashlib.sha256(json.dumps(what, default=str).encode())
    sample = sorted({records[0], records[len(records) // 2], records[-1]})
    for scan in log.scans_of(sample, odometry=False):
        digest.update(np.asarray(scan.ranges, dtype=float).tobytes())
    for r in rows:
        cov = r.result.covariance
        digest.update(np.array([r.ref, r.obj, *r.result.pose.as_array()], dtype=float).tobytes())
        digest.update(np.zeros(9) if cov is None else np.asarray(cov, dtype=float).tobytes())
    return cache_root() / "loops" / digest.hexdigest()[:32]


def _closure_json(c: Closure) -> dict:
    s = c.search
    search = None
    if s is not None:
        search = {
            "pose": s.pose.as_array().tolist(),
            "coarse": s.coarse.as_array().tolist(),
            "score": s.score,
            "best_per_angle": s.best_per_angle.tolist(),
            "angles": s.angles.tolist(),
        }
    return {
        "old": c.old,
        "key": c.key,
        "judged": c.judged.value,
        "peak_ratio": c.peak_ratio,
        "guess": c.guess.as_array().tolist(),
        "match": c.match.to_json(),
        "search": search,
    }


def _closure(obj: dict, path: str, line: int) -> Closure:
    s = obj["search"]
    search = None
    if s is not None:
        search = SearchResult(
            Pose2(*s["pose"]),
            Pose2(*s["coarse"]),
            float(s["score"]),
            np.array(s["best_per_angle"], dtype=float),
            np.array(s["angles"], dtype=float),
        )
    judged = Verdict(obj["judged"])
    match = parse_row(obj["match"], path, line)
    return Closure(
        int(obj["old"]),
        int(obj["key"]),
        match,
        judged,
        judged,
        float(obj["peak_ratio"]),
        search,
        Pose2(*obj["guess"]),
    )


def save(folder: Path, found: Found, log: ScanLog) -> None:
    """Keep what was found in ``folder``, whole or not at all (over an entry that could not be
    read)."""
    from mbicp_viz.outputs import written_folder

    shutil.rmtree(folder, ignore_errors=True)
    folder.parent.mkdir(parents=True, exist_ok=True)
    body = {
        "closures": [_closure_json(c) for c in found.closures],
        "estimate": [q.as_array().tolist() for q in found.estimate],
        "optimise_s": found.optimise_s,
    }
    with written_folder(folder) as tmp:
        tmp.mkdir()
        (tmp / FOUND).write_text(json.dumps(body))
        (tmp / META).write_text(json.dumps({"log": log.path, "format": FORMAT}))
    prune(folder.parent, CACHE_BYTES, keep=folder)


def load(folder: Path) -> Found | None:
    """What an earlier run found, or None (no entry, or one that cannot be read)."""
    path = folder / FOUND
    try:
        body = json.loads(path.read_text())
        closures = [_closure(c, str(path), k + 1) for k, c in enumerate(body["closures"])]
        found = Found(
            closures,
            [Pose2(*q) for q in body["estimate"]],
            [float(t) for t in body["optimise_s"]],
        )
        os.utime(folder / META)  # used: the last to be removed
    except (OSError, ValueError, KeyError, TypeError, InputError):
        return None
    return found
