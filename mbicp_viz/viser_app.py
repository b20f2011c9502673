"""The interactive debugger in the browser (viser): step, play, tune live, compare, export.

Every browser tab gets its own ``Session`` (GUI, scene, parameters, runs), so tabs never share
state. A session re-runs the match when a parameter, the guess or the pair changes, keeps every
iteration's events, and redraws from them when the iteration slider moves (no re-run). Drawing
goes through the shared scene mapping (``scene.py``) and ``viser_draw.py``.
"""

from __future__ import annotations

import math
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import viser
import viser.uplot as uplot

from core import (MATCHERS, ParamError, Params, Pose2, Recorder, ScanError, field_specs, pose_error, relative)
from core.agreement import INLIER_RADIUS_M, inlier_fraction
from core.params import check_value

from . import scene, viser_draw
from .errors import InputError
from .inputs import search_window_text, stored_guess
from .params_io import params_to_toml
from .readers import ScanLog

COMPARE = "compare"
RUN_COLORS = {"icp": (230, 120, 20), "mbicp": (40, 90, 220), "improved": (140, 60, 200)}


@dataclass
class Source:
    """What the debugger opens: a log (any two scans can be picked) or one fixed pair."""

    label: str
    log: ScanLog
    pair: tuple[int, int] = (0, 1)
    pick_pair: bool = False
    guess: Pose2 | None = None  # None: from the poses/odometry the log stores
    truth: Pose2 | None = None
    params: dict[str, Params] = field(default_factory=dict)
    algorithm: str = "improved"


@dataclass
class RunRecord:
    name: str
    start: object
    iterations: list
    result: object


def run_match(name: str, ref, obj, guess: Pose2, params: Params) -> RunRecord:
    from core import match

    rec = Recorder()
    result = match(ref, obj, guess, params, rec)
    return RunRecord(name, rec.start, rec.iterations, result)


