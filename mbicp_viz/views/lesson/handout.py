"""The lesson as a handout: Markdown with a PNG per step (``mbicp-viz lesson --export DIR``), each
picture the step's layers as the debugger opens it."""

from __future__ import annotations

from pathlib import Path

from mbicp_viz.outputs import write_bytes, write_text
from mbicp_viz.views.lesson.steps import StepRun

from .. import scene
from ..figure import Plot, scene_png


def side_plot(sr: StepRun, iteration: int | None = None) -> Plot | None:
    """The plot beside the scans: the step's distances, else a polar matcher's ranges per bearing
    (the reference's, and the object's projected onto its bearings), else the first run's pair
    distances; at ``iteration`` (default: the step's)."""
    if "distances" in sr.facts:
        d = sr.facts["distances"]
        return Plot(
            f"paper 000 Fig. 9: {d['n']} distances",
            "distance (the paper's unit)",
            "",
            sr.distance_layers(),
            y_values=False,
        )
    k = sr.iteration if iteration is None else iteration
    for run in sr.runs:
        ranges = [ly for ly in sr.layers(run, k) if ly.path.startswith(f"{scene.POLAR}/ranges/")]
        if ranges:
            return Plot(
                f"{run.matcher}: ranges per bearing at iteration {k}",
                "bearing [deg]",
                "range [dm]",
                ranges,
            )
    hist = (
        [ly for ly in sr.layers(sr.runs[0], k) if ly.path.startswith(f"{scene.TEACH}/histogram/")]
        if sr.runs
        else []
    )
    if hist:
        return Plot(
            f"{sr.runs[0].matcher}: pair distances at iteration {k}",
            "pair distance [m]",
            "pairs per bin (relative heights)",
            hist,
            y_values=False,
        )
    return None


def panel_title(sr: StepRun, name: str, n: int) -> str:
    k = min(sr.iteration, n)
    return f"{name}: initial guess" if k == 0 else f"{name}: iteration {k} of {n}"


def step_png(sr: StepRun) -> bytes:
    panels = [
        (panel_title(sr, r.matcher, len(r.iterations)), sr.layers(r, shown_only=True))
        for r in sr.runs
    ]
    return scene_png(
        panels, side_plot(sr), f"Step {sr.step.number}: {sr.step.title}", sr.step.window
    )


def handout_markdown(step_runs: list[StepRun], pngs: list[str]) -> str:
    parts = [
        "# MbICP, step by step\n",
        "A guided lesson from mbicp-viz (`mbicp-viz lesson`): each step is a real scan pair, a "
        "matcher and "
        "its parameters; every number in the texts comes from the step's own run.\n",
    ]
    for sr, png in zip(step_runs, pngs):
        s = sr.step
        parts.append(
            f"## Step {s.number}: {s.title}\n\n![Step {s.number}]({png})\n\n{sr.text}\n\n"
            f"**Try:** {sr.try_text}\n\n*Data: `{s.path.name}`; matchers: "
            f"{', '.join(r.matcher for r in sr.runs)}.*\n"
        )
    return "\n".join(parts)


def write_handout(step_runs: list[StepRun], out: Path) -> Path:
    """``out/lesson.md`` and ``out/step-NN.png``; returns the Markdown file's path."""
    out.mkdir(parents=True, exist_ok=True)
    pngs = []
    for sr in step_runs:
        name = f"step-{sr.step.number:02d}.png"
        write_bytes(out / name, step_png(sr))
        pngs.append(name)
    md = out / "lesson.md"
    write_text(md, handout_markdown(step_runs, pngs))
    return md
