"""The live page (``live URL --serve``): a running robot's run as it grows, in the world frame of
the first scan the page drew (its trajectory, the map, the newest pair's scans), the health of every
pair in the buffer, how far behind the robot each result came, and the status (connected, scans
matched and skipped, the buffer's seconds and size). "freeze" opens the buffer in the debugger
(its run view, any pair in the pair debugger with everything it has); "resume" goes live again.
"""

from __future__ import annotations

import math
import tempfile
import threading
import time
import traceback
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import viser
import viser.uplot as uplot

from mbicp_viz.core import Pose2

from .. import scene, viser_draw
from . import panels
from .camera import TopDownCamera
from .markdown import literal, wrapping
from .run_model import MAP_POINTS, RunModel

REFRESH_S = 0.5  # the page follows the run this often
TIME_AXIS = "time of the scan [s], 0 = the newest"
LAG = scene.Style("lag: from a scan's arrival to its result [ms]", (220, 40, 40))
PERIOD = scene.Style("one scan period of the robot [ms]", (120, 120, 120))


@dataclass(frozen=True)
class Placed:
    """A scan of the live run as the page placed it, once: its pose is not composed anew."""

    pose: Pose2  # in the page's world frame
    # the odometry chained to it from the page's first scan, or from the newest scan before it
    # without odometry (None: its pair has none)
    odometry: Pose2 | None
    # the pair that placed it: its scan's stamp [s], the health timeline's overlap [%], distance
    # from odometry [mm], flagged (100, else 0) and residual [mm] (``RunModel.series``), and its
    # result's lag [ms]; None at the scan the world starts at
    health: np.ndarray | None


