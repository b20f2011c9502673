"""``eval relations``: Kümmerle et al. 2009 relations (``# t1 t2 x y z roll pitch yaw``).

Each relation is the pose at t2 seen from the pose at t1 (frame of the first). A relation is
matched when both of its times fall within ``tolerance`` of a scan's stamp (after adding the
``offset`` that aligns the log's relative stamps with the relations' absolute ones).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from core import Params, Pose2, match, pose_error

from .errors import InputError
from .readers import ScanLog
from .readers.text import open_text
from .sequence import pair_guess


@dataclass(frozen=True)
class Relation:
    t1: float
    t2: float
    pose: Pose2  # pose at t2 in the frame of the pose at t1


def read_relations(path: str) -> list[Relation]:
    out = []
    with open_text(path) as f:
        for line_no, line in enumerate(f, start=1):
            toks = line.split("#", 1)[0].split()
            if not toks:
                continue
            if len(toks) != 8:
                raise InputError(f"expected 't1 t2 x y z roll pitch yaw', got {len(toks)} fields", path, line_no)
            try:
                v = [float(t) for t in toks]
            except ValueError:
                bad = next(t for t in toks if not _is_float(t))
                raise InputError(f"expected a number, got {bad[:40]!r}", path, line_no) from None
            if not all(math.isfinite(x) for x in v):
                raise InputError("not finite", path, line_no)
            out.append(Relation(v[0], v[1], Pose2(v[2], v[3], v[7])))
    if not out:
        raise InputError("no relations", path)
    return out


def _is_float(t):
    try:
        float(t)
        return True
    except ValueError:
        return False


def nearest_scan(stamps: np.ndarray, t: float, tolerance: float) -> int | None:
    k = int(np.argmin(np.abs(stamps - t)))
    return k if abs(stamps[k] - t) <= tolerance else None


def match_relations(log: ScanLog, relations: list[Relation], params: Params, offset: float, tolerance: float,
                    guess: str = "identity") -> tuple[list[dict], int]:
    """Rows for the relations whose both ends have a scan; and how many relations had none."""
    stamps = np.array([s.stamp if s.stamp is not None else np.nan for s in log.scans]) + offset
    if np.all(np.isnan(stamps)):
        raise InputError("the log's scans carry no time stamps", log.path, field="stamps")
    rows, missing = [], 0
    for rel in relations:
        i, j = nearest_scan(stamps, rel.t1, tolerance), nearest_scan(stamps, rel.t2, tolerance)
        if i is None or j is None or i == j:
            missing += 1
            continue
        g, _ = pair_guess(log.scans[i], log.scans[j], guess)
        t0 = time.perf_counter()
        r = match(log.scans[i], log.scans[j], g, params)
        et, er = pose_error(r.pose, rel.pose)
        rows.append({"ref": i, "obj": j, "t1": rel.t1, "t2": rel.t2, "x": r.pose.x, "y": r.pose.y,
                     "theta": r.pose.theta, "error_xy": et, "error_theta": er, "converged": r.converged,
                     "iterations": r.iterations, "time_ms": 1000.0 * (time.perf_counter() - t0)})
    return rows, missing


def summary(rows: list[dict]) -> str:
    if not rows:
        return "no relation had a scan at both ends: check --offset and --tolerance"
    et = np.array([r["error_xy"] for r in rows])
    er = np.degrees([r["error_theta"] for r in rows])
    return (f"{len(rows)} relations matched; translation error mean {et.mean() * 1000:.1f} mm, median "
            f"{np.median(et) * 1000:.1f} mm, max {et.max() * 1000:.1f} mm; rotation error mean {er.mean():.3f} deg, "
            f"median {np.median(er):.3f} deg, max {er.max():.3f} deg")
