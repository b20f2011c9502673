"""ICP and PL-ICP as Censi's CSM runs them (``sm_icp`` with the defaults of its ``sm2`` program).

One loop serves both (CSM's ``icp_loop``): each object ray in the reference frame takes the
Euclidean-nearest valid reference ray j1 (within ``max_correspondence_dist``; never the scan's
first or last ray) and of j1's two valid neighbours the nearer, j2. Pairs several object rays
share a j1 with are dropped beyond 3x the nearest one's distance; then every pair farther from
the segment j1-j2 than min(the ``outliers_maxPerc`` quantile, ``outliers_adaptive_mult`` x the
``outliers_adaptive_order`` quantile) is trimmed. The pose is then solved exactly (``gpc``):

- ICP ("vanilla" in CSM): each ray to its projection on the segment j1-j2, all directions weighed
  alike; it stops when the step is below ``epsilon_xy`` and ``epsilon_theta``.
- PL-ICP (Censi, ICRA 2008): each ray to the line through j1 and j2, only the distance along
  the line's normal counts; it also stops when the pairs repeat those of an earlier iteration.

When the final mean distance exceeds ``restart_threshold_mean_error``, CSM restarts from the
result moved by +/-``restart_dt`` in x, in y and +/-``restart_dtheta``, and keeps the run of
smallest total distance. The loop is compiled; with an observer attached, each run is run again
with its iterations recorded (the same numbers: the loop is deterministic).
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from . import budget
from .events import (
    Correspondences,
    FinishEvent,
    IterationEvent,
    Observer,
    PairKind,
    PairStatus,
    StartEvent,
)
from .gpc import normal_terms, solve
from .metric import kth_smallest
from .params import IcpParams, PlIcpParams
from .result import MatchResult, Termination
from .scan import Scan
from .se2 import Pose2
from .tiers import kernel, run
from .uncertainty import DEGENERACY_LENGTH_M, FinalSystem, build_result

# CSM's icp_loop: fewer pairs than this share of the object's rays, before or after trimming, fails.
FAIL_FRACTION = 0.05
DOUBLES_FACTOR = 3.0  # kill_outliers_double: a pair farther than this times its j1's nearest pair

# Pair statuses as the compiled loop writes them (numba compares plain integers)
_KEPT, _OUTSIDE, _TRIMMED, _DOUBLE = (
    int(s) for s in (PairStatus.KEPT, PairStatus.OUTSIDE_BR, PairStatus.TRIMMED, PairStatus.DOUBLE)
)

# Outcomes of one run of the loop
_OK, _TOO_FEW, _SINGULAR, _HALTED = 0, 1, 2, 3


class Rays(NamedTuple):
    """Both scans as CSM holds them: every ray (valid or not) in scan order, readings outside
    (min_reading, max_reading] invalid. A named tuple: the compiled loop takes it whole."""

    rx: np.ndarray  # the reference rays' points [m], bearings [rad] and their cos and sin
    ry: np.ndarray
    rtheta: np.ndarray
    rcos: np.ndarray
    rsin: np.ndarray
    rvalid: np.ndarray
    sx: np.ndarray  # the object rays' points [m]
    sy: np.ndarray
    svalid: np.ndarray
    full_circle: bool  # the reference covers 360 degrees

    @staticmethod
    def of(ref: Scan, obj: Scan, params: IcpParams) -> Rays:
        def of_scan(scan):
            r = np.where(scan.valid, scan.ranges, 0.0)
            ok = scan.valid & (r > params.min_reading) & (r <= params.max_reading)
            return (
                r * np.cos(scan.bearings),
                r * np.sin(scan.bearings),
                np.ascontiguousarray(scan.bearings, float),
                ok,
            )

        rx, ry, rtheta, rvalid = of_scan(ref)
        sx, sy, _, svalid = of_scan(obj)
        rcos, rsin = np.cos(rtheta), np.sin(rtheta)
        return Rays(rx, ry, rtheta, rcos, rsin, rvalid, sx, sy, svalid, ref.is_full_circle())

    def ref_points(self) -> tuple[np.ndarray, np.ndarray]:
        """The valid reference points, and for each ray the index of its point there."""
        return np.column_stack((self.rx, self.ry))[self.rvalid], np.cumsum(self.rvalid) - 1


class IcpLoopParams(NamedTuple):
    """What CSM's icp_loop reads of the parameters (a named tuple: numba passes it whole)."""

    line: bool  # PL-ICP: point to line, else point to segment
    max_iter: int
    eps_xy: float  # a step below both ends the loop [m, rad]
    eps_th: float
    max_dist: float  # max_correspondence_dist [m]
    order: float  # outliers_adaptive_order: the quantile ...
    mult: float  # ... times outliers_adaptive_mult, and the outliers_maxPerc quantile, trim
    max_perc: float
    doubles: bool  # outliers_remove_doubles
    halt: np.ndarray  # raised (1) when the match must stop: core/budget.py

    @staticmethod
    def of(p: IcpParams) -> IcpLoopParams:
        return IcpLoopParams(
            isinstance(p, PlIcpParams),
            int(p.max_iterations),
            float(p.epsilon_xy),
            float(p.epsilon_theta),
            float(p.max_correspondence_dist),
            float(p.outliers_adaptive_order),
            float(p.outliers_adaptive_mult),
            float(p.outliers_maxPerc),
            bool(p.outliers_remove_doubles),
            budget.current().flag,
        )


