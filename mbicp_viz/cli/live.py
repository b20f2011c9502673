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
    KeyframeDegOpt,
    KeyframeOpt,
    MatcherOpt,
    ParamsOpt,
    RrdOpt,
    TopicOpt,
    TypestoreOpt,
    say,
    user_errors,
)
from .serve import ForOpt, ServePortOpt

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
            help="when stopped, save the buffer as a bag every command reads: a ROS 2 bag folder "
            "in MCAP storage (a ROS 1 robot's messages converted), or NAME.bag for a ROS 1 "
            "robot's own messages",
        ),
    ] = None,
    rrd: RrdOpt = None,
    serve: Annotated[
        bool,
        typer.Option(
            "--serve",
            help="the live page on 127.0.0.1: the run growing, each pair's health and lag; "
            "'freeze' opens the buffer in the debugger (its run view, any pair's iterations)",
        ),
    ] = False,
    port: ServePortOpt = 8080,
    for_seconds: ForOpt = None,
    budget_s: BudgetOpt = MATCH_BUDGET_S,
    keyframe_m: KeyframeOpt = 0.0,
    keyframe_deg: KeyframeDegOpt = 30.0,
):
    """Match a running robot's scans as they arrive (each against the previous one, or the last
    key frame with --keyframe-m, guess as `eval sequence` takes it): one line per pair on stdout,
    the status each second on stderr, until Ctrl-C (or --for-seconds); the last --buffer-s
    seconds of messages are kept for --save and --rrd."""
    from mbicp_viz.core import tiers
    from mbicp_viz.evaluation.keyframes import KeyFrames
    from mbicp_viz.evaluation.pool import stopping
    from mbicp_viz.live.run import LiveRun, steady_latency
    from mbicp_viz.readers.params_toml import read_params

    tiers.quick_start()
    p = read_params(params, [matcher.value]).matchers[matcher.value]
    keyframes = KeyFrames(keyframe_m, math.radians(keyframe_deg)) if keyframe_m > 0 else None
    run = LiveRun(url, p, topic, buffer_s, typestore, guess, budget_s, keyframes)
    saved = " and ".join(str(p) for p in (save, rrd) if p is not None)
    say(f"mbicp-viz: live from {url}; Ctrl-C stops" + (f" and saves to {saved}" if saved else ""))
    done, shown, notes, page = threading.Event(), 0, 0, None
    try:
        if serve:
            from mbicp_viz.views.debugger.app import App

            page = App(None, "127.0.0.1", port, live=run)
            say(f"mbicp-viz: the live page is at http://127.0.0.1:{page.port}")
        steady_latency()
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
        if page is not None:
            page.stop()
        run.stop()
    status, _ = run.snapshot()
    say(status.line())
    if save is not None:
        n = run.save(save)
        say(f"saved the last {status.buffer_s:.0f} s ({n} messages) to {save}")
    if rrd is not None:
        _save_rrd(run, rrd)


def _save_rrd(run, path: Path) -> None:
    """The buffer's run (the pairs matched live on its scans) as an .rrd, written whole."""
    import tempfile

    from mbicp_viz.views.rrd import record_sequence

    with tempfile.TemporaryDirectory(prefix="mbicp-viz-live-") as folder:
        log, rows = run.freeze(Path(folder))
        if not rows:
            say(f"nothing matched: {path} not written")
            return
        record_sequence(log, rows, str(path))
    say(f"saved the buffer's {len(rows)} pairs to {path}")


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
