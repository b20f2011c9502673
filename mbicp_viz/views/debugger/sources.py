"""What ``serve`` and ``demo`` open: a log, two scan files, or a curated scenario."""

from __future__ import annotations

from mbicp_viz.core import Pose2
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.pairs import Guess
from mbicp_viz.evaluation.run_rows import RunRows, run_of_log
from mbicp_viz.evaluation.scenarios import find_scenario
from mbicp_viz.evaluation.trajectory import is_run
from mbicp_viz.evaluation.versus import versus as compare_runs
from mbicp_viz.readers import ReadOptions, ScanLog, read_log
from mbicp_viz.readers.pair_match import PairMatch
from mbicp_viz.readers.relations import read_relations
from mbicp_viz.readers.rows import rows_of_log

from .state import Source


def scenario_source(name: str) -> Source:
    s = find_scenario(name)
    log = ScanLog(s.name, [s.ref, s.obj])
    return Source(
        s.title,
        log,
        (0, 1),
        False,
        s.guess,
        Guess.stored,
        s.truth,
        s.params,
        tuple(s.params),
        note=s.note.strip(),
        teaching=s.teaching,
    )


def files_source(
    first: str | None,
    second: str | None,
    pair: tuple[int, int] | None = None,
    guess: Guess = Guess.stored,
    options: ReadOptions | None = None,
    rows: str | None = None,
    versus: str | None = None,
    relations: str | None = None,
    offset: float = 0.0,
) -> Source:
    """``serve REF OBJ`` (the first scan of each) or ``serve LOG [--pair I J] [--rows FILE]`` (pick
    any two; with an evaluation's rows, its failures and suspicious pairs open as they ran, the
    worst first; with ``versus``, a second run's rows of the same pairs beside them; with
    ``relations``, the run scored on them, the costliest to bring into view)."""
    if first is None:
        raise InputError("give a log, two scan files, or --scenario NAME", field="FILE")
    if second is not None:
        if pair is not None or rows is not None:
            raise InputError(
                "give either two files or one log with --pair I J or --rows FILE, not both",
                field="--pair" if pair is not None else "--rows",
            )
        log = ScanLog(
            f"{first} + {second}",
            [read_log(first, options).scan(0), read_log(second, options).scan(0)],
        )
        return Source(f"{first} -> {second}", log, guess_kind=guess)
    log = read_log(first, options)
    run = run_of_log(rows, log) if rows is not None else []
    both = None
    if versus is not None:
        if rows is None:
            raise InputError(
                "--versus compares with the run of --rows: give both", field="--versus"
            )
        both = compare_runs(run, rows_of_log(versus, log), rows, versus)
        run = both.a
    if relations is not None and (rows is None or not is_run(run)):
        raise InputError(
            "--relations scores a run: give the rows of `eval sequence` with --rows",
            field="--relations",
        )
    return log_source(
        first,
        log,
        pair,
        guess,
        options,
        run,
        f"{rows}: {len(run)} rows" if rows is not None else "",
        both,
        read_relations(relations) if relations is not None else None,
        offset,
    )


def log_source(
    label: str,
    log: ScanLog,
    pair: tuple[int, int] | None = None,
    guess: Guess = Guess.stored,
    options: ReadOptions | None = None,
    run: list[PairMatch] = (),
    rows_label: str = "",
    versus=None,
    relations: list | None = None,
    offset: float = 0.0,
) -> Source:
    """The debugger on ``log``: any two scans can be picked; with a ``run``'s rows, its failures
    and suspicious pairs open as they ran, the worst first (the first opened unless ``pair`` is
    given), and a chained run has its run view."""
    if len(log.record_numbers(2)) < 2:
        raise InputError("needs at least two usable scans (or give two files)", log.path)
    run = RunRows.of(run) if len(run) else []
    failed, suspects = (run.worst_first(), run.ranked()) if run else ([], [])
    opened = (failed or suspects or [None])[0] if pair is None else None
    i, j = (
        pair
        if pair is not None
        else (opened.ref, opened.obj)
        if opened
        else log.consecutive_pairs(1)[0]
    )
    log.scan(i), log.scan(j)  # an unusable or missing scan is refused here, in one line
    return Source(
        label,
        log,
        (i % log.records, j % log.records),
        pick_pair=True,
        guess_kind=guess,
        failures=failed,
        suspects=suspects,
        run=run if is_run(run) else None,
        versus=versus,
        relations=relations,
        offset=offset,
        rows_label=rows_label,
        opened=opened,
        options=options,
    )


def demo_source(path: str) -> Source:
    return Source(
        "bundled example: hand-held Hokuyo URG-04LX, scans 125 -> 130",
        read_log(path),
        guess=Pose2(),
    )
