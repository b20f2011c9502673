"""``live``: a running robot's scans matched as they arrive from its Foxglove bridge."""

from __future__ import annotations

import math
import threading
from pathlib import Path
from typing import Annotated

import typer

from mbicp_viz.choices import DEFAULT_TYPESTORE, MATCH_BUDGET_S

from .options import (
    DEFAULT_MATCHER,
    BudgetOpt,
    Guess,
    GuessOpt,
    MatcherOpt,
    ParamsOpt,
    TopicOpt,
    TypestoreOpt,
    say,
    user_errors,
)
from .serve import ForOpt, ServePortOpt, open_debugger

STATUS_EVERY_S = 1.0


def live(
    url: Annotated[
        str,
        typer.Argument(
            metavar="URL",
            help="the robot's Foxglove WebSocket server: foxglove_bridge or the Foxglove SDK, "
            "e.g. ws://robot:8765",
        ),
    ],
    topic: TopicOpt = None,
    matcher: MatcherOpt = DEFAULT_MATCHER,
    params: ParamsOpt = None,
    guess: GuessOpt = Guess.stored,
    typestore: TypestoreOpt = DEFAULT_TYPESTORE,
    buffer_s: Annotated[
        float,
        typer.Option("--buffer-s", min=1.0, help="keep the last this many seconds of messages"),
    ] = 60.0,
    save: Annotated[
        Path | None,
        typer.Option(
            "--save",
            help="when stopped, save the buffer as a bag every command reads: NAME.bag (ROS 1 "
            "messages) or a ROS 2 bag folder in MCAP storage (CDR messages)",
        ),
    ] = None,
    serve: Annotated[
        bool,
        typer.Option(
            "--serve",
            help="when stopped, freeze: open the buffer in the debugger on 127.0.0.1 (its run view "
            "of the pairs matched, any pair opening in the pair debugger)",
        ),
    ] = False,
    port: ServePortOpt = 8080,
    for_seconds: ForOpt = None,
    budget_s: BudgetOpt = MATCH_BUDGET_S,
):
    """Match a running robot's scans as they arrive (each against the previous one, guess as
    `eval sequence` takes it): one line per pair on stdout, the status each second on stderr,
    until Ctrl-C (or --for-seconds); the last --buffer-s seconds of messages are kept for
    --save."""
    from mbicp_viz.core import tiers
    from mbicp_viz.evaluation.pool import stopping
    from mbicp_viz.live.run import LiveRun
    from mbicp_viz.readers.params_toml import read_params

    tiers.quick_start()
    p = read_params(params, [matcher.value]).matchers[matcher.value]
    run = LiveRun(url, p, topic, buffer_s, typestore, guess, budget_s)
    say(f"mbicp-viz: live from {url}; Ctrl-C stops" + (f" and saves to {save}" if save else ""))
    done, shown, notes = threading.Event(), 0, 0
    try:
        with stopping(done):
            waited = 0.0
            while not done.wait(STATUS_EVERY_S) and (for_seconds is None or waited < for_seconds):
                waited += STATUS_EVERY_S
                if (error := run.error()) is not None:
                    raise error
                status, rows = run.snapshot()
                for note in status.notes[notes:]:
                    say(note)
                notes = len(status.notes)
                fresh = rows[-(status.matched - shown) :] if status.matched > shown else []
                for m in fresh:
                    typer.echo(_pair_line(m))
                shown = status.matched
                say(status.line())
    finally:
        run.stop()
    status, _ = run.snapshot()
    say(status.line())
    if save is not None:
        n = run.save(save)
        say(f"saved the last {status.buffer_s:.0f} s ({n} messages) to {save}")
    if serve:
        _frozen(run, url, port, budget_s)


def _frozen(run, url: str, port: int, budget_s: float) -> None:
    """The buffer in the debugger: its run view, each pair as it was matched live."""
    import tempfile
    from dataclasses import replace

    from mbicp_viz.views.debugger.sources import log_source

    with tempfile.TemporaryDirectory(prefix="mbicp-viz-live-") as folder:
        log, rows = run.freeze(folder)
        label = f"the last {len(rows)} pairs matched live from {url}"
        source = log_source(f"{url} (frozen)", log, run=rows, rows_label=label)
        open_debugger(replace(source, budget_s=budget_s), "127.0.0.1", port, (), None)


def _pair_line(m) -> str:
    p = m.result.pose
    flags = f"; flagged: {', '.join(str(f) for f in m.flags)}" if m.flags else ""
    return (
        f"scans {m.ref} -> {m.obj}: x {p.x:+.4f} m, y {p.y:+.4f} m, theta "
        f"{math.degrees(p.theta):+.3f} deg ({m.frame}), {m.result.iterations} iterations, "
        f"{m.result.reason.value}{flags}"
    )


def register(app: typer.Typer) -> None:
    app.command("live")(user_errors(live))
