"""``lesson``: the guided MbICP lesson in the debugger, or exported as a handout and an .rrd."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from mbicp_viz.errors import InputError

from .options import user_errors
from .serve import ForOpt, ServePortOpt, open_debugger


def lesson(
    step: Annotated[
        int, typer.Option("--step", min=1, help="open at this step (1: the first)")
    ] = 1,
    directory: Annotated[
        Path | None,
        typer.Option(
            "--dir",
            help="a folder of lesson steps (*.toml, in file-name order); default: the bundled "
            "lesson",
        ),
    ] = None,
    export: Annotated[
        Path | None,
        typer.Option(
            "--export",
            help="write the lesson to this folder instead of serving it: lesson.md with a PNG per "
            "step, and lesson.rrd (a step timeline, the step's text, its layers)",
        ),
    ] = None,
    notebooks: Annotated[
        Path | None,
        typer.Option(
            "--notebooks",
            help="write the lesson to this folder as Jupyter notebooks instead of serving it, "
            'one per step (run them with pip install "mbicp-viz[notebook]")',
        ),
    ] = None,
    port: ServePortOpt = 8080,
    for_seconds: ForOpt = None,
):
    """The guided MbICP lesson: from one laser scan to improved MbICP, step by step
    (next/previous), each step a real scan pair whose text quotes its own run."""
    from mbicp_viz.views.lesson.steps import load_lesson

    steps = tuple(load_lesson(directory))
    if step > len(steps):
        raise InputError(f"the lesson has {len(steps)} steps", field="--step")
    if export is not None and notebooks is not None:
        raise InputError("give --export or --notebooks, not both", field="--notebooks")
    for out, option in ((export, "--export"), (notebooks, "--notebooks")):
        if out is not None and out.exists() and not out.is_dir():
            raise InputError("exists and is not a folder", str(out), field=option)
    if export is not None:
        _export(steps, export)
        return
    if notebooks is not None:
        from mbicp_viz.views.lesson.notebooks import write_notebooks

        paths = write_notebooks(steps, notebooks, directory)
        typer.echo(f"written {len(paths)} notebooks to {notebooks} (open them with: jupyter lab)")
        return
    from mbicp_viz.views.debugger.lesson import step_source

    open_debugger(step_source(steps[step - 1], steps), "127.0.0.1", port, (), for_seconds)


def _export(steps, out: Path) -> None:
    from mbicp_viz.views.lesson.handout import write_handout
    from mbicp_viz.views.lesson.recording import record_lesson
    from mbicp_viz.views.lesson.steps import run_step

    runs = []
    for s in steps:
        runs.append(run_step(s))
        typer.echo(f"step {s.number}: {s.title}")
    md = write_handout(runs, out)
    record_lesson(runs, str(out / "lesson.rrd"))
    typer.echo(
        f"written {md}, {len(runs)} PNGs and {out / 'lesson.rrd'} (open it with: rerun "
        f"{out / 'lesson.rrd'})"
    )


def register(app: typer.Typer) -> None:
    app.command("lesson")(user_errors(lesson))