@kernel
def _nearest(S: Rays, px, py, phi):
    """The Euclidean-nearest valid reference ray to (px, py): walk outwards from the ray nearest
    in bearing, up and down, while a ray can still be nearer. Every point of a ray u_j lies at
    least as far from p as p's distance to the ray, |p x u_j| when p lies ahead of it (p . u_j > 0)
    and |p| behind it, and that bound grows as the walk moves away from p's bearing."""
    rx, ry, rtheta, rcos, rsin, rvalid = S.rx, S.ry, S.rtheta, S.rcos, S.rsin, S.rvalid
    n = len(rx)
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if rtheta[mid] < phi:
            lo = mid + 1
        else:
            hi = mid
    rho2 = px * px + py * py
    best, d_best = -1, np.inf
    up, down = lo, lo - 1
    while up < n or down >= 0:
        if up < n:
            if rvalid[up]:
                dx, dy = px - rx[up], py - ry[up]
                d = dx * dx + dy * dy
                if d < d_best:
                    best, d_best = up, d
            up += 1
            if up < n:
                ahead = px * rcos[up] + py * rsin[up] > 0.0
                cross = px * rsin[up] - py * rcos[up]
                if (cross * cross if ahead else rho2) > d_best:
                    up = n
        if down >= 0:
            if rvalid[down]:
                dx, dy = px - rx[down], py - ry[down]
                d = dx * dx + dy * dy
                if d < d_best:
                    best, d_best = down, d
            down -= 1
            if down >= 0:
                ahead = px * rcos[down] + py * rsin[down] > 0.0
                cross = px * rsin[down] - py * rcos[down]
                if (cross * cross if ahead else rho2) > d_best:
                    down = -1
    return best, d_best


@kernel
def _on_branch(phi, rtheta):
    """A bearing turned by whole turns onto the scan's bearings: into [first, first + 2 pi), then
    back a turn when it lies nearer the first bearing than the last (so CSM's atan2 angle, for a
    scan whose bearings lie within +/-pi, and every scan turned by any angle, search alike)."""
    first, last = rtheta[0], rtheta[len(rtheta) - 1]
    a = first + (phi - first) % (2.0 * np.pi)
    if a > last and (first + 2.0 * np.pi - a) < (a - last):
        a -= 2.0 * np.pi
    return a


@kernel
def _segment_foot(ax, ay, bx, by, px, py, clamp: bool):
    """The point of segment a-b (or of its line, ``clamp`` False) nearest to p."""
    ex, ey = bx - ax, by - ay
    ee = ex * ex + ey * ey
    t = ((px - ax) * ex + (py - ay) * ey) / ee if ee > 0.0 else 0.0
    if clamp:
        t = min(max(t, 0.0), 1.0)
    return ax + t * ex, ay + t * ey


