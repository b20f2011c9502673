"""The run view (``serve LOG --rows ROWS`` on the rows of ``eval sequence``): the whole run in the
world frame — the trajectory its chained matches make, the map they build up to the pair in view,
the log's own poses and odometry where it has them, the flagged pairs — a slider over the pairs,
each pair's health, and "open this pair" into the pair debugger exactly as the run matched it.

The world frame is the first scan's (the robot base's when the rows report its motion, else the
laser's), as ``eval sequence --png`` and ``--rrd`` draw it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import viser.uplot as uplot

from mbicp_viz.core import Pose2, relative
from mbicp_viz.evaluation.health import flags_text
from mbicp_viz.evaluation.run_score import RelationErrors, relation_errors
from mbicp_viz.evaluation.trajectory import accumulate, log_poses, scan_indices, stamps
from mbicp_viz.evaluation.versus import Versus
from mbicp_viz.readers import ScanLog
from mbicp_viz.readers.pair_match import PairMatch, Suspicion
from mbicp_viz.readers.relations import Relation

from .. import scene, viser_draw
from . import panels
from .camera import on_scan_plane

RELATION_TOLERANCE_S = 0.025  # a relation's stamp meets a scan within this (eval relations')
MAP_POINTS = 150_000  # the most map points sent to the page: the scans are thinned evenly to it
# The map goes to the page once, in chunks whose visibility follows the slider (a step sends the
# pair's own scans and a few flags, not the map: 4.6 s a step on the full Intel run before)
MAP_CHUNKS = 100


def is_chain(rows: list[PairMatch]) -> bool:
    """Whether the rows are a run: each pair starts at the scan the one before ended at."""
    return len(rows) > 0 and all(b.ref == a.obj for a, b in zip(rows, rows[1:]))


@dataclass
class RunModel:
    """A run's rows on their log: the poses and the map, computed once."""

    log: ScanLog
    rows: list[PairMatch]
    versus: Versus | None = None  # a second configuration's run of the same pairs (run B)
    relations: list[Relation] | None = None  # Kümmerle et al.'s, on the log's clock + offset
    offset: float = 0.0

    @cached_property
    def poses(self) -> list[Pose2]:
        return accumulate(self.rows)

    @cached_property
    def other(self) -> list[Pose2] | None:
        return accumulate(self.versus.b) if self.versus is not None else None

    @cached_property
    def scans(self) -> list[int]:
        """The record number of each scan the run visits."""
        return scan_indices(self.rows)

    @cached_property
    def mount(self) -> Pose2:
        """T_base_laser when the rows report the base's motion, else the identity."""
        return self.log.frames.mount if self.rows[0].frame != "laser" else Pose2()

    @cached_property
    def stored(self) -> list[Pose2] | None:
        """The log's scan poses (laser frame) as the base's, in the run's world frame."""
        laser = log_poses(self.log, self.rows)
        if laser is None:
            return None
        m, inv = self.mount, self.mount.inverse()
        return [m @ p @ inv for p in laser]

    @cached_property
    def odometry(self) -> list[Pose2] | None:
        odo = [self.log.scan(i).odometry for i in self.scans]
        if any(o is None for o in odo):
            return None
        m, inv = self.mount, self.mount.inverse()
        return [m @ relative(odo[0], o) @ inv for o in odo]

    @cached_property
    def flagged(self) -> list[int]:
        return [n for n, r in enumerate(self.rows) if r.flags]

    def world_points(self, k: int) -> np.ndarray:
        """The points of the run's k-th scan in the world frame."""
        return (self.poses[k] @ self.mount).apply(self.log.scan(self.scans[k]).points())

    @cached_property
    def _map(self) -> tuple[np.ndarray, np.ndarray]:
        """Every ``step``-th scan's points (world frame) and the scan each belongs to."""
        n = len(self.poses)
        sizes = [self.log.scan(i).n_valid for i in self.scans]
        step = max(1, math.ceil(sum(sizes) / MAP_POINTS))
        parts = [(k, self.world_points(k)) for k in range(0, n, step)]
        xy = np.concatenate([p for _, p in parts]) if parts else np.zeros((0, 2))
        owner = np.concatenate([np.full(len(p), k) for k, p in parts]) if parts else np.zeros(0)
        return xy, owner

    @cached_property
    def relation_errors(self) -> RelationErrors | None:
        """The relations the run covers, scored on its chained poses."""
        if self.relations is None:
            return None
        t = np.array([s + self.offset for s in stamps(self.log, self.rows)])
        return relation_errors(t, self.poses, self.relations, RELATION_TOLERANCE_S)

    def costliest(self, most: int = 100) -> list[int]:
        """Positions in ``relation_errors`` of the relations the run misses most, worst first."""
        e = self.relation_errors
        return [int(k) for k in np.argsort(-e.trans, kind="stable")[:most]]

    def relation_label(self, rank: int, k: int) -> str:
        e = self.relation_errors
        i, j = e.ends[k]
        rel = self.relations[e.index[k]]
        return (
            f"{rank}. relation {e.index[k] + 1}: scans {self.scans[i]} → {self.scans[j]} "
            f"({rel.t2 - rel.t1:.0f} s apart): missed by {e.trans[k]:.3f} m, "
            f"{math.degrees(e.rot[k]):.2f} deg"
        )

    def relation_ends(self, k: int) -> tuple[Pose2, Pose2]:
        """A relation's earlier end where the run put it, and where the relation puts the later
        one from there (base frame: the relations are the robot's)."""
        e = self.relation_errors
        start = self.poses[e.ends[k][0]]
        return start, start @ self.relations[e.index[k]].pose

    @cached_property
    def chunks(self) -> list[tuple[int, np.ndarray]]:
        """The map in ``MAP_CHUNKS`` chunks of consecutive scans: (its last scan, its points)."""
        xy, owner = self._map
        cuts = np.array_split(np.arange(len(self.poses)), min(MAP_CHUNKS, len(self.poses)))
        return [(int(c[-1]), xy[(owner >= c[0]) & (owner <= c[-1])]) for c in cuts if len(c)]

    def whole_chunks(self, n: int) -> int:
        """How many chunks the pair n has passed whole (their scans all up to its second)."""
        return sum(last <= n + 1 for last, _ in self.chunks)

    def tracks(self) -> scene.RunTracks:
        fp = np.array([[self.poses[f + 1].x, self.poses[f + 1].y] for f in self.flagged])
        return scene.RunTracks(
            self.poses,
            self.stored,
            self.odometry,
            fp.reshape(-1, 2),
            self.other,
            self.versus.name_b if self.versus is not None else "",
        )

    def pair_at(self, n: int, relation: int | None = None) -> scene.RunPair:
        """Pair n: the map's scans since the last whole chunk, up to its second scan, its scans
        and pose, and a chosen relation (a position in ``relation_errors``)."""
        xy, owner = self._map
        shown = self.whole_chunks(n)
        first = self.chunks[shown - 1][0] + 1 if shown else 0
        return scene.RunPair(
            xy[(owner >= first) & (owner <= n + 1)],
            self.world_points(n),
            self.world_points(n + 1),
            self.poses[n + 1],
            self.relation_ends(relation) if relation is not None else None,
        )

    def extent(self) -> np.ndarray:
        xy, _ = self._map
        track = np.array([[p.x, p.y] for p in self.poses])
        return np.concatenate([xy, track]) if len(xy) else track

    def health(self, n: int) -> str:
        """Pair n in words: its motion, how it ended, its numbers and its signs."""
        row = self.rows[n]
        r = row.result
        parts = [
            f"**pair {n + 1} of {len(self.rows)}**: scans {row.ref} → {row.obj}, {row.matcher}, "
            f"motion {r.pose} of the {row.frame} frame",
            f"{r.iterations} iterations, {r.reason.value}; {r.pairs_kept} pairs kept, "
            f"{r.pairs_rejected} rejected",
        ]
        if row.overlap is not None:
            parts.append(f"{100 * row.overlap:.0f} % of the object points on the reference")
        if r.degeneracy is not None:
            parts.append(f"condition number {r.degeneracy.condition_number:.0f}")
        if row.odometry_xy is not None:
            parts.append(
                f"{1000 * row.odometry_xy:.1f} mm, {math.degrees(row.odometry_theta):.2f} deg "
                "from the odometry"
            )
        parts.append(f"**flagged**: {flags_text(row)}" if row.flags else "not flagged")
        return "  \n".join(parts)

    def series(self) -> tuple[np.ndarray, ...]:
        """The health timeline: pair number, overlap [%], distance from odometry [mm], flagged
        (100 where a pair is, else 0), residual (RMS of the kept pairs' distances) [mm] and,
        beside a run B, how far A and B end apart where they disagree [mm]."""
        x = np.arange(1, len(self.rows) + 1, dtype=float)
        apart = [r.flags.get(Suspicion.DISAGREE, (0.0,))[0] * 1000 for r in self.rows]
        overlap = [100 * r.overlap if r.overlap is not None else np.nan for r in self.rows]
        # the RMS of the kept pairs' distances (the record's error is their mean square)
        residual = [1000 * math.sqrt(r.result.error) for r in self.rows]
        odo = [1000 * r.odometry_xy if r.odometry_xy is not None else np.nan for r in self.rows]
        flagged = [100.0 if r.flags else 0.0 for r in self.rows]
        out = (x, np.array(overlap), np.array(odo), np.array(flagged), np.array(residual))
        return out + ((np.array(apart),) if self.versus is not None else ())


