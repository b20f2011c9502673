"""The lesson as one rerun recording: a ``step`` timeline, the step's text in a text panel, its
matchers' layers at the step's iteration (the first matcher and the second side by side) and the
plot beside them. A step logs its layers over the last step's, and clears what the last step
showed and it does not: scrubbing the timeline shows one step at a time."""

from __future__ import annotations

import rerun as rr
import rerun.blueprint as rrb

from mbicp_viz.views.lesson.steps import StepRun

from . import scene
from .handout import panel_title, side_plot
from .rrd import log_layer, log_y_up, new_stream, y_up_view

ROOT = "lesson"
SLOTS = ("first", "second")  # a step shows at most two matchers side by side (steps.MAX_MATCHERS)
TEXT = f"{ROOT}/text"
PLOT = f"{ROOT}/plot"


def step_markdown(sr: StepRun, total: int) -> str:
    """The text panel of one step: its text, what to try, what each view shows."""
    views = "; ".join(f"{slot} view: {panel_title(sr, r.name, len(r.iterations))}" for slot, r in zip(SLOTS, sr.runs))
    plot = side_plot(sr)
    beside = f"; plot view: {plot.title} (x: {plot.x_label})" if plot is not None else ""
    return (f"## Step {sr.step.number} of {total}: {sr.step.title}\n\n{sr.text}\n\n**Try** (in `mbicp-viz lesson`): "
            f"{sr.try_text}\n\n*{views}{beside}.*\n")


def record_lesson(step_runs: list[StepRun], path: str) -> None:
    stream = new_stream("mbicp-viz/lesson")
    scans = [y_up_view(f"/{ROOT}/{slot}", f"{slot} matcher of the step: scans (reference frame, m)") for slot in SLOTS]
    stream.save(path, default_blueprint=rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(rrb.Horizontal(*scans), y_up_view(f"/{PLOT}", "plot beside the scans"),
                                    row_shares=[3, 2]),
                       rrb.TextDocumentView(origin=f"/{TEXT}", name="the step"), column_shares=[3, 1]),
        rrb.TimePanel(timeline="step", expanded=True, play_state="paused"), collapse_panels=True))
    for space in (*(f"{ROOT}/{slot}" for slot in SLOTS), PLOT):
        log_y_up(stream, space)
    before: set[str] = set()
    for sr in step_runs:
        stream.set_time("step", sequence=sr.step.number)
        now = set()
        layers = [(f"{ROOT}/{slot}", ly) for slot, run in zip(SLOTS, sr.runs)
                  for ly in sr.layers(run, shown_only=True) if ly.path.startswith(f"{scene.SCANS}/")]
        plot = side_plot(sr)
        layers += [(PLOT, ly) for ly in (plot.layers if plot is not None else [])]
        for root, layer in layers:
            log_layer(stream, root, layer)
            now.add(f"{root}/{layer.path}")
        for path in sorted(before - now):  # what the last step showed and this one does not
            stream.log(path, rr.Clear(recursive=True))
        before = now
        stream.log(TEXT, rr.TextDocument(step_markdown(sr, len(step_runs)), media_type=rr.MediaType.MARKDOWN))
    stream.flush()
    stream.disconnect()