class Session:
    """One browser tab: its controls, its scene, its runs."""

    def __init__(self, client: viser.ClientHandle | viser.ViserServer, source: Source):
        """``client``: a browser tab's handle, or the server itself (state shared by every tab)."""
        self.client, self.source = client, source
        self.lock = threading.RLock()
        self.algorithm = source.algorithm
        self.params: dict[str, Params] = {n: source.params.get(n, m.params_type()) for n, m in MATCHERS.items()}
        self.pair = source.pair
        self.guess = self._initial_guess()
        self.runs: list[RunRecord] = []
        self.iteration = 0
        self.visible = {g: g not in viser_draw.DEFAULT_OFF for g in viser_draw.GROUPS}
        self.playing = False
        self.fps = 4.0
        self.closed = threading.Event()
        self.match_ms = 0.0
        self._quiet = False
        self.nodes: dict[str, object] = {}  # scene node name -> viser handle, as last drawn
        self.iso_point: int | None = None  # object point whose iso-distance curves are shown
        self._build_gui()
        self.rematch()
        self._frame_camera()
        threading.Thread(target=self._player, daemon=True).start()

    # ---- data -------------------------------------------------------------------------------
    @property
    def ref(self):
        return self.source.log.scans[self.pair[0]]

    @property
    def obj(self):
        return self.source.log.scans[self.pair[1]]

    def _initial_guess(self) -> Pose2:
        return self.source.guess if self.source.guess is not None else stored_guess(self.ref, self.obj)[0]

    def truth(self) -> Pose2 | None:
        if self.source.truth is not None:
            return self.source.truth
        if self.ref.pose is not None and self.obj.pose is not None and self.source.pick_pair:
            return relative(self.ref.pose, self.obj.pose)
        return None

    def algorithms(self) -> list[str]:
        return list(MATCHERS) if self.algorithm == COMPARE else [self.algorithm]

    # ---- matching ---------------------------------------------------------------------------
    def rematch(self) -> bool:
        """Re-run every shown matcher; on failure keep the last good runs and say why."""
        with self.lock:
            t0 = time.perf_counter()
            try:
                runs = [run_match(n, self.ref, self.obj, self.guess, self.params[n]) for n in self.algorithms()]
            except (ScanError, ParamError, InputError, ValueError, FloatingPointError, np.linalg.LinAlgError) as e:
                self._say(f"**The match failed** and the last good result is kept: `{e}`")
                return False
            except Exception as e:  # a bug must not take the server down: show it, keep serving
                self._say(f"**Internal error** (the last good result is kept): `{type(e).__name__}: {e}`")
                traceback.print_exc()
                return False
            self.match_ms = 1000.0 * (time.perf_counter() - t0)
            self.runs = runs
            n = self.max_iteration()
            self.iteration = n  # show where the match ended
            self.h_iter.max = max(n, 1)
            self.h_iter.value = n  # fires the redraw
            if n == 0:
                self.redraw()
            self._say("")
            self._update_result()
            self._update_error_plot()
            return True

    def max_iteration(self) -> int:
        return max((len(r.iterations) for r in self.runs), default=0)

    # ---- drawing ----------------------------------------------------------------------------
    def layers(self, run: RunRecord, k: int):
        """Scene layers of ``run`` at iteration k (0: the initial guess, before any pairing)."""
        start = run.start
        layers = scene.start_layers(start)
        truth = self.truth()
        if truth is not None:
            layers.append(scene.Points(f"{scene.SCANS}/truth", truth.apply(start.obj_points), scene.TRUTH, 0.01))
        if k == 0 or not run.iterations:
            layers += [scene.Points(f"{scene.SCANS}/object", start.initial_guess.apply(start.obj_points[start.used]),
                                    scene.OBJECT, 0.02), scene.Frame(f"{scene.SCANS}/estimate", start.initial_guess)]
            return layers
        ev = run.iterations[min(k, len(run.iterations)) - 1]
        layers += scene.iteration_layers(start, ev)
        layers += scene.teaching_layers(start, ev, chosen=self.iso_point)
        return layers

    def redraw(self) -> None:
        with self.lock, self.client.atomic():
            compare = len(self.runs) > 1
            for run in self.runs:
                for layer in self.layers(run, self.iteration):
                    group = viser_draw.group_of(layer.path)
                    if group is None or (compare and group == "reference" and run is not self.runs[0]):
                        continue
                    if compare and layer.path.endswith("/object"):
                        layer = scene.Points(layer.path, layer.xy, RUN_COLORS.get(run.name, scene.OBJECT), layer.radius)
                    name = f"/{run.name}/{layer.path}"
                    self.nodes[name] = viser_draw.draw(self.client.scene, name, layer, self.visible[group])
            self._update_histogram()
            self._update_cost_plot()
            self.h_iter_info.content = self._iteration_text()

    def _iteration_text(self) -> str:
        if self.iteration == 0:
            return "iteration 0: the initial guess"
        run = self.runs[0]
        if not run.iterations:
            return "no iterations"
        ev = run.iterations[min(self.iteration, len(run.iterations)) - 1]
        return scene.iteration_text(ev)

    def _frame_camera(self) -> None:
        pts = self.runs[0].start.ref_points if self.runs else np.zeros((1, 2))
        c = pts.mean(axis=0)
        extent = float(np.ptp(pts, axis=0).max()) if len(pts) > 1 else 10.0
        cam = self.client.camera if isinstance(self.client, viser.ClientHandle) else self.client.initial_camera
        cam.up_direction = (0.0, 1.0, 0.0)
        cam.position = (float(c[0]), float(c[1]), max(extent * 1.2, 3.0))
        cam.look_at = (float(c[0]), float(c[1]), 0.0)

    # ---- panels -----------------------------------------------------------------------------
    def _say(self, text: str) -> None:
        self.h_status.content = text

    def _update_result(self) -> None:
        lines = []
        truth = self.truth()
        for r in (run.result for run in self.runs):
            st = "converged" if r.converged else f"**not converged** ({r.reason.value})"
            s = (f"**{r.algorithm}**: pose x {r.pose.x:+.4f} m, y {r.pose.y:+.4f} m, "
                 f"θ {math.degrees(r.pose.theta):+.3f}°  \n{st} after {r.iterations} iterations; "
                 f"pairs kept {r.pairs_kept}, rejected {r.pairs_rejected}")
            if r.degeneracy is not None:
                d = r.degeneracy
                s += (f"  \ndegeneracy: condition number {d.condition_number:.1f}, weakest direction "
                      f"heading {d.weakest_heading_deg:+.0f}°")
            s += (f"  \nobject points within {100 * INLIER_RADIUS_M:.0f} cm of the reference: "
                  f"{100 * inlier_fraction(self.ref, self.obj, r.pose):.1f} %")
            if truth is not None:
                et, er = pose_error(r.pose, truth)
                s += (f"  \nerror against the known answer: {et * 1000:.1f} mm, {math.degrees(er):.3f}° "
                      f"(there: {100 * inlier_fraction(self.ref, self.obj, truth):.1f} % within "
                      f"{100 * INLIER_RADIUS_M:.0f} cm)")
            lines.append(s)
        lines.append(f"match time {self.match_ms:.1f} ms")
        self.h_result.content = "\n\n".join(lines)

    def _update_error_plot(self) -> None:
        run = self.runs[0]
        n = len(run.iterations)
        x = np.arange(1, n + 1, dtype=float)
        err = np.array([e.error for e in run.iterations], dtype=float)
        thr = np.array([np.nan if e.threshold is None else e.threshold for e in run.iterations], dtype=float)
        self.h_error_plot.data = (x, err, thr)

    def _update_cost_plot(self) -> None:
        """PSM/PMWN: the orientation step's cost per shift and the V or parabola fitted at its minimum."""
        run = self.runs[0]
        k = min(self.iteration, len(run.iterations))
        polar = run.iterations[k - 1].polar if k else None
        if polar is None or not np.any(np.isfinite(polar.cost)):
            self.h_cost.data = (np.zeros(1), np.zeros(1), np.zeros(1))
            return
        step_deg = math.degrees(float(np.median(np.diff(polar.bearings))))
        x = polar.shifts * step_deg
        fit = np.full(len(x), np.nan)
        curve = scene.fitted_curve(polar, step_deg, n=201)
        if curve is not None:
            near = np.abs(x - curve[:, 0].mean()) <= step_deg * 1.0001
            fit[near] = np.interp(x[near], curve[:, 0], curve[:, 1])
        self.h_cost.data = (x.astype(float), polar.cost.astype(float), fit)

    def _update_histogram(self) -> None:
        run = self.runs[0]
        if self.iteration == 0 or not run.iterations:
            self.h_hist.data = (np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1))
            return
        ev = run.iterations[min(self.iteration, len(run.iterations)) - 1]
        d = ev.pairs.distance
        hi = max(float(d.max()) if len(d) else 1.0, ev.threshold or 0.0) * 1.05 or 1.0
        counts, edges = np.histogram(d, bins=30, range=(0.0, hi))
        centers = 0.5 * (edges[1:] + edges[:-1])
        top = float(counts.max()) if len(counts) else 1.0

        def marker(v):  # a spike at the bin holding v
            m = np.zeros(len(centers))
            if v is not None and len(d):
                m[min(int(v / hi * len(centers)), len(centers) - 1)] = top
            return m

        self.h_hist.data = (centers, counts.astype(float), marker(float(np.median(d)) if len(d) else None),
                            marker(ev.threshold))

    # ---- GUI --------------------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.client.gui
        gui.add_markdown(f"**mbicp-viz** — {self.source.label}")
        self.h_status = gui.add_markdown("")
        with gui.add_folder("Playback"):
            self.h_iter = gui.add_slider("iteration", min=0, max=1, step=1, initial_value=0)
            self.h_iter.on_update(lambda _: self._on_iteration())
            prev_b, next_b = gui.add_button("previous"), gui.add_button("next")
            prev_b.on_click(lambda _: self.step(-1))
            next_b.on_click(lambda _: self.step(+1))
            self.h_play = gui.add_checkbox("play", False)
            self.h_play.on_update(lambda _: setattr(self, "playing", self.h_play.value))
            self.h_fps = gui.add_slider("speed (iterations/s)", min=0.5, max=30.0, step=0.5, initial_value=self.fps)
            self.h_fps.on_update(lambda _: setattr(self, "fps", self.h_fps.value))
            self.h_iter_info = gui.add_markdown("")
        with gui.add_folder("Result"):
            self.h_result = gui.add_markdown("")
        with gui.add_folder("Matcher"):
            self.h_algo = gui.add_dropdown("algorithm", [*MATCHERS, COMPARE], initial_value=self.algorithm)
            self.h_algo.on_update(lambda _: self._on_algorithm())
            self.h_param_msg = gui.add_markdown("")
            self.param_folder = None
            self._build_param_panel()
        with gui.add_folder("Initial guess"):
            self.h_gx = gui.add_number("x [m]", self.guess.x, step=0.01)
            self.h_gy = gui.add_number("y [m]", self.guess.y, step=0.01)
            self.h_gt = gui.add_number("theta [deg]", math.degrees(self.guess.theta), step=0.5)
            for h in (self.h_gx, self.h_gy, self.h_gt):
                h.on_update(lambda _: self._on_guess_numbers())
            self.h_gizmo_on = gui.add_checkbox("drag the guess in the view", True)
            self.h_gizmo_on.on_update(lambda _: setattr(self.gizmo, "visible", self.h_gizmo_on.value))
            b_search = gui.add_button(f"search the guess ({search_window_text()})",
                                      hint="correlative search around the current guess; the match restarts from "
                                           "its best pose")
            b_search.on_click(lambda _: self._guarded(self.search_guess))
        if self.source.pick_pair:
            with gui.add_folder("Scans"):
                n = len(self.source.log.scans)
                self.h_ref = gui.add_number("reference scan", self.pair[0], min=0, max=n - 1, step=1)
                self.h_obj = gui.add_number("object scan", self.pair[1], min=0, max=n - 1, step=1)
                self.h_consecutive = gui.add_checkbox("consecutive (object = reference + 1)", True)
                for h in (self.h_ref, self.h_obj, self.h_consecutive):
                    h.on_update(lambda _: self._on_pair())
        with gui.add_folder("Layers"):
            self.layer_boxes = {}
            for g in viser_draw.GROUPS:
                cb = gui.add_checkbox(g, self.visible[g])
                cb.on_update(lambda ev, g=g: self._on_layer(g, ev.target.value))
                self.layer_boxes[g] = cb
            self.h_iso = gui.add_number("iso-curves: object point (-1: spread)", -1, step=1, min=-1,
                                        hint="click a blue point in the view, or type its index")
            self.h_iso.on_update(lambda _: self._on_iso_number())
        with gui.add_folder("Plots"):
            self.h_error_plot = gui.add_uplot(
                data=(np.zeros(1), np.zeros(1), np.zeros(1)),
                series=(uplot.Series(label="iteration"), uplot.Series(label="error [m²]", stroke="gray", width=2),
                        uplot.Series(label="threshold [m]", stroke="orange", width=2)),
                title="error and threshold per iteration", aspect=1.6)
            self.h_hist = gui.add_uplot(
                data=(np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1)),
                series=(uplot.Series(label="distance [m]"), uplot.Series(label="pairs", stroke="gray", width=2),
                        uplot.Series(label="median", stroke="black", width=2),
                        uplot.Series(label="threshold", stroke="orange", width=2)),
                title="pair distances (current iteration)", aspect=1.6)
            self.h_cost = gui.add_uplot(
                data=(np.zeros(1), np.zeros(1), np.zeros(1)),
                series=(uplot.Series(label="shift [deg]"), uplot.Series(label="cost [m]", stroke="gray", width=2),
                        uplot.Series(label="fit", stroke="green", width=2)),
                title="polar matchers: cost per shift (current iteration)", aspect=1.6)
        with gui.add_folder("Export"):
            b_rrd = gui.add_button("export .rrd")
            b_rrd.on_click(lambda _: self._guarded(self.export_rrd))
            b_toml = gui.add_button("save parameters (TOML)")
            b_toml.on_click(lambda _: self._guarded(self.export_params))
        self.gizmo = self.client.scene.add_transform_controls(
            "/guess", scale=0.8, disable_sliders=True, position=(self.guess.x, self.guess.y, 0.0),
            wxyz=viser_draw.yaw_to_wxyz(self.guess.theta))
        self.gizmo.on_update(lambda _: self._on_gizmo())
        self.client.scene.on_click()(lambda ev: self._guarded(lambda: self.click(ev.ray_origin, ev.ray_direction)))

    def _build_param_panel(self) -> None:
        if self.param_folder is not None:
            self.param_folder.remove()
        self.param_handles = {}
        name = "improved" if self.algorithm == COMPARE else self.algorithm
        params = self.params[name]
        with self.client.gui.add_folder(f"Parameters: {name}") as folder:
            self.param_folder = folder
            for s in field_specs(type(params)):
                v = getattr(params, s.name)
                hint = f"[{s.unit}] {s.help}"
                if s.type is bool:
                    h = self.client.gui.add_checkbox(s.name, v, hint=hint)
                elif s.unit == "rad":
                    h = self.client.gui.add_number(f"{s.name} [deg]", round(math.degrees(v), 6), step=0.5,
                                                   min=math.degrees(s.lo), max=math.degrees(s.hi), hint=hint)
                elif s.type is int:
                    h = self.client.gui.add_number(s.name, v, step=1, min=s.lo, max=s.hi, hint=hint)
                else:
                    step = 10.0 ** math.floor(math.log10(abs(v))) / 10 if v else 0.01
                    h = self.client.gui.add_number(f"{s.name} [{s.unit}]" if s.unit != "1" else s.name, v,
                                                   step=step, min=s.lo, max=s.hi, hint=hint)
                h.on_update(lambda ev, s=s, name=name: self._on_param(name, s, ev.target.value))
                self.param_handles[s.name] = h

    # ---- callbacks --------------------------------------------------------------------------
    def _guarded(self, fn) -> None:
        try:
            fn()
        except Exception as e:  # keep serving; tell the user
            self._say(f"**Error**: `{type(e).__name__}: {e}`")
            traceback.print_exc()

    def _on_iteration(self) -> None:
        with self.lock:
            self.iteration = int(self.h_iter.value)
            self.redraw()

    def step(self, delta: int) -> None:
        with self.lock:
            self.h_iter.value = int(np.clip(self.iteration + delta, 0, self.max_iteration()))

    def _on_algorithm(self) -> None:
        with self.lock:
            self.algorithm = self.h_algo.value
            self._clear_runs()
            self._build_param_panel()
            self.rematch()

    def set_param(self, name: str, spec_name: str, value) -> bool:
        """Validate and apply one parameter (degrees for radian fields); re-match when it is valid."""
        spec = next(s for s in field_specs(type(self.params[name])) if s.name == spec_name)
        return self._on_param(name, spec, value)

    def _on_param(self, name: str, spec, value) -> bool:
        with self.lock:
            try:
                v = math.radians(value) if spec.unit == "rad" and not isinstance(value, bool) else value
                v = check_value(spec, v)
                new = self.params[name].replace(**{spec.name: v})
            except ParamError as e:
                shown = str(e) if spec.unit != "rad" else f"{e} (entered {value} deg)"
                self.h_param_msg.content = f"⚠ {shown} — the last good result is kept"
                return False
            except TypeError:
                self.h_param_msg.content = f"⚠ parameter {spec.name!r}: not a number: {value!r}"
                return False
            old = self.params[name]
            self.params[name] = new
            self.h_param_msg.content = ""
            if not self.rematch():
                self.params[name] = old
                return False
            return True

    def set_guess(self, guess: Pose2, move_gizmo: bool = True) -> None:
        with self.lock:
            self.guess = guess
            self._show_guess(guess, move_gizmo)
            self.rematch()

    def _show_guess(self, guess: Pose2, move_gizmo: bool = True) -> None:
        """Put the number fields (and the gizmo) on ``guess``, without each field re-running the match."""
        if move_gizmo:
            self.gizmo.position = (guess.x, guess.y, 0.0)
            self.gizmo.wxyz = viser_draw.yaw_to_wxyz(guess.theta)
        self._quiet = True
        try:
            for h, v in ((self.h_gx, guess.x), (self.h_gy, guess.y), (self.h_gt, math.degrees(guess.theta))):
                h.value = v
        finally:
            self._quiet = False

    def search_guess(self) -> Pose2:
        """Replace the guess by the best pose of the correlative search around it (core/search.py)."""
        from core.search import correlative_search

        with self.lock:
            found = correlative_search(self.ref, self.obj, self.guess)
            self.set_guess(found.pose)
            self._say(f"searched around the guess: best {found.pose} (score {found.score:.1f})")
            return found.pose

    def _on_guess_numbers(self) -> None:
        if self._quiet:
            return
        vals = (self.h_gx.value, self.h_gy.value, self.h_gt.value)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in vals):
            self.h_param_msg.content = "⚠ the initial guess must be finite numbers"
            return
        self.set_guess(Pose2(float(vals[0]), float(vals[1]), math.radians(vals[2])))

    def _on_gizmo(self) -> None:
        x, y, _ = (float(v) for v in self.gizmo.position)
        theta = viser_draw.wxyz_to_yaw(self.gizmo.wxyz)
        self.set_guess(Pose2(x, y, theta), move_gizmo=False)

    def _on_pair(self) -> None:
        with self.lock:
            i = int(self.h_ref.value)
            j = i + 1 if self.h_consecutive.value else int(self.h_obj.value)
            n = len(self.source.log.scans)
            if not (0 <= i < n and 0 <= j < n):
                self._say(f"⚠ scan indices must lie in 0..{n - 1} (the last scan has no successor)")
                return
            self.pair = (i, j)
            self._clear_runs()
            self.guess = self._initial_guess()
            self._show_guess(self.guess)
            self.rematch()
            self._frame_camera()

    def click(self, origin, direction) -> int | None:
        """Choose the object point nearest to where a view ray meets the scan plane (z = 0)."""
        o, d = np.asarray(origin, float), np.asarray(direction, float)
        if abs(d[2]) < 1e-9 or not self.runs:
            return None
        xy = (o - o[2] / d[2] * d)[:2]
        run = self.runs[0]
        k = min(self.iteration, len(run.iterations))
        moved = run.iterations[k - 1].moved_points if k else run.start.initial_guess.apply(
            run.start.obj_points[run.start.used])
        j = int(np.argmin(np.hypot(*(moved - xy).T)))
        self.h_iso.value = int(run.start.used[j])  # fires the redraw
        return self.iso_point

    def _on_iso_number(self) -> None:
        with self.lock:
            v = int(self.h_iso.value)
            self.iso_point = None if v < 0 else v
            if self.iso_point is not None and not self.visible["iso-distance curves"]:
                self.layer_boxes["iso-distance curves"].value = True  # redraws
            else:
                self.redraw()

    def _on_layer(self, group: str, value: bool) -> None:
        with self.lock:
            self.visible[group] = bool(value)
            self.redraw()

    def _clear_runs(self) -> None:
        for name, handle in self.nodes.items():
            handle.remove()
        self.nodes = {}

    def _player(self) -> None:
        while not self.closed.is_set():
            if self.playing and self.runs:
                with self.lock:
                    if self.closed.is_set():  # closed while this frame waited for the lock
                        break
                    n = self.max_iteration()
                    self.h_iter.value = 0 if self.iteration >= n else self.iteration + 1
            time.sleep(1.0 / max(self.fps, 0.5))

    def close(self) -> None:
        """Stop the player; returns once a frame it was drawing has been sent (nothing is queued
        for a client that has gone, or on a stopped server)."""
        self.closed.set()
        with self.lock:
            pass

    # ---- export -----------------------------------------------------------------------------
    def export_rrd(self) -> bytes:
        """The session (data, parameters, all iterations) as an .rrd, offered as a download."""
        from .rrd import Run, record

        with self.lock, tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "session.rrd"
            runs = [Run(n, self.ref, self.obj, self.guess, self.params[n], self.truth()) for n in self.algorithms()]
            record(runs, str(path), teaching=True, recording_id="mbicp-viz/session",
                   about=f"# mbicp-viz session\n\n{self.source.label}, scans {self.pair[0]} -> {self.pair[1]}\n")
            data = path.read_bytes()
        self.client.send_file_download("mbicp-viz-session.rrd", data, save_immediately=True)
        self._say(f"exported the session: {len(data) / 1e6:.2f} MB .rrd")
        return data

    def export_params(self) -> str:
        name = "improved" if self.algorithm == COMPARE else self.algorithm
        text = params_to_toml(self.params[name])
        self.client.send_file_download(f"params-{name}.toml", text.encode(), save_immediately=True)
        self._say(f"saved the {name} parameters (TOML, readable with --params)")
        return text


