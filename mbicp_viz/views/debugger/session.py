"""One browser tab: the controls wired to the model, and the scene drawn from it.

Every tab has its own ``Session`` (model, controls, scene nodes), so tabs never share state.
Callbacks run on viser's threads; one lock per tab orders them.
"""

from __future__ import annotations

import threading
import time
import traceback
from contextlib import contextmanager
from dataclasses import replace

import numpy as np
import viser

from mbicp_viz.core import tiers
from mbicp_viz.readers.params_toml import params_to_toml

from .. import scene, viser_draw
from . import controls, lesson, panels, report
from .camera import TopDownCamera
from .markdown import literal, wrapping
from .state import DebugState, Source

# A callback running longer than this shows how long it has run, the budget and the stop button
BUSY_AFTER_S = 1.0

COMPILING = (
    "Compiling the matchers' kernels (the first start after an install takes a few seconds)…"
)


class Session:
    """The wiring of one tab: it reads the controls, drives the model and redraws."""

    def __init__(
        self,
        client: viser.ClientHandle | viser.ViserServer,
        source: Source,
        ready: threading.Event | None = None,
    ):
        """``client``: a browser tab, or the server itself (tests: state shared by every tab).
        Without ``ready`` the first match runs at once; with it, the caller runs ``first_match``
        and the page says meanwhile that the matchers' kernels are being compiled."""
        self.client, self.lock = client, threading.RLock()
        self.state = DebugState(source)
        self.nodes: dict[str, object] = {}  # scene node name -> viser handle, as last drawn
        self.grid_m = 1.0  # the metric grid's cell [m]
        self.shown: list[scene.Style] = []  # the styles of what is drawn, for the legend
        self.closed = threading.Event()  # the tab has gone
        self._build(client.gui, source)
        if ready is None:
            self.first_match()
        elif not ready.is_set():
            self.say(COMPILING)

    def _pair_lists(self, gui, src: Source) -> None:
        """An evaluation's pairs to open: its failures, its suspicious pairs, beside a run B where
        the two differ, and a run's loop candidates (with the buttons that decide them)."""
        from mbicp_viz.evaluation.failures import failure_label
        from mbicp_viz.evaluation.health import suspect_label

        lists = [
            (
                "Failures",
                src.failures,
                failure_label,
                "failed, worst first (translation error)",
                "open",
            ),
            (
                "Suspicious pairs",
                src.suspects,
                suspect_label,
                "flagged without truth, the most suspicious first",
                "open flagged",
            ),
        ]
        if src.versus is not None:
            lists.append(
                (
                    "Where runs A and B differ",
                    src.versus.differing(),
                    suspect_label,
                    "pairs end apart, the farthest first (run A's match opens)",
                    "open where they differ",
                )
            )
        for k, (title, rows, label, order_text, pick) in enumerate(lists):
            controls.PairList(self, gui, 5 + 0.5 * k, title, rows, label, order_text, pick)
        if src.loops is not None:
            from .loops import LoopPanel

            LoopPanel(self, gui, 5 + 0.5 * len(lists), src.loops)

    def show_notes(self) -> None:
        """What to look at, and how the log on screen was read (a scan stream picked is read
        anew)."""
        src = self.state.source
        notes = "\n\n".join(filter(None, [src.note, *(f"*{literal(n)}*" for n in src.log.notes)]))
        self.h_notes.content = wrapping(notes) if notes else ""
        self.h_notes.visible = bool(notes)

    def first_match(self, ready: threading.Event | None = None) -> None:
        """The tab's first match, once the kernels are ready (``ready`` set)."""
        if ready is not None:
            ready.wait()
        with self.lock, self._busy():
            if self.lesson is not None:
                self.lesson.open(self.state.source.lesson_step)
                return
            error = self.state.rematch()
            if self.run is not None:  # the rows of a run open on the whole run: the pair's scene
                self.run.enter()  # is drawn when the pair is shown (not sent to be hidden)
            else:
                self.fit_view()
            self.after_match(error)

    def load(self, source: Source, iteration: int | None = None) -> None:
        """Open another source (a lesson's step) in this tab: its pair, matchers, parameters and
        layers, shown at ``iteration`` (None: where the match ended)."""
        self.state = DebugState(source)
        self.show_notes()
        error = self.state.rematch()
        if iteration is not None:
            self.state.iteration = min(iteration, self.state.max_iteration())
        self.matchers.show()
        self.layers.show()
        self.clear_scene()
        self.after_match(error)
        self.fit_view()

    def _build(self, gui, src: Source) -> None:
        gui.configure_theme(control_width="large", show_logo=False, show_share_button=False)
        gui.main_panel.dock_right()  # beside the view, never over it
        gui.add_markdown(wrapping(f"**mbicp-viz** — {literal(src.label)}"), order=0)
        self.h_status, self.status = gui.add_markdown("", order=1), ""
        self.h_stop = gui.add_button(
            "stop the match", order=1.5, color="red", visible=False, hint="keeps the last iteration"
        )
        # not under the tab's lock: the match holds it; the flag is all the loops read
        self.h_stop.on_click(lambda _: self.state.halt.stop("stopped from the page"))
        self.h_notes = gui.add_markdown("", order=2)
        self.show_notes()
        self.lesson = lesson.Lesson(self, gui, src.lesson, order=2) if src.lesson else None
        self.h_legend = gui.add_html(panels.legend_html([]), order=3)
        self.camera = TopDownCamera(self.client)
        gui.add_button("fit the view", order=4, hint="top-down over the reference scan").on_click(
            lambda _: self.fit_view()
        )
        self.run = None
        self._run_panels(gui, src)
        if src.background is not None:
            from .background import BackgroundPanel

            BackgroundPanel(self, gui, 4.5, src.background)
        self.playback = controls.Playback(self, gui, order=10)
        with gui.add_folder("Result", order=20):
            self.h_result = gui.add_markdown("")
        self.matchers = controls.Matchers(self, gui, order=30)
        self.guess = controls.Guess(self, gui, order=40)
        self.scans = controls.Scans(self, gui, order=50) if src.pick_pair else None
        self.layers = controls.Layers(self, gui, order=60)
        self.plots = panels.Plots(gui, order=70)
        with gui.add_folder("Export", order=80):
            gui.add_button("export .rrd").on_click(lambda _: self.guarded(self.export_rrd))
            gui.add_button("save parameters (TOML)").on_click(
                lambda _: self.guarded(self.export_params)
            )

    # ---- showing the model ------------------------------------------------------------------
    def say(self, text: str) -> None:
        self.show_status(panels.warning(text))

    def show_status(self, content: str) -> None:
        """The status line as the model's last news has it (a busy note only covers it)."""
        self.status = self.h_status.content = content

    def compiled(self) -> None:
        """The kernels are ready: the notice that they run interpreted goes (an error stays)."""
        with self.lock:
            if self.status == panels.warning(tiers.INTERPRETED):
                self.say("")

    def after_match(self, error: str | None) -> None:
        """Show a new match, or say why it failed (the last good one stays on screen)."""
        self.say(error or (tiers.INTERPRETED if tiers.compiling() else ""))
        if error:
            return
        self.playback.show(self.state.max_iteration())
        self.redraw()
        self.h_result.content = report.result_markdown(self.state)
        self.plots.show_runs(self.state)
        self.guess.show()

    def _run_panels(self, gui, src: Source) -> None:
        """A run's view and an evaluation's lists of pairs to open."""
        if src.run is not None:
            from .run import RunPanel
            from .run_model import tab_model

            self.run = RunPanel(self, gui, 4.5, tab_model(src))
        if src.rows_label:
            self._pair_lists(gui, src)

    def open_run(self, source: Source) -> None:
        """A run matched in the background (views/debugger/background.py): its view and lists
        added to the tab, and the run shown."""
        self.state.source = source
        self._run_panels(self.client.gui, source)
        if self.run is not None:
            self.run.enter()

    def set_loops(self, loops) -> None:
        """The run's closures decided again (the loop panel): the run view and the result's words
        follow this tab's decisions."""
        self.state.source = replace(self.state.source, loops=loops)
        if self.run is not None:
            self.run.set_loops(loops)
        self.h_result.content = report.result_markdown(self.state)

    def loop_score(self, loops) -> float | None:
        """The mean translational error of the run with its loops closed on the log's relations
        (None: no relations, or none with a scan of the run at both ends)."""
        return self.run.model.mean_error(loops.optimised) if self.run is not None else None

    def open_row(self, row) -> None:
        """Reopen an evaluated pair as it ran (out of the run view); the controls then show its
        matcher, pair and guess."""
        if self.run is not None and self.run.active:
            self.run.leave()
        error = self.state.open_row(row)
        if not error:
            self.matchers.show()
            self.layers.show()  # the layers its failure is seen in
        self.scans.open(error)

    def redraw(self) -> None:
        """Every run's layers at the current iteration, the legend of what is shown, the plots (the
        scene only while the run view is not shown)."""
        if self.run is not None and self.run.active:
            return
        with self.lock, self.client.atomic():
            self.layers.offered(self.state)
            shown: dict[str, scene.Style] = {}
            drawn = []
            for run in self.state.runs:
                for layer in report.layers(self.state, run):
                    if not viser_draw.in_scan_plane(layer):
                        continue
                    visible = self.state.visible.get(layer.style.label, True)
                    drawn.append((f"/{run.matcher}/{layer.path}", layer, visible))
                    if visible and scene.has_content(layer):
                        shown.setdefault(layer.style.label, layer.style)
            # a node of a layer not drawn now (another iteration's step) is removed
            self.nodes = viser_draw.draw_nodes(self.client.scene, self.nodes, drawn)
            self.shown = list(shown.values())
            self.h_legend.content = panels.legend_html(self.shown, self.grid_m)
            self.playback.text.content = "  \n".join(
                f"**{r.matcher}**: {report.iteration_text(self.state, r)}" for r in self.state.runs
            )
            if self.plots.shown is not None:
                self.plots.iteration(self.state)

    def clear_scene(self) -> None:
        for handle in self.nodes.values():
            handle.remove()
        self.nodes = {}

    def fit_view(self) -> None:
        """Top-down over the reference scan (or the source's view), with a metric grid under it (its
        cell size in the legend)."""
        pts = self.state.runs[0].start.ref_points if self.state.runs else np.zeros((1, 2))
        if self.state.source.view is not None:
            pts = np.reshape(self.state.source.view, (2, 2))
        self.camera.fit(pts)
        self.grid_m = viser_draw.metric_grid(self.client.scene, pts)
        self.h_legend.content = panels.legend_html(self.shown, self.grid_m)

    def guarded(self, fn) -> None:
        """Run a callback under the tab's lock; a bug inside it is shown in the page and the server
        keeps serving."""
        try:
            with self.lock, self._busy():
                fn()
        except Exception as e:
            self.say(f"Internal error (the last good result is kept): {type(e).__name__}: {e}")
            traceback.print_exc()

    @contextmanager
    def _busy(self):
        """While a callback runs past ``BUSY_AFTER_S``: how long, each match's budget, and the
        button that stops the match now; the page's text returns when it ends."""
        done, t0 = threading.Event(), time.monotonic()
        limit = report.budget_text(self.state.source.budget_s)

        def tick():
            if done.wait(BUSY_AFTER_S):
                return
            self.h_stop.visible = True
            while True:
                self.h_status.content = panels.warning(
                    f"working for {time.monotonic() - t0:.0f} s ({limit}; the button below "
                    "stops it at its next iteration)"
                )
                if done.wait(0.5):
                    return

        ticker = threading.Thread(target=tick, daemon=True)
        ticker.start()
        try:
            yield
        finally:
            done.set()
            ticker.join()
            self.h_stop.visible = False
            self.h_status.content = self.status

    # ---- export ---------------------------------------------------------------------------
    def export_rrd(self) -> bytes:
        data = report.session_rrd(self.state)
        self.client.send_file_download("mbicp-viz-session.rrd", data, save_immediately=True)
        self.show_status(f"exported the session: {len(data) / 1e6:.2f} MB .rrd")
        return data

    def export_params(self) -> str:
        edited = self.matchers.edited
        text = params_to_toml(self.state.params[edited], self.state.search)
        self.client.send_file_download(
            f"params-{edited}.toml", text.encode(), save_immediately=True
        )
        self.show_status(
            f"saved the {edited} parameters and the search's (TOML, readable with --params)"
        )
        return text

    def close(self) -> None:
        """Stop the player; returns once a frame it was drawing has been sent (nothing is queued
        for a client that has gone, or on a stopped server)."""
        self.closed.set()
        self.playback.closed.set()
        self.camera.stop()
        with self.lock:
            pass
