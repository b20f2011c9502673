"""MbICP (Minguez, Lamiraux & Montesano, T-RO 2006) and the improved MbICP of paper 000.

One loop serves both: ``ImprovedParams`` switch on the three additions of Li et al. 2018 —
grid resampling (§2.3), point-to-point + point-to-line pairs (§2.4.1) and MAD-from-median
rejection (§2.4.2) — each on its own, so their effect can be seen one at a time. With the three
off and ``MbicpParams``' defaults it is the original C code (tests/test_originals.py).

The loop is compiled. With an observer attached it runs a second time with every iteration
recorded (the same numbers: the loop is deterministic), and the recording becomes the events.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from . import budget
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
from .stopping import CYCLE_PERIOD_MAX, SETTLED, UNSETTLED, remember, returned, streaks
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
    Termination.HALTED,
    Termination.OSCILLATING,
)
_MAX_ITER, _CONVERGED, _CYCLE, _TOO_FEW, _SINGULAR, _HALTED, _OSCILLATING = range(7)


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


class MbicpLoopParams(NamedTuple):
    """What the compiled loop reads of the parameters, by the names of the C code and paper 000
    (a named tuple: numba passes it whole). Numbers stay floats, as the C code compares them."""

    max_iter: int  # MaxIter
    L: float  # the metric's rotation weight [m] (MbICP §III)
    Bw: float  # the angular window [rad] (§IV)
    Br: float  # the radial window [m]: pairs farther are cut (§IV)
    max_inter: float  # MaxDistInter: longest segment interpolated [m^2, compared squared]
    keep: float  # filter: the share of pairs kept, the closest (§IV)
    asoc: float  # AsocError: the share of points that must find a pair
    ratio: float  # errorRatio: the error's relative change that counts as converged
    smooth: float  # IterSmoothConv: iterations in a row converged (or cycling) before stopping
    errx: float  # an increment below errx, erry, errt in every component counts as converged
    erry: float
    errt: float
    mad_k: float  # paper 000 §2.4.2: reject beyond median + mad_k MAD, never below the floor
    mad_floor: float
    mad_anneal: float
    hold: float  # the weak-direction hold's condition number (0: off; ``_hold_weak``)
    accelerate: float  # the largest extrapolation factor (0: off; ``_extrapolate``)
    point_line: bool  # paper 000 §2.4.1 pairs, else MbICP's
    mad: bool  # paper 000 §2.4.2 rejection, else the C code's filter
    projection: bool  # the projection filter (§IV) ...
    zbuffer: bool  # ... as a z-buffer of the reference viewpoint, else the C code's scan order
    bin_start: float  # the z-buffer's first bin: the reference's first bearing [rad]
    bin_width: float  # [rad]
    halt: np.ndarray  # raised (1) when the match must stop: core/budget.py


@kernel
def _move(P, x, y, th, moved, alpha, rng):
    """The object points in the reference frame at the estimate (x, y, th), with their bearings
    and ranges, into the buffers ``moved``, ``alpha`` and ``rng``."""
    c, s = np.cos(th), np.sin(th)
    for i in range(len(P)):
        mx, my = c * P[i, 0] - s * P[i, 1] + x, s * P[i, 0] + c * P[i, 1] + y
        moved[i, 0], moved[i, 1], alpha[i], rng[i] = mx, my, np.arctan2(my, mx), np.hypot(mx, my)


@kernel
def _visible(alpha, rng, lp: MbicpLoopParams):
    """The projection filter (MbICP §IV): which moved points the reference can see."""
    if not lp.projection:
        return np.ones(len(alpha), dtype=np.bool_)
    if lp.zbuffer:
        return visible_from_reference(alpha, rng, lp.bin_start, lp.bin_width, PROJECTION_MARGIN_M)
    return visible_in_order(alpha)


@kernel
def _gather(vis, moved, alpha, rng, rows, v_moved, v_alpha, v_rng) -> int:
    """The visible points into buffers kept across iterations; how many there are."""
    m = 0
    for i in range(len(vis)):
        if vis[i]:
            rows[m], v_moved[m, 0], v_moved[m, 1], v_alpha[m], v_rng[m] = (
                i,
                moved[i, 0],
                moved[i, 1],
                alpha[i],
                rng[i],
            )
            m += 1
    return m


@kernel
def _mean_sq_residual(pk, ck, ix, iy, ith) -> float:
    """The mean squared Euclidean residual of the pairs (pk -> ck) after the increment."""
    ci, si = np.cos(ith), np.sin(ith)
    err = 0.0
    for k in range(len(pk)):
        ux, uy = (
            ci * pk[k, 0] - si * pk[k, 1] + ix - ck[k, 0],
            si * pk[k, 0] + ci * pk[k, 1] + iy - ck[k, 1],
        )
        err += ux * ux + uy * uy
    return err / len(pk)


@kernel
def _loop(P, x, y, th, R: ReferenceIndex, lp: MbicpLoopParams, ref_tangents, trace):
    """The iterations from (x, y, th): returns the estimate, how it ended, the iterations run and
    the last solved system. ``trace`` records each iteration when it has rows (see ``_trace``)."""
    L, Br, errx, erry, errt = lp.L, lp.Br, lp.errx, lp.erry, lp.errt
    record = len(trace[0]) > 0
    n = len(P)
    recent = np.zeros((CYCLE_PERIOD_MAX - 1, 3))
    n_recent, n_short, n_any, n_conv, prev_error, end, it = 0, 0, 0, 0, -1.0, _MAX_ITER, 0
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
    for it in range(1, lp.max_iter + 1):
        # the object points at the estimate, those the reference sees (§IV's projection filter)
        _move(P, x, y, th, moved, alpha, rng)
        vis = _visible(alpha, rng, lp)
        m = _gather(vis, moved, alpha, rng, rows_all, v_moved, v_alpha, v_rng)
        rows = rows_all[:m]
        # correspondences: MbICP's window search (§IV), or paper 000's point + line pairs (§2.4.1)
        found, target, kind, ref_index, d2 = candidates(
            lp.point_line, v_moved[:m], v_alpha[:m], v_rng[:m], R, lp.Bw, Br, L, lp.max_inter
        )
        obj_rows, dist = rows[found], np.sqrt(np.maximum(d2, 0.0))
        # rejection: beyond Br, then the C code's filter or paper 000's MAD rule (§2.4.2)
        floor = rejection_floor(Br, lp.mad_floor, lp.mad_anneal, it) if lp.mad else 0.0
        status, thr = reject(dist, Br, lp.keep, lp.mad, lp.mad_k, floor, record)
        kept = np.flatnonzero(status == KEPT)
        n_within = np.count_nonzero(status != OUTSIDE_BR)
        # the C code's association test: pairs within Br against the points the filter left
        step_ok = False
        ix, iy, ith, error = 0.0, 0.0, 0.0, np.nan
        held = np.zeros(4)
        factor = 0.0
        A = np.zeros((3, 3))
        if n_within >= lp.asoc * len(rows) and len(kept) >= 3:
            # the increment minimising the metric distances of the kept pairs (MbICP §V)
            pk, ck = moved[obj_rows[kept]], target[kept]
            A, b = metric_normal_equations(pk, ck, L)
            step, step_ok = solve3(A, b)
            if step_ok and lp.hold > 0.0:
                held = _hold_weak(ck, ref_index[kept, 0], ref_tangents, L, lp.hold, step)
            if step_ok:
                ix, iy, ith = step[0], step[1], (step[2] + np.pi) % (2.0 * np.pi) - np.pi
                if lp.accelerate > 0.0 and not (
                    abs(ix) < errx and abs(iy) < erry and abs(ith) < errt
                ):
                    ix, iy, ith, factor = _extrapolate(
                        x, y, th, ix, iy, ith, d_prev, have_prev, L, lp.accelerate
                    )
                    have_prev = True
                error = _mean_sq_residual(pk, ck, ix, iy, ith)
            else:
                end = _SINGULAR
        else:
            end = _TOO_FEW
        ci, si = np.cos(ith), np.sin(ith)
        nx, ny = ix + ci * x - si * y, iy + si * x + ci * y
        nth = (ith + th + np.pi) % (2.0 * np.pi) - np.pi
        if record:
            pairs = (obj_rows, target, kind, ref_index, dist, status)
            _record(
                trace,
                it - 1,
                (x, y, th, nx, ny, nth, ix, iy, ith),
                vis,
                pairs,
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
            abs(1.0 - error_sum / prev_error) <= lp.ratio if prev_error > 0.0 else error_sum == 0.0
        )
        n_conv = (
            n_conv + 1
            if (small_ratio or (abs(ix) < errx and abs(iy) < erry and abs(ith) < errt))
            else 0
        )
        prev_error = error_sum
        if n_conv > lp.smooth:
            end = _CONVERGED
            break
        # a cycle: the estimate returned to one of the last few (stopping.py)
        back = returned(recent, n_recent, x, y, th, errx, erry, errt)
        n_recent = remember(recent, n_recent, bx, by, bth)
        n_short, n_any, cycle = streaks(n_short, n_any, back, lp.smooth + 1)
        if cycle == SETTLED:
            end = _CYCLE
            break
        if cycle == UNSETTLED:  # a long cycle (stopping.py)
            end = _OSCILLATING
            break
        if lp.halt[0]:
            end = _HALTED
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
def _record(trace, k, poses_k, vis, pairs, thr, error, held, factor):
    """Iteration ``k`` into the trace, element by element (slice assignments are slow to
    compile). ``pairs``: (object rows, target, kind, reference indices, distance, status)."""
    rows, target, kind, ref_index, dist, status = pairs
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
    hold = improved and params.hold_weak > 0
    lp = MbicpLoopParams(
        max_iter=int(params.MaxIter),
        L=float(params.L),
        Bw=float(params.Bw),
        Br=float(params.Br),
        max_inter=float(params.MaxDistInter),
        keep=float(params.filter),
        asoc=float(params.AsocError),
        ratio=float(params.errorRatio),
        smooth=float(params.IterSmoothConv),
        errx=float(params.errx_out),
        erry=float(params.erry_out),
        errt=float(params.errt_out),
        mad_k=float(params.mad_k) if improved else 0.0,
        mad_floor=float(params.mad_floor) if improved else 0.0,
        mad_anneal=float(params.mad_anneal) if improved else 0.0,
        hold=float(params.hold_weak) if hold else 0.0,
        accelerate=float(params.extrapolate) if improved else 0.0,
        point_line=bool(improved and params.point_line),
        mad=bool(improved and params.mad_rejection),
        projection=bool(params.ProjectionFilter),
        zbuffer=bool(params.projection_zbuffer),
        bin_start=float(R.bearings[0]) if len(R.bearings) else 0.0,
        bin_width=float(run(projection_bin_width, R.bearings)),
        halt=budget.current().flag,
    )
    tangents = (
        surface_tangents(R.points, R.full_circle, np.arange(len(R.points)))
        if hold
        else np.zeros((0, 2))
    )
    P = np.ascontiguousarray(P, float)
    return run(_loop, P, guess.x, guess.y, guess.theta, R, lp, tangents, trace)


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
    with budget.limited(None):  # the same iterations, to where the match ended (halted or not)
        _run(R, P, guess, replace(params, MaxIter=iterations), improved, trace)
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
