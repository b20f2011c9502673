"""Lesson mode (``mbicp-viz lesson``): the step's text, Back and Next, and the step opened in the
debugger with its scans, matchers, parameters, layers and iteration. Everything else in the page
stays live: the teacher (or the student) changes a parameter or drags the guess, and the Result
panel follows; the step's text keeps the numbers of the step as its file sets it up."""

from __future__ import annotations

import io

import numpy as np

from mbicp_viz.readers import ScanLog
from mbicp_viz.views.lesson.steps import Step, StepRun, run_step

from ..figure import Plot, scene_png
from .state import Source

CHANGED = (
    "*The numbers above are the step's own run, as its file sets it up; the Result panel follows "
    "what you change.*"
)


def step_source(step: Step, lesson: tuple[Step, ...]) -> Source:
    """The debugger's source for one step of ``lesson``."""
    s = step.scenario
    return Source(
        "the MbICP lesson",
        ScanLog(s.name, [s.ref, s.obj]),
        (0, 1),
        False,
        s.guess,
        truth=s.truth,
        params=dict(s.params),
        matchers=tuple(s.params),
        teaching=True,
        shown=tuple(st.label for st in step.layers),
        lesson=lesson,
        lesson_step=lesson.index(step),
        view=step.window,
    )


def plot_image(plot: Plot) -> np.ndarray:
    """A plot beside the text (the step's list of distances), as RGB pixels."""
    import matplotlib.image

    return (matplotlib.image.imread(io.BytesIO(scene_png([], plot, ""))) * 255).astype(np.uint8)[
        :, :, :3
    ]


class Lesson:
    """The lesson panel: which step, its text and what to try, Back and Next."""

    def __init__(self, session, gui, steps: tuple[Step, ...], order: float):
        self.s, self.steps, self.k = session, steps, 0
        self.runs: dict[int, StepRun] = {}  # step number -> its run (run once per tab)
        with gui.add_folder("Lesson", order=order):
            self.heading = gui.add_markdown("")
            self.text = gui.add_markdown("")
            self.figure = gui.add_image(
                np.full((8, 8, 3), 255, np.uint8), label="paper 000 Fig. 9", visible=False
            )
            self.try_text = gui.add_markdown("")
            back, forward = gui.add_button("previous step"), gui.add_button("next step")
            self.pick = gui.add_dropdown(
                "step", [self._label(s) for s in steps], initial_value=self._label(steps[0])
            )
        back.on_click(lambda _: session.guarded(lambda: self.open(self.k - 1)))
        forward.on_click(lambda _: session.guarded(lambda: self.open(self.k + 1)))
        self.pick.on_update(lambda _: session.guarded(self._picked))

    @staticmethod
    def _label(step: Step) -> str:
        return f"{step.number}. {step.title}"

    def _picked(self) -> None:
        k = next((i for i, s in enumerate(self.steps) if self._label(s) == self.pick.value), None)
        if k is None:  # not one of the listed steps (a message no page of ours sends)
            self.s.say(f"no such step: {str(self.pick.value)[:80]!r}")
            self.pick.value = self._label(self.steps[self.k])
        elif k != self.k:
            self.open(k)

    def open(self, k: int) -> None:
        """Open step ``k`` (0-based; clipped to the lesson)."""
        self.k = int(np.clip(k, 0, len(self.steps) - 1))
        step = self.steps[self.k]
        if step.number not in self.runs:
            self.runs[step.number] = run_step(step)
        sr = self.runs[step.number]
        # the scene first: the text then describes it
        self.s.load(step_source(step, self.steps), sr.iteration)
        self.heading.content = f"**Step {step.number} of {len(self.steps)}: {step.title}**"
        self.text.content = sr.text
        self.try_text.content = f"**Try:** {sr.try_text}\n\n{CHANGED}"
        distances = sr.distance_layers()
        if distances:
            from ..lesson.handout import side_plot

            self.figure.image = plot_image(side_plot(sr))
        self.figure.visible = bool(distances)
        self.pick.value = self._label(step)