class LiveTab:
    """One browser tab on a live run (``live.run.LiveRun``): the live view, or the debugger on a
    frozen buffer (saved under ``folder``) until "resume"."""

    def __init__(
        self,
        client: viser.ClientHandle | viser.ViserServer,
        run,
        folder: Path,
        budget_s: float | None,
    ):
        """``client``: a browser tab, or a server (``bench live --page``: the page's work)."""
        self.client, self.run, self.folder, self.budget_s = client, run, folder, budget_s
        self.every_s = REFRESH_S
        self.refresh_s: deque[float] = deque(maxlen=10_000)  # [s] each refresh that drew
        self.lock = threading.RLock()
        self.session = None  # the debugger on a frozen buffer
        self.closed = threading.Event()
        self.camera = TopDownCamera(client)
        with self.lock:
            self.show_live()
        threading.Thread(target=self._follow, daemon=True).start()

    # ---- live ---------------------------------------------------------------------------------
    def show_live(self) -> None:
        gui = self.client.gui
        gui.reset()
        self.client.scene.reset()
        gui.configure_theme(control_width="large", show_logo=False, show_share_button=False)
        gui.main_panel.dock_right()
        gui.add_markdown(wrapping(f"**mbicp-viz** — live from {literal(self.run.url)}"))
        self.h_status = gui.add_markdown("waiting for the first pair …")
        self.h_notes = gui.add_markdown("")
        freeze = gui.add_button(
            "freeze", hint="open the buffer in the debugger: its run, any pair's iterations"
        )
        freeze.on_click(lambda _: self._guarded(self.freeze))
        self.h_legend = gui.add_html(panels.legend_html([]))
        gui.add_button("fit the view").on_click(lambda _: self._guarded(self.fit))
        series = tuple(panels.health_legend("s"))
        self.health = gui.add_uplot(
            data=tuple(np.zeros(0) for _ in series),
            series=series,
            aspect=1.6,
            title="health of each pair in the buffer",
            **panels.health_axes(TIME_AXIS, 1.0),
        )
        self.lateness = gui.add_uplot(
            data=(np.zeros(0), np.zeros(0), np.zeros(0)),
            series=(
                uplot.Series(label="s"),
                panels._line("lag [ms]", "ms", LAG),
                panels._line("scan period [ms]", "ms", PERIOD, dash=True),
            ),
            aspect=2.2,
            title="how far behind the robot: each result after its scan arrived",
            **panels._numeric(TIME_AXIS, ("ms", "[ms]", 3, 1.0)),
        )
        self.nodes: dict[str, object] = {}
        self.drawn: tuple = ()  # what the scene shows: (pairs, the newest pair's scans)
        self.box: np.ndarray | None = None  # what the view was fitted to (lo, hi) [m]
        self.extent = np.zeros((1, 2))
        self.scale = 1.0  # the dots' and lines' size, set when the view is fitted
        # the page's world frame is the first scan it drew, carried along as the buffer drops its
        # oldest scans: each scan as the page placed it, by its number in the robot's run
        self.world: dict[int, Placed] = {}
        # the map, drawn once per refresh for the scans new to it: (its last scan's number, its
        # node, its points' lower and upper corners), removed once its scans left the buffer
        self.map_parts: deque[tuple[int, object, np.ndarray]] = deque()
        self.mapped = -1  # the number of the last scan the map has

    def _follow(self) -> None:
        while not self.closed.wait(self.every_s):
            with self.lock:
                if self.session is None and not self.closed.is_set():
                    self._guarded(self.refresh)

    def _guarded(self, fn) -> None:
        """A callback under the tab's lock; a bug is said on the page and the run goes on."""
        try:
            with self.lock:
                fn()
        except Exception as e:
            self.h_status.content = panels.warning(f"Internal error: {type(e).__name__}: {e}")
            traceback.print_exc()

    def refresh(self) -> None:
        """The status each time; the scene and the plots when a pair was added."""
        status, log, rows, lags, numbers = self.run.view()
        error = self.run.error()
        line = status.line()
        self.h_status.content = (
            panels.warning(str(error)) if error is not None else line[0].upper() + line[1:]
        )
        self.h_notes.content = wrapping(
            "  \n".join(
                [
                    literal(_mount_text(log.frames)),
                    *(f"*{literal(n)}*" for n in status.notes[-3:]),
                ]
            )
        )
        if not rows:
            return
        key = (len(rows), rows[-1].obj, rows[-1].result.pose)
        if key == self.drawn:
            return
        self.drawn = key
        t0 = time.perf_counter()
        model = RunModel(log, rows)
        visited = [numbers[k] for k in model.scans]  # each scan's number in the robot's run
        self._place(model, visited, numbers, lags)
        chain = [self.world[v] for v in visited]
        self.draw(model, visited, chain)
        self.plot(np.array([p.health for p in chain[1:]]))
        self.refresh_s.append(time.perf_counter() - t0)

    def _place(
        self, model: RunModel, visited: list[int], numbers: list[int], lags: list[float]
    ) -> None:
        """The scans new to the page placed in its world frame on those it placed before, each
        once (composing the whole buffer anew took most of a refresh, and the matcher waited on
        it), with their pairs' health; the scans that left the buffer forgotten."""
        if visited[0] not in self.world:  # the first pair, or the chain broke: it starts here
            self._clear_map()
            self.world[visited[0]] = Placed(Pose2(), Pose2(), None)
        while (first := next(iter(self.world))) < visited[0]:
            del self.world[first]
        fresh = [k for k, v in enumerate(visited[1:]) if v not in self.world]
        if not fresh:
            return
        new = [model.rows[k] for k in fresh]
        stamps = [model.log.scan(r.obj).stamp or 0.0 for r in new]
        lag_ms = [1000 * lags[k] for k in fresh]
        health = np.column_stack([stamps, *RunModel(model.log, new).series[1:5], lag_ms])
        base = model.base
        for r, h in zip(new, health):
            start = self.world[numbers[r.ref]]  # placed before, or by a pair before it here
            odometry = None
            if r.odometry is not None:  # chained on the start's, or from its pose after a gap
                at = start.pose if start.odometry is None else start.odometry
                odometry = at @ model.log.frames.reported(r.odometry, base)
            self.world[numbers[r.obj]] = Placed(start.pose @ r.result.pose, odometry, h)

    def draw(self, model: RunModel, visited: list[int], chain: list[Placed]) -> None:
        """The buffer's run in the page's world frame: its tracks and the newest pair drawn anew,
        the map only for the scans new to it (the whole map each refresh took most of it), and
        the map of scans that left the buffer removed."""
        poses = [p.pose for p in chain]
        # the odometry since the newest scan without it (drawn from that scan's pose), if any
        gap = max((k for k, p in enumerate(chain) if p.odometry is None), default=-1)
        odometry = [poses[gap]] * (gap >= 0) + [p.odometry for p in chain[gap + 1 :]]
        track = np.array([[p.x, p.y] for p in poses])
        self.extent = np.concatenate([track, *(part[2] for part in self.map_parts)])
        lo, hi = self.extent.min(axis=0), self.extent.max(axis=0)
        if self.box is None or np.any(lo < self.box[0]) or np.any(hi > self.box[1]):
            self.fit()  # the run left the view
        flagged = np.flatnonzero([p.health[3] for p in chain[1:]])
        n = len(model.rows) - 1
        mount = model.mount
        layers = [
            *scene.run_track_layers(
                scene.RunTracks(
                    poses,
                    odometry=odometry if len(odometry) > 1 else None,
                    suspects=track[flagged + 1].reshape(-1, 2),
                ),
                self.scale,
            ),
            *scene.run_pair_layers(
                scene.RunPair(
                    [],
                    (poses[n] @ mount).apply(model.log.scan(model.scans[n]).points()),
                    (poses[n + 1] @ mount).apply(model.log.scan(model.scans[n + 1]).points()),
                    poses[n + 1],
                ),
                self.scale,
            ),
        ]
        with self.client.atomic():
            self._extend_map(model, visited, poses)
            self.nodes = viser_draw.draw_nodes(
                self.client.scene, self.nodes, ((f"/{x.path}", x, True) for x in layers)
            )
        shown = {layer.style.label: layer.style for layer in layers if scene.has_content(layer)}
        if self.map_parts:
            shown[scene.RUN_MAP.label] = scene.RUN_MAP
        frame = f"the world frame: the first scan this page drew ({model.rows[0].frame})"
        self.h_legend.content = panels.legend_html(list(shown.values()), self.grid_m, frame)

    def _extend_map(self, model: RunModel, visited: list[int], poses: list[Pose2]) -> None:
        """The scans new to the map added as one node (every k-th scan of the run, the map kept
        near ``MAP_POINTS``), the parts whose scans all left the buffer removed."""
        while self.map_parts and self.map_parts[0][0] < visited[0]:
            self.map_parts.popleft()[1].remove()
        beams = len(model.log.scan(model.scans[-1]).ranges)
        every = max(1, math.ceil(len(visited) * beams / MAP_POINTS))
        new = [k for k, v in enumerate(visited) if v > self.mapped and v % every == 0]
        self.mapped = visited[-1]
        if not new:
            return
        scans = model.log.scans_of([model.scans[k] for k in new], False)
        xy = np.concatenate(
            [(poses[k] @ model.mount).apply(s.points()) for k, s in zip(new, scans)]
        )
        if not len(xy):
            return
        layer = scene.Points(
            f"{scene.RUN}/map/{visited[new[0]]:09d}", xy, scene.RUN_MAP, 0.01 * self.scale
        )
        node = viser_draw.draw(self.client.scene, f"/{layer.path}", layer)
        self.map_parts.append((visited[new[-1]], node, np.stack([xy.min(axis=0), xy.max(axis=0)])))

    def _clear_map(self) -> None:
        while self.map_parts:
            self.map_parts.popleft()[1].remove()
        self.world, self.mapped = {}, -1

    def fit(self) -> None:
        """Top-down over the run so far, with room to grow, and a metric grid under it."""
        lo, hi = self.extent.min(axis=0), self.extent.max(axis=0)
        margin = np.maximum(0.25 * (hi - lo), 2.0)
        self.box = np.stack([lo - margin, hi + margin])
        self.scale = scene.scene_scale(self.extent)
        self.camera.fit(self.box)
        self.grid_m = viser_draw.metric_grid(self.client.scene, self.box)

    def plot(self, health: np.ndarray) -> None:
        """The health and the lag of the buffer's pairs (``Placed.health``, one row a pair)."""
        t = health[:, 0] - health[-1, 0]
        overlap, odo, flagged, residual, lag_ms = health[:, 1:].T
        # the time axis set each time (the page keeps an auto range from the plot's first data)
        x = {"x": uplot.Scale(time=False, auto=False, range=(min(float(t[0]), -1.0), 0.0))}
        self.health.data = (t, overlap, odo, flagged, residual)
        self.health.scales = panels.health_axes("", panels._top([*odo, *residual]))["scales"] | x
        period = np.median(np.diff(t)) * 1000 if len(t) > 1 else np.nan
        self.lateness.data = (t, lag_ms, np.full(len(t), period))
        top = panels._top([*lag_ms, period])
        self.lateness.scales = panels._numeric("", ("ms", "", 3, top))["scales"] | x

    # ---- frozen -------------------------------------------------------------------------------
    def freeze(self) -> None:
        """The buffer saved as a bag and opened in the debugger, each pair as it was matched."""
        from .session import Session
        from .sources import log_source

        folder = Path(tempfile.mkdtemp(prefix="frozen-", dir=self.folder))
        log, rows = self.run.freeze(folder)
        if not rows:
            self.h_status.content = panels.warning("nothing to freeze yet: no pair matched")
            return
        label = f"the last {len(rows)} pairs matched live from {self.run.url}"
        source = log_source(f"{self.run.url} (frozen)", log, run=rows, rows_label=label)
        gui = self.client.gui
        gui.reset()
        self.client.scene.reset()
        self.nodes, self.drawn, self.box = {}, (), None
        gui.add_button("resume", order=0.5, color="green", hint="back to the live run").on_click(
            lambda _: self._guarded(self.resume)
        )
        self.session = Session(self.client, replace(source, budget_s=self.budget_s))

    def resume(self) -> None:
        self.session.close()
        self.session = None
        self.show_live()
        self.refresh()

    def close(self) -> None:
        self.closed.set()
        self.camera.stop()
        with self.lock:
            if self.session is not None:
                self.session.close()


def _mount_text(frames) -> str:
    """The laser's mount on the robot as tf gave it, or that it has none."""
    if frames.mount_source is None:
        return "laser mount: none on /tf_static yet (poses are the laser's)"
    m = frames.mount
    return (
        f"laser mount ({frames.mount_source}): {frames.frame_id} at x {m.x:+.3f} m, "
        f"y {m.y:+.3f} m, theta {math.degrees(m.theta):+.2f} deg in {frames.base_frame}"
    )
