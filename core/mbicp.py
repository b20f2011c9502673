"""MbICP (Minguez, Lamiraux & Montesano, T-RO 2006) and the improved MbICP of paper 000.

One loop serves both: ``ImprovedParams`` switch on the three additions of Li et al. 2018 —
grid resampling (§2.3), point-to-point + point-to-line pairs (§2.4.1) and MAD-from-median
rejection (§2.4.2) — each on its own, so their effect can be seen one at a time.
"""

from __future__ import annotations

import numpy as np

from .correspondence import (ReferenceIndex, mbicp_pairs, point_line_pairs, polar, visible_from_reference,
                             visible_in_order)
from .events import Correspondences, FinishEvent, IterationEvent, Observer, PairStatus, StartEvent
from .rejection import reject
from .metric import mean_sq_residual, metric_normal_equations, solve3
from .params import ImprovedParams, MbicpParams
from .resample import grid_resample
from .result import MatchResult, Termination
from .scan import Scan
from .se2 import Pose2
from .stopping import CycleWatch
from .uncertainty import FinalSystem, build_result

# Projection filter: a point more than this behind the nearest one in its bearing bin is hidden.
PROJECTION_MARGIN_M = 0.2


def projection_bin_width(bearings: np.ndarray) -> float:
    """The projection filter's bearing bin: two beam steps, but never finer than a quarter of the
    beam count spread over the circle, so that its z-buffer is bounded by the beams, not by
    1/step (a damaged scan's bearings can be nanoradians apart)."""
    if len(bearings) < 2:
        return 2.0 * np.pi
    return max(2.0 * float(np.median(np.diff(bearings))), 2.0 * np.pi / (4 * len(bearings)))


def rejection_floor(params: ImprovedParams, iteration: int) -> float:
    """The distance below which MAD never rejects a pair at this (1-based) iteration [m].

    Paper 000 §2.4.2 treats the pairs above median + k MAD as "a few incorrect correspondences",
    which holds once the scans are roughly aligned; far from the answer the pairs that would pull
    the scan home (frontal structure in a corridor) are the long ones, and rejecting them leaves
    the local minimum that §2.4.2 and §3.3 warn of. So the floor starts at the radial window Br
    (MAD rejects nothing Br keeps) and shrinks geometrically to ``mad_floor``; ``mad_anneal`` = 0
    applies the published rule from the first iteration.
    """
    decay = params.mad_anneal ** (iteration - 1) if params.mad_anneal > 0 else 0.0
    return max(params.mad_floor, params.Br * decay)


def match(ref: Scan, obj: Scan, initial_guess: Pose2 = Pose2(), params: MbicpParams | None = None,
          observer: Observer | None = None) -> MatchResult:
    """Pose of the object frame in the reference frame, starting from ``initial_guess``."""
    params = params if params is not None else MbicpParams()
    improved = isinstance(params, ImprovedParams)
    name = "improved" if improved else "mbicp"
    ref, obj = ref.within(params.max_range), obj.within(params.max_range)
    R = ReferenceIndex.build(ref, params.L)
    obj_pts = obj.points()
    resampling = grid_resample(obj_pts, params.cell_size) if improved and params.resample else None
    used = (resampling.kept if resampling is not None else np.arange(len(obj_pts)))[:: params.laserStep]
    P = obj_pts[used]
    pair_fn = point_line_pairs if improved and params.point_line else mbicp_pairs
    bin_width = projection_bin_width(R.bearings)
    if observer is not None:
        observer(StartEvent(name, params, R.points, obj_pts, used, initial_guess, resampling))

    est = initial_guess
    cycles = CycleWatch(params)
    prev_error = None
    n_conv = 0
    reason = Termination.MAX_ITERATIONS if len(R.points) else Termination.TOO_FEW_PAIRS
    it = 0
    last = None
    for it in range(1, params.MaxIter + 1 if len(R.points) else 1):
        moved = est.apply(P)
        moved_polar = polar(moved)
        if not params.ProjectionFilter:
            vis = np.ones(len(P), dtype=bool)
        elif params.projection_zbuffer:
            vis = visible_from_reference(moved_polar, R.bearings[0], bin_width, PROJECTION_MARGIN_M)
        else:
            vis = visible_in_order(moved_polar)
        rows = np.flatnonzero(vis)
        pairs = pair_fn(R, moved, moved_polar, rows, params.Bw, params.Br, params.L, params.MaxDistInter)
        status, thr = reject(pairs.dist, params.Br, params.filter,
                             params.mad_k if improved and params.mad_rejection else None,
                             rejection_floor(params, it) if improved else 0.0)
        kept = status == PairStatus.KEPT
        n_kept = int(np.count_nonzero(kept))
        # the C code's association test: pairs within Br against the points the filter left
        n_within = int(np.count_nonzero(status != PairStatus.OUTSIDE_BR))
        step = None
        if n_within >= params.AsocError * len(rows) and n_kept >= 3:
            p_k, c_k = moved[pairs.obj[kept]], pairs.target[kept]
            A, b = metric_normal_equations(p_k, c_k, params.L)
            step = solve3(A, b)
            if step is None:
                reason = Termination.SINGULAR
        else:
            reason = Termination.TOO_FEW_PAIRS
        inc = Pose2.from_array(step) if step is not None else Pose2()
        error = mean_sq_residual(inc.apply(p_k), c_k) if step is not None else float("nan")
        error_sum = error * n_kept  # the C code's error: the ratio compares sums
        new_est = inc @ est
        if observer is not None:
            observer(IterationEvent(
                it, est, new_est, moved, used[~vis],
                Correspondences(used[pairs.obj], pairs.target, pairs.kind, pairs.ref_index, pairs.dist, status,
                                moved[pairs.obj]),
                thr, error, inc))
        if step is None:
            break
        before, est = est, new_est
        last = FinalSystem(A, error, c_k, pairs.ref_index[kept, 0], n_kept, len(status) - n_kept)
        # MbICP's counted convergence: error ratio OR every increment component small.
        small_ratio = prev_error is not None and (
            abs(1.0 - error_sum / prev_error) <= params.errorRatio if prev_error > 0 else error_sum == 0.0)
        n_conv = n_conv + 1 if (small_ratio or params.small(inc)) else 0
        prev_error = error_sum
        if n_conv > params.IterSmoothConv:
            reason = Termination.CONVERGED
            break
        if cycles.step(before, est) > params.IterSmoothConv:
            reason = Termination.CYCLE
            break

    result = build_result(name, est, reason, it, last, R.points, R.full_circle, params.L)
    if observer is not None:
        observer(FinishEvent(result))
    return result
