"""The run view (``serve LOG --rows ROWS`` on the rows of ``eval sequence``): the whole run in the
world frame — the trajectory its chained matches make, the map they build up to the pair in view,
the log's own poses and odometry where it has them, the flagged pairs — a slider over the pairs,
each pair's health, and "open this pair" into the pair debugger exactly as the run matched it.
The run itself is ``run_model.RunModel``.
"""

from __future__ import annotations

import numpy as np

from .. import scene, viser_draw
from . import panels
from .camera import on_scan_plane
from .markdown import literal
from .run_model import MapAt, RunModel


class RunPanel:
    """The run view's controls; in the scene it replaces the pair's layers while it is shown."""

    def __init__(self, session, gui, order: float, model: RunModel):
        self.s, self.model, self.active, self.scale = session, model, False, 1.0
        self.nodes: dict[str, object] = {}  # drawn once per showing of the run
        self.pair_nodes: dict[str, object] = {}  # drawn at each pair
        self.chunk_nodes: list[list] = []  # each map's chunks, shown as the pair passes them
        self.still: list = []
        self.chunks_shown = 0
        rows = model.rows
        with gui.add_folder("Run", order=order):
            gui.add_markdown(
                f"{len(rows)} pairs matched with {rows[0].matcher}; {len(model.flagged)} flagged "
                f"without truth. World frame: the first scan's ({literal(rows[0].frame)})."
            )
            self.toggle = gui.add_button("show the run", hint="the whole run, or back to the pair")
            data = model.series
            top = max(
                (float(np.nanmax(v)) for v in (data[2], *data[4:]) if np.any(np.isfinite(v))),
                default=1.0,
            )
            series = panels.health_legend("pair")
            if model.versus is not None:
                series.append(panels._line("A and B apart [mm]", "mm", scene.RUN_OTHER))
            data, each = panels.worst_of_each(data)
            self.plot = gui.add_uplot(
                data=data,
                series=tuple(series),
                aspect=1.6,
                title="health of every pair"
                + (f" (each point the worst of {each}; flagged: their share)" if each > 1 else ""),
                **panels.timeline_over_slider("pair", top * 1.08, len(rows)),
            )
            # the timeline's own scrubber, right under it: a click under a spike picks its pair
            self.slider = gui.add_slider("pair", 1, len(rows), 1, 1)
            self.prev_flagged = gui.add_button("previous flagged")
            self.next_flagged = gui.add_button("next flagged")
            self.text = gui.add_markdown("")
            self.open = gui.add_button("open this pair", hint="as the run matched it")
            self.relation = None  # the relation drawn (a position in model.relation_errors)
            if model.relation_errors is not None:
                self._relations(gui)
            self.loop_score = gui.add_markdown("")
            if model.loops is not None:
                self.map_at = gui.add_dropdown(
                    "map at", tuple(MapAt), hint="the map before or after the pose graph, or both"
                )
                self.map_at.on_update(lambda _: session.guarded(self.map_switched))
                self.show_loop_score()
            if model.versus is not None:
                gui.add_markdown("  \n".join(model.versus.verdict()))
                self.open_b = gui.add_button("open run B's match of this pair")
                self.open_b.on_click(lambda _: session.guarded(self.open_pair_b))
        self.toggle.on_click(lambda _: session.guarded(self.switch))
        self.slider.on_update(lambda _: session.guarded(self.draw))
        self.prev_flagged.on_click(lambda _: session.guarded(lambda: self.step_flagged(-1)))
        self.next_flagged.on_click(lambda _: session.guarded(lambda: self.step_flagged(+1)))
        self.open.on_click(lambda _: session.guarded(self.open_pair))
        session.client.scene.on_click()(
            lambda ev: session.guarded(lambda: self.click(ev.ray_origin, ev.ray_direction))
        )
        self.text.content = model.health(0)

    def _relations(self, gui) -> None:
        """The relations the run misses most, to bring into view."""
        e = self.model.relation_errors
        if not len(e.index):
            gui.add_markdown("no relation has a scan of this run at both ends")
            return
        worst = self.model.costliest()
        self.relation_labels = {self.model.relation_label(r + 1, k): k for r, k in enumerate(worst)}
        gui.add_markdown(
            f"{len(e.index)} relations scored: translation {e.trans.mean():.3f} ± "
            f"{e.trans.std(ddof=1) if len(e.index) > 1 else 0.0:.3f} m (Kümmerle et al.)"
        )
        self.pick_relation = gui.add_dropdown(
            "relations, costliest first", ["(none)", *self.relation_labels], initial_value="(none)"
        )
        self.pick_relation.on_update(lambda _: self.s.guarded(self.relation_picked))

    def relation_picked(self) -> None:
        """The chosen relation drawn, the slider at the pair that ends at its later scan."""
        self.relation = self.relation_labels.get(self.pick_relation.value)
        if self.relation is None:
            self.draw()
            return
        j = int(self.model.relation_errors.ends[self.relation][1])
        if int(self.slider.value) == max(j, 1):
            self.draw()
        self.slider.value = max(j, 1)

    def show_loop_score(self) -> None:
        """The relation score of the run with its loops closed, beside the chained one's."""
        closed = self.model.mean_error(self.model.loops.optimised)
        if closed is not None:
            self.loop_score.content = (
                f"with the loops closed: translation {closed:.3f} m "
                f"(chained: {self.model.mean_error(self.model.poses):.3f} m)"
            )

    def map_switched(self) -> None:
        self.model.map_at = MapAt(self.map_at.value)
        if self.active:
            self.draw_whole()

    def set_loops(self, loops) -> None:
        """The closures decided again (the loop panel): the run with its loops closed anew."""
        self.model.loops = loops
        self.show_loop_score()
        if self.active:
            self.draw_whole()

    @property
    def n(self) -> int:
        return int(self.slider.value) - 1

    def switch(self) -> None:
        """Into the run view, or back to the pair."""
        if self.active:
            self.leave()
        else:
            self.enter()

    def enter(self) -> None:
        """The run drawn whole once (trajectories, flagged pairs, the map's chunks hidden), then
        at the slider's pair."""
        self.active = True
        self.toggle.label = "back to the pair"
        for handle in self.s.nodes.values():
            handle.visible = False
        # the pair's plots are the pair debugger's match, not what is in view
        self.s.plots.folder.visible = False
        pts = self.model.extent()
        self.scale = scene.scene_scale(pts)
        self.s.camera.fit(pts)
        self.s.grid_m = viser_draw.metric_grid(self.s.client.scene, pts)
        self.draw_whole()

    def draw_whole(self) -> None:
        """The run's trajectories, closures and the map's chunks (hidden) drawn anew, then the
        slider's pair."""
        api = self.s.client.scene
        with self.s.client.atomic():
            for handle in [*self.nodes.values(), *(h for m in self.chunk_nodes for h in m)]:
                handle.remove()
            self.still = scene.run_track_layers(self.model.tracks(), self.scale)
            self.nodes = {
                f"/{layer.path}": viser_draw.draw(api, f"/{layer.path}", layer)
                for layer in self.still
            }
            self.chunk_nodes = [
                [
                    viser_draw.draw(api, f"/{layer.path}", layer, visible=False)
                    for layer in scene.run_map_layers(
                        self.model.chunks(poses), self.scale, style, name
                    )
                ]
                for name, poses, style in self.model.maps()
            ]
        self.chunks_shown = 0
        self.draw()

    def leave(self) -> None:
        self.active = False
        self.toggle.label = "show the run"
        chunks = [h for m in self.chunk_nodes for h in m]
        for handle in [*self.nodes.values(), *self.pair_nodes.values(), *chunks]:
            handle.remove()
        self.nodes, self.pair_nodes, self.chunk_nodes = {}, {}, []
        self.s.plots.folder.visible = True
        self.s.fit_view()
        self.s.redraw()

    def draw(self) -> None:
        """The run at the slider's pair: the map's chunks it has passed shown (only those that
        change), its own layers sent, then its health in words (so the words on the page come
        with the scene they describe: ``bench page`` times a step to them)."""
        if self.active:
            self._draw_scene()
        self.text.content = self.model.health(self.n)

    def _draw_scene(self) -> None:
        """The pair's layers, the map's chunks up to it and the legend of what is drawn."""
        layers = scene.run_pair_layers(self.model.pair_at(self.n, self.relation), self.scale)
        whole = self.model.whole_chunks(self.n)
        with self.s.client.atomic():
            for c in range(min(whole, self.chunks_shown), max(whole, self.chunks_shown)):
                for nodes in self.chunk_nodes:
                    nodes[c].visible = c < whole
            self.chunks_shown = whole
            self.pair_nodes = viser_draw.draw_nodes(
                self.s.client.scene, self.pair_nodes, ((f"/{x.path}", x, True) for x in layers)
            )
        shown = {
            layer.style.label: layer.style
            for layer in [*self.still, *layers]
            if scene.has_content(layer)
        }
        if whole:
            for _, _, style in self.model.maps():
                shown.setdefault(style.label, style)
        self.s.h_legend.content = panels.legend_html(
            list(shown.values()), self.s.grid_m, "the world frame: the run's first scan"
        )

    def click(self, origin, direction) -> int | None:
        """In the run view, the pair that ends nearest to a click on the trajectory comes into
        view (the first pair for its start); returns its number (0-based)."""
        at = on_scan_plane(origin, direction)
        if not self.active or at is None:
            return None
        track = np.array([[p.x, p.y] for p in self.model.poses])
        k = int(np.argmin(np.hypot(*(track - at).T)))
        self.slider.value = max(k, 1)
        return max(k, 1) - 1

    def step_flagged(self, direction: int) -> None:
        """The slider to the next (or previous) flagged pair."""
        flagged = self.model.flagged
        ahead = [f for f in flagged if (f - self.n) * direction > 0]
        if ahead:
            self.slider.value = (ahead[0] if direction > 0 else ahead[-1]) + 1

    def open_pair(self) -> None:
        """The pair in view, in the pair debugger, as the run matched it."""
        self.s.open_row(self.model.rows[self.n])

    def open_pair_b(self) -> None:
        """The pair in view as run B matched it."""
        self.s.open_row(self.model.versus.b[self.n])
