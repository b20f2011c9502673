"""MbICP (Minguez, Lamiraux & Montesano, T-RO 2006) and the improved MbICP of paper 000.

One loop serves both: ``ImprovedParams`` switch on the three additions of Li et al. 2018 —
grid resampling (§2.3), point-to-point + point-to-line pairs (§2.4.1) and MAD-from-median
rejection (§2.4.2) — each on its own, so their effect can be seen one at a time. With the three
off and ``MbicpParams``' defaults it is the original C code (tests/test_originals.py).

The loop is compiled. With an observer attached it runs a second time with every iteration
recorded (the same numbers: the loop is deterministic), and the recording becomes the events.
"""

from __future__ import annotations

import numpy as np

from .correspondence import ReferenceIndex, candidates, visible_from_reference, visible_in_order
from .events import (
    Correspondences,
    FinishEvent,
    HeldDirection,
    IterationEvent,
    Observer,
    StartEvent,
)
from .metric import median, metric_normal_equations, solve3, weakest_direction
from .params import ImprovedParams, MbicpParams
from .rejection import KEPT, OUTSIDE_BR, reject
from .resample import grid_resample
from .result import MatchResult, Termination
from .scan import Scan
from .se2 import Pose2
from .stopping import CYCLE_PERIOD_MAX, remember, returned
from .tiers import kernel, run
from .uncertainty import FinalSystem, build_result, surface_information, surface_tangents

# Projection filter: a point more than this behind the nearest one in its bearing bin is hidden.
PROJECTION_MARGIN_M = 0.2

# How the compiled loop ended (Termination by index)
_ENDS = (
    Termination.MAX_ITERATIONS,
    Termination.CONVERGED,
    Termination.CYCLE,
    Termination.TOO_FEW_PAIRS,
    Termination.SINGULAR,
)
_MAX_ITER, _CONVERGED, _CYCLE, _TOO_FEW, _SINGULAR = range(5)


@kernel
def projection_bin_width(bearings: np.ndarray) -> float:
    """The projection filter's bearing bin: two beam steps (the median step), but never finer than
    a quarter of the beam count spread over the circle, so that its z-buffer is bounded by the
    beams, not by 1/step (a damaged scan's bearings can be nanoradians apart)."""
    if len(bearings) < 2:
        return 2.0 * np.pi
    steps = np.empty(len(bearings) - 1)
    for i in range(len(steps)):
        steps[i] = bearings[i + 1] - bearings[i]
    return max(2.0 * median(steps), 2.0 * np.pi / (4 * len(bearings)))


@kernel
def rejection_floor(Br: float, mad_floor: float, mad_anneal: float, iteration: int) -> float:
    """The distance below which MAD never rejects a pair at this (1-based) iteration [m].

    Paper 000 §2.4.2 treats the pairs above median + k MAD as "a few incorrect correspondences",
    which holds once the scans are roughly aligned; far from the answer the pairs that would pull
    the scan home (frontal structure in a corridor) are the long ones, and rejecting them leaves
    the local minimum that §2.4.2 and §3.3 warn of. So the floor starts at the radial window Br
    (MAD rejects nothing Br keeps) and shrinks geometrically to ``mad_floor``; ``mad_anneal`` = 0
    applies the published rule from the first iteration.
    """
    decay = mad_anneal ** (iteration - 1) if mad_anneal > 0 else 0.0
    return max(mad_floor, Br * decay)


