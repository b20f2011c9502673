"""A matcher's run kept whole: its start, every iteration's events and its result, for the front
ends that replay it (the debugger, the lesson) without re-matching."""

from __future__ import annotations

from dataclasses import dataclass

from mbicp_viz.core import (
    IterationEvent,
    MatchResult,
    Params,
    Pose2,
    Recorder,
    Scan,
    StartEvent,
    match,
)


@dataclass
class Run:
    """One matcher's recorded match."""

    name: str
    start: StartEvent
    iterations: list[IterationEvent]
    result: MatchResult


def run_match(name: str, ref: Scan, obj: Scan, guess: Pose2, params: Params) -> Run:
    rec = Recorder()
    result = match(ref, obj, guess, params, rec)
    return Run(name, rec.start, rec.iterations, result)
