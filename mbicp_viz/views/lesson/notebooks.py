"""The lesson as Jupyter notebooks (``mbicp-viz lesson --notebooks DIR``): one per step, each
running the step through the Python API (``mbicp_viz/api.py``) so that its text's numbers are
computed as the notebook runs, then its picture, its iterations in rerun's notebook viewer, and
what to try as an exercise whose cell, run as written, repeats the step's own match.

The files are nbformat 4.5 JSON, written directly: writing needs no Jupyter package (running them
does: ``pip install "mbicp-viz[notebook]"``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from mbicp_viz.outputs import write_text
from mbicp_viz.readers.params_toml import changed_values

from .steps import Step, lesson_dir

NBFORMAT, NBFORMAT_MINOR = 4, 5


def _cell(kind: str, number: int, source: str) -> dict:
    cell = {"cell_type": kind, "id": f"{kind}-{number}", "metadata": {}, "source": source}
    if kind == "code":
        cell |= {"execution_count": None, "outputs": []}
    return cell


def _call(name: str, args: list[str]) -> str:
    return f"{name}({', '.join(args)})"


def _params_line(matcher: str, params) -> str:
    keys = [f"{k}={v!r}" for k, v in changed_values(params).items()]
    return f"    {matcher!r}: {_call('mv.params', [repr(matcher), *keys])},"


def exercise(step: Step, open_step: str) -> str:
    """The "Try" cell: the step's pair, guess and parameters written out to be changed; run as
    written it repeats the step's matches."""
    s = step.scenario
    g = s.guess
    return "\n".join(
        [
            "# Change the guess or a parameter, then run this cell again.",
            f"step = {open_step}",
            "ref, obj, truth = step.scenario.ref, step.scenario.obj, step.scenario.truth",
            f"guess = mv.pose_deg({g.x!r}, {g.y!r}, {float(f'{math.degrees(g.theta):.12g}')!r})"
            "  # x [m], y [m], theta [deg]",
            "params = {",
            *[_params_line(name, p) for name, p in s.params.items()],
            "}",
            "for name, p in params.items():",
            "    m = mv.match_scans(ref, obj, p, guess=guess, truth=truth)",
            "    print(mv.report(m), end='\\n\\n')",
        ]
    )


def step_notebook(step: Step, steps: int, directory: Path | None) -> dict:
    """Step ``step``'s notebook (``steps``: how many the lesson has; ``directory``: the lesson's
    folder when not the bundled one)."""
    where = [] if directory is None else [f"directory={str(directory.resolve())!r}"]
    open_step = _call("mv.lesson_step", [str(step.number), *where])
    cells = [
        (
            "markdown",
            f"# Step {step.number} of {steps}: {step.title}\n\n"
            "Part of mbicp-viz's MbICP lesson: `mbicp-viz lesson --step "
            f"{step.number}` opens the same step in the debugger. The text below is filled in "
            "with the numbers of the step's own run, computed as this notebook runs.",
        ),
        (
            "code",
            "import mbicp_viz as mv\nfrom IPython.display import Image, Markdown\n\n"
            f"step = {open_step}\nrun = mv.run_lesson_step(step)\nMarkdown(run.text)",
        ),
        ("code", "Image(mv.lesson_picture(run))"),
        (
            "markdown",
            "Every iteration in rerun's viewer: drag along the `iteration` timeline at the bottom.",
        ),
        ("code", "mv.show(run.runs, teaching=True)"),
        ("markdown", "## Try"),
        ("code", "Markdown(run.try_text)"),
        ("code", exercise(step, open_step)),
    ]
    return {
        "cells": [_cell(kind, k, text) for k, (kind, text) in enumerate(cells, 1)],
        "metadata": {
            "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
            "language_info": {"name": "python"},
        },
        "nbformat": NBFORMAT,
        "nbformat_minor": NBFORMAT_MINOR,
    }


def notebook_name(step: Step) -> str:
    return f"step-{step.number:02d}-{step.path.stem.split('-', 1)[-1]}.ipynb"


def write_notebooks(steps: tuple[Step, ...], out: Path, directory: Path | None) -> list[Path]:
    """One notebook per step in ``out`` (each written whole); their paths."""
    bundled = directory is None or directory.resolve() == lesson_dir().resolve()
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for step in steps:
        path = out / notebook_name(step)
        nb = step_notebook(step, len(steps), None if bundled else directory)
        write_text(path, json.dumps(nb, indent=1) + "\n")
        paths.append(path)
    return paths
