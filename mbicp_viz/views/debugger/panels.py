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
from dataclasses import dataclass, replace

import numpy as np
import viser
import viser.uplot as uplot

from mbicp_viz.core import MATCHERS, ParamError, Params, field_specs

from .. import scene
from . import report
from .markdown import literal
from .state import DebugState, box_label, parse_entry, shown_value


def warning(text: str) -> str:
    """A status line that something went wrong or is slow ("" clears it), shown as written."""
    return f"⚠ {literal(text)}" if text else ""


class CommitBox:
    """A text box whose value is applied when the user presses Enter, exactly as typed.

    viser's client sends GUI changes through a 50 ms throttle that keeps only the latest message:
    a value typed just before pressing Enter in a form can be dropped, and the form would submit
    the value before it. Here Enter puts a line break into the box's own value, so the commit and
    the text travel in one message, the latest, which the throttle always delivers. (Two boxes
    changed within 50 ms of each other, faster than a hand moves, still lose the first change.)
    """

    def __init__(self, gui, label: str, text: str, hint: str, on_commit, on_pending=None):
        self.applied = text
        self.handle = gui.add_text(label, text, multiline=True, hint=f"{hint} (Enter applies)")
        self.on_commit, self.on_pending = on_commit, on_pending
        self.handle.on_update(lambda _: self._changed())

    @property
    def text(self) -> str:
        return self.handle.value.split("\n")[0].strip()

    def _changed(self) -> None:
        if "\n" in self.handle.value:
            text = self.applied = self.text
            self.handle.value = text  # the box shows exactly what is applied
            self.on_commit(text)
        elif self.on_pending is not None:  # typed, not applied: the page must not pass it off
            self.on_pending(self.text if self.text != self.applied else None)

    def show(self, text: str) -> None:
        self.applied = text
        self.handle.value = text  # sent to the page when it differs from what the page sent


@dataclass
class ParamPanel:
    """A folder of commit boxes, one per field of a parameter dataclass, and its message line."""

    folder: viser.GuiFolderHandle
    boxes: dict[str, CommitBox]
    message: viser.GuiMarkdownHandle

    def pending(self, label: str, text: str | None) -> None:
        """Say that a box shows text that is not applied (typed without Enter); None: it is."""
        notice = f"{label}: '{text}' is not applied yet: Enter applies it"
        if text is not None:
            self.message.content = warning(notice)
        elif "is not applied yet" in self.message.content:
            self.message.content = ""

    def show(self, params: Params) -> None:
        """Put every box on ``params``: after any change, the page shows what the matcher uses (a
        box edited without Enter goes back), in the words the user typed when they say the same."""
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
            lo, hi = (
                None if b is None else (math.degrees(b) if s.unit == "rad" else b)
                for b in (s.lo, s.hi)
            )
            bounds = (
                ""
                if lo is None and hi is None
                else f" [{lo:g} .. {hi:g}]"
                if s.type is not bool
                else ""
            )
            label = box_label(s)
            boxes[s.name] = CommitBox(
                gui,
                label,
                shown_value(s, getattr(params, s.name)),
                f"{s.help}{bounds}",
                lambda text, name=s.name: on_commit(name, text),
                lambda text, label=label: panel.pending(label, text),
            )
    panel = ParamPanel(folder, boxes, message)
    return panel


def _numeric(x_label: str, *axes: tuple[str, str, int, float]) -> dict:
    """uPlot options: a numeric x axis (uPlot's is a time axis unless told otherwise) and y axes of
    fixed range [0, top]. The ranges cover every iteration of the runs, so the axes stay still while
    stepping, and a gap (NaN) in a line cannot break the auto-ranging (uPlot draws nothing when a
    line on an auto-ranged axis starts with one)."""
    scales = {"x": uplot.Scale(time=False, auto=True)}
    scales |= {key: uplot.Scale(auto=False, range=(0.0, top)) for key, _, _, top in axes}
    return dict(
        scales=scales,
        axes=(
            uplot.Axis(label=x_label, scale="x"),
            *(
                uplot.Axis(label=label, scale=key, side=side)
                for key, label, side, _ in axes
                if label
            ),
        ),
    )


def health_legend(x_label: str) -> list[uplot.Series]:
    """The lines of a run's health timeline (``RunModel.series``), after its x."""
    return [
        uplot.Series(label=x_label),
        _line("overlap [%]", "pct", scene.SURFACE),
        _line("from odometry [mm]", "mm", scene.FROM_ODOMETRY),
        _line("flagged [% of pairs]", "pct", scene.SUSPECT),
        _line("residual [mm]", "mm", scene.RESIDUAL),
    ]


# the most points a health timeline sends: a plot a few hundred pixels wide shows no more, and
# the full Intel run's five lines of 13,630 pairs took the browser 1.7 s (median) to draw
HEALTH_POINTS = 2_000