@kernel
def _pairs(S: Rays, x, y, th, lp: IcpLoopParams):
    """One iteration's correspondences at the pose (x, y, th): per object ray the moved point,
    j1, j2 (-1: none), its status and its distance to the segment j1-j2."""
    rx, ry, rvalid, sx, sy = S.rx, S.ry, S.rvalid, S.sx, S.sy
    n, m = len(sx), len(rx)
    c, s = np.cos(th), np.sin(th)
    wx, wy = np.empty(n), np.empty(n)
    j1, j2 = np.full(n, -1), np.full(n, -1)
    status = np.full(n, np.int8(_OUTSIDE))
    d2 = np.full(n, np.inf)
    for i in range(n):
        wx[i], wy[i] = c * sx[i] - s * sy[i] + x, s * sx[i] + c * sy[i] + y
        if not S.svalid[i]:
            continue
        best, d = _nearest(S, wx[i], wy[i], _on_branch(np.arctan2(wy[i], wx[i]), S.rtheta))
        d2[i] = d
        if best < 0 or d > lp.max_dist * lp.max_dist or best == 0 or best == m - 1:
            continue
        up, down = best + 1, best - 1
        while up < m and not rvalid[up]:
            up += 1
        while down >= 0 and not rvalid[down]:
            down -= 1
        if up >= m and down < 0:
            continue
        if up >= m:
            other = down
        elif down < 0:
            other = up
        else:
            du = (wx[i] - rx[up]) ** 2 + (wy[i] - ry[up]) ** 2
            dd = (wx[i] - rx[down]) ** 2 + (wy[i] - ry[down]) ** 2
            other = up if du < dd else down
        j1[i], j2[i], status[i] = best, other, _KEPT
    if lp.doubles:  # several object rays on one j1: only those near the nearest one stay
        nearest_d2 = np.full(m, np.inf)
        for i in range(n):
            if status[i] == _KEPT:
                nearest_d2[j1[i]] = min(nearest_d2[j1[i]], d2[i])
        for i in range(n):
            if status[i] == _KEPT and d2[i] > DOUBLES_FACTOR * DOUBLES_FACTOR * nearest_d2[j1[i]]:
                status[i] = _DOUBLE
    dist = np.full(n, np.inf)
    k = 0
    for i in range(n):
        if status[i] == _KEPT or status[i] == _DOUBLE:
            fx, fy = _segment_foot(rx[j1[i]], ry[j1[i]], rx[j2[i]], ry[j2[i]], wx[i], wy[i], True)
            dist[i] = np.hypot(wx[i] - fx, wy[i] - fy)
            k += status[i] == _KEPT
    limit = np.inf
    if k > 0:
        kept = dist[status == _KEPT]
        lim1 = kth_smallest(kept, max(0, min(int(np.floor(k * lp.max_perc)), k - 1)))
        lim2 = lp.mult * kth_smallest(kept, max(0, min(int(np.floor(k * lp.order)), k - 1)))
        limit = min(lim1, lim2)
        for i in range(n):
            if status[i] == _KEPT and dist[i] > limit:
                status[i] = _TRIMMED
    return wx, wy, j1, j2, status, dist, limit, k


@kernel
def _targets(S: Rays, wx, wy, j1, j2, status, line: bool):
    """The kept pairs as the solver takes them: object point (sensor frame), target and weight.
    ICP: the foot on the segment, weight I; PL-ICP: the point j1 and n n^T of the segment's
    normal."""
    rx, ry, sx, sy = S.rx, S.ry, S.sx, S.sy
    idx = np.flatnonzero(status == _KEPT)
    K = len(idx)
    p, q, C = np.empty((K, 2)), np.empty((K, 2)), np.zeros((K, 2, 2))
    for k in range(K):
        i = idx[k]
        p[k, 0], p[k, 1] = sx[i], sy[i]
        a, b = j1[i], j2[i]
        if line:
            q[k, 0], q[k, 1] = rx[a], ry[a]
            dx, dy = rx[a] - rx[b], ry[a] - ry[b]
            norm = np.hypot(dx, dy)
            nx, ny = dy / norm, -dx / norm
            C[k, 0, 0], C[k, 0, 1], C[k, 1, 0], C[k, 1, 1] = nx * nx, nx * ny, nx * ny, ny * ny
        else:
            q[k, 0], q[k, 1] = _segment_foot(rx[a], ry[a], rx[b], ry[b], wx[i], wy[i], True)
            C[k, 0, 0], C[k, 1, 1] = 1.0, 1.0
    return p, q, C


