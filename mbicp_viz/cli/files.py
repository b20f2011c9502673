"""``record`` and ``params``: the curated recordings, and parameter files."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from mbicp_viz.outputs import write_text

from .options import DEFAULT_MATCHER, MatcherOpt, user_errors


def record(
    names: Annotated[list[str] | None, typer.Argument(help="scenario names (default: all)")] = None,
    out_dir: Annotated[
        Path | None,
        typer.Option(
            "--out-dir",
            help="write the .rrd files here (made if missing; default: the checkout's recordings/)",
        ),
    ] = None,
    list_only: Annotated[bool, typer.Option("--list", help="list the scenarios and stop")] = False,
):
    """Regenerate the curated recordings (.rrd) from the scenario files."""
    from mbicp_viz.evaluation.scenarios import load_scenario, scenario_paths
    from mbicp_viz.views.recordings import record_all

    if list_only:
        for p in scenario_paths():
            typer.echo(f"{p.stem:<18} {load_scenario(p).title}")
        return
    for s, out, lines in record_all(names, out_dir):
        typer.echo(f"{out}  ({s.title})")
        for line in lines:
            typer.echo(f"    {line}")


def params(
    matcher: MatcherOpt = DEFAULT_MATCHER,
    out: Annotated[Path | None, typer.Option("--out", help="write to this file")] = None,
    presets: Annotated[
        bool,
        typer.Option(
            "--presets", help="list the presets --params NAME reads, with their files, and stop"
        ),
    ] = False,
):
    """Print (or write) the default parameters of a matcher and of the search, as a file for
    --params."""
    from mbicp_viz.core import MATCHERS, SearchParams
    from mbicp_viz.readers.params_toml import (
        PRESETS,
        make_params,
        params_to_toml,
        preset_names,
        presets_for,
    )

    if presets:
        for name in preset_names():
            matchers = ",".join(m for m in MATCHERS if name in presets_for(m))
            typer.echo(f"{name:<18} {matchers:<28} {PRESETS / name}.toml")
        return
    text = params_to_toml(make_params(matcher.value, None), SearchParams())
    if out:
        write_text(out, text)
    else:
        typer.echo(text, nl=False)


def register(app: typer.Typer) -> None:
    app.command("record")(user_errors(record))
    app.command("params")(user_errors(params))