def worst_of_each(series: tuple[np.ndarray, ...], most: int = HEALTH_POINTS):
    """A health timeline (``RunModel.series``) thinned to at most ``most`` points, each the worst
    of the consecutive pairs it covers (the lowest overlap; the largest distances and residual)
    at the first one's number: a spike stays on the plot. The flag line is the share of those
    pairs flagged [%]: the largest would be a solid band where flags are frequent (the Intel
    run), the share shows where they crowd. Returns the series and how many pairs a point
    covers."""
    n = len(series[0])
    k = math.ceil(n / most)
    if k <= 1:
        return series, 1
    starts = np.arange(0, n, k)
    counts = np.diff(np.append(starts, n))
    lowest, share = 1, 3  # the overlap: its lowest is its worst; the flags (0 or 100 a pair)
    thinned = [
        np.add.reduceat(y, starts) / counts
        if i == share
        else (np.fmin if i == lowest else np.fmax).reduceat(y, starts)
        for i, y in enumerate(series[1:], start=1)
    ]
    return (series[0][starts], *thinned), k


def health_axes(x_label: str, top_mm: float) -> dict:
    """The health timeline's axes: overlap [%] on the left, millimetres up to ``top_mm`` on the
    right."""
    return _numeric(x_label, ("pct", "overlap [%]", 3, 105.0), ("mm", "[mm]", 1, top_mm))


# viser's slider row below a plot: its label column (7.25em less 0.6375em a folder level, at the
# panel's 14.8 px font) and its number box (3rem and a margin) around the track, measured in
# Chromium (tests/test_browser.py checks the plot's area stays over the track)
SLIDER_LEFT_PX, SLIDER_RIGHT_PX = 100.5, 58.3
LABEL_PX = 16  # the right axis's label, narrowed to fit the number box's width


def timeline_over_slider(x_label: str, top_mm: float, last: int) -> dict:
    """The health timeline's options (``health_axes``) with its area exactly over the slider row
    below it, x from 1 to ``last`` at the track's ends: a click on the track under a spike picks
    its pair (viser's plots send no clicks). uPlot's axis size leaves out its label; the x range
    is fixed (no drag zoom), so the alignment holds."""
    options = health_axes(x_label, top_mm)
    x, overlap, mm = options["axes"]
    return options | dict(
        scales=options["scales"]
        | {"x": uplot.Scale(time=False, auto=False, range=(1, max(last, 2)))},
        axes=(
            x,
            overlap | uplot.Axis(size=SLIDER_LEFT_PX - 30),  # uPlot's label is 30 px
            mm
            | uplot.Axis(
                size=SLIDER_RIGHT_PX - LABEL_PX,
                labelSize=LABEL_PX,
                font="10px system-ui",
                gap=2,
                ticks=uplot.Axis_Ticks(size=4),
            ),
        ),
        padding=(10, 0, 0, 0),
        cursor=uplot.Cursor(drag=uplot.Cursor_Drag(x=False, y=False)),
    )


def _line(label: str, scale: str, style: scene.Style, dash: bool = False) -> uplot.Series:
    return uplot.Series(
        label=label, scale=scale, stroke=_css(style.color), width=2, dash=[6, 4] if dash else None
    )


def _top(values) -> float:
    """The top of a fixed y range: a little above the largest finite value (1 when there is
    none)."""
    v = np.asarray([x for x in values if x is not None], dtype=float)
    v = v[np.isfinite(v)]
    return float(v.max()) * 1.08 if len(v) and v.max() > 0 else 1.0