@kernel
def _hash(j1, j2, status):
    """A 64-bit fingerprint of the kept pairs (PL-ICP's test for a repeated set of pairs)."""
    h = np.uint64(1469598103934665603)
    for i in range(len(j1)):
        v = (
            np.uint64(i * 1000003 + (j1[i] + 1) * 7919 + (j2[i] + 1))
            if status[i] == _KEPT
            else np.uint64(i)
        )
        h = (h ^ v) * np.uint64(1099511628211)
    return h


@kernel
def _loop(S: Rays, x, y, th, lp: IcpLoopParams, trace):
    """CSM's icp_loop from (x, y, th): (outcome, x, y, th, total distance, kept pairs, iterations,
    converged, and the last iteration's pairs: wx, wy, j1, j2, status). ``trace`` (poses (n, 6),
    statuses, ... for n iterations) records each iteration; an empty one records nothing."""
    record = len(trace[0]) > 0
    hashes = np.empty(lp.max_iter, dtype=np.uint64)
    n = len(S.sx)
    total, valid, it, code, converged = 0.0, 0, 0, _OK, False
    wx, wy, j1, j2 = np.empty(0), np.empty(0), np.empty(0, np.int64), np.empty(0, np.int64)
    status = np.empty(0, np.int8)
    for it in range(lp.max_iter):
        wx, wy, j1, j2, status, dist, limit, k = _pairs(S, x, y, th, lp)
        kept = np.flatnonzero(status == _KEPT)
        if k < FAIL_FRACTION * n or len(kept) < FAIL_FRACTION * n or len(kept) < 3:
            code = _TOO_FEW
            break
        total, valid = dist[kept].sum(), len(kept)
        p, q, C = _targets(S, wx, wy, j1, j2, status, lp.line)
        A, b = normal_terms(p, q, C)
        nx, ny, nth, ok = solve(A, b)
        if not ok:
            code = _SINGULAR
            break
        if record:
            poses, stat, first, second, dists, limits = trace
            poses[it, 0], poses[it, 1], poses[it, 2], poses[it, 3], poses[it, 4], poses[it, 5] = (
                x,
                y,
                th,
                nx,
                ny,
                nth,
            )
            stat[it], first[it], second[it], dists[it], limits[it] = status, j1, j2, dist, limit
        # the step as CSM measures it: the new pose seen from the old one
        c, s = np.cos(th), np.sin(th)
        dx, dy = c * (nx - x) + s * (ny - y), -s * (nx - x) + c * (ny - y)
        dth = np.arctan2(np.sin(nth - th), np.cos(nth - th))
        x, y, th = nx, ny, nth
        hashes[it] = _hash(j1, j2, status)
        if lp.line:  # PL-ICP ends when the pairs repeat those of an earlier iteration
            for a in range(it):
                if hashes[a] == hashes[it]:
                    converged = True
        if converged or (np.hypot(dx, dy) < lp.eps_xy and abs(dth) < lp.eps_th):
            converged = True
            break
        if lp.halt[0]:
            code = _HALTED
            break
    return code, x, y, th, total, valid, it + 1, converged, wx, wy, j1, j2, status


def _empty_trace(n_iter: int, n: int):
    return (
        np.zeros((n_iter, 6)),
        np.zeros((n_iter, n), np.int8),
        np.zeros((n_iter, n), np.int64),
        np.zeros((n_iter, n), np.int64),
        np.zeros((n_iter, n)),
        np.zeros(n_iter),
    )