class App:
    """A viser server with one Session per connected browser tab."""

    def __init__(self, source: Source, host: str = "127.0.0.1", port: int = 8080):
        self.source = source
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.sessions: dict[int, Session] = {}
        self._lock = threading.Lock()
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)

    def _connect(self, client: viser.ClientHandle) -> None:
        session = Session(client, self.source)
        with self._lock:
            self.sessions[client.client_id] = session

    def _disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            s = self.sessions.pop(client.client_id, None)
        if s is not None:
            s.close()

    @property
    def port(self) -> int:
        return self.server.get_port()

    def stop(self) -> None:
        for s in list(self.sessions.values()):
            s.close()
        self.server.stop()


def source_for(first: str | None, second: str | None, scenario: str | None) -> Source:
    """``serve REF OBJ``, ``serve LOG`` (pick any pair) or ``serve --scenario NAME``."""
    from .readers import read_log
    from .scenarios import RECORDINGS, load_scenario

    if scenario is not None:
        path = RECORDINGS / "scenarios" / f"{scenario}.toml"
        if not path.exists():
            known = ", ".join(p.stem for p in sorted((RECORDINGS / "scenarios").glob("*.toml")))
            raise InputError(f"unknown scenario {scenario!r}; known: {known}", field="--scenario")
        s = load_scenario(path)
        log = ScanLog(s.name, [s.ref, s.obj])
        return Source(s.title, log, (0, 1), False, s.guess, s.truth, s.params, next(iter(s.params)))
    if first is None:
        raise InputError("give a log, two scan files, or --scenario NAME", field="FILE")
    if second is not None:
        log = ScanLog(f"{first} + {second}", [read_log(first).scan(0), read_log(second).scan(0)])
        return Source(f"{first} -> {second}", log)
    log = read_log(first)
    if len(log.scans) < 2:
        raise InputError("needs at least two scans (or give two files)", first)
    return Source(first, log, (0, 1), pick_pair=True)