@kernel
def _loop(
    P,
    x,
    y,
    th,
    eb,
    ex,
    ey,
    ek,
    eux,
    euy,
    ext_map,
    ref_points,
    neighbours,
    full,
    max_factor,
    max_step,
    bin_start,
    bin_width,
    projection,
    zbuffer,
    point_line,
    mad,
    p,
    ref_tangents,
    trace,
):
    """The iterations from (x, y, th). ``p``: (MaxIter, L, Bw, Br, MaxDistInter, filter, AsocError,
    errorRatio, IterSmoothConv, errx, erry, errt, mad_k, mad_floor, mad_anneal, hold_weak,
    extrapolate). Returns the
    estimate, how it ended, the iterations run and the last solved system. ``trace`` records each
    iteration when it has rows (see ``_trace``)."""
    max_iter, L, Bw, Br, max_inter, keep, asoc = int(p[0]), p[1], p[2], p[3], p[4], p[5], p[6]
    ratio, smooth, errx, erry, errt, mad_k, mad_floor, mad_anneal = (
        p[7],
        p[8],
        p[9],
        p[10],
        p[11],
        p[12],
        p[13],
        p[14],
    )
    hold, accelerate = p[15], p[16]
    record = len(trace[0]) > 0
    n = len(P)
    recent = np.zeros((CYCLE_PERIOD_MAX - 1, 3))
    n_recent, n_cycle, n_conv, prev_error, end, it = 0, 0, 0, -1.0, _MAX_ITER, 0
    A_last, err_last, targets_last = np.zeros((3, 3)), np.nan, np.zeros((0, 2))
    ref_last, kept_last, rejected_last, solved = np.zeros(0, np.int64), 0, 0, False
    moved, alpha, rng = np.empty((n, 2)), np.empty(n), np.empty(n)
    rows_all, v_moved, v_alpha, v_rng = (
        np.empty(n, np.int64),
        np.empty((n, 2)),
        np.empty(n),
        np.empty(n),
    )
    d_prev, have_prev = np.zeros(3), False
    for it in range(1, max_iter + 1):
        c, s = np.cos(th), np.sin(th)
        for i in range(n):
            mx, my = c * P[i, 0] - s * P[i, 1] + x, s * P[i, 0] + c * P[i, 1] + y
            moved[i, 0], moved[i, 1], alpha[i], rng[i] = (
                mx,
                my,
                np.arctan2(my, mx),
                np.hypot(mx, my),
            )
        if not projection:
            vis = np.ones(n, dtype=np.bool_)
        elif zbuffer:
            vis = visible_from_reference(alpha, rng, bin_start, bin_width, PROJECTION_MARGIN_M)
        else:
            vis = visible_in_order(alpha)
        m = 0
        for i in range(n):  # the visible points, gathered into buffers kept across iterations
            if vis[i]:
                rows_all[m], v_moved[m, 0], v_moved[m, 1], v_alpha[m], v_rng[m] = (
                    i,
                    moved[i, 0],
                    moved[i, 1],
                    alpha[i],
                    rng[i],
                )
                m += 1
        rows = rows_all[:m]
        found, target, kind, ref_index, d2 = candidates(
            point_line,
            v_moved[:m],
            v_alpha[:m],
            v_rng[:m],
            eb,
            ex,
            ey,
            ek,
            eux,
            euy,
            ext_map,
            ref_points,
            neighbours,
            full,
            max_factor,
            max_step,
            Bw,
            Br,
            L,
            max_inter,
        )
        obj_rows, dist = rows[found], np.sqrt(np.maximum(d2, 0.0))
        status, thr = reject(
            dist,
            Br,
            keep,
            mad,
            mad_k,
            rejection_floor(Br, mad_floor, mad_anneal, it) if mad else 0.0,
            record,
        )
        kept = np.flatnonzero(status == KEPT)
        n_within = np.count_nonzero(status != OUTSIDE_BR)
        # the C code's association test: pairs within Br against the points the filter left
        step_ok = False
        ix, iy, ith, error = 0.0, 0.0, 0.0, np.nan
        held = np.zeros(4)
        factor = 0.0
        A = np.zeros((3, 3))
        if n_within >= asoc * len(rows) and len(kept) >= 3:
            pk, ck = moved[obj_rows[kept]], target[kept]
            A, b = metric_normal_equations(pk, ck, L)
            step, step_ok = solve3(A, b)
            if step_ok and hold > 0.0:
                held = _hold_weak(ck, ref_index[kept, 0], ref_tangents, L, hold, step)
            if step_ok:
                ix, iy, ith = step[0], step[1], (step[2] + np.pi) % (2.0 * np.pi) - np.pi
                if accelerate > 0.0 and not (abs(ix) < errx and abs(iy) < erry and abs(ith) < errt):
                    ix, iy, ith, factor = _extrapolate(
                        x, y, th, ix, iy, ith, d_prev, have_prev, L, accelerate
                    )
                    have_prev = True
                ci, si = np.cos(ith), np.sin(ith)
                err = 0.0
                for k in range(len(kept)):
                    ux, uy = (
                        ci * pk[k, 0] - si * pk[k, 1] + ix - ck[k, 0],
                        si * pk[k, 0] + ci * pk[k, 1] + iy - ck[k, 1],
                    )
                    err += ux * ux + uy * uy
                error = err / len(kept)
            else:
                end = _SINGULAR
        else:
            end = _TOO_FEW
        ci, si = np.cos(ith), np.sin(ith)
        nx, ny = ix + ci * x - si * y, iy + si * x + ci * y
        nth = (ith + th + np.pi) % (2.0 * np.pi) - np.pi
        if record:
            _record(
                trace,
                it - 1,
                (x, y, th, nx, ny, nth, ix, iy, ith),
                vis,
                obj_rows,
                target,
                kind,
                ref_index,
                dist,
                status,
                thr,
                error,
                held,
                factor,
            )
        if not step_ok:
            break
        bx, by, bth = x, y, th
        x, y, th = nx, ny, nth
        A_last, err_last, targets_last = A, error, target[kept]
        ref_last, kept_last, rejected_last, solved = (
            ref_index[kept, 0],
            len(kept),
            len(status) - len(kept),
            True,
        )
        # MbICP's counted convergence: error ratio OR every increment component small; the C code
        # compares the summed squared residuals of consecutive iterations
        error_sum = error * len(kept)
        small_ratio = prev_error >= 0.0 and (
            abs(1.0 - error_sum / prev_error) <= ratio if prev_error > 0.0 else error_sum == 0.0
        )
        n_conv = (
            n_conv + 1
            if (small_ratio or (abs(ix) < errx and abs(iy) < erry and abs(ith) < errt))
            else 0
        )
        prev_error = error_sum
        if n_conv > smooth:
            end = _CONVERGED
            break
        back = returned(recent, n_recent, x, y, th, errx, erry, errt)
        n_recent = remember(recent, n_recent, bx, by, bth)
        n_cycle = n_cycle + 1 if back else 0
        if n_cycle > smooth:
            end = _CYCLE
            break
    return (
        x,
        y,
        th,
        end,
        it,
        solved,
        A_last,
        err_last,
        targets_last,
        ref_last,
        kept_last,
        rejected_last,
    )


