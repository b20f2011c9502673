"""``eval corridor``: how the matchers fare where the scene leaves a direction free (paper 000
§3.3).

A pair is degenerate when, at its true pose, the surfaces the object points land on constrain
one direction of motion far less than the others: the condition number of their point-to-line
information in (x, y, L theta) (the degeneracy indicator's, ``core/uncertainty.py``) is above a
limit. Every consecutive pair of a corrected log is matched from its stored pose moved uniformly
within +/-XY, +/-THETA (a poor guess, or odometry-like with a small one), and each matcher's
successes are counted on the degenerate pairs and on the others apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from mbicp_viz.core import Params, Pose2, Scan, match, pose_error
from mbicp_viz.core.uncertainty import DEGENERACY_LENGTH_M, degeneracy, surface_tangents
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ScanLog

from .bench import bench_guesses
from .criteria import PAPER_000
from .pairs import stored_truth
from .pool import ordered_map

# Object points farther than this from the reference at the true pose see no surface there.
ON_SURFACE_M = 0.1


def surface_condition(ref: Scan, obj: Scan, truth: Pose2) -> float:
    """Condition number of the point-to-line information of the object points at ``truth`` on the
    reference surfaces they land on (within ``ON_SURFACE_M``); inf when fewer than three do."""
    pts = ref.points()
    d, j = cKDTree(pts).query(truth.apply(obj.points()), k=1, distance_upper_bound=ON_SURFACE_M)
    j = j[np.isfinite(d)]
    deg = degeneracy(pts[j], surface_tangents(pts, ref.is_full_circle(), j), DEGENERACY_LENGTH_M)
    return deg.condition_number if deg is not None else math.inf


@dataclass(frozen=True)
class CorridorRow:
    pair: tuple[int, int]
    condition: float
    success: dict[str, bool]  # matcher name -> within PAPER_000 of the stored pose


def _row(job) -> CorridorRow:
    i, j, ref, obj, truth, guess, params = job
    out = {}
    for name, p in params.items():
        et, er = pose_error(match(ref, obj, guess, p).pose, truth)
        out[name] = PAPER_000.correct(et, er)
    return CorridorRow((i, j), surface_condition(ref, obj, truth), out)


def corridor(
    log: ScanLog,
    params: dict[str, Params],
    perturb: tuple[float, float],
    seed: int = 0,
    workers: int | None = None,
    on_row=None,
) -> list[CorridorRow]:
    """One row per consecutive pair with stored poses, its matches from a perturbed guess."""
    pairs = log.consecutive_pairs(None)
    guesses = bench_guesses(log, pairs, perturb, seed)
    jobs = []
    for (i, j), g in zip(pairs, guesses):
        ref, obj = log.scan(i), log.scan(j)
        truth = stored_truth(ref, obj)
        if truth is None:
            raise InputError(
                f"scan {i} or {j} has no pose: eval corridor needs a corrected log", log.path
            )
        jobs.append((i, j, ref, obj, truth, g, params))
    return ordered_map(_row, jobs, workers, on_row)


def corridor_summary(rows: list[CorridorRow], limit: float) -> list[str]:
    """Per matcher: successes on the degenerate pairs (condition above ``limit``) and on the
    rest."""
    degenerate = [r for r in rows if r.condition > limit]
    others = [r for r in rows if r.condition <= limit]
    lines = [
        f"{len(degenerate)} of {len(rows)} pairs degenerate at the truth (surface condition number "
        "above "
        f"{limit:g})"
    ]
    for name in rows[0].success if rows else []:
        d = sum(r.success[name] for r in degenerate)
        o = sum(r.success[name] for r in others)
        lines.append(
            f"{name:<10} degenerate pairs {d}/{len(degenerate)} "
            f"({100 * d / max(len(degenerate), 1):.1f} %), "
            f"the others {o}/{len(others)} ({100 * o / max(len(others), 1):.1f} %)"
        )
    return lines
