"""Rows of a long run kept across a stop: Ctrl-C, a kill or a crash loses at most the pair under
way, and the same command started again goes on from the rows already written."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
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


@dataclass(frozen=True)
class Plan:
    """The pairs a run matches, in order. Given whole (``Plan.of``), or found by the run itself
    as it reads a lazily read log front to back (``consecutive``): reading the whole log first
    only to list them took as long as a tenth of the run. ``first(n)`` gives the first ``n``
    (reading no further than they go: a resumed run's rows are checked against them);
    ``total()`` is how many there are, or while the log has records not yet read, how many
    there are at most; ``exact()`` says which."""

    first: Callable[[int], list[tuple[int | None, int]]]
    total: Callable[[], int]
    exact: Callable[[], bool]

    @staticmethod
    def of(pairs: list[tuple[int | None, int]]) -> Plan:
        """The pairs given; a pair whose reference is None takes any (a key-frame run decides it
        as it goes)."""
        return Plan(lambda n: pairs[:n], lambda: len(pairs), lambda: True)

    @staticmethod
    def consecutive(log, limit: int | None) -> Plan:
        """Each usable scan of ``log`` with the next usable one (the first ``limit``), as
        ``ScanLog.consecutive_pairs``: a log read whole lists them at once; a lazily read log
        counts every record not known to be unusable until its run has read them all."""
        if log.surveyed:
            return Plan.of(log.consecutive_pairs(limit))
        log.consecutive_pairs(1)  # its first two usable scans, or the error of a log without

        def total() -> int:
            n = log.records - 1 - len(log.known_unusable)
            return n if limit is None else min(limit, n)

        def first(n: int) -> list[tuple[int, int]]:
            return log.consecutive_pairs(n if limit is None else min(n, limit)) if n else []

        return Plan(first, total, lambda: log.surveyed)

    def total_text(self) -> str:
        return f"{self.total()}" if self.exact() else f"up to {self.total()}"


def resumable_rows(out: Path, run: dict, plan: Plan, decode, sink=None) -> PartialRows:
    """The rows ``out`` will hold, resumed from those a stopped run of the same ``run`` left
    (``decode``-d from the file, path and line, appended to ``sink``: a list when None), which
    must be the plan's first pairs."""
    from mbicp_viz.readers.rows import PartialRows

    rows = PartialRows(out, run, decode, sink)
    done = rows.pairs
    pairs = plan.first(len(done))
    if len(done) > len(pairs) or any(
        p[1] != d[1] or p[0] not in (None, d[0]) for p, d in zip(pairs, done)
    ):
        raise InputError(
            "its rows are not this run's first pairs: delete it to start afresh", str(rows.path)
        )
    if done:
        say(f"resuming from {rows.path}: {len(done)} of {plan.total_text()} pairs already matched")
    return rows


def stop_if_interrupted(rows: PartialRows, plan: Plan) -> None:
    """A run stopped before its last pair ends here: where its rows are and how to go on."""
    if rows.count < plan.total():
        say(
            f"interrupted after {rows.count} of {plan.total_text()} pairs: the rows so far are in "
            f"{rows.path}; the same command goes on from them"
        )
        raise typer.Exit(INTERRUPTED_CODE)


def matched_rows(
    out: Path | None,
    run: dict,
    plan: Plan,
    match: Callable[..., object],
    encode: Callable[[object], dict] = lambda row: row,
    decode: Callable[[dict, str, int], object] = lambda row, path, line: row,
    on_progress: Callable[[Progress], None] | None = None,
    columns: bool = False,
):
    """Every pair's row, ``match(on_row, done)`` running the pairs of ``plan`` after the rows
    ``done``. With ``out``, each row is on disk as it is finished (``OUT.partial``, ``encode``-d
    to JSON), a stopped run ends here with its rows kept and the same command resumes from them
    (``decode``-d from the file, path and line), and ``out`` is written whole at the end;
    without, the rows stay in memory (a Ctrl-C still ends the command, ``user_errors``).
    ``on_progress(bar)`` follows the progress bar after each row (a page showing it too).
    With ``columns`` and ``out``, the rows are not kept: their columns are made as they arrive
    (``run_rows.RunColumns``, ``done`` then holds only the last two) and the run is returned as a
    ``RunRows`` over ``out``, its records read from it when asked for (an hour-long run's
    records took 260 MB)."""
    if columns and out is not None:
        from mbicp_viz.evaluation.run_rows import RunColumns

        sink = RunColumns(numbered=True)
    else:
        sink = None
    kept = resumable_rows(out, run, plan, decode, sink) if out is not None else None
    rows = kept.rows if kept is not None else []
    with Progress(plan.total()) as bar:
        bar.resumed(len(rows))

        def take(row) -> None:
            rows.append(row)
            if kept is not None:
                kept.add(encode(row))
            bar.update(1, plan.total())
            if on_progress is not None:
                on_progress(bar)

        if kept is None:
            match(take, [])
        else:
            with kept:
                match(take, rows if sink is not None else list(rows))
    if kept is not None:
        stop_if_interrupted(kept, plan)
        kept.finish()
        if sink is not None:
            return sink.over(out, kept.offsets())
    return rows
