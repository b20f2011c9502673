"""What ``serve`` and ``demo`` open: a log, two scan files, or a curated scenario."""

from __future__ import annotations

from mbicp_viz.core import Pose2
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.pairs import Guess
from mbicp_viz.evaluation.scenarios import find_scenario
from mbicp_viz.readers import ReadOptions, ScanLog, read_log
from mbicp_viz.readers.pair_match import PairMatch
from mbicp_viz.readers.rows import read_rows

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
) -> Source:
    """``serve REF OBJ`` (the first scan of each) or ``serve LOG [--pair I J] [--rows FILE]`` (pick
    any two; with an evaluation's rows, its failures open as they ran, the worst first)."""
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
    if len(log.scans) < 2:
        raise InputError("needs at least two usable scans (or give two files)", first)
    failed, label = _failures(rows, log) if rows is not None else ([], "")
    opened = failed[0] if failed and pair is None else None
    i, j = (
        pair
        if pair is not None
        else (opened.ref, opened.obj)
        if opened
        else log.consecutive_pairs(1)[0]
    )
    log.scan(i), log.scan(j)  # an unusable or missing scan is refused here, in one line
    return Source(
        first,
        log,
        (i % log.records, j % log.records),
        pick_pair=True,
        guess_kind=guess,
        failures=failed,
        rows_label=label,
        opened=opened,
        options=options,
    )


def _failures(path: str, log: ScanLog) -> tuple[list[PairMatch], str]:
    """The failed rows of an evaluation of ``log``, worst first, each checked against the log."""
    from mbicp_viz.evaluation.failures import worst_first

    rows = read_rows(path)
    for row in rows:
        for key, k in (("ref", row.ref), ("obj", row.obj)):
            if k >= log.records:
                raise InputError(
                    f"record {k} is beyond the {log.records} records of {log.path}: rows of "
                    "another "
                    "log?",
                    path,
                    row.line,
                    key,
                )
    if rows[0].stream != log.topic and rows[0].stream is not None:
        raise InputError(
            f"written for the scans of {rows[0].stream!r}, but {log.path} is read as "
            f"{log.topic or 'its only stream'!r}: open it with --topic {rows[0].stream}",
            path,
            rows[0].line,
            "stream",
        )
    frames = log.frames
    if rows[0].frame not in (frames.frame_name(True), frames.frame_name(False)):
        raise InputError(
            f"written for poses in {rows[0].frame!r}, but {log.path} reads as "
            f"{frames.frame_name(True)!r}: rows of another log, or read with other options?",
            path,
            rows[0].line,
            "frame",
        )
    return worst_first(rows), f"{path}: {len(rows)} rows"


def demo_source(path: str) -> Source:
    return Source(
        "bundled example: hand-held Hokuyo URG-04LX, scans 125 -> 130",
        read_log(path),
        guess=Pose2(),
    )