class Plots:
    """Error and threshold of every run per iteration; each run's pair distances and (PSM, PMWN)
    cost per shift at the current iteration. The plots follow the runs: each run its lines,
    each line its legend entry, numeric axes with units."""

    def __init__(self, gui, order: float):
        self.gui, self.shown = gui, None
        with gui.add_folder("Plots", order=order) as self.folder:
            self.error = self.cost = None
            self.histograms = []

    def show_runs(self, state: DebugState) -> None:
        """Rebuild the plots when the runs (matchers, parameters, pair, guess) change; then fill
        them."""
        key = tuple(id(r) for r in state.runs)
        if key != self.shown:
            self.shown = key
            for handle in (self.error, self.cost, *self.histograms):
                if handle is not None:
                    handle.remove()
            with self.folder:
                self._build(state)
        self.error.data = error_series(state)
        self.iteration(state)

    def _build(self, state: DebugState) -> None:
        events = [e for r in state.runs for e in r.iterations]
        polar = polar_run(state)
        self.error = self.gui.add_uplot(
            data=error_series(state),
            series=error_legend(state),
            aspect=1.6,
            title="error and threshold per iteration",
            **_numeric(
                "iteration",
                ("err", "error [mm²]", 3, _top(e.error * MM2_PER_M2 for e in events)),
                ("m", "threshold [m]", 1, _top(e.threshold for e in events)),
            ),
        )
        self.histograms = [self._histogram(state, run) for run in state.runs]
        costs = [
            np.nanmax(e.polar.cost)
            for r in polar_runs(state)
            for e in r.iterations
            if np.any(np.isfinite(e.polar.cost))
        ]
        names = " and ".join(r.matcher for r in polar_runs(state)) or "polar matchers"
        self.cost = self.gui.add_uplot(
            data=cost_series(state) or (np.zeros(1),) * len(cost_legend(state)),
            aspect=1.6,
            visible=polar is not None,
            title=f"{names}: cost per shift (this iteration)",
            series=cost_legend(state),
            **_numeric("shift [deg]", ("m", "cost [m]", 3, _top(costs))),
        )

    def _histogram(self, state: DebugState, run):
        counts = [
            scene.histogram(e.pairs.distance, e.threshold).counts.max()
            for e in run.iterations
            if len(e.pairs.distance)
        ]
        return self.gui.add_uplot(
            data=histogram_series(state, run),
            series=histogram_legend(state, run),
            legend=uplot.Legend(live=False),
            aspect=1.6,
            title=f"{run.matcher}: pair distances (this iteration)",
            **_numeric(
                "pair distance [m]", ("n", "pairs per bin", 3, _top(counts)), ("mark", "", 1, 1.0)
            ),
        )

    def iteration(self, state: DebugState) -> None:
        """The plots of the current iteration."""
        for plot, run in zip(self.histograms, state.runs):
            plot.data = histogram_series(state, run)
            legend = histogram_legend(state, run)
            if legend != plot.series:
                plot.series = legend
        cost = cost_series(state)
        if cost is not None:
            self.cost.data = cost


def _css(rgb) -> str:
    return "rgb({},{},{})".format(*rgb)


def legend_html(
    styles: list[scene.Style],
    grid_m: float | None = None,
    frame: str = "the reference laser frame",
) -> str:
    """A swatch and a label per style (the layers shown now), and the grid's cell size."""
    grid = (
        '<div class="legend-entry" style="font-size:12px;line-height:1.6;color:#666">grid: '
        f"{grid_m:g} m cells, "
        f"thicker every {5 * grid_m:g} m; x right, y up ({html.escape(frame)})</div>"
        if grid_m
        else ""
    )
    rows = "".join(
        '<div class="legend-entry" '
        'style="display:flex;align-items:center;gap:6px;font-size:12px;line-height:1.6">'
        '<span style="display:inline-block;width:12px;height:12px;border-radius:6px;'
        f'background:{_css(s.color)}">'
        f"</span><span>{html.escape(s.label)}</span></div>"
        for s in styles
    )
    return (
        f'<div class="mbicp-legend" style="padding:2px 8px">{rows or "no layer shown"}{grid}</div>'
    )


# ---- plot data (what the plots show at the current iteration) ---------------------------------


# The page plots the error in mm²: uPlot labels a tick with at most three decimals, so the m² of
# a converged match (1e-5 and below) read "0" at every tick of the axis.
MM2_PER_M2 = 1e6
ERROR_MM2 = replace(scene.ERROR, label="mean squared residual [mm²]")


def error_legend(state: DebugState) -> tuple[uplot.Series, ...]:
    series = [uplot.Series(label="iteration")]
    for run in state.runs:
        own = MATCHERS[run.matcher].colour if len(state.runs) > 1 else ERROR_MM2.color
        series.append(
            _line(f"{run.matcher}: {ERROR_MM2.label}", "err", replace(ERROR_MM2, color=own))
        )
        thr = scene.threshold_style(run.start.params)
        own = MATCHERS[run.matcher].colour if len(state.runs) > 1 else thr.color
        series.append(_line(f"{run.matcher}: {thr.label}", "m", replace(thr, color=own), dash=True))
    return tuple(series)


def error_series(state: DebugState) -> tuple[np.ndarray, ...]:
    """Iteration, then error [mm²] and threshold [m] of each run (NaN past its end or without
    one)."""
    n = max(state.max_iteration(), 1)
    out = [np.arange(1, n + 1, dtype=float)]
    for run in state.runs:
        err, thr = np.full(n, np.nan), np.full(n, np.nan)
        for k, e in enumerate(run.iterations):
            err[k] = e.error * MM2_PER_M2
            thr[k] = np.nan if e.threshold is None else e.threshold
        out += [err, thr]
    return tuple(out)