@kernel
def _hold_weak(targets, ref, ref_tangents, L, hold, step):
    """Solution remapping (Zhang, Kaess & Singh, ICRA 2016): when the pairs' point-to-line
    information (the surfaces they lie on, as the degeneracy indicator measures it) has a
    condition number above ``hold`` in (x, y, L theta), remove from ``step`` (in place) its
    component along the weakest direction, where the surfaces do not fix the motion (a corridor's
    axis, paper 000 §3.3): the estimate keeps its value there. MbICP's point pairs constrain every
    direction, wrongly where a wall offers no point opposite: they are why a corridor shortens.
    (condition, direction) when held, else zeros."""
    H = surface_information(targets, ref_tangents[ref], L)
    cond, v = weakest_direction(H, 1.0)
    out = np.zeros(4)
    if cond > hold:
        s = np.array([step[0], step[1], L * step[2]])
        along = s @ v
        step[0], step[1], step[2] = (
            s[0] - along * v[0],
            s[1] - along * v[1],
            (s[2] - along * v[2]) / L,
        )
        out[0], out[1], out[2], out[3] = cond, v[0], v[1], v[2]
    return out


@kernel
def _extrapolate(x, y, th, ix, iy, ith, d_prev, have_prev, L, most):
    """Aitken's extrapolation of a linearly converging iteration, in the spirit of Besl & McKay's
    accelerated ICP (PAMI 1992), which extrapolates along successive steps that keep their
    direction. MbICP's steps shrink by a near-constant ratio r while its point pairs slide (they
    pull towards reference points, not lines), so when this step d (in x, y, L theta) points
    within 90 degrees of the previous one and is shorter, the estimate moves on by d r / (1 - r),
    the rest of the geometric series, at most ``most`` times d. Returns the
    composed increment and the factor applied (0: none); ``d_prev`` becomes this step."""
    ci, si = np.cos(ith), np.sin(ith)
    d = np.array([ix + ci * x - si * y - x, iy + si * x + ci * y - y, L * ith])
    factor = 0.0
    if have_prev:
        n2, p2, dp = d @ d, d_prev @ d_prev, d @ d_prev
        if dp > 0.0 and n2 < p2:
            r = np.sqrt(n2 / p2)
            factor = min(r / (1.0 - r), most)
    d_prev[:] = d
    if factor == 0.0:
        return ix, iy, ith, 0.0
    nx, ny = x + (1.0 + factor) * d[0], y + (1.0 + factor) * d[1]
    jth = ((1.0 + factor) * ith + np.pi) % (2.0 * np.pi) - np.pi
    cj, sj = np.cos(jth), np.sin(jth)
    return nx - (cj * x - sj * y), ny - (sj * x + cj * y), jth, factor


