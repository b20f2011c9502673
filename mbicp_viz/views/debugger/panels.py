"""The debugger's panels: viser GUI elements built from the model's data, and the plot data they
show. Nothing here decides anything: the wiring (``app.py``) reads the handles and drives the
model (``state.py``).

Every number a user types goes through a form of text boxes: the value is applied exactly as
typed when Enter is pressed (or the form's button clicked), or refused with a message; nothing
is reformatted, rounded or clamped on the way.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass

import numpy as np
import viser
import viser.uplot as uplot

from mbicp_viz.core import ParamError, Params, field_specs

from .. import scene
from .state import DebugState, box_label, parse_entry, shown_value


class CommitBox:
    """A text box whose value is applied when the user presses Enter, exactly as typed.

    viser's client sends GUI changes through a 50 ms throttle that keeps only the latest message:
    a value typed just before pressing Enter in a form can be dropped, and the form would submit
    the value before it. Here Enter puts a line break into the box's own value, so the commit and
    the text travel in one message, the latest, which the throttle always delivers. (Two boxes
    changed within 50 ms of each other, faster than a hand moves, still lose the first change.)
    """

    def __init__(self, gui, label: str, text: str, hint: str, on_commit):
        self.handle = gui.add_text(label, text, multiline=True, hint=f"{hint} (Enter applies)")
        self.on_commit = on_commit
        self.handle.on_update(lambda _: self._changed())

    @property
    def text(self) -> str:
        return self.handle.value.split("\n")[0].strip()

    def _changed(self) -> None:
        if "\n" in self.handle.value:
            text = self.text
            self.handle.value = text  # the box shows exactly what is applied
            self.on_commit(text)

    def show(self, text: str) -> None:
        self.handle.value = text  # sent to the page when it differs from what the page sent


@dataclass
class ParamPanel:
    """A folder of commit boxes, one per field of a parameter dataclass, and its message line."""

    folder: viser.GuiFolderHandle
    boxes: dict[str, CommitBox]
    message: viser.GuiMarkdownHandle

    def show(self, params: Params) -> None:
        """Put every box on ``params``: after any change, the page shows what the matcher uses (a box
        edited without Enter goes back), in the words the user typed when they say the same."""
        for s in field_specs(type(params)):
            value, box = getattr(params, s.name), self.boxes[s.name]
            box.show(box.text if _says(s, box.text, value) else shown_value(s, value))


def _says(spec, text: str, value) -> bool:
    try:
        return parse_entry(spec, text) == value
    except ParamError:
        return False


def param_panel(gui, title: str, params: Params, order: float, on_commit) -> ParamPanel:
    """A box per field of ``params`` (units in the label, bounds and help in the hint);
    ``on_commit(name, text)`` runs when the user presses Enter in one."""
    with gui.add_folder(title, order=order) as folder:
        message = gui.add_markdown("")
        boxes = {}
        for s in field_specs(type(params)):
            lo, hi = (None if b is None else (math.degrees(b) if s.unit == "rad" else b) for b in (s.lo, s.hi))
            bounds = "" if lo is None and hi is None else f" [{lo:g} .. {hi:g}]" if s.type is not bool else ""
            boxes[s.name] = CommitBox(gui, box_label(s), shown_value(s, getattr(params, s.name)),
                                      f"{s.help}{bounds}", lambda text, name=s.name: on_commit(name, text))
    return ParamPanel(folder, boxes, message)


@dataclass
class Plots:
    error: viser.GuiUplotHandle
    histogram: viser.GuiUplotHandle
    cost: viser.GuiUplotHandle


def _numeric(x_label: str, *axes: tuple[str, str, int]) -> dict:
    """uPlot options for numeric axes (uPlot's x axis is a time axis unless told otherwise)."""
    scales = {"x": uplot.Scale(time=False, auto=True)} | {key: uplot.Scale(auto=True) for key, _, _ in axes}
    return dict(scales=scales, axes=(uplot.Axis(label=x_label, scale="x"),
                                     *(uplot.Axis(label=label, scale=key, side=side) for key, label, side in axes)))


def plots(gui, order: float) -> Plots:
    empty3 = (np.zeros(1), np.zeros(1), np.zeros(1))
    with gui.add_folder("Plots", order=order):
        error = gui.add_uplot(
            data=empty3, title="error and threshold per iteration", aspect=1.6,
            series=(uplot.Series(label="iteration"),
                    uplot.Series(label=scene.ERROR.label, scale="err", stroke=_css(scene.ERROR.color), width=2),
                    uplot.Series(label=scene.THRESHOLD.label, scale="m", stroke=_css(scene.THRESHOLD.color),
                                 width=2)),
            **_numeric("iteration", ("err", "error [m²]", 3), ("m", "threshold [m]", 1)))
        histogram = gui.add_uplot(
            data=(np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1)),
            title="pair distances (current iteration)", aspect=1.6,
            series=(uplot.Series(label="distance [m]"),
                    uplot.Series(label="pairs", scale="n", stroke=_css(scene.HIST_BARS.color), width=2),
                    uplot.Series(label=scene.MEDIAN.label, scale="n", stroke=_css(scene.MEDIAN.color), width=2),
                    uplot.Series(label=scene.THRESHOLD.label, scale="n", stroke=_css(scene.THRESHOLD.color),
                                 width=2)),
            **_numeric("pair distance [m]", ("n", "pairs per bin", 3)))
        cost = gui.add_uplot(
            data=empty3, title="polar matchers: cost per shift (current iteration)", aspect=1.6, visible=False,
            series=(uplot.Series(label="shift [deg]"),
                    uplot.Series(label="cost [m]", scale="m", stroke=_css(scene.COST.color), width=2),
                    uplot.Series(label=scene.FIT.label, scale="m", stroke=_css(scene.FIT.color), width=2)),
            **_numeric("shift [deg]", ("m", "cost [m]", 3)))
    return Plots(error, histogram, cost)


