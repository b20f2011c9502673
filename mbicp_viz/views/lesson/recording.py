"""The lesson as one rerun recording, on two timelines:

- ``step``: one tick per step, showing it as the debugger opens it (its iteration);
- ``lesson_iteration``: every iteration of every step in turn (step k's iteration i at
  k * 1000 + i), to scrub a step's match as in the debugger.

Beside the time panel: the step's text in a text panel, the first and second matcher side by side
and the plot beside them. Each tick logs its layers over the last tick's and clears what the last
one showed and it does not, so the views show one step (one iteration) at a time.
"""

from __future__ import annotations

import rerun as rr
import rerun.blueprint as rrb

from mbicp_viz.views.lesson.steps import StepRun

from .. import scene
from ..rrd import log_layer, log_y_up, new_stream, saving, y_up_view
from .handout import panel_title, side_plot

ROOT = "lesson"
SLOTS = ("first", "second")  # a step shows at most two matchers side by side (steps.MAX_MATCHERS)
TEXT = f"{ROOT}/text"
PLOT = f"{ROOT}/plot"


ITERATIONS = "lesson_iteration"
PER_STEP = 1000  # lesson_iteration = step * PER_STEP + iteration


def step_markdown(sr: StepRun, total: int, every_iteration: bool = False) -> str:
    """The text panel of one step: its text, what to try, what each view shows."""
    if every_iteration:
        views = (
            f"timeline {ITERATIONS}: each iteration of this step from {sr.step.number * PER_STEP} "
            "(the initial "
            f"guess) on; the views show the iteration under the cursor"
        )
    else:
        views = "; ".join(
            f"{slot} view: {panel_title(sr, r.matcher, len(r.iterations))}"
            for slot, r in zip(SLOTS, sr.runs)
        )
        plot = side_plot(sr)
        views += f"; plot view: {plot.title} (x: {plot.x_label})" if plot is not None else ""
    return (
        f"## Step {sr.step.number} of {total}: {sr.step.title}\n\n{sr.text}\n\n**Try** (in "
        "`mbicp-viz lesson`): "
        f"{sr.try_text}\n\n*{views}.*\n"
    )


def _frame(sr: StepRun, iteration: int | None) -> list[tuple[str, scene.Layer]]:
    """(root, layer) of everything the views show of a step at ``iteration`` (None: the step's)."""
    layers = [
        (f"{ROOT}/{slot}", ly)
        for slot, run in zip(SLOTS, sr.runs)
        for ly in sr.layers(run, iteration, shown_only=True)
        if ly.path.startswith(f"{scene.SCANS}/")
    ]
    plot = side_plot(sr, iteration)
    return layers + [(PLOT, ly) for ly in (plot.layers if plot is not None else [])]


def _show(
    stream: rr.RecordingStream, layers: list[tuple[str, scene.Layer]], before: set[str]
) -> set[str]:
    """Log a tick's layers and clear what the last tick showed and this one does not."""
    now = set()
    for root, layer in layers:
        log_layer(stream, root, layer)
        now.add(f"{root}/{layer.path}")
    for path in sorted(before - now):
        stream.log(path, rr.Clear(recursive=True))
    return now


def record_lesson(step_runs: list[StepRun], path: str) -> None:
    stream = new_stream("mbicp-viz/lesson")
    scans = [
        y_up_view(f"/{ROOT}/{slot}", f"{slot} matcher of the step: scans (reference frame, m)")
        for slot in SLOTS
    ]
    bp = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Horizontal(*scans),
                y_up_view(f"/{PLOT}", "plot beside the scans"),
                row_shares=[3, 2],
            ),
            rrb.TextDocumentView(origin=f"/{TEXT}", name="the step"),
            column_shares=[3, 1],
        ),
        rrb.TimePanel(timeline="step", expanded=True, play_state="paused"),
        collapse_panels=True,
    )
    with saving(stream, path, bp):
        for space in (*(f"{ROOT}/{slot}" for slot in SLOTS), PLOT):
            log_y_up(stream, space)
        shown = {"step": set(), ITERATIONS: set()}  # what each timeline's last tick showed
        for sr in step_runs:
            stream.disable_timeline(ITERATIONS)
            stream.set_time("step", sequence=sr.step.number)
            shown["step"] = _show(stream, _frame(sr, None), shown["step"])
            stream.log(
                TEXT,
                rr.TextDocument(
                    step_markdown(sr, len(step_runs)), media_type=rr.MediaType.MARKDOWN
                ),
            )
            stream.disable_timeline("step")
            for i in range(max(len(r.iterations) for r in sr.runs) + 1):
                stream.set_time(ITERATIONS, sequence=sr.step.number * PER_STEP + i)
                shown[ITERATIONS] = _show(stream, _frame(sr, i), shown[ITERATIONS])
                if i == 0:
                    stream.log(
                        TEXT,
                        rr.TextDocument(
                            step_markdown(sr, len(step_runs), True),
                            media_type=rr.MediaType.MARKDOWN,
                        ),
                    )