def _run(S: Rays, start: Pose2, params: IcpParams, trace=None):
    """One run of the loop from ``start`` (recorded into ``trace`` when given)."""
    trace = trace if trace is not None else _empty_trace(0, 0)
    return run(_loop, S, start.x, start.y, start.theta, IcpLoopParams.of(params), trace)


def _restarts(params: IcpParams, result: Pose2) -> list[tuple[Pose2, str]]:
    dt, dth = params.restart_dt, params.restart_dtheta
    moves = (
        (dt, 0, 0, "x + dt"),
        (-dt, 0, 0, "x - dt"),
        (0, dt, 0, "y + dt"),
        (0, -dt, 0, "y - dt"),
        (0, 0, dth, "theta + dtheta"),
        (0, 0, -dth, "theta - dtheta"),
    )
    return [
        (Pose2(result.x + a, result.y + b, result.theta + c), label) for a, b, c, label in moves
    ]


def match(
    ref: Scan,
    obj: Scan,
    initial_guess: Pose2 = Pose2(),
    params: IcpParams | None = None,
    observer: Observer | None = None,
) -> MatchResult:
    """Pose of the object frame in the reference frame, starting from ``initial_guess``."""
    params = params if params is not None else IcpParams()
    line = isinstance(params, PlIcpParams)
    name = "plicp" if line else "icp"
    rays = Rays.of(ref, obj, params)
    runs = [(initial_guess, "")]
    outcomes = [_run(rays, initial_guess, params)]
    code, x, y, th, total, valid = outcomes[0][:6]
    best = 0
    if code == _OK and params.restart and total / valid > params.restart_threshold_mean_error:
        for start, label in _restarts(params, Pose2(x, y, th)):
            out = _run(rays, start, params)
            if out[0] not in (_OK, _HALTED):  # CSM stops restarting at the first failure
                break
            runs.append((start, f"restart from the first run's result, {label}"))
            outcomes.append(out)
            if out[4] < outcomes[best][4]:
                best = len(outcomes) - 1
            if out[0] == _HALTED:
                break
    if observer is not None:
        _replay(observer, name, params, rays, runs, outcomes, best, initial_guess)
    result = _result(name, rays, params, outcomes, best)
    if observer is not None:
        observer(FinishEvent(result))
    return result


def _replay(observer, name, params, rays, runs, outcomes, best, initial_guess) -> None:
    """The recorded events of every run (the restarts continue the iteration count)."""
    ref_pts, ref_of_ray = rays.ref_points()
    obj_valid = np.flatnonzero(rays.svalid)
    obj_pts = np.column_stack((rays.sx, rays.sy))[obj_valid]
    used = np.arange(len(obj_pts))
    observer(StartEvent(name, params, ref_pts, obj_pts, used, initial_guess, None))
    count = 0
    for k, ((start, label), out) in enumerate(zip(runs, outcomes)):
        trace = _empty_trace(out[6], len(rays.sx))
        with budget.limited(None):  # the same iterations, to where the run ended (halted or not)
            _run(rays, start, replace(params, max_iterations=out[6]), trace)
        poses, stat, first, second, dists, limits = trace
        # a failed iteration computes no pose
        recorded = out[6] if out[0] in (_OK, _HALTED) else out[6] - 1
        for it in range(recorded):
            before, after = Pose2(*poses[it, :3]), Pose2(*poses[it, 3:])
            st, j1, j2 = stat[it][obj_valid], first[it][obj_valid], second[it][obj_valid]
            has = st != PairStatus.OUTSIDE_BR
            moved = before.apply(obj_pts)
            target = _feet(
                ref_pts[ref_of_ray[j1[has]]],
                ref_pts[ref_of_ray[j2[has]]],
                moved[has],
                clamp=not isinstance(params, PlIcpParams),
            )
            pairs = Correspondences(
                used[has],
                target,
                np.full(len(target), PairKind.INTERPOLATED, np.int8),
                np.column_stack((ref_of_ray[j1[has]], ref_of_ray[j2[has]])),
                dists[it][obj_valid][has],
                st[has],
                moved[has],
            )
            kept = st[has] == PairStatus.KEPT
            err = float(
                np.mean(np.sum((after.apply(obj_pts[has][kept]) - target[kept]) ** 2, axis=1))
            )
            note = label if it == 0 else ""
            if k == best and it == recorded - 1 and len(runs) > 1:
                note = f"the run kept: the smallest total distance of {len(runs)} runs"
            count += 1
            observer(
                IterationEvent(
                    count,
                    before,
                    after,
                    moved,
                    np.empty(0, np.int64),
                    pairs,
                    float(limits[it]) if np.isfinite(limits[it]) else None,
                    err,
                    after @ before.inverse(),
                    note=note,
                )
            )