def _css(rgb) -> str:
    return "rgb({},{},{})".format(*rgb)


def legend_html(styles: list[scene.Style]) -> str:
    """A swatch and a label per style (the layers shown now)."""
    rows = "".join(
        f'<div class="legend-entry" style="display:flex;align-items:center;gap:6px;font-size:12px;line-height:1.6">'
        f'<span style="display:inline-block;width:12px;height:12px;border-radius:6px;background:{_css(s.color)}">'
        f'</span><span>{html.escape(s.label)}</span></div>' for s in styles)
    return f'<div class="mbicp-legend" style="padding:2px 8px">{rows or "no layer shown"}</div>'


# ---- plot data (what the plots show at the current iteration) ---------------------------------

def error_series(state: DebugState) -> tuple[np.ndarray, ...]:
    """Iteration, error [m²] and threshold [m] of the first run (compare: see ``compare_series``)."""
    run = state.runs[0]
    x = np.arange(1, len(run.iterations) + 1, dtype=float)
    err = np.array([e.error for e in run.iterations], dtype=float)
    thr = np.array([np.nan if e.threshold is None else e.threshold for e in run.iterations], dtype=float)
    return x, err, thr


def histogram_series(state: DebugState) -> tuple[np.ndarray, ...]:
    """The current iteration's pair distances as a staircase of bars, with vertical median and
    threshold lines (uPlot joins consecutive points: two points at one x make a vertical line)."""
    ev = state.event(state.runs[0])
    if ev is None or not len(ev.pairs.distance):
        z = np.zeros(1)
        return z, z, np.full(1, np.nan), np.full(1, np.nan)
    h = scene.histogram(ev.pairs.distance, ev.threshold)
    top, nan = float(h.counts.max()) or 1.0, float("nan")
    bx, by = np.repeat(h.edges, 2)[1:-1], np.repeat(h.counts.astype(float), 2)
    rows = [(x, b, nan, nan) for x, b in zip(bx, by)] + [(h.median, nan, 0.0, nan), (h.median, nan, top, nan)]
    if h.threshold is not None:
        rows += [(h.threshold, nan, nan, 0.0), (h.threshold, nan, nan, top)]
    rows.sort(key=lambda r: r[0])  # stable: a line's two points stay in order
    x, bars, median, threshold = np.array(rows).T
    gaps = np.isnan(bars)
    bars[gaps] = np.interp(x[gaps], bx, by)  # the bars' height where a line is inserted
    return x, bars, median, threshold


def cost_series(state: DebugState) -> tuple[np.ndarray, ...] | None:
    """PSM/PMWN: the orientation step's cost per shift and the fit at its minimum; None otherwise."""
    ev = state.event(state.runs[0])
    polar = ev.polar if ev is not None else None
    if polar is None or not np.any(np.isfinite(polar.cost)):
        return None
    step_deg = scene.polar_step_deg(polar)
    x = polar.shifts * step_deg
    fit = np.full(len(x), np.nan)
    curve = scene.fitted_curve(polar, step_deg, n=201)
    if curve is not None:
        near = np.abs(x - curve[:, 0].mean()) <= step_deg * 1.0001
        fit[near] = np.interp(x[near], curve[:, 0], curve[:, 1])
    return x.astype(float), polar.cost.astype(float), fit
