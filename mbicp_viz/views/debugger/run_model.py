"""A run's model for the run view (views/debugger/run.py): the rows of ``eval sequence`` on their
log — the poses the chained matches make, the map they build (thinned and in chunks for the page),
the log's own poses and odometry, the flagged pairs, a second run beside it, the relations it is
scored on. No viser here.

The world frame is the first scan's (the robot base's when the rows report its motion, else the
laser's), as ``eval sequence --png`` and ``--rrd`` draw it. With its loops closed, the map and the
pair are drawn at the chained poses, at the pose graph's, or at both, one map over the other
(``map_at``).
"""

from __future__ import annotations

import copy
import math
import threading
from dataclasses import dataclass, field
from enum import StrEnum
from functools import cached_property

import numpy as np

from mbicp_viz.core import Pose2
from mbicp_viz.evaluation.health import flags_text
from mbicp_viz.evaluation.loops import LoopRun
from mbicp_viz.evaluation.run_rows import RunRows
from mbicp_viz.evaluation.run_score import RelationErrors, relation_errors
from mbicp_viz.evaluation.trajectory import (
    accumulate,
    log_poses,
    map_step,
    odometry_placed,
    placed,
    scan_indices,
    stamps,
)
from mbicp_viz.evaluation.versus import Versus
from mbicp_viz.readers import ScanLog
from mbicp_viz.readers.relations import Relation

from .. import scene
from .markdown import literal


class MapAt(StrEnum):
    """The poses the run view's map is drawn at (its "map at" list)."""

    CHAINED = "the chained poses"
    LOOPS = "the poses with the loops closed"
    BOTH = "both, the loops closed over the chained"


RELATION_TOLERANCE_S = 0.025  # a relation's stamp meets a scan within this (eval relations')
MAP_POINTS = 150_000  # the most map points sent to the page: the scans are thinned evenly to it
# The map goes to the page once, in chunks whose visibility follows the slider (a step sends the
# pair's own scans and a few flags, not the map: 4.6 s a step on the full Intel run before)
MAP_CHUNKS = 100