@kernel
def _record(
    trace, k, poses_k, vis, rows, target, kind, ref_index, dist, status, thr, error, held, factor
):
    """Iteration ``k`` into the trace, element by element (slice assignments are slow to
    compile)."""
    (
        poses,
        visible,
        count,
        prow,
        ptarget,
        pkind,
        pref,
        pdist,
        pstatus,
        thresholds,
        errors,
        holds,
        factors,
    ) = trace
    factors[k] = factor
    for c in range(4):
        holds[k, c] = held[c]
    for c in range(9):
        poses[k, c] = poses_k[c]
    for i in range(len(vis)):
        visible[k, i] = vis[i]
    count[k] = len(rows)
    for i in range(len(rows)):
        prow[k, i], pkind[k, i], pdist[k, i], pstatus[k, i] = rows[i], kind[i], dist[i], status[i]
        ptarget[k, i, 0], ptarget[k, i, 1], pref[k, i, 0], pref[k, i, 1] = (
            target[i, 0],
            target[i, 1],
            ref_index[i, 0],
            ref_index[i, 1],
        )
    thresholds[k], errors[k] = thr, error


def _trace(iterations: int, n: int):
    """Buffers for ``iterations`` recorded iterations of ``n`` object points (none: nothing
    recorded)."""
    return (
        np.zeros((iterations, 9)),
        np.zeros((iterations, n), np.bool_),
        np.zeros(iterations, np.int64),
        np.zeros((iterations, n), np.int64),
        np.zeros((iterations, n, 2)),
        np.zeros((iterations, n), np.int8),
        np.zeros((iterations, n, 2), np.int64),
        np.zeros((iterations, n)),
        np.zeros((iterations, n), np.int8),
        np.zeros(iterations),
        np.zeros(iterations),
        np.zeros((iterations, 4)),
        np.zeros(iterations),
    )


