"""Rows of a long run kept across a stop: Ctrl-C, a kill or a crash loses at most the pair under
way, and the same command started again goes on from the rows already written."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from mbicp_viz.errors import InputError

from .options import INTERRUPTED_CODE, Progress, say

if TYPE_CHECKING:  # the rows reader loads the core (numpy): only once a command runs
    from mbicp_viz.readers.rows import PartialRows


def log_identity(path: str) -> dict:
    """What names a log's content for a resumed run: its full path, size and modification time."""
    st = Path(path).stat()
    return {"path": str(Path(path).resolve()), "bytes": st.st_size, "mtime_ns": st.st_mtime_ns}


def settings_of(reading) -> dict:
    """How a run read its logs (``ReadOptions``), as its rows or study record it."""
    from dataclasses import asdict

    return {k: getattr(v, "value", v) for k, v in asdict(reading).items()}


def resumable_rows(out: Path, run: dict, pairs: list[tuple[int, int]], decode) -> PartialRows:
    """The rows ``out`` will hold, resumed from those a stopped run of the same ``run`` left
    (``decode``-d from the file, path and line). A pair of ``pairs`` whose reference is None
    takes any (a key-frame run decides it as it goes)."""
    from mbicp_viz.readers.rows import PartialRows

    rows = PartialRows(out, run, decode)
    done = rows.pairs
    if len(done) > len(pairs) or any(
        p[1] != d[1] or p[0] not in (None, d[0]) for p, d in zip(pairs, done)
    ):
        raise InputError(
            "its rows are not this run's first pairs: delete it to start afresh", str(rows.path)
        )
    if done:
        say(f"resuming from {rows.path}: {len(done)} of {len(pairs)} pairs already matched")
    return rows


def stop_if_interrupted(rows: PartialRows, total: int) -> None:
    """A run stopped before its last pair ends here: where its rows are and how to go on."""
    if rows.count < total:
        say(
            f"interrupted after {rows.count} of {total} pairs: the rows so far are in "
            f"{rows.path}; the same command goes on from them"
        )
        raise typer.Exit(INTERRUPTED_CODE)


def matched_rows(
    out: Path | None,
    run: dict,
    pairs: list[tuple[int, int]],
    match: Callable[..., object],
    encode: Callable[[object], dict] = lambda row: row,
    decode: Callable[[dict, str, int], object] = lambda row, path, line: row,
    on_progress: Callable[[Progress], None] | None = None,
) -> list:
    """Every pair's row, ``match(on_row, done)`` running the pairs after the rows ``done``. With
    ``out``, each row is on disk as it is finished (``OUT.partial``, ``encode``-d to JSON), a
    stopped run ends here with its rows kept and the same command resumes from them (``decode``-d
    from the file, path and line), and ``out`` is written whole at the end; without, the rows stay
    in memory (a Ctrl-C still ends the command, ``user_errors``). ``on_progress(bar)`` follows
    the progress bar after each row (a page showing it too)."""
    kept = resumable_rows(out, run, pairs, decode) if out is not None else None
    rows = kept.rows if kept is not None else []
    with Progress(len(pairs)) as bar:
        bar.resumed(len(rows))

        def take(row) -> None:
            rows.append(row)
            if kept is not None:
                kept.add(encode(row))
            bar.update(1)
            if on_progress is not None:
                on_progress(bar)

        if kept is None:
            match(take, [])
        else:
            with kept:
                match(take, list(rows))
    if kept is not None:
        stop_if_interrupted(kept, len(pairs))
        kept.finish()
    return rows