class RunPanel:
    """The run view's controls; in the scene it replaces the pair's layers while it is shown."""

    def __init__(self, session, gui, order: float, model: RunModel):
        self.s, self.model, self.active, self.scale = session, model, False, 1.0
        self.nodes: dict[str, object] = {}  # drawn once per showing of the run
        self.pair_nodes: dict[str, object] = {}  # drawn at each pair
        self.chunk_nodes: list = []  # the map's chunks, shown as the pair passes them
        self.still: list = []
        self.chunks_shown = 0
        rows = model.rows
        with gui.add_folder("Run", order=order):
            gui.add_markdown(
                f"{len(rows)} pairs matched with {rows[0].matcher}; {len(model.flagged)} flagged "
                f"without truth. World frame: the first scan's ({rows[0].frame})."
            )
            self.toggle = gui.add_button("show the run", hint="the whole run, or back to the pair")
            self.slider = gui.add_slider("pair", 1, len(rows), 1, 1)
            self.prev_flagged = gui.add_button("previous flagged")
            self.next_flagged = gui.add_button("next flagged")
            self.text = gui.add_markdown("")
            self.open = gui.add_button("open this pair", hint="as the run matched it")
            self.relation = None  # the relation drawn (a position in model.relation_errors)
            if model.relation_errors is not None:
                self._relations(gui)
            if model.versus is not None:
                gui.add_markdown("  \n".join(model.versus.verdict()))
                self.open_b = gui.add_button("open run B's match of this pair")
                self.open_b.on_click(lambda _: session.guarded(self.open_pair_b))
            data = model.series()
            top = max(
                (float(np.nanmax(v)) for v in (data[2], *data[4:]) if np.any(np.isfinite(v))),
                default=1.0,
            )
            series = [
                uplot.Series(label="pair"),
                panels._line("overlap [%]", "pct", scene.SURFACE),
                panels._line("from odometry [mm]", "mm", scene.FROM_ODOMETRY),
                panels._line("flagged", "pct", scene.SUSPECT),
                panels._line("residual [mm]", "mm", scene.RESIDUAL),
            ]
            if model.versus is not None:
                series.append(panels._line("A and B apart [mm]", "mm", scene.RUN_OTHER))
            self.plot = gui.add_uplot(
                data=data,
                series=tuple(series),
                aspect=1.6,
                title="health of every pair",
                **panels._numeric(
                    "pair", ("pct", "overlap [%]", 3, 105.0), ("mm", "[mm]", 1, top * 1.08)
                ),
            )
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
            "relations, costliest first", ["(none)", *self.relation_labels], "(none)"
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
        pts = self.model.extent()
        self.scale = scene.scene_scale(pts)
        self.s.camera.fit(pts)
        self.s.grid_m = viser_draw.metric_grid(self.s.client.scene, pts)
        api = self.s.client.scene
        with self.s.client.atomic():
            self.still = scene.run_track_layers(self.model.tracks(), self.scale)
            for layer in self.still:
                self.nodes[f"/{layer.path}"] = viser_draw.draw(api, f"/{layer.path}", layer)
            self.chunk_nodes = [
                viser_draw.draw(api, f"/{layer.path}", layer, visible=False)
                for layer in scene.run_map_layers([xy for _, xy in self.model.chunks], self.scale)
            ]
        self.chunks_shown = 0
        self.draw()

    def leave(self) -> None:
        self.active = False
        self.toggle.label = "show the run"
        for handle in [*self.nodes.values(), *self.pair_nodes.values(), *self.chunk_nodes]:
            handle.remove()
        self.nodes, self.pair_nodes, self.chunk_nodes = {}, {}, []
        self.s.fit_view()
        self.s.redraw()

    def draw(self) -> None:
        """The run at the slider's pair: the map's chunks it has passed shown (only those that
        change), its own layers sent, its health in words."""
        self.text.content = self.model.health(self.n)
        if not self.active:
            return
        layers = scene.run_pair_layers(self.model.pair_at(self.n, self.relation), self.scale)
        whole = self.model.whole_chunks(self.n)
        with self.s.client.atomic():
            for c in range(min(whole, self.chunks_shown), max(whole, self.chunks_shown)):
                self.chunk_nodes[c].visible = c < whole
            self.chunks_shown = whole
            drawn = {}
            for layer in layers:
                name = f"/{layer.path}"
                drawn[name] = viser_draw.draw(self.s.client.scene, name, layer)
            for name in self.pair_nodes.keys() - drawn.keys():  # a relation no longer chosen
                self.pair_nodes[name].remove()
            self.pair_nodes = drawn
        shown = {
            layer.style.label: layer.style
            for layer in [*self.still, *layers]
            if scene.has_content(layer)
        }
        if whole:
            shown.setdefault(scene.RUN_MAP.label, scene.RUN_MAP)
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
