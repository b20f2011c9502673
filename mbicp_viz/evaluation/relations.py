"""``eval relations``: Kümmerle et al. 2009 relations (``# t1 t2 x y z roll pitch yaw``).

Each relation is the pose at t2 seen from the pose at t1 (frame of the first). A relation is
matched when both of its times fall within ``tolerance`` of a scan's stamp (after adding the
``offset`` that aligns the log's relative stamps with the relations' absolute ones).
"""

from __future__ import annotations

import time

import numpy as np

from mbicp_viz.core import Params, SearchParams, match, pose_error
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ScanLog
from mbicp_viz.readers.relations import Relation

from .pairs import Guess, pair_guess, stored_truth
from .pool import ordered_map


def nearest_scan(stamps: np.ndarray, t: float, tolerance: float) -> int | None:
    k = int(np.argmin(np.abs(stamps - t)))
    return k if abs(stamps[k] - t) <= tolerance else None


def relation_pairs(
    log: ScanLog, relations: list[Relation], offset: float, tolerance: float
) -> tuple[list[tuple[int, int, Relation]], int]:
    """(i, j, relation) for the relations whose both ends have a scan (indices into ``log.scans``),
    and how many relations had none."""
    stamps = np.array([s.stamp if s.stamp is not None else np.nan for s in log.scans]) + offset
    if np.all(np.isnan(stamps)):
        raise InputError("the log's scans carry no time stamps", log.path, field="stamps")
    out = []
    for rel in relations:
        i, j = nearest_scan(stamps, rel.t1, tolerance), nearest_scan(stamps, rel.t2, tolerance)
        if i is not None and j is not None and i != j:
            out.append((i, j, rel))
    return out, len(relations) - len(out)


def match_relations(
    log: ScanLog,
    found: list[tuple[int, int, Relation]],
    params: Params,
    guess: Guess | str = Guess.identity,
    search: SearchParams | None = None,
    on_row=None,
    skip: int = 0,
    workers: int | None = None,
) -> list[dict]:
    """A row per relation of ``found`` (``relation_pairs``) but the first ``skip`` (a run resumed
    from its rows), in order; ``ref`` and ``obj`` of a row are scan record numbers. Spread over
    ``workers`` processes; ``on_row`` sees each row as it arrives, and Ctrl-C keeps the rows so
    far."""
    records = log.record_numbers()
    jobs = [
        (records[i], records[j], log.scans[i], log.scans[j], rel, params, guess, search)
        for i, j, rel in found[skip:]
    ]
    return ordered_map(_relation_row, jobs, workers, on_row)


def _relation_row(job) -> dict:
    ref_record, obj_record, ref, obj, rel, params, guess, search = job
    g, _ = pair_guess(ref, obj, guess, search)
    t0 = time.perf_counter()
    r = match(ref, obj, g, params)
    et, er = pose_error(r.pose, rel.pose)
    row = {
        "ref": ref_record,
        "obj": obj_record,
        "t1": rel.t1,
        "t2": rel.t2,
        "x": r.pose.x,
        "y": r.pose.y,
        "theta": r.pose.theta,
        "error_xy": et,
        "error_theta": er,
        "converged": r.converged,
        "iterations": r.iterations,
        "time_ms": 1000.0 * (time.perf_counter() - t0),
    }
    stored = stored_truth(ref, obj)
    if stored is not None:
        # the log's own poses judged by the same relation: how good a truth they are for --truth
        # pose
        st, sr = pose_error(stored, rel.pose)
        row |= {"stored_error_xy": st, "stored_error_theta": sr}
    return row


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
    return (
        f"translation error mean {et.mean() * 1000:.1f} mm, median {np.median(et) * 1000:.1f} mm, "
        "max "
        f"{et.max() * 1000:.1f} mm; rotation error mean {er.mean():.3f} deg, median "
        f"{np.median(er):.3f} deg, "
        f"max {er.max():.3f} deg"
    )