def _run(
    R: ReferenceIndex, P: np.ndarray, guess: Pose2, params: MbicpParams, improved: bool, trace
):
    point_line = improved and params.point_line
    mad = improved and params.mad_rejection
    p = np.array(
        [
            params.MaxIter,
            params.L,
            params.Bw,
            params.Br,
            params.MaxDistInter,
            params.filter,
            params.AsocError,
            params.errorRatio,
            params.IterSmoothConv,
            params.errx_out,
            params.erry_out,
            params.errt_out,
            params.mad_k if improved else 0.0,
            params.mad_floor if improved else 0.0,
            params.mad_anneal if improved else 0.0,
            params.hold_weak if improved else 0.0,
            params.extrapolate if improved else 0.0,
        ]
    )
    bin_start = float(R.bearings[0]) if len(R.bearings) else 0.0
    hold = improved and params.hold_weak > 0
    tangents = (
        surface_tangents(R.points, R.full_circle, np.arange(len(R.points)))
        if hold
        else np.zeros((0, 2))
    )
    return run(
        _loop,
        np.ascontiguousarray(P, float),
        guess.x,
        guess.y,
        guess.theta,
        R.ext_bearings,
        R.ext_x,
        R.ext_y,
        R.ext_sq_norm_L2,
        R.ext_ux,
        R.ext_uy,
        R.ext_map,
        R.points,
        R.neighbours,
        R.full_circle,
        R.max_factor,
        R.max_step,
        bin_start,
        run(projection_bin_width, R.bearings),
        params.ProjectionFilter,
        params.projection_zbuffer,
        point_line,
        mad,
        p,
        tangents,
        trace,
    )


def match(
    ref: Scan,
    obj: Scan,
    initial_guess: Pose2 = Pose2(),
    params: MbicpParams | None = None,
    observer: Observer | None = None,
) -> MatchResult:
    """Pose of the object frame in the reference frame, starting from ``initial_guess``."""
    params = params if params is not None else MbicpParams()
    improved = isinstance(params, ImprovedParams)
    name = "improved" if improved else "mbicp"
    R = ReferenceIndex.build(ref, params.L, params.max_range)
    obj_pts = obj.points(params.max_range)
    resampling = grid_resample(obj_pts, params.cell_size) if improved and params.resample else None
    used = (resampling.kept if resampling is not None else np.arange(len(obj_pts)))[
        :: params.laserStep
    ]
    P = obj_pts[used]
    if observer is not None:
        observer(StartEvent(name, params, R.points, obj_pts, used, initial_guess, resampling))
    if len(R.points) == 0:  # nothing of the reference within max_range
        result = build_result(
            name, initial_guess, Termination.TOO_FEW_PAIRS, 0, None, R.points, False, params.L
        )
    else:
        out = _run(R, P, initial_guess, params, improved, _trace(0, 0))
        if observer is not None:
            _replay(observer, R, P, used, initial_guess, params, improved, out[4])
        x, y, th, end, it, solved, A, error, targets, ref_index, n_kept, n_rejected = out
        last = FinalSystem(A, error, targets, ref_index, n_kept, n_rejected) if solved else None
        result = build_result(
            name, Pose2(x, y, th), _ENDS[end], it, last, R.points, R.full_circle, params.L
        )
    if observer is not None:
        observer(FinishEvent(result))
    return result


def _replay(observer, R, P, used, guess, params, improved, iterations) -> None:
    """The loop again, recorded, as one IterationEvent per iteration."""
    trace = _trace(iterations, len(P))
    _run(R, P, guess, params, improved, trace)
    (
        poses,
        visible,
        count,
        prow,
        ptarget,
        pkind,
        pref,
        pdist,
        pstatus,
        thresholds,
        errors,
        holds,
        factors,
    ) = trace
    for k in range(iterations):
        before, after, inc = Pose2(*poses[k, :3]), Pose2(*poses[k, 3:6]), Pose2(*poses[k, 6:])
        moved = before.apply(P)
        m = count[k]
        rows = prow[k, :m]
        pairs = Correspondences(
            used[rows],
            ptarget[k, :m],
            pkind[k, :m],
            pref[k, :m],
            pdist[k, :m],
            pstatus[k, :m],
            moved[rows],
        )
        held = (
            HeldDirection(float(holds[k, 0]), tuple(float(c) for c in holds[k, 1:]), params.L)
            if holds[k, 0]
            else None
        )
        observer(
            IterationEvent(
                k + 1,
                before,
                after,
                moved,
                used[~visible[k]],
                pairs,
                None if np.isnan(thresholds[k]) else float(thresholds[k]),
                float(errors[k]),
                inc,
                held=held,
                extrapolated=float(factors[k]),
            )
        )
