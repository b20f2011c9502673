"""The pairs an evaluation scores (``tune``, ``eval covariance``): scans, a guess and the truth.

The truth is a corrected log's scan poses or Kümmerle's relations; the guess a ``Guess`` kind or,
with "perturb", the truth moved uniformly within bounds (seeded, as ``bench matches --perturb``):
the protocol the baselines are compared with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbicp_viz.core import Pose2, SearchParams
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ScanLog

from .bench import bench_guesses
from .pairs import pair_guess, stored_truth

GUESSES = ("perturb", "identity", "odometry", "search")  # the truth itself is never a guess


@dataclass(frozen=True)
class Case:
    """One pair to score: indices into its log's scans, the guess (laser frame) and the truth."""

    log: int
    i: int
    j: int
    guess: Pose2
    truth: Pose2


def pose_cases(
    k: int,
    log: ScanLog,
    guesses: str,
    perturb: tuple[float, float] | None,
    seed: int,
    search: SearchParams | None,
    limit: int | None,
) -> list[Case]:
    """The consecutive pairs of a corrected log, scored against its scan poses. ``guesses``: a
    ``Guess`` kind (not the poses themselves), or "perturb": the stored pose moved within
    ``perturb``."""
    pairs = log.consecutive_pairs(limit)
    scans = {r: n for n, r in enumerate(log.record_numbers())}
    out = []
    moved = bench_guesses(log, pairs, perturb, seed) if guesses == "perturb" else None
    for n, (i, j) in enumerate(pairs):
        ref, obj = log.scan(i), log.scan(j)
        truth = stored_truth(ref, obj)
        if truth is None:
            raise InputError(
                f"scan {i} or {j} has no pose: --truth pose needs a corrected log",
                log.path,
                field="--truth",
            )
        g = moved[n] if moved is not None else pair_guess(ref, obj, guesses, search)[0]
        out.append(Case(k, scans[i], scans[j], g, truth))
    return out


def relation_cases(
    k: int,
    log: ScanLog,
    relations,
    offset: float,
    tolerance: float,
    guesses: str,
    perturb: tuple[float, float] | None,
    seed: int,
    search: SearchParams | None,
) -> list[Case]:
    """The relations whose two ends have a scan (Kümmerle et al. 2009), from a ``Guess`` kind or,
    with "perturb", from the relation moved within ``perturb``."""
    from .relations import relation_pairs

    found, _ = relation_pairs(log, relations, offset, tolerance)
    if not found:
        raise InputError(
            "no relation has a scan at both ends: check --offset and --tolerance",
            log.path,
            field="--relations",
        )
    rng = np.random.default_rng(seed)
    out = []
    for i, j, rel in found:
        if guesses == "perturb":
            dx, dy, dth = rng.uniform(-1.0, 1.0, 3) * (perturb[0], perturb[0], perturb[1])
            g = Pose2(rel.pose.x + dx, rel.pose.y + dy, rel.pose.theta + dth)
        else:
            g = pair_guess(log.scans[i], log.scans[j], guesses, search)[0]
        out.append(Case(k, i, j, g, rel.pose))
    return out


def cases_for(
    k: int,
    log: ScanLog,
    truth: str,
    relations,
    offset: float,
    tolerance: float,
    guesses: str,
    perturb: tuple[float, float],
    seed: int,
    search: SearchParams | None,
    limit: int | None,
) -> list[Case]:
    """The cases of log number ``k``: its consecutive pairs against its scan poses (``truth``
    "pose"), or its ``relations``."""
    if truth == "pose":
        return pose_cases(k, log, guesses, perturb, seed, search, limit)
    return relation_cases(k, log, relations, offset, tolerance, guesses, perturb, seed, search)
