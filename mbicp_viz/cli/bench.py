"""``bench``: how fast the matchers, the recordings, the debugger and the command itself answer."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from mbicp_viz.errors import InputError

from .options import DEFAULT_ALGO, AlgoOpt, PairOpt, ParamsOpt, TeachOpt, user_errors
from .serve import DEMO_PAIR


def matches(log: Annotated[str, typer.Argument(help="scan log")], algo: AlgoOpt = DEFAULT_ALGO,
            params: ParamsOpt = None,
            limit: Annotated[int, typer.Option("--limit", min=1, help="consecutive pairs to time")] = 50,
            repeat: Annotated[int, typer.Option("--repeat", min=1, help="runs per pair")] = 3,
            rrd: Annotated[bool, typer.Option("--rrd", help="also time writing each match to an .rrd")] = False,
            teach: TeachOpt = False,
            perturb: Annotated[Optional[tuple[float, float]], typer.Option(
                "--perturb", metavar="XY_M THETA_DEG", help="move each stored guess uniformly within +/-XY_M in x "
                "and y and +/-THETA_DEG (seeded)")] = None,
            seed: Annotated[int, typer.Option("--seed", help="seed of --perturb")] = 0):
    """Time per match on consecutive pairs: mean, median, p90, matches per second; events off and on."""
    import numpy as np

    from mbicp_viz.evaluation.bench import bench, machine_line, speed_probe_us
    from mbicp_viz.readers import read_log
    from mbicp_viz.readers.params_toml import make_params

    lg = read_log(log)
    p = make_params(algo.value, params)
    typer.echo(f"{algo.value} on {log}: {len(lg.scans[0].ranges)} beams; {machine_line()}")
    before = speed_probe_us()
    moved = None
    if perturb is not None:
        import math

        if not all(math.isfinite(v) and v >= 0 for v in perturb):
            raise InputError(f"expected two finite numbers >= 0, got {perturb[0]} {perturb[1]}", field="--perturb")
        moved = (perturb[0], math.radians(perturb[1]))
        typer.echo(f"guesses: the stored ones moved within +/-{perturb[0]:g} m, +/-{perturb[1]:g} deg (seed {seed})")
    timings = bench(lg, p, limit, repeat, moved, seed)
    after = speed_probe_us()
    for t in timings:
        typer.echo(t.line())
    typer.echo(f"machine speed probe    {before:.2f} us before, {after:.2f} us after (a fixed numpy workload; "
               "lower is faster)")
    typer.echo(f"observer overhead      {100.0 * (timings[1].median / timings[0].median - 1.0):+.0f} % (median)")
    if rrd:
        from mbicp_viz.views.rrd import time_recordings

        t, sizes = time_recordings(lg, p, limit, 1, teach)
        typer.echo(t.line())
        typer.echo(f".rrd size              median {np.median(sizes) / 1e6:.2f} MB   max {sizes.max() / 1e6:.2f} MB")


def gui(scans: Annotated[Path, typer.Argument(help="scan file")] = DEMO_PAIR, pair: PairOpt = None):
    """Latency of the debugger: iteration step -> redraw, parameter change -> re-match -> redraw."""
    from mbicp_viz.evaluation.bench import machine_line
    from mbicp_viz.views.debugger.latency import gui_latency

    typer.echo(f"viser debugger on {scans}; {machine_line()}")
    for t in gui_latency(str(scans), pair or (0, 1)):
        typer.echo(t.line())


def startup(repeat: Annotated[int, typer.Option("--repeat", min=3, help="runs of --help")] = 10):
    """How soon the tool answers: --help, the first match with an empty kernel cache, the debugger."""
    from mbicp_viz.evaluation.bench import machine_line, startup as startup_times

    from . import app

    script = Path(sys.executable).parent / "mbicp-viz"  # the installed command, as a user runs it
    exe = [str(script)] if script.exists() else [sys.executable, "-m", "mbicp_viz"]
    commands = [exe + ["--help"]] + [exe + name.split() + ["--help"] for name in command_names(app)]
    match = exe + ["match", str(DEMO_PAIR), "--pair", "0", "1", "--guess", "identity", "--json"]
    debugger = [sys.executable, "-c", "import sys; from mbicp_viz.views.debugger.latency import first_result_ms; "
                f"print(first_result_ms({str(DEMO_PAIR)!r}))"]
    typer.echo(f"start-up; {machine_line()}")
    for t in startup_times(commands, match, debugger, repeat):
        typer.echo(t.line())


def command_names(app: typer.Typer) -> list[str]:
    """Every command of the CLI as typed (``eval sequence``, ``bench startup`` ...)."""
    out = []
    for c in app.registered_commands:
        out.append(c.name)
    for group in app.registered_groups:
        out += [f"{group.name} {c.name}" for c in group.typer_instance.registered_commands]
    return out


def register(app: typer.Typer) -> None:
    group = typer.Typer(no_args_is_help=True, help="Time the matchers, the debugger and the start-up.")
    for name, fn in (("matches", matches), ("gui", gui), ("startup", startup)):
        group.command(name)(user_errors(fn))
    app.add_typer(group, name="bench")