def histogram_legend(state: DebugState, run) -> tuple[uplot.Series, ...]:
    """A run's distance plot entries, each with its value at the current iteration: the marks are
    vertical lines, so a value under the cursor would be a gap (uPlot's live legend read "NaN")."""
    params = run.start.params
    cut = scene.hard_cut(params)
    ev = report.event(state, run)
    pairs = len(ev.pairs.distance) if ev is not None else 0
    h = scene.histogram(ev.pairs.distance, ev.threshold) if pairs else None

    def at(label: str, value: float | None) -> str:
        shown = "none this iteration" if value is None else f"{value:.3g} m"
        return f"{label.removesuffix(' [m]')}: {shown}"

    return (
        uplot.Series(label="distance [m]"),
        _line(f"{scene.HIST_BARS.label} ({pairs} pairs)", "n", scene.HIST_BARS),
        _line(at(scene.MEDIAN.label, h and h.median), "mark", scene.MEDIAN),
        _line(at(scene.threshold_style(params).label, h and h.threshold), "mark", scene.THRESHOLD),
        _line(cut[0].label if cut else "no hard cut", "mark", scene.HARD_CUT, dash=True),
    )


def polar_runs(state: DebugState) -> list:
    """The runs of the polar matchers (PSM, PMWN): the ones with a cost per shift."""
    return [r for r in state.runs if r.iterations and r.iterations[0].polar is not None]


def polar_run(state: DebugState):
    return next(iter(polar_runs(state)), None)


def cost_legend(state: DebugState) -> tuple[uplot.Series, ...]:
    """The shift, then each polar run's cost and fit, in its matcher's colour when there are
    several (PMWN's V beside PSM's parabola)."""
    runs = polar_runs(state) or [None]
    series = [uplot.Series(label="shift [deg]")]
    for run in runs:
        name = f"{run.matcher}: " if run is not None and len(runs) > 1 else ""
        own = MATCHERS[run.matcher].colour if run is not None and len(runs) > 1 else None
        for label, style, dash in (
            ("cost [m]", scene.COST, False),
            (scene.FIT.label, scene.FIT, True),
        ):
            drawn = replace(style, color=own) if own else style
            line = _line(f"{name}{label}", "m", drawn, dash=dash and own is not None)
            series.append(uplot.Series(**line, spanGaps=True))
    return tuple(series)


def histogram_series(state: DebugState, run) -> tuple[np.ndarray, ...]:
    """A run's pair distances at the current iteration as a staircase of bars, and vertical lines
    (0 to 1 on the plot's full height) at the median, the threshold and the hard cut; uPlot joins
    consecutive points, so two points at one x make a vertical line."""
    ev = report.event(state, run)
    if ev is None or not len(ev.pairs.distance):
        z, nan = np.zeros(2), np.full(2, np.nan)
        return np.array([0.0, 1.0]), z, nan, nan, nan
    h = scene.histogram(ev.pairs.distance, ev.threshold)
    cut = scene.hard_cut(run.start.params)
    bx, by = np.repeat(h.edges, 2)[1:-1], np.repeat(h.counts.astype(float), 2)
    return with_marks(bx, by, [h.median, h.threshold, cut[1] if cut else None])


def with_marks(x: np.ndarray, y: np.ndarray, marks: list[float | None]) -> tuple[np.ndarray, ...]:
    """A curve and, for each mark, a vertical line at its x (0 to 1 on the plot's full height;
    None: no line); uPlot joins consecutive points, so two points at one x make a vertical line.
    The curve's height is interpolated where a line's points are inserted (0 past its end)."""
    nan, width = float("nan"), 2 + len(marks)
    rows = [(a, b, *[nan] * len(marks)) for a, b in zip(x, y)]
    for column, value in enumerate(marks, start=2):
        if value is not None:
            rows += [
                tuple(value if c == 0 else (h if c == column else nan) for c in range(width))
                for h in (0.0, 1.0)
            ]
    rows.sort(key=lambda r: r[0])  # stable: a line's two points stay in order
    xs, curve, *lines = np.array(rows).T
    gaps = np.isnan(curve)
    curve[gaps] = np.interp(xs[gaps], x, y, right=0.0)
    return (xs, curve, *lines)


def cost_series(state: DebugState) -> tuple[np.ndarray, ...] | None:
    """PSM/PMWN: each polar run's orientation-step cost per shift and the fit at its minimum, on
    the shifts of all of them (a run's gaps where its shifts end); None without a cost."""
    curves = [_cost_curve(state, r) for r in polar_runs(state)]
    if not curves or all(c is None for c in curves):
        return None
    x = np.unique(np.concatenate([c[0] for c in curves if c is not None]))
    out = [x]
    for c in curves:
        for k in (1, 2):
            y = np.full(len(x), np.nan)
            if c is not None:
                y[np.searchsorted(x, c[0])] = c[k]
            out.append(y)
    return tuple(out)


def _cost_curve(state: DebugState, run) -> tuple[np.ndarray, ...] | None:
    ev = report.event(state, run)
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
