"""The SLAM benchmark's own score of a whole run (Kümmerle et al. 2009, "On measuring the accuracy
of SLAM algorithms"): for each relation, the motion the run estimates between the relation's two
stamps against the reference motion.

For a relation from t1 to t2 with reference motion d* and the run's poses P1, P2 at those stamps,
the run's motion is d = P1^-1 P2 and its error e = d*^-1 d (the paper's d (-) d*); the
translational error is |t(e)| (equal to |t(d) - t(d*)|), the rotational |theta(e)|. The paper
reports mean and (sample) standard deviation of both, absolute and squared. A relation scores
only where the run has a scan within ``tolerance`` of both of its stamps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mbicp_viz.core import Pose2, pose_error, relative
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ScanLog
from mbicp_viz.readers.pair_match import PairMatch
from mbicp_viz.readers.relations import Relation

from .relations import nearest_scan
from .trajectory import (
    FUSED,
    MATCH_SIGMA,
    ODOMETRY_SIGMA,
    accumulate,
    kalman,
    odometry_chain,
    off_the_run,
    stamps,
)

LOOPS_CLOSED = "pose graph (loops closed)"  # the track of a run with its loops closed

# Kümmerle et al. 2009, Table I (translational error [m], mean ± sd over all relations): scan
# matching, and the best graph mapping (GMapping) beside it; by the log the relations belong to.
PUBLISHED = {
    "intel": ((0.220, 0.296), 0.070),
    "aces": ((0.173, 0.614), 0.060),
    "fr079": ((0.258, 0.427), 0.061),
}


DEG2_PER_RAD2 = (180.0 / math.pi) ** 2


@dataclass(frozen=True)
class RunScore:
    """One trajectory's errors over the relations it covers: mean and sd, absolute and squared."""

    track: str
    relations: int  # scored
    missed: int  # relations without a pose of this run at both stamps
    trans: tuple[float, float]  # [m]
    rot: tuple[float, float]  # [rad]
    trans_sq: tuple[float, float]  # [m^2]
    rot_sq: tuple[float, float]  # [rad^2]
    # the relations with the largest translational errors: (index, error [m], error [rad])
    worst: tuple[tuple[int, float, float], ...]

    def line(self) -> str:
        if not self.relations:
            return f"{self.track}: no relation has a pose of it at both stamps"
        (t, ts), (r, rs) = self.trans, self.rot
        (t2, t2s), (r2, r2s) = self.trans_sq, self.rot_sq
        return (
            f"{self.track}: translation {t:.3f} ± {ts:.3f} m, rotation {math.degrees(r):.3f} ± "
            f"{math.degrees(rs):.3f} deg; squared {t2:.4f} ± {t2s:.4f} m², "
            f"{r2 * DEG2_PER_RAD2:.3f} ± {r2s * DEG2_PER_RAD2:.3f} deg² "
            f"({self.relations} relations, {self.missed} without both stamps)"
        )


@dataclass(frozen=True)
class RelationErrors:
    """The relations a trajectory covers (a pose at both stamps): their index in the file, the
    poses at their two ends, translational error [m] and rotational error [rad]."""

    index: np.ndarray
    ends: np.ndarray  # (n, 2) pose indices
    trans: np.ndarray
    rot: np.ndarray


def relation_errors(
    stamps: np.ndarray, poses: list[Pose2], relations: list[Relation], tolerance: float
) -> RelationErrors:
    """Each relation covered, scored (Kümmerle et al.'s e = d*^-1 d)."""
    index, ends, et, er = [], [], [], []
    for k, rel in enumerate(relations):
        i, j = nearest_scan(stamps, rel.t1, tolerance), nearest_scan(stamps, rel.t2, tolerance)
        if i is None or j is None:
            continue
        t, r = pose_error(relative(poses[i], poses[j]), rel.pose)
        index.append(k), ends.append((i, j)), et.append(t), er.append(r)
    return RelationErrors(
        np.array(index, int), np.array(ends, int).reshape(-1, 2), np.array(et), np.array(er)
    )


def score_track(
    track: str,
    stamps: list[float],
    poses: list[Pose2],
    relations: list[Relation],
    tolerance: float,
    worst: int = 5,
) -> RunScore:
    """The score of one trajectory (a pose per stamp, any world frame: only motions count)."""
    e = relation_errors(np.asarray(stamps, float), poses, relations, tolerance)
    index, et, er = e.index, e.trans, e.rot

    def stats(v: np.ndarray) -> tuple[float, float]:
        # the sample standard deviation, as the benchmark's own scorer reports it
        if not len(v):
            return math.nan, math.nan
        return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0

    order = np.argsort(-et, kind="stable")[:worst]
    return RunScore(
        track,
        len(index),
        len(relations) - len(index),
        stats(et),
        stats(er),
        stats(et**2),
        stats(er**2),
        tuple((int(index[k]), float(et[k]), float(er[k])) for k in order),
    )


def run_tracks(
    log: ScanLog, rows: list[PairMatch], path: str, offset: float
) -> dict[str, tuple[list[float], list[Pose2]]]:
    """The trajectories an ``eval sequence`` run's rows give, each with its stamps (+ ``offset``,
    the relations' clock): the matches chained, their Kalman fusion with the odometry and the raw
    odometry (both where the log has odometry for every scan). The rows must form a chain (each
    from a scan placed before: the one before it, or a key frame)."""
    if (k := off_the_run(rows)) is not None:
        raise InputError(
            f"the rows are no chain: scans {rows[k].ref} -> {rows[k].obj} do not start from a "
            "scan the rows before placed, or place one again (eval sequence writes a chain)",
            path,
            rows[k].line,
            field="ref",
        )
    t = [s + offset for s in stamps(log, rows)]
    tracks = {"matches chained": (t, accumulate(rows))}
    if (odometry := odometry_chain(log, rows)) is not None:
        tracks[FUSED] = (t, kalman(rows, odometry, ODOMETRY_SIGMA, MATCH_SIGMA))
        tracks["raw odometry"] = (t, odometry)
    return tracks


def published_line(relations_path: str) -> str | None:
    """The paper's figures for the log a relations file belongs to (by its name), if it is one of
    the paper's."""
    name = Path(relations_path).name.lower()
    for log, ((mean, sd), graph) in PUBLISHED.items():
        if log in name:
            return (
                f"published (Kümmerle et al. 2009, {log}): scan matching {mean:.3f} ± {sd:.3f} m, "
                f"graph mapping (GMapping) {graph:.3f} m"
            )
    return None