@dataclass
class RunModel:
    """A run's rows on their log: the poses and the map, computed once."""

    log: ScanLog
    rows: RunRows  # (a list of records is taken as one)
    versus: Versus | None = None  # a second configuration's run of the same pairs (run B)
    relations: list[Relation] | None = None  # Kümmerle et al.'s, on the log's clock + offset
    offset: float = 0.0
    loops: LoopRun | None = None  # the run with its loops closed
    map_at: MapAt = MapAt.CHAINED  # the poses the map is drawn at
    # the map at each set of poses it was drawn at: id(poses) -> (poses, (points, their scans))
    _maps: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self):
        self.rows = RunRows.of(self.rows)

    @cached_property
    def poses(self) -> list[Pose2]:
        r = self.rows
        return placed(r.column("ref"), r.column("obj"), r.poses("motion"))

    @property
    def drawn(self) -> list[Pose2]:
        """The poses the pair, the closures and the map on top are drawn at."""
        chained = self.map_at is MapAt.CHAINED or self.loops is None
        return self.poses if chained else self.loops.optimised

    def maps(self) -> list[tuple[str, list[Pose2], scene.Style]]:
        """Each map drawn (its name, its poses, its legend entry), the one on top first: the
        chained run's, the loops-closed one's, or that over the chained one's."""
        if self.drawn is self.poses:
            return [("map", self.poses, scene.RUN_MAP)]
        loops = [("map", self.drawn, scene.RUN_LOOP_MAP)]
        return loops + (
            [("map_before", self.poses, scene.RUN_MAP)] if self.map_at is MapAt.BOTH else []
        )

    @cached_property
    def other(self) -> list[Pose2] | None:
        return accumulate(self.versus.b) if self.versus is not None else None

    @cached_property
    def scans(self) -> list[int]:
        """The record number of each scan the run visits."""
        return scan_indices(self.rows)

    @cached_property
    def base(self) -> bool:
        """Whether the rows report the robot base's motion (else the laser's)."""
        return self.rows.first.frame != "laser"

    @cached_property
    def mount(self) -> Pose2:
        """T_base_laser when the rows report the base's motion, else the identity."""
        return self.log.frames.mount if self.base else Pose2()

    @cached_property
    def stored(self) -> list[Pose2] | None:
        """The log's scan poses (laser frame) in the frame the rows report, the run's world."""
        laser = log_poses(self.log, self.scans)
        if laser is None:
            return None
        return [self.log.frames.reported(p, self.base) for p in laser]

    @cached_property
    def odometry(self) -> list[Pose2] | None:
        """The odometry's track, chained from each row's odometry motion (the log's scans are
        not read again)."""
        r = self.rows
        return odometry_placed(
            self.log, r.column("ref"), r.column("obj"), r.poses("odometry"), r.first.frame
        )

    @cached_property
    def flagged(self) -> list[int]:
        return np.flatnonzero(self.rows.column("flagged")).tolist()

    def world_points(self, k: int) -> np.ndarray:
        """The points of the run's k-th scan in the world frame."""
        return (self.drawn[k] @ self.mount).apply(self.log.scan(self.scans[k]).points())

    @cached_property
    def _sampled(self) -> list[tuple[int, np.ndarray]]:
        """Every ``step``-th scan of the run and its points (in its own frame), read once."""
        kept = list(range(0, len(self.poses), map_step(self.log, self.scans, MAP_POINTS)))
        scans = self.log.scans_of([self.scans[k] for k in kept], False)
        return [(k, self.mount.apply(s.points())) for k, s in zip(kept, scans)]

    def _map(self, poses: list[Pose2]) -> tuple[np.ndarray, np.ndarray]:
        """The sampled scans' points at ``poses`` (world frame) and the scan each belongs to;
        kept while those poses are (closures decided again make new ones)."""
        if id(poses) not in self._maps:
            parts = [(k, poses[k].apply(p)) for k, p in self._sampled]
            xy = np.concatenate([p for _, p in parts]) if parts else np.zeros((0, 2))
            owner = np.concatenate([np.full(len(p), k) for k, p in parts]) if parts else []
            self._maps = {
                i: m for i, m in self._maps.items() if m[0] in (self.poses, self.drawn)
            } | {id(poses): (poses, (xy, np.asarray(owner)))}
        return self._maps[id(poses)][1]

    @cached_property
    def relation_errors(self) -> RelationErrors | None:
        """The relations the run covers, scored on its chained poses."""
        return self.errors_on(self.poses)

    def errors_on(self, poses: list[Pose2]) -> RelationErrors | None:
        """The relations the run covers, scored on ``poses`` (one per scan of the run)."""
        if self.relations is None:
            return None
        t = np.array([s + self.offset for s in stamps(self.log, self.rows)])
        return relation_errors(t, poses, self.relations, RELATION_TOLERANCE_S)

    def mean_error(self, poses: list[Pose2]) -> float | None:
        """The mean translational error of ``poses`` on the relations [m] (None: no relations,
        or none with a scan of the run at both ends)."""
        e = self.errors_on(poses)
        return float(e.trans.mean()) if e is not None and len(e.index) else None

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
        start = self.drawn[e.ends[k][0]]
        return start, start @ self.relations[e.index[k]].pose

    @cached_property
    def _cuts(self) -> list[np.ndarray]:
        """The run's scans in ``MAP_CHUNKS`` chunks of consecutive ones."""
        cuts = np.array_split(np.arange(len(self.poses)), min(MAP_CHUNKS, len(self.poses)))
        return [c for c in cuts if len(c)]

    def chunks(self, poses: list[Pose2]) -> list[np.ndarray]:
        """The map at ``poses``, its points in its chunks."""
        xy, owner = self._map(poses)
        return [xy[(owner >= c[0]) & (owner <= c[-1])] for c in self._cuts]

    def whole_chunks(self, n: int) -> int:
        """How many chunks the pair n has passed whole (their scans all up to its second)."""
        return sum(int(c[-1]) <= n + 1 for c in self._cuts)

    def tracks(self) -> scene.RunTracks:
        fp = np.array([[self.poses[f + 1].x, self.poses[f + 1].y] for f in self.flagged])
        return scene.RunTracks(
            self.poses,
            self.stored,
            self.odometry,
            fp.reshape(-1, 2),
            self.other,
            self.versus.name_b if self.versus is not None else "",
            self.loops.optimised if self.loops is not None else None,
            [
                (c.verdict, *self.loops.ends(c, self.drawn))
                for c in (self.loops.closures if self.loops is not None else [])
            ],
        )

    def pair_at(self, n: int, relation: int | None = None) -> scene.RunPair:
        """Pair n: the map's scans since the last whole chunk, up to its second scan, its scans
        and pose, and a chosen relation (a position in ``relation_errors``)."""
        shown = self.whole_chunks(n)
        first = int(self._cuts[shown - 1][-1]) + 1 if shown else 0
        last = []
        for name, poses, style in self.maps():
            xy, owner = self._map(poses)
            last.append((name, xy[(owner >= first) & (owner <= n + 1)], style))
        return scene.RunPair(
            last,
            self.world_points(n),
            self.world_points(n + 1),
            self.drawn[n + 1],
            self.relation_ends(relation) if relation is not None else None,
        )

    def extent(self) -> np.ndarray:
        xy, _ = self._map(self.drawn)
        track = np.array([[p.x, p.y] for p in self.drawn])
        return np.concatenate([xy, track]) if len(xy) else track

    def health(self, n: int) -> str:
        """Pair n in words: its motion, how it ended, its numbers and its signs."""
        row = self.rows[n]
        r = row.result
        parts = [
            f"**pair {n + 1} of {len(self.rows)}**: scans {row.ref} → {row.obj}, {row.matcher}, "
            f"motion {r.pose} of the {literal(row.frame)} frame",
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
        if self.loops is not None:
            parts.append(f"loops: {self.loops.around(n + 1)}")
        return "  \n".join(parts)

    def warmed(self) -> RunModel:
        """This model with what every tab needs computed (the poses, the map at them, the health
        series, the relation errors): its copies share them (``tab_model``)."""
        _ = self.stored, self.odometry, self.flagged, self.relation_errors, self.series
        self._map(self.poses)
        return self

    @cached_property
    def series(self) -> tuple[np.ndarray, ...]:
        """The health timeline: pair number, overlap [%], distance from odometry [mm], flagged
        (100 where a pair is, else 0), residual (RMS of the kept pairs' distances) [mm] and,
        beside a run B, how far A and B end apart where they disagree [mm]."""
        c = self.rows.column
        x = np.arange(1, len(self.rows) + 1, dtype=float)
        # the RMS of the kept pairs' distances (the record's error is their mean square)
        residual = 1000 * np.sqrt(c("error").astype(float))
        flagged = np.where(c("flagged"), 100.0, 0.0)
        out = (x, 100 * c("overlap"), 1000 * c("odometry_xy"), flagged, residual)
        return out + ((1000 * c("apart"),) if self.versus is not None else ())


# one warmed model per run a source holds, computed once (by the server when it starts, or by the
# first tab) and copied for each tab, which keeps its own map choice and closures decided by hand
_SHARED: dict[int, tuple[object, RunModel]] = {}
_SHARED_LOCK = threading.Lock()
_SHARED_MOST = 4


def tab_model(src) -> RunModel:
    """A tab's model of the run of ``src`` (a debugger ``Source``): a shallow copy of the one
    warmed model of that run, so a second tab, or the first after the server's warm-up, opens
    without computing it again (the Intel run: about 1 s a tab)."""
    with _SHARED_LOCK:
        hit = _SHARED.get(id(src))
        if hit is None or hit[0] is not src:
            model = RunModel(src.log, src.run, src.versus, src.relations, src.offset, src.loops)
            hit = _SHARED[id(src)] = (src, model.warmed())
            while len(_SHARED) > _SHARED_MOST:
                _SHARED.pop(next(iter(_SHARED)))
    return copy.copy(hit[1])
