"""A pair's health without ground truth: the signs that its match went wrong, each with the
number that decided it, kept in its record (``PairMatch.flags``) so that a run view, a rows file or
a script finds the suspicious pairs of a log that has no truth.

The signs, and why each means what it says:
- **stopped early**: the matcher did not settle (iteration cap, too few pairs, halted);
- **weak direction**: the final constraints are ill-conditioned (paper 000 §3.3: a corridor lets
  the pose slide along it), condition number above ``failures.DEGENERATE_CONDITION``;
- **little overlap**: under half of the object points lie on the reference's surface at the
  matched pose (``core.agreement.surface_overlap``: sparse long-range scans are not penalised);
- **jumps against odometry**: the motion differs from the wheels' by more than a wheel slip;
- **sigma inconsistent with the step**: the difference from odometry is far outside what the
  match's own covariance and the odometry's noise allow (squared Mahalanobis distance);
- **scan out of place**: the motion jumps away from the previous pair's (constant velocity over
  the scans' time stamps) and comes back at the next pair: the scan between them does not belong
  there (a dropped, replayed or displaced scan);
- **matchers disagree**: a second configuration's run ends elsewhere on the same pair
  (evaluation/versus.py).

The thresholds were chosen on the shared logs with truth (``mbicp-viz eval flags``; the README
quotes how often a flagged pair is a real failure and how many failures go unflagged).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from mbicp_viz.core import MatchResult, Pose2, pose_error
from mbicp_viz.readers.pair_match import PairMatch, Suspicion

from .criteria import CONSECUTIVE, Criteria
from .failures import DEGENERATE_CONDITION
from .trajectory import ODOMETRY_SIGMA

LITTLE_OVERLAP = 0.5  # share of object points on the reference's surface
ODOMETRY_JUMP = Criteria("odometry jump", 0.15, math.radians(5.0))
# chi-square, 3 degrees of freedom, p = 0.9999: the difference is not noise
SIGMA_MAHALANOBIS2 = 21.1
# a step may differ from the previous one by this, plus a share of that step (see out_of_place)
STEADY = Criteria("constant velocity", 0.1, math.radians(5.0))
STEADY_SHARE = 0.5


Flags = dict[Suspicion, tuple[float, ...]]


def pair_flags(r: MatchResult, overlap: float, odometry_shown: Pose2 | None) -> Flags:
    """The signs one pair's match ``r`` shows by itself, each with its deciding numbers (a pose
    difference: [m], [rad]). ``odometry_shown`` is the odometry's motion in the frame ``r`` is
    reported in (None: the log has none)."""
    flags = {}
    if not r.converged:
        flags[Suspicion.STOPPED_EARLY] = (float(r.iterations),)
    if r.degeneracy is not None and r.degeneracy.condition_number > DEGENERATE_CONDITION:
        flags[Suspicion.WEAK_DIRECTION] = (float(r.degeneracy.condition_number),)
    if overlap < LITTLE_OVERLAP:
        flags[Suspicion.LITTLE_OVERLAP] = (overlap,)
    if odometry_shown is not None:
        et, er = pose_error(r.pose, odometry_shown)
        if not ODOMETRY_JUMP.correct(et, er):
            flags[Suspicion.ODOMETRY_JUMP] = (et, er)
        d2 = _mahalanobis2(r.pose, odometry_shown, r.covariance)
        if d2 > SIGMA_MAHALANOBIS2:
            flags[Suspicion.SIGMA] = (d2,)
    return flags


_ODOMETRY_COVARIANCE = np.diag(np.square(ODOMETRY_SIGMA))


def _mahalanobis2(pose: Pose2, odometry: Pose2, covariance: np.ndarray | None) -> float:
    """(match - odometry)' (C_match + C_odometry)^-1 (match - odometry), the difference taken in the
    reference frame as the covariance is."""
    e = [pose.x - odometry.x, pose.y - odometry.y]
    e.append(math.remainder(pose.theta - odometry.theta, 2.0 * math.pi))
    c = _ODOMETRY_COVARIANCE
    if covariance is not None and np.isfinite(covariance).all():
        c = c + covariance
    d2 = _ldl_quadratic(c.tolist(), e)
    return d2 if d2 is not None else float(np.asarray(e) @ np.linalg.solve(c, e))


def _ldl_quadratic(c: list, e: list) -> float | None:
    """e' c^-1 e for a symmetric 3x3 ``c`` through c = L D L' (None unless c is positive definite,
    as the odometry's covariance makes a match's): a run's parent judges every row, and
    ``np.linalg.solve``'s checks cost five times the arithmetic."""
    (a, b, d), (_, f, g), (_, _, h) = c
    x, y, z = e
    if not a > 0.0:
        return None
    l21, l31 = b / a, d / a
    d2 = f - l21 * b
    if not d2 > 0.0:
        return None
    l32 = (g - l31 * b) / d2
    d3 = h - l31 * d - l32 * l32 * d2
    if not d3 > 0.0:
        return None
    u = y - l21 * x
    v = z - l31 * x - l32 * u
    return x * x / a + u * u / d2 + v * v / d3


