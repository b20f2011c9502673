"""Trajectories from a run's matches: accumulation, a Kalman filter with odometry, TUM files,
plots.

A run's rows each place a new scan from one placed before: the scan before it (consecutive pairs)
or the last key frame (a key-frame run, evaluation/keyframes.py). The world frame is the first
scan's sensor frame. Paper 003 §5.3 builds its maps with a Kalman filter fusing the matcher with
odometry; ``kalman`` does that on SE(2): odometry increments predict, the matcher's increments
(composed on the estimate of the scan they start from) correct.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from mbicp_viz.core import Pose2, relative, wrap_angle
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ScanLog
from mbicp_viz.readers.pair_match import PairMatch

# The EKF's noise, per axis (m, m, rad): odometry increments predict, matches correct.
ODOMETRY_SIGMA = (0.05, 0.05, math.radians(2.0))
MATCH_SIGMA = (0.02, 0.02, math.radians(0.5))
MATCHED = "matcher"
FUSED = "kalman (matcher + odometry)"
STORED = "log poses"


def accumulate(rows: list[PairMatch]) -> list[Pose2]:
    """Poses of scans rows[0].ref, rows[k].obj ... composed from the matched motions."""
    return placed(*_pairs(rows), _columns(rows).poses("motion"))


def _columns(rows: Sequence[PairMatch]):
    """The rows as a ``run_rows.RunRows`` (itself when it is one): what is read of them, read from
    its columns, no record made again from a rows file."""
    from .run_rows import RunRows  # it ranks with health.py, which imports this module

    return RunRows.of(rows)


def _pairs(rows: list[PairMatch]) -> tuple[list[int], list[int]]:
    """(refs, objs) of the rows."""
    run = _columns(rows)
    return run.column("ref").tolist(), run.column("obj").tolist()


def placed(refs: Sequence[int], objs: Sequence[int], motions: Sequence[Pose2]) -> list[Pose2]:
    """The poses of the scans a run visits (refs[0], objs[0], objs[1] ...), from the identity at
    the first: each pair's motion composed on the pose of the scan it starts from."""
    at = {refs[0]: Pose2()}
    for ref, obj, m in zip(refs, objs, motions):
        at[obj] = at[ref] @ m
    return [at[refs[0]], *(at[k] for k in objs)]


def is_run(rows: list[PairMatch]) -> bool:
    """Whether the rows are a run: each pair places a new scan from one the run placed before."""
    return bool(rows) and off_the_run(rows) is None


def off_the_run(rows: list[PairMatch]) -> int | None:
    """The first row that starts from a scan the rows before it did not place, or places one
    again (None: the rows are a run)."""
    if not rows:
        return None
    refs, objs = _pairs(rows)
    seen = {refs[0]}
    for k, (ref, obj) in enumerate(zip(refs, objs)):
        if ref not in seen or obj in seen:
            return k
        seen.add(obj)
    return None


def odometry_chain(log: ScanLog, rows: list[PairMatch]) -> list[Pose2] | None:
    """The odometry's track over the scans the rows visit, from the first, in the frame the rows
    report (the base's when they do): each row's odometry motion chained, no scan read again.
    None when a row has no odometry."""
    run = _columns(rows)
    return odometry_placed(log, *_pairs(run), run.poses("odometry"), run.first.frame)


def odometry_placed(
    log: ScanLog, refs: Sequence[int], objs: Sequence[int], odometry: list, frame: str
) -> list[Pose2] | None:
    """``odometry_chain`` of a run's pairs and their odometry motions (laser frame; None: none)
    reported in ``frame``."""
    if any(o is None for o in odometry):
        return None
    base = frame != "laser"
    return placed(refs, objs, [log.frames.reported(o, base) for o in odometry])


def scan_indices(rows: list[PairMatch]) -> list[int]:
    """The scans a run visits, in its order."""
    refs, objs = _pairs(rows)
    return [refs[0], *objs]


def log_poses(log: ScanLog, records: list[int]) -> list[Pose2] | None:
    """The log's own poses of the scans ``records``, in the first one's frame (None if one has
    none)."""
    xyt = log.poses_of(records)
    if np.isnan(xyt).any():  # a bag stores none
        return None
    # each pose relative to the first (``relative``, for all at once)
    c, s = math.cos(xyt[0, 2]), math.sin(xyt[0, 2])
    d = xyt - xyt[0]
    x, y = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    theta = wrap_angle(d[:, 2])
    return [Pose2(*p) for p in np.column_stack([x, y, theta]).tolist()]


def sequence_tracks(log: ScanLog, rows: list[PairMatch], fuse: bool) -> dict[str, list[Pose2]]:
    """The trajectories of a sequence: the matches composed, the log's poses when it stores them,
    and with ``fuse`` the EKF of the matches with the log's odometry (last; the one a map is drawn
    on)."""
    out = {MATCHED: accumulate(rows)}
    stored = log_poses(log, scan_indices(rows))
    if stored is not None:
        out[STORED] = stored
    if fuse:
        odo = odometry_chain(log, rows)
        if odo is None:
            raise InputError(
                "--kalman needs odometry for every scan; this log has none",
                log.path,
                field="--kalman",
            )
        out[FUSED] = kalman(rows, odo, ODOMETRY_SIGMA, MATCH_SIGMA)
    return out