def _feet(a: np.ndarray, b: np.ndarray, p: np.ndarray, clamp: bool) -> np.ndarray:
    """Where each pair ends: the foot of p on the segment a-b (``clamp``) or on its line."""
    e = b - a
    t = np.einsum("ij,ij->i", p - a, e) / np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
    return a + (np.clip(t, 0.0, 1.0) if clamp else t)[:, None] * e


def _result(name, rays, params, outcomes, best) -> MatchResult:
    """The kept run's pose; its last iteration's kept pairs make the final system (as CSM reports
    their count), for the covariance and the degeneracy indicator. A run stopped by the budget
    ends the match halted, whichever run is kept."""
    code, x, y, th, total, valid, _, converged, wx, wy, j1, j2, status = outcomes[best]
    iterations = sum(o[6] for o in outcomes)
    pose = Pose2(x, y, th)
    ref_pts, ref_of_ray = rays.ref_points()
    if code not in (_OK, _HALTED):
        reason = Termination.TOO_FEW_PAIRS if code == _TOO_FEW else Termination.SINGULAR
        return build_result(
            name, pose, reason, iterations, None, ref_pts, rays.full_circle, DEGENERACY_LENGTH_M
        )
    if any(o[0] == _HALTED for o in outcomes):
        reason = Termination.HALTED
    else:
        reason = Termination.CONVERGED if converged else Termination.MAX_ITERATIONS
    line = isinstance(params, PlIcpParams)
    A, err, foot, first = run(_final_system, rays, wx, wy, j1, j2, status, x, y, th, line)
    n_candidates = int(np.count_nonzero(status != PairStatus.OUTSIDE_BR))
    last = FinalSystem(A, err, foot, ref_of_ray[first], len(first), n_candidates - len(first))
    return build_result(
        name, pose, reason, iterations, last, ref_pts, rays.full_circle, DEGENERACY_LENGTH_M
    )


@kernel
def _final_system(S: Rays, wx, wy, j1, j2, status, x, y, th, line: bool):
    """The kept pairs seen from the final pose (x, y, th): the normal matrix A = sum J^T C J in
    (x, y, theta) (C: the pair's weight as ``_targets`` gives it; J = [[1, 0, -y], [0, 1, x]] at
    the moved point), the mean squared distance of the moved points to their segments' feet, the
    feet, and each pair's j1 ray."""
    rx, ry = S.rx, S.ry
    p, _, C = _targets(S, wx, wy, j1, j2, status, line)
    idx = np.flatnonzero(status == _KEPT)
    c, s = np.cos(th), np.sin(th)
    A, foot, err = np.zeros((3, 3)), np.empty((len(idx), 2)), 0.0
    for k in range(len(idx)):
        mx, my = c * p[k, 0] - s * p[k, 1] + x, s * p[k, 0] + c * p[k, 1] + y
        jac = ((1.0, 0.0, -my), (0.0, 1.0, mx))
        for i in range(3):
            for m in range(3):
                for a in range(2):
                    for b in range(2):
                        A[i, m] += jac[a][i] * C[k, a, b] * jac[b][m]
        i = idx[k]
        foot[k, 0], foot[k, 1] = _segment_foot(
            rx[j1[i]], ry[j1[i]], rx[j2[i]], ry[j2[i]], mx, my, True
        )
        err += (mx - foot[k, 0]) ** 2 + (my - foot[k, 1]) ** 2
    return A, err / len(idx), foot, j1[idx]
