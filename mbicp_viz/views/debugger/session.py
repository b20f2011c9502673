"""One browser tab: the panels wired to the model, and the scene drawn from it.

Every tab has its own ``Session`` (model, panels, scene nodes), so tabs never share state.
Callbacks run on viser's threads; one lock orders them.
"""

from __future__ import annotations

import math
import tempfile
import threading
import traceback
from pathlib import Path

import numpy as np
import viser

from mbicp_viz.core import MATCHERS, Pose2
from mbicp_viz.readers.params_toml import params_to_toml

from .. import scene, viser_draw
from . import panels
from .camera import TopDownCamera
from .state import DebugState, Source

GUESS_FIELDS = (("x", "x [m]"), ("y", "y [m]"), ("theta", "theta [deg]"))


class Session:
    """The wiring of one tab: it reads the panels, drives the model and redraws."""

    def __init__(self, client: viser.ClientHandle | viser.ViserServer, source: Source,
                 ready: threading.Event | None = None):
        """``client``: a browser tab, or the server itself (tests: state shared by every tab);
        ``ready``: set once the matchers' kernels are compiled (the page says so meanwhile)."""
        self.client, self.lock = client, threading.RLock()
        self.state = DebugState(source)
        self.nodes: dict[str, object] = {}  # scene node name -> viser handle, as last drawn
        self.closed = threading.Event()
        self.fps, self.playing = 4.0, False
        self.edited = self.state.algorithms[0]  # the matcher whose parameters the form shows
        self._build()
        if ready is not None and not ready.is_set():
            self.say("Compiling the matchers' kernels (the first start after an install takes a few seconds)…")
            ready.wait()
        with self.lock:
            self._after_match(self.state.rematch())
            self.camera.fit(self._extent_points())
        threading.Thread(target=self._player, daemon=True).start()

    # ---- building -------------------------------------------------------------------------
    def _build(self) -> None:
        gui, src = self.client.gui, self.state.source
        gui.add_markdown(f"**mbicp-viz** — {src.label}", order=0)
        self.h_status = gui.add_markdown("", order=1)
        if src.note:
            gui.add_markdown(src.note, order=2)
        self.h_legend = gui.add_html(panels.legend_html([]), order=3)
        self.playback = panels.playback(gui, order=10)
        self.playback.slider.on_update(lambda _: self._guarded(self._on_iteration))
        self.playback.previous.on_click(lambda _: self._guarded(lambda: self.step(-1)))
        self.playback.next.on_click(lambda _: self._guarded(lambda: self.step(+1)))
        self.playback.play.on_update(lambda _: setattr(self, "playing", self.playback.play.value))
        self.playback.speed.on_update(lambda _: setattr(self, "fps", self.playback.speed.value))
        with gui.add_folder("Result", order=20):
            self.h_result = gui.add_markdown("")
        self.gizmo = self.client.scene.add_transform_controls(
            "/guess", scale=0.8, disable_sliders=True, active_axes=(True, True, False),
            rotation_limits=((0.0, 0.0), (0.0, 0.0), (-1000.0, 1000.0)))
        self.gizmo.on_update(lambda _: self._guarded(self._on_gizmo))
        self._build_matchers(gui)
        self._build_guess(gui)
        if src.pick_pair:
            self._build_scans(gui)
        self._build_layers(gui)
        self.plots = panels.plots(gui, order=70)
        with gui.add_folder("Export", order=80):
            gui.add_button("export .rrd").on_click(lambda _: self._guarded(self.export_rrd))
            gui.add_button("save parameters (TOML)").on_click(lambda _: self._guarded(self.export_params))
        self.camera = TopDownCamera(self.client)
        gui.add_button("fit the view", order=5, hint="top-down over the reference scan").on_click(
            lambda _: self.camera.fit(self._extent_points()))
        self.client.scene.on_click()(lambda ev: self._guarded(lambda: self.click(ev.ray_origin, ev.ray_direction)))

    def _build_matchers(self, gui) -> None:
        with gui.add_folder("Matchers", order=30):
            self.h_matchers = {}
            for name, m in MATCHERS.items():
                box = gui.add_checkbox(name, name in self.state.algorithms, hint=m.title)
                box.on_update(lambda _: self._guarded(self._on_matchers))
                self.h_matchers[name] = box
            self.h_edit = gui.add_dropdown("parameters of", list(MATCHERS), initial_value=self.edited)
            self.h_edit.on_update(lambda _: self._guarded(self._on_edit))
        self.params_panel = None
        self._build_params_panel()

    def _build_params_panel(self) -> None:
        if self.params_panel is not None:
            self.params_panel.folder.remove()
        self.params_panel = panels.param_panel(
            self.client.gui, f"Parameters: {self.edited}", self.state.params[self.edited], order=31,
            on_commit=lambda name, text: self._guarded(lambda: self._on_param(name, text)))

    def _build_guess(self, gui) -> None:
        with gui.add_folder("Initial guess", order=40):
            self.h_guess_info = gui.add_markdown("")
            self.h_guess = {key: panels.CommitBox(gui, label, "", "the object frame in the reference frame",
                                                  lambda text, key=key: self._guarded(lambda: self._on_guess(key, text)))
                            for key, label in GUESS_FIELDS}
            self.h_gizmo_on = gui.add_checkbox("drag the guess in the view", True)
            self.h_gizmo_on.on_update(lambda _: setattr(self.gizmo, "visible", self.h_gizmo_on.value))
            gui.add_button("search the guess", hint="correlative search around the current guess (search "
                                                    "parameters below); the match restarts from its best pose"
                           ).on_click(lambda _: self._guarded(self._on_search))
        self.search_panel = panels.param_panel(
            gui, "Search parameters", self.state.search, order=41,
            on_commit=lambda name, text: self._guarded(lambda: self._on_search_param(name, text)))
        self._show_guess()

    def _build_scans(self, gui) -> None:
        n = self.state.source.log.records
        with gui.add_folder(f"Scans (0 .. {n - 1})", order=50):
            self.h_consecutive = gui.add_checkbox("consecutive (object = reference + 1)", True)
            self.h_ref = panels.CommitBox(gui, "reference scan", str(self.state.pair[0]), "a scan number",
                                          lambda text: self._guarded(lambda: self._on_pair(ref=text)))
            self.h_obj = panels.CommitBox(gui, "object scan", str(self.state.pair[1]), "a scan number",
                                          lambda text: self._guarded(lambda: self._on_pair(obj=text)))

    def _build_layers(self, gui) -> None:
        with gui.add_folder("Layers", order=60):
            self.layer_boxes = {}
            for s in scene.STYLES:
                box = gui.add_checkbox(s.label, self.state.visible[s.label])
                box.on_update(lambda ev, label=s.label: self._guarded(lambda: self._on_layer(label, ev.target.value)))
                self.layer_boxes[s.label] = box
            self.h_iso = panels.CommitBox(gui, "iso-curves of object point", "",
                                          "click a blue point in the view, or type its index (empty: a few spread)",
                                          lambda text: self._guarded(lambda: self._on_iso(text)))

    # ---- drawing --------------------------------------------------------------------------
    def say(self, text: str) -> None:
        self.h_status.content = f"⚠ {text}" if text else ""

    def redraw(self) -> None:
        with self.lock, self.client.atomic():
            shown: dict[str, scene.Style] = {}
            for run in self.state.runs:
                for layer in self.state.layers(run):
                    if not viser_draw.in_scan_plane(layer):
                        continue
                    visible = self.state.visible.get(layer.style.label, True)
                    self.nodes[f"/{run.name}/{layer.path}"] = viser_draw.draw(
                        self.client.scene, f"/{run.name}/{layer.path}", layer, visible)
                    if visible and _has_content(layer):
                        shown.setdefault(layer.style.label, layer.style)
            self.h_legend.content = panels.legend_html(list(shown.values()))
            self.playback.text.content = "  \n".join(
                f"**{r.name}**: {self.state.iteration_text(r)}" for r in self.state.runs)
            self._update_plots()

    def _update_plots(self) -> None:
        self.plots.histogram.data = panels.histogram_series(self.state)
        cost = panels.cost_series(self.state)
        self.plots.cost.visible = cost is not None
        if cost is not None:
            self.plots.cost.data = cost

    def _after_match(self, error: str | None) -> None:
        """Show a new match (or say why it failed, keeping the last good one)."""
        self.say(error or "")
        if error:
            return
        n = self.state.max_iteration()
        self.playback.slider.max = max(n, 1)
        self.playback.slider.value = n  # the model is there already: no second redraw
        self.redraw()
        self.h_result.content = self.state.result_markdown()
        self.plots.error.data = panels.error_series(self.state)
        self._show_guess()

    def _show_guess(self) -> None:
        g = self.state.guess
        for key, value in (("x", g.x), ("y", g.y), ("theta", math.degrees(g.theta))):
            self.h_guess[key].show(repr(round(value, 9)))
        self.h_guess_info.content = f"from: {self.state.guess_source}"
        self.gizmo.position, self.gizmo.wxyz = (g.x, g.y, 0.0), viser_draw.yaw_to_wxyz(g.theta)

    def _extent_points(self) -> np.ndarray:
        return self.state.runs[0].start.ref_points if self.state.runs else np.zeros((1, 2))

    # ---- callbacks --------------------------------------------------------------------------
    def _guarded(self, fn) -> None:
        """Run a callback; a bug inside it is shown in the page and the server keeps serving."""
        try:
            with self.lock:
                fn()
        except Exception as e:
            self.say(f"Internal error (the last good result is kept): {type(e).__name__}: {e}")
            traceback.print_exc()

    def _on_iteration(self) -> None:
        k = int(self.playback.slider.value)
        if k != self.state.iteration:
            self.state.iteration = k
            self.redraw()

    def step(self, delta: int) -> None:
        self.playback.slider.value = int(np.clip(self.state.iteration + delta, 0, self.state.max_iteration()))

    def _on_matchers(self) -> None:
        chosen = [n for n, box in self.h_matchers.items() if box.value]
        error = self.state.set_algorithms(chosen)
        if error:
            for n, box in self.h_matchers.items():
                box.value = n in self.state.algorithms
        self._clear_nodes()
        self._after_match(error)

    def _on_edit(self) -> None:
        self.edited = self.h_edit.value
        self._build_params_panel()

    def _on_param(self, name: str, text: str) -> None:
        """Apply one parameter as typed, or say why not (the box goes back, the last good result stays)."""
        error = self.state.set_params(self.edited, {name: text})
        refused = error is not None and error != self.state.message  # a value, not the match, is wrong
        self.params_panel.message.content = f"⚠ {error} — the last good value is kept" if refused else ""
        self.params_panel.show(self.state.params[self.edited])  # the boxes show what the matcher uses
        if not refused:
            self._after_match(error)

    def _on_search_param(self, name: str, text: str) -> None:
        error = self.state.set_search({name: text})
        self.search_panel.message.content = f"⚠ {error} — the last good value is kept" if error else ""
        self.search_panel.show(self.state.search)

    def _on_guess(self, key: str, text: str) -> None:
        try:
            value = float(text)
        except ValueError:
            self.say(f"initial guess {key}: not a number: {text!r}")
            return
        g = self.state.guess
        x, y, theta = (value if key == k else v for k, v in (("x", g.x), ("y", g.y), ("theta", math.degrees(g.theta))))
        self._after_match(self.state.set_guess(Pose2(x, y, math.radians(theta))))

    def _on_gizmo(self) -> None:
        x, y, _ = (float(v) for v in self.gizmo.position)
        self._after_match(self.state.set_guess(Pose2(x, y, viser_draw.wxyz_to_yaw(self.gizmo.wxyz)), "dragged"))

    def _on_search(self) -> None:
        self._after_match(self.state.search_guess())

    def _on_pair(self, ref: str | None = None, obj: str | None = None) -> None:
        try:
            i = int(ref) if ref is not None else self.state.pair[0]
            j = i + 1 if self.h_consecutive.value else (int(obj) if obj is not None else self.state.pair[1])
        except ValueError:
            self.say("scan numbers must be whole numbers")
            return
        error = self.state.set_pair(i, j)
        if not error:
            self._clear_nodes()
        self.h_ref.show(str(self.state.pair[0]))
        self.h_obj.show(str(self.state.pair[1]))
        self._after_match(error)
        self.camera.fit(self._extent_points())

    def _on_iso(self, text: str) -> None:
        if not text:
            self.state.iso_point = None
        elif text.isdigit():
            self.state.iso_point = int(text)
            self._show_teaching()
        else:
            self.say(f"iso-curves: an object point index, got {text!r}")
            return
        self.redraw()

    def _show_teaching(self) -> None:
        for style in (scene.ISO_METRIC, scene.ISO_EUCLID):
            self.state.visible[style.label] = True
            self.layer_boxes[style.label].value = True

    def _on_layer(self, label: str, value: bool) -> None:
        self.state.visible[label] = bool(value)
        self.redraw()

    def click(self, origin, direction) -> int | None:
        """Choose the object point nearest to where a view ray meets the scan plane (z = 0)."""
        o, d = np.asarray(origin, float), np.asarray(direction, float)
        if abs(d[2]) < 1e-9 or not self.state.runs:
            return None
        xy = (o - o[2] / d[2] * d)[:2]
        run = self.state.runs[0]
        ev = self.state.event(run)
        moved = ev.moved_points if ev is not None else run.start.initial_guess.apply(run.start.obj_points[run.start.used])
        self.state.iso_point = int(run.start.used[int(np.argmin(np.hypot(*(moved - xy).T)))])
        self.h_iso.show(str(self.state.iso_point))
        self._show_teaching()
        self.redraw()
        return self.state.iso_point

    def _clear_nodes(self) -> None:
        for handle in self.nodes.values():
            handle.remove()
        self.nodes = {}

    # ---- export -----------------------------------------------------------------------------
    def export_rrd(self) -> bytes:
        """The session (data, parameters, all iterations) as an .rrd, offered as a download."""
        from ..rrd import Run, record

        s = self.state
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "session.rrd"
            runs = [Run(n, s.ref, s.obj, s.guess, s.params[n], s.truth()) for n in s.algorithms]
            record(runs, str(path), teaching=True, recording_id="mbicp-viz/session",
                   about=f"# mbicp-viz session\n\n{s.source.label}: {s.pair_label()}; initial guess {s.guess} "
                         f"({s.guess_source})\n")
            data = path.read_bytes()
        self.client.send_file_download("mbicp-viz-session.rrd", data, save_immediately=True)
        self.say("")
        self.h_status.content = f"exported the session: {len(data) / 1e6:.2f} MB .rrd"
        return data

    def export_params(self) -> str:
        text = params_to_toml(self.state.params[self.edited], self.state.search)
        self.client.send_file_download(f"params-{self.edited}.toml", text.encode(), save_immediately=True)
        self.h_status.content = f"saved the {self.edited} parameters and the search's (TOML, readable with --params)"
        return text

    # ---- playback ---------------------------------------------------------------------------
    def _player(self) -> None:
        while not self.closed.wait(1.0 / max(self.fps, 0.5)):
            if self.playing and self.state.runs:
                with self.lock:
                    if self.closed.is_set():  # closed while this frame waited for the lock
                        break
                    n = self.state.max_iteration()
                    self.playback.slider.value = 0 if self.state.iteration >= n else self.state.iteration + 1

    def close(self) -> None:
        """Stop the player; returns once a frame it was drawing has been sent (nothing is queued
        for a client that has gone, or on a stopped server)."""
        self.closed.set()
        with self.lock:
            pass


def _has_content(layer: scene.Layer) -> bool:
    if isinstance(layer, scene.Points):
        return len(layer.xy) > 0
    if isinstance(layer, scene.Segments):
        return len(layer.starts) > 0
    if isinstance(layer, scene.Strips):
        return len(layer.strips) > 0
    if isinstance(layer, scene.Boxes):
        return len(layer.centers) > 0
    return True
