"""``serve`` and ``demo``: the interactive debugger in the browser."""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from mbicp_viz.choices import DEFAULT_TYPESTORE, MATCH_BUDGET_S
from mbicp_viz.errors import InputError

from .options import (
    BudgetOpt,
    CloseLoopsOpt,
    DeskewOpt,
    Guess,
    GuessOpt,
    LoopGapOpt,
    MountOpt,
    OffsetOpt,
    PairOpt,
    TopicOpt,
    TypestoreOpt,
    UpsideDownOpt,
    closed_run,
    read_options,
    user_errors,
)

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
DEMO_PAIR = EXAMPLES / "hokuyo-125-130.npz"
HostOpt = Annotated[
    str, typer.Option("--host", help="address to bind; anything but 127.0.0.1 exposes the app")
]
ServePortOpt = Annotated[
    int, typer.Option("--port", min=0, max=65535, help="port (0: any free port)")
]
ForOpt = Annotated[
    float | None, typer.Option("--for-seconds", min=0.0, help="stop after this long")
]
OriginOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--allow-origin",
        help="also accept websockets from this page origin, e.g. http://myhost:8080 (by default "
        "only "
        "the debugger's own page)",
    ),
]


def serve(
    first: Annotated[
        str | None, typer.Argument(help="a scan log, or the reference scan file")
    ] = None,
    second: Annotated[str | None, typer.Argument(help="the object scan file")] = None,
    scenario: Annotated[
        str | None,
        typer.Option("--scenario", help="a curated scenario (see `mbicp-viz record --list`)"),
    ] = None,
    pair: PairOpt = None,
    guess: GuessOpt = Guess.stored,
    host: HostOpt = "127.0.0.1",
    port: ServePortOpt = 8080,
    allow_origin: OriginOpt = None,
    for_seconds: ForOpt = None,
    topic: TopicOpt = None,
    typestore: TypestoreOpt = DEFAULT_TYPESTORE,
    mount: MountOpt = None,
    upside_down: UpsideDownOpt = False,
    deskew: DeskewOpt = None,
    rows: Annotated[
        str | None,
        typer.Option(
            "--rows",
            help="an evaluation's rows (`eval sequence --out`): "
            "its failures listed worst first, each opened as it ran",
        ),
    ] = None,
    versus: Annotated[
        str | None,
        typer.Option(
            "--versus",
            metavar="ROWS",
            help="a second run of the same log (another matcher or parameters, `eval sequence "
            "--out`): drawn beside the --rows run, where they differ listed, and which does better",
        ),
    ] = None,
    relations: Annotated[
        str | None,
        typer.Option(
            "--relations",
            metavar="FILE",
            help="score the --rows run on a relations file (Kümmerle et al. 2009) and list the "
            "relations it misses most, each drawn in the run view",
        ),
    ] = None,
    offset: OffsetOpt = 0.0,
    budget_s: BudgetOpt = MATCH_BUDGET_S,
    close_loops: CloseLoopsOpt = False,
    loop_gap_m: LoopGapOpt = 10.0,
):
    """The interactive debugger in the browser: step, play, tune live, compare, export."""
    from mbicp_viz.views.debugger.sources import files_source, scenario_source

    if scenario is not None and (first is not None or rows is not None):
        raise InputError(
            "a scenario brings its own scans: give --scenario alone", field="--scenario"
        )
    reading = read_options(topic, typestore, mount, upside_down, deskew)
    source = (
        scenario_source(scenario)
        if scenario is not None
        else files_source(first, second, pair, guess, reading, rows, versus, relations, offset)
    )
    if close_loops:
        if source.run is None:
            raise InputError(
                "--close-loops closes the loops of a run: give the rows of `eval sequence` with "
                "--rows",
                field="--rows",
            )
        # the records in memory: closing loops reads them all, several times
        source = replace(source, loops=closed_run(source.log, list(source.run), loop_gap_m))
    open_debugger(
        replace(source, budget_s=budget_s), host, port, tuple(allow_origin or ()), for_seconds
    )


def demo(port: ServePortOpt = 8080, for_seconds: ForOpt = None):
    """The debugger on a bundled real pair: a hand-held Hokuyo turning 17 degrees, from the
    identity."""
    from mbicp_viz.views.debugger.sources import demo_source

    open_debugger(demo_source(str(DEMO_PAIR)), "127.0.0.1", port, (), for_seconds)


def open_debugger(
    source, host: str, port: int, origins: tuple[str, ...], for_seconds: float | None
) -> None:
    """The debugger on ``source`` until Ctrl-C (or ``for_seconds``)."""
    with started_debugger(source, host, port, origins) as application:
        if for_seconds is not None:
            until_ctrl_c(lambda: time.sleep(for_seconds))
        else:
            until_ctrl_c(application.server.sleep_forever)


def until_ctrl_c(wait) -> None:
    """``wait()`` until it returns or Ctrl-C, which ends it as a stop asked for (not raised
    again: ``pool._insist``)."""
    from mbicp_viz.evaluation.pool import interrupt_taken

    try:
        wait()
    except KeyboardInterrupt:
        interrupt_taken()


@contextmanager
def started_debugger(source, host: str, port: int, origins: tuple[str, ...] = ()):
    """The debugger on ``source``, serving while the block runs (its address said), stopped at
    its end whatever ends it."""
    from mbicp_viz.views.debugger.app import App

    if host != "127.0.0.1":
        typer.echo(
            f"warning: binding {host}: anyone who can reach this machine can use the app", err=True
        )
    application = App(source, host, port, origins)
    shown = "127.0.0.1" if host in ("127.0.0.1", "0.0.0.0") else host
    typer.echo(f"mbicp-viz: open http://{shown}:{application.port} in a browser (Ctrl-C stops)")
    try:
        yield application
    finally:
        application.stop()


def register(app: typer.Typer) -> None:
    app.command("serve")(user_errors(serve))
    app.command("demo")(user_errors(demo))
