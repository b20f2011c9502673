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

from core import Params, Pose2, match, pose_error, relative

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
        row = {"ref": i, "obj": j, "t1": rel.t1, "t2": rel.t2, "x": r.pose.x, "y": r.pose.y,
               "theta": r.pose.theta, "error_xy": et, "error_theta": er, "converged": r.converged,
               "iterations": r.iterations, "time_ms": 1000.0 * (time.perf_counter() - t0)}
        if log.scans[i].pose is not None and log.scans[j].pose is not None:
            # the log's own poses judged by the same relation: how good a truth they are for --truth pose
            st, sr = pose_error(relative(log.scans[i].pose, log.scans[j].pose), rel.pose)
            row |= {"stored_error_xy": st, "stored_error_theta": sr}
        rows.append(row)
    return rows, missing


def summary(rows: list[dict]) -> str:
    if not rows:
        return "no relation had a scan at both ends: check --offset and --tolerance"
    return f"{len(rows)} relations matched; {error_summary(rows, 'error')}"


def stored_summary(rows: list[dict]) -> str | None:
    """The same errors for the poses stored in the log, when every matched relation has them."""
    if not rows or not all("stored_error_xy" in r for r in rows):
        return None
    return f"the log's scan poses against the same relations: {error_summary(rows, 'stored_error')}"


def error_summary(rows: list[dict], key: str) -> str:
    et = np.array([r[f"{key}_xy"] for r in rows])
    er = np.degrees([r[f"{key}_theta"] for r in rows])
    return (f"translation error mean {et.mean() * 1000:.1f} mm, median {np.median(et) * 1000:.1f} mm, max "
            f"{et.max() * 1000:.1f} mm; rotation error mean {er.mean():.3f} deg, median {np.median(er):.3f} deg, "
            f"max {er.max():.3f} deg")