def out_of_place(
    steps: tuple[PairMatch, PairMatch, PairMatch], dts: tuple[float | None, ...]
) -> tuple[float, float] | None:
    """Whether the scan between the last two of three consecutive pairs is out of place: the
    motion jumps away from the previous step's (constant velocity over the time stamps ``dts``;
    equal steps without them) and returns, the two steps together steady again. Returns the jump
    ([m], [rad]), or None. The tolerance grows with the step (a robot's speed changes by some
    part of it between scans; the logs of key frames step unevenly)."""
    p, a, b = (m.result.pose for m in steps)
    dp, da, db = dts
    ok = all(dts)

    def scaled(step: Pose2, k: float) -> Pose2:
        return Pose2(step.x * k, step.y * k, step.theta * k)

    def beyond(pose: Pose2, predicted: Pose2, step: Pose2) -> float:
        et, er = pose_error(pose, predicted)
        tol_m = STEADY.max_error_m + STEADY_SHARE * step.translation_norm()
        tol_rad = STEADY.max_error_rad + STEADY_SHARE * abs(step.theta)
        return max(et / tol_m, er / tol_rad)

    predicted = scaled(p, da / dp if ok else 1.0)
    jump = beyond(a, predicted, p)
    if jump <= 1.0:  # most pairs: the rest is not computed (a run's parent judges every row)
        return None
    back = beyond(b, scaled(a, db / da if ok else 1.0), p)
    if back <= 1.0:
        return None
    both = beyond(a @ b, scaled(p, (da + db) / dp if ok else 2.0), p)
    if both >= 0.5 * min(jump, back):
        return None
    return pose_error(a, predicted)


def severity(m: PairMatch) -> float:
    """How suspicious a pair is, to rank them: the number of its signs, then how far beyond its
    threshold the worst one is."""
    if not m.flags:
        return 0.0
    return len(m.flags) + min(max(_beyond(k, v) for k, v in m.flags.items()), 1e3) / 1e3


def _beyond(name: Suspicion, value: tuple[float, ...]) -> float:
    """How many times its threshold a sign's number is (at least 1)."""
    poses = {
        Suspicion.ODOMETRY_JUMP: ODOMETRY_JUMP,
        Suspicion.OUT_OF_PLACE: STEADY,
        Suspicion.DISAGREE: CONSECUTIVE,
    }
    if name in poses:
        c = poses[name]
        return max(value[0] / c.max_error_m, value[1] / c.max_error_rad)
    if name is Suspicion.LITTLE_OVERLAP:
        return LITTLE_OVERLAP / max(value[0], 1e-3)
    if name is Suspicion.STOPPED_EARLY:  # its number is the iterations run: no threshold
        return 1.0
    limit = {Suspicion.WEAK_DIRECTION: DEGENERATE_CONDITION, Suspicion.SIGMA: SIGMA_MAHALANOBIS2}
    return value[0] / limit[name]


def ranked(rows: Sequence[PairMatch]) -> Sequence[PairMatch]:
    """The flagged rows, the most suspicious first (then by their records; each made when read:
    a run over a rows file may have thousands)."""
    from .run_rows import RunRows  # it ranks with this module's ``severity``

    return RunRows.of(rows).ranked() if len(rows) else []


def flag_text(name: Suspicion, value: tuple[float, ...]) -> str:
    """One sign in words, with its numbers."""
    match name:
        case Suspicion.STOPPED_EARLY:
            return f"{name} (after {value[0]:.0f} iterations)"
        case Suspicion.WEAK_DIRECTION:
            return f"{name} (condition number {value[0]:.0f})"
        case Suspicion.LITTLE_OVERLAP:
            return (
                f"{name} ({100 * value[0]:.0f} % of the object points on the reference's surface)"
            )
        case Suspicion.SIGMA:
            return f"{name} (squared Mahalanobis distance from odometry {value[0]:.0f})"
        case Suspicion.OUT_OF_PLACE:
            return (
                f"{name} (the pair's first scan: the motion jumps {100 * value[0]:.1f} cm, "
                f"{math.degrees(value[1]):.2f} deg there and returns)"
            )
        case _:
            return f"{name} ({100 * value[0]:.1f} cm, {math.degrees(value[1]):.2f} deg)"


def flags_text(m: PairMatch) -> str:
    return "; ".join(flag_text(k, v) for k, v in m.flags.items())


def suspect_label(rank: int, row: PairMatch) -> str:
    """One line per flagged pair, as the debugger's list shows it."""
    return f"{rank}. scans {row.ref} -> {row.obj}: {flags_text(row)}"


def suspect_summary(rows: list[PairMatch], shown: int = 3) -> list[str]:
    """The most suspicious pairs, for the end of ``eval sequence``."""
    flagged = ranked(rows)
    if not flagged:
        return ["no pair flagged as suspicious (evaluation/health.py's signs)"]
    return [
        f"suspicious pairs, found without truth: {len(flagged)}; the first:",
        *(f"  {suspect_label(k + 1, r)}" for k, r in enumerate(flagged[:shown])),
    ]