def map_step(log: ScanLog, records: list[int], budget: int, sample: int = 50) -> int:
    """Every how many of a run's scans (``records``) a map of at most ``budget`` points takes:
    the valid readings of ``sample`` scans spread over the run say how many a scan holds."""
    n = len(records)
    picked = np.unique(np.linspace(0, n - 1, min(n, sample)).astype(int))
    per_scan = np.median([s.n_valid for s in log.scans_of([records[k] for k in picked], False)])
    return max(1, math.ceil(n * per_scan / budget))


def stamps(log: ScanLog, rows: list[PairMatch]) -> list[float]:
    """Each visited scan's time stamp (its record number when it has none)."""
    records = scan_indices(rows)
    scans = log.scans_of(records, odometry=False)
    return [s.stamp if s.stamp is not None else float(i) for i, s in zip(records, scans)]


def _jacobians(x: Pose2, u: Pose2):
    """d(x (+) u)/dx and d(x (+) u)/du for SE(2) composition."""
    c, s = math.cos(x.theta), math.sin(x.theta)
    Jx = np.array([[1.0, 0.0, -s * u.x - c * u.y], [0.0, 1.0, c * u.x - s * u.y], [0.0, 0.0, 1.0]])
    Ju = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Jx, Ju


def kalman(
    rows: list[PairMatch],
    odometry: list[Pose2],
    q_sigma: tuple[float, float, float],
    r_sigma: tuple[float, float, float],
) -> list[Pose2]:
    """EKF over the scan poses: predict with the odometry increment (noise ``q_sigma`` per axis:
    m, m, rad), update with the matcher's increment composed on the previous estimate (noise
    ``r_sigma``). A match that did not converge is skipped (prediction only). In a key-frame run
    the match is composed on the key frame's estimate (its correlation with the newest estimate is
    left out, as a filter over the newest pose alone must)."""
    Q, R = np.diag(np.square(q_sigma)), np.diag(np.square(r_sigma))
    x, P = Pose2(), np.zeros((3, 3))
    if not len(rows):
        return [x]
    run = _columns(rows)
    refs, objs = _pairs(run)
    out, at = [x], {refs[0]: x}
    steps = zip(refs, objs, run.column("converged").tolist(), run.poses("motion"))
    for k, (ref, obj, converged, m) in enumerate(steps):
        u = relative(odometry[k], odometry[k + 1])
        Jx, Ju = _jacobians(x, u)
        prior, Pp = x @ u, Jx @ P @ Jx.T + Ju @ Q @ Ju.T
        if converged:
            start = at[ref]
            _, Ju_m = _jacobians(start, m)
            z = start @ m
            Rz = Ju_m @ R @ Ju_m.T
            innov = np.array(
                [
                    z.x - prior.x,
                    z.y - prior.y,
                    (z.theta - prior.theta + math.pi) % (2 * math.pi) - math.pi,
                ]
            )
            K = Pp @ np.linalg.inv(Pp + Rz)
            prior = Pose2.from_array(prior.as_array() + K @ innov)
            Pp = (np.eye(3) - K) @ Pp
        x, P = prior, Pp
        out.append(x)
        at[obj] = x
    return out


def tum_text(poses: list[Pose2], stamps: list[float]) -> str:
    """TUM trajectory format (``timestamp tx ty tz qx qy qz qw``), which evo reads."""
    lines = ["# timestamp tx ty tz qx qy qz qw  (mbicp-viz; world = first scan's sensor frame)"]
    for t, p in zip(stamps, poses):
        lines.append(
            f"{t:.6f} {p.x:.6f} {p.y:.6f} 0.000000 0.000000 0.000000 "
            f"{math.sin(p.theta / 2):.9f} {math.cos(p.theta / 2):.9f}"
        )
    return "\n".join(lines) + "\n"


def plot_png(
    log: ScanLog, rows: list[PairMatch], tracks: dict[str, list[Pose2]], path: str, map_track: str
) -> None:
    """Trajectories, and the map: every scan drawn at its pose on ``map_track``."""
    from mbicp_viz.pyplot import pyplot, save_png

    plt = pyplot()

    fig, ax = plt.subplots(figsize=(8, 8))
    for scan, pose in zip(log.scans_of(scan_indices(rows), odometry=False), tracks[map_track]):
        pts = pose.apply(scan.points()[::2])
        ax.plot(pts[:, 0], pts[:, 1], ",", color=(0.85, 0.15, 0.15), alpha=0.5)
    for name, poses in tracks.items():
        xy = np.array([[p.x, p.y] for p in poses])
        ax.plot(xy[:, 0], xy[:, 1], "-", lw=1.5, label=name)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend()
    ax.set_title(f"{log.path}: map on the {map_track} trajectory")
    fig.tight_layout()
    save_png(fig, path, 110)
