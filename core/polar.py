"""Machinery shared by the polar matchers (PSM, Diosi & Kleeman 2007; PMWN, paper 003).

Both work on ranges at the reference bearings instead of point pairs: the object scan is moved
by the estimate, projected onto the reference bearings (scan projection), and compared range by
range. The reference bearings must be uniformly spaced (rotation is a shift of bearing indices);
a 360-degree reference wraps around.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
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
    PolarStep,
    StartEvent,
)
from .metric import kth_smallest
from .result import MatchResult, Termination
from .scan import Scan, ScanError
from .se2 import Pose2
from .stopping import CycleWatch
from .tiers import kernel, run
from .uncertainty import DEGENERACY_LENGTH_M, degeneracy, surface_tangents


@dataclass(frozen=True, eq=False)
class PolarScan:
    """A preprocessed scan: median-filtered ranges, validity, and segment ids (-1: not in a
    segment)."""

    ranges: np.ndarray
    bearings: np.ndarray
    valid: np.ndarray
    segment: np.ndarray
    rays: np.ndarray  # (N, 2) unit vector (cos, sin) of every bearing
    xy: np.ndarray  # (N, 2) every beam as a point (invalid ones too; ``valid`` says which count)
    edges: np.ndarray  # beams k such that k and k + 1 bound a surface of one segment

    def points(self) -> np.ndarray:
        return self.xy[self.valid]


def segment(r: np.ndarray, valid: np.ndarray, max_jump: float) -> np.ndarray:
    """Segment id per beam, -1 outside any segment (PSM §3 step 1).

    Consecutive valid readings (in scan order, skipping invalid beams) belong to one segment while
    their ranges differ by at most ``max_jump``; one-reading segments are dropped. Diosi's code also
    keeps a beam whose range continues the line through the two before it; on Intel's 1-degree
    scans that links sparse far readings into false surfaces and lowers accuracy (40 seeded small
    displacements within 1 cm / 0.2 deg: 82.5 % with it, 97.5 % without), so it is left out.
    """
    return run(_segment_kernel, r, valid, max_jump)


@kernel
def _segment_kernel(r, valid, max_jump: float):
    """The loop of ``segment``: number the runs of valid readings, then drop the one-reading runs
    (their numbers stay unused)."""
    # (np.full in compiled code costs a quarter second to compile)
    seg = np.empty(len(r), dtype=np.int64)
    seg[:] = -1
    beam = np.empty(len(r), dtype=np.int64)
    run = np.empty(len(r), dtype=np.int64)
    m, current, previous = 0, -1, -1
    for k in range(len(r)):
        if valid[k]:
            if previous < 0 or abs(r[k] - r[previous]) > max_jump:
                current += 1
            beam[m], run[m] = k, current
            m += 1
            previous = k
    size = np.zeros(current + 1, dtype=np.int64)
    for t in range(m):
        size[run[t]] += 1
    for t in range(m):
        if size[run[t]] >= 2:
            seg[beam[t]] = run[t]
    return seg


@kernel
def median_nearest(x, window: int):
    """Running median of ``window`` values with the ends repeated: scipy.ndimage.median_filter(x,
    size=window, mode="nearest") (for an even window the upper of the two middle values), as one
    compiled loop instead of scipy's per-call setup."""
    n = len(x)
    out = np.empty(n)
    buf = np.empty(window)
    for i in range(n):
        for j in range(window):  # insertion sort: a window holds a handful of values
            v = x[min(max(i - window // 2 + j, 0), n - 1)]
            k = j
            while k > 0 and buf[k - 1] > v:
                buf[k] = buf[k - 1]
                k -= 1
            buf[k] = v
        out[i] = buf[window // 2]
    return out


def preprocess(
    scan: Scan, median_window: int, min_range: float, max_range: float, max_jump: float
) -> PolarScan:
    """PSM §3 step 1 (also PMWN's): median filter, drop near/far readings, segment, drop lone
    points.

    The median filter runs over valid readings in scan order (invalid ones neither vote nor get
    filled); see ``segment``.
    """
    valid = scan.valid & (scan.ranges > min_range) & (scan.ranges < max_range)
    r = scan.ranges.copy()
    idx = np.flatnonzero(valid)
    if len(idx) and median_window > 1:
        r[idx] = run(median_nearest, scan.ranges[idx], median_window)
    seg = segment(r, valid, max_jump)
    rays = np.column_stack((np.cos(scan.bearings), np.sin(scan.bearings)))
    return PolarScan(
        r,
        scan.bearings,
        seg >= 0,
        seg,
        rays,
        r[:, None] * rays,
        np.flatnonzero((seg[:-1] >= 0) & (seg[:-1] == seg[1:])),
    )


@dataclass(frozen=True, eq=False)
class Grid:
    """The reference bearings as a uniform grid: b0 + i * step, i < n; ``full``: it wraps around."""

    b0: float
    step: float
    n: int
    full: bool

    @staticmethod
    def of(scan: Scan, name: str) -> Grid:
        b = scan.bearings
        if len(b) < 3:
            raise ScanError(scan.source, f"{name} needs at least 3 reference beams")
        d = np.diff(b)
        step = float(np.median(d))
        if np.max(np.abs(d - step)) > 0.01 * step:
            raise ScanError(
                scan.source,
                f"{name} needs uniformly spaced reference bearings (increments from "
                f"{np.degrees(d.min()):.4f} to {np.degrees(d.max()):.4f} deg); use icp, mbicp or "
                "improved",
            )
        return Grid(float(b[0]), step, len(b), scan.is_full_circle())

    @cached_property
    def bearings(self) -> np.ndarray:
        return self.b0 + self.step * np.arange(self.n)


def project(grid: Grid, cur: PolarScan, pose: Pose2, pad: int = 0) -> np.ndarray:
    """Scan projection (PSM §3 step 2): ranges of the moved object scan at the reference bearings.

    Returns bins -pad .. n + pad - 1 of the bearing grid (the orientation step compares shifts of up
    to ``pad`` bins, which bring in surfaces from beyond the field of view; a 360-degree grid
    wraps). Between consecutive points of one segment the range is interpolated linearly in
    bearing; where several surfaces project onto one bearing the closest is kept (occlusion). As
    in Diosi's pm_scan_project, an edge whose bearing decreases along the scan faces away from the
    reference viewpoint: it still hides what lies behind it, but a bearing whose closest surface is
    such a back face is not compared (NaN), as is a bearing where nothing projects.
    """
    out = run(
        _project_kernel,
        cur.xy,
        cur.edges,
        pose.x,
        pose.y,
        math.cos(pose.theta),
        math.sin(pose.theta),
        grid.b0,
        grid.step,
        grid.n,
        grid.full,
        pad,
    )
    return np.concatenate((out[grid.n - pad :], out, out[:pad])) if grid.full and pad else out


@kernel
def _project_kernel(
    xy,
    edges,
    tx: float,
    ty: float,
    c: float,
    s: float,
    b0: float,
    step: float,
    n: int,
    full: bool,
    pad: int,
):
    """The loop of ``project``: move the scan by (tx, ty, angle with cosine c and sine s), then walk
    its edges (bins of a full grid not yet extended)."""
    size = n if full else n + 2 * pad
    a = np.empty(len(xy))
    r = np.empty(len(xy))
    for k in range(len(xy)):
        x, y = c * xy[k, 0] - s * xy[k, 1] + tx, s * xy[k, 0] + c * xy[k, 1] + ty
        a[k] = b0 + np.mod(np.arctan2(y, x) - b0, 2 * np.pi)  # in [b0, b0 + 2pi)
        r[k] = np.hypot(x, y)
    out = np.empty(size)  # closest surface per bin
    out[:] = np.inf
    front = np.empty(size)  # closest surface facing the reference viewpoint
    front[:] = np.inf
    for k in edges:
        a1, a2, r1, r2 = a[k], a[k + 1], r[k], r[k + 1]
        span = a2 - a1
        if not abs(span) < np.pi / 2:  # an edge across the seam of the angle range is not a surface
            continue
        lo, hi = min(a1, a2), max(a1, a2)
        # range per radian along the edge
        slope = (r2 - r1) / (span if abs(span) > 1e-12 else np.inf)
        i0, i1 = int(np.ceil((lo - b0) / step - 1e-9)), int(np.floor((hi - b0) / step + 1e-9))
        # only the bins of the grid: time bounded by the beams, not by the edge's span / step
        if not full:
            i0, i1 = max(i0, -pad), min(i1, n + pad - 1)
        for i in range(i0, i1 + 1):
            rr = r1 + (b0 + i * step - a1) * slope
            j = i % n if full else i + pad
            if 0 <= j < size:
                out[j] = min(out[j], rr)
                if span > 0:
                    front[j] = min(front[j], rr)
    for j in range(size):
        if not (front[j] == out[j] and out[j] < np.inf):
            out[j] = np.nan
    return out


def shift_costs(
    ref_r: np.ndarray, proj_ext: np.ndarray, K: int, min_pairs: int, cap: float | None = None
):
    """Mean |r_ref(i) - r_proj(i + k)| and the pair count for every shift k in -K..K (PSM §3 step
    4).

    ``proj_ext`` holds the projection on bins -K .. n + K - 1; NaN marks missing ranges. ``cap``
    (not published) limits each difference: after a long move most bearings compare different
    surfaces, and their metres of difference, not the few bearings that agree, decide Diosi's
    mean (a nearly flat curve whose minimum wanders); capped, a bearing that compares different
    surfaces costs the same at every shift and the agreeing ones decide.
    """
    return run(
        _shift_costs_kernel, ref_r, proj_ext, K, min_pairs, np.inf if cap is None else float(cap)
    )


@kernel
def _shift_costs_kernel(ref_r, proj_ext, K: int, min_pairs: int, cap: float):
    """Sum over the bearings with both ranges of min(|difference|, cap) / their count, per shift
    (NaN with fewer than min_pairs)."""
    cost = np.zeros(2 * K + 1)
    count = np.zeros(2 * K + 1, dtype=np.int64)
    for s in range(2 * K + 1):  # shift k = s - K: r_proj(i + k) is proj_ext[i + s]
        total, m = 0.0, 0
        for i in range(len(ref_r)):
            d = abs(proj_ext[i + s] - ref_r[i])
            if d == d:  # both ranges present
                total += min(d, cap)
                m += 1
        cost[s], count[s] = total / max(m, 1) if m >= min_pairs else np.nan, m
    return cost, count


def refine_parabola(a: float, b: float, c: float) -> float:
    """Offset of the vertex of the parabola through (-1, a), (0, b), (1, c) (PSM's refinement)."""
    den = a - 2.0 * b + c
    return min(max(0.5 * (a - c) / den, -0.5), 0.5) if den > 0 else 0.0


def refine_v(a: float, b: float, c: float) -> float:
    """Vertex of the linear absolute-value function m|x - x0| + b0 through (-1, a), (0, b), (1, c).

    Paper 003 §4.1 (its eqs. 20-22 are lost; this is the closed form of that model): with the
    steeper side setting the slope m = max(a, c) - b, x0 = (a - c) / (2 m).
    """
    m = max(a, c) - b
    return min(max((a - c) / (2.0 * m), -0.5), 0.5) if m > 0 else 0.0


def least(cost: np.ndarray) -> int | None:
    """Index of the smallest cost, NaN meaning "too few pairs at that shift"; None if all are
    NaN."""
    j = run(_least_kernel, cost)
    return j if j >= 0 else None


@kernel
def _least_kernel(cost) -> int:
    """First index of the smallest finite cost (NaN and inf skipped); -1 if there is none."""
    j, best = -1, np.inf
    for k in range(len(cost)):
        if cost[k] < best:
            j, best = k, cost[k]
    return j


def best_shift(shifts: np.ndarray, cost: np.ndarray, refine, fit_cost: np.ndarray | None = None):
    """The refined minimum of the cost curve (in shift units) and the three samples the fit used.

    ``fit_cost`` (default: ``cost``) is the curve the sub-shift fit runs on: PMWN picks the shift
    with its metric-weighted norm but refines it on the range term alone, since the weight's own
    V at zero would pull every refinement towards no correction.
    """
    j = least(cost)
    if j is None:
        return None, None
    f = cost if fit_cost is None else fit_cost
    if 0 < j < len(f) - 1:
        abc = (float(f[j - 1]), float(f[j]), float(f[j + 1]))
        if all(map(math.isfinite, abc)):
            return float(shifts[j]) + refine(*abc), abc
    return float(shifts[j]), None


class Residuals(NamedTuple):
    """The range residuals of one translation step: all at shared bearings, and the used ones (the
    kernel returns both, so the loop does not index the arrays again each iteration)."""

    i: np.ndarray  # bearing indices where both scans have a range
    e: np.ndarray  # r_ref - r_proj there [m]
    w: np.ndarray  # PSM weights C / (C + e^2)
    used: np.ndarray  # |e| within the cut
    iu: np.ndarray  # i[used]
    eu: np.ndarray  # e[used]
    wu: np.ndarray  # w[used]


def translation_residuals(
    ref: PolarScan, proj_r: np.ndarray, max_error: float, C: float, min_pairs: int | None = None
) -> Residuals:
    """Residuals e_i = r_ref - r_proj at shared bearings, PSM weights w = C / (C + e^2), and which
    are used.

    With ``min_pairs`` (not published) the cut never keeps fewer than that many residuals: when
    fewer lie within ``max_error`` it rises to the min_pairs-th smallest |e|, so that a long move
    is still corrected (the weights keep the far ones weak) instead of ending with too few pairs.
    """
    relaxed = 0 if min_pairs is None else min_pairs
    return Residuals(*run(_residuals_kernel, ref.ranges, ref.valid, proj_r, max_error, C, relaxed))


@kernel
def _residuals_kernel(ref_r, valid, proj_r, max_error: float, C: float, min_pairs: int):
    """``translation_residuals`` as one loop (min_pairs 0: no relaxed cut)."""
    i = np.empty(len(ref_r), dtype=np.int64)
    m = 0
    for k in range(len(ref_r)):
        if valid[k] and np.isfinite(proj_r[k]):
            i[m] = k
            m += 1
    i = i[:m]
    e = ref_r[i] - proj_r[i]
    a = np.abs(e)
    if 0 < min_pairs <= m:
        max_error = max(max_error, kth_smallest(a, min_pairs - 1))
    w = C / (C + e * e)
    used = a <= max_error
    return i, e, w, used, i[used], e[used], w[used]


def beam_normals(scan: PolarScan) -> np.ndarray:
    """Unit surface normal at every beam, from its neighbours in the same segment (central
    differences, one-sided at a segment's ends); the beam's own direction where it has none."""
    k = np.arange(len(scan.ranges))
    joined = np.zeros(len(k), dtype=bool)  # joined[j]: beams j and j + 1 lie on one segment
    joined[scan.edges] = True
    lo = np.where(np.roll(joined, 1) & (k > 0), k - 1, k)
    hi = np.where(joined, k + 1, k)
    t = scan.xy[hi] - scan.xy[lo]
    norm = np.hypot(t[:, 0], t[:, 1])
    normal = np.column_stack((-t[:, 1], t[:, 0])) / np.where(norm > 0, norm, 1.0)[:, None]
    return np.where((norm > 0)[:, None], normal, scan.rays)


@dataclass(frozen=True, eq=False)
class TranslationStep:
    """One translation step: its system rows_i . dt = rhs_i (weights w_i) and what it found."""

    rows: np.ndarray  # (m, 2) per used residual: the ray u_i (Diosi) or the surface normal n_i
    rhs: np.ndarray  # (m,)
    dt: tuple[float, float] | None  # the weighted least-squares translation [m]; None when singular
    error: float  # mean e^2 of the used residuals [m^2]
    mean_abs: float  # mean |e| of the used residuals [m]


def translation_step(
    ref: PolarScan, iu: np.ndarray, eu: np.ndarray, wu: np.ndarray, normals: np.ndarray | None
) -> TranslationStep:
    """Weighted least squares of rhs_i ~ rows_i . dt (PSM §3 step 3; PMWN's circle) over the used
    residuals (bearing indices iu, residuals eu, weights wu).

    Diosi's model (``normals`` None): moving the scan by dt changes the range along ray u by
    u . dt — exact for a surface facing the sensor, wrong for a wall seen at a grazing angle, whose
    range changes by (n . dt) / (n . u). With the reference normals n the step solves the
    surface-aware form n . dt = e (n . u) instead, i.e. point-to-line distances along the ray's
    surface. It has the same fixed point (all residuals zero) but a model of the right size in
    corridors, where Diosi's under-estimates the range change of the walls, over-corrects and
    drifts (his code's own limitation note; `eval ceiling` measures it).
    """
    rows, rhs, sums = run(
        _translation_kernel,
        iu,
        eu,
        wu,
        ref.rays,
        ref.rays if normals is None else normals,
        normals is not None,
    )
    a, b, d, rx, ry, e2, e1 = sums
    det = a * d - b * b
    m = len(eu)
    # all rows alike: translation across them is unobservable
    dt = None if det <= 1e-9 * (a + d) ** 2 else ((d * rx - b * ry) / det, (a * ry - b * rx) / det)
    return TranslationStep(rows, rhs, dt, float(e2 / m), float(e1 / m))


@kernel
def _translation_kernel(iu, eu, wu, rays, normals, surface: bool):
    """Rows, right-hand sides and the sums of the normal equations (see ``translation_step``):
    sum w r0^2, w r0 r1, w r1^2, w r0 rhs, w r1 rhs, e^2, |e|."""
    m = len(eu)
    rows = np.empty((m, 2))
    rhs = np.empty(m)
    sums = np.zeros(7)
    for t in range(m):
        k = iu[t]
        if surface:
            rows[t, 0], rows[t, 1] = normals[k, 0], normals[k, 1]
            rhs[t] = eu[t] * (normals[k, 0] * rays[k, 0] + normals[k, 1] * rays[k, 1])
        else:
            rows[t, 0], rows[t, 1] = rays[k, 0], rays[k, 1]
            rhs[t] = eu[t]
        wc, ws = wu[t] * rows[t, 0], wu[t] * rows[t, 1]
        sums[0] += wc * rows[t, 0]
        sums[1] += wc * rows[t, 1]
        sums[2] += ws * rows[t, 1]
        sums[3] += wc * rhs[t]
        sums[4] += ws * rhs[t]
        sums[5] += eu[t] * eu[t]
        sums[6] += abs(eu[t])
    return rows, rhs, sums


def polar_pairs(
    grid: Grid,
    ref: PolarScan,
    proj_r: np.ndarray,
    i: np.ndarray,
    e: np.ndarray,
    used: np.ndarray,
    ref_point_of: np.ndarray,
) -> Correspondences:
    """The range comparisons as point pairs: projected surface point -> reference point, one
    bearing each."""
    u = ref.rays[i]
    src = proj_r[i, None] * u
    tgt = ref.ranges[i, None] * u
    status = np.full(len(i), PairStatus.OUTSIDE_BR, dtype=np.int8)
    status[used] = PairStatus.KEPT
    return Correspondences(
        np.full(len(i), -1),
        tgt,
        np.full(len(i), PairKind.POINT, dtype=np.int8),
        np.column_stack((ref_point_of[i], np.full(len(i), -1))),
        np.abs(e),
        status,
        src,
    )


@dataclass(frozen=True)
class Strategy:
    """How one polar matcher differs from the other inside the shared loop."""

    name: str
    orientation_due: Callable[[int], bool]  # iteration -> run the orientation step?
    # three costs -> fractional offset of the minimum
    refine: Callable[[float, float, float], float]
    fit: str  # "parabola" | "V"
    metric: bool  # PMWN: add lambda * |shift angle| to the cost and adapt lambda


@dataclass(frozen=True, eq=False)
class _Prepared:
    """Both scans ready for the loop (PSM §3 step 1: median filter, range limits, segments) and
    the bearing shifts the orientation step compares."""

    grid: Grid
    ref: PolarScan
    obj: PolarScan
    ref_pts: np.ndarray
    obj_pts: np.ndarray
    ref_point_of: np.ndarray  # bearing -> index of its valid reference point
    normals: np.ndarray | None  # the reference's surface normals (surface_jacobian)
    ref_r: np.ndarray  # the reference ranges, NaN where invalid
    K: int  # the largest shift [bins]: no shift beyond the scan's own beams
    shifts: np.ndarray  # -K .. K

    @staticmethod
    def of(strategy: Strategy, ref: Scan, obj: Scan, params) -> _Prepared:
        grid = Grid.of(ref, strategy.name.upper())
        pre = (params.median_window, params.min_range, params.max_range, params.max_jump)
        ref_pre, obj_pre = preprocess(ref, *pre), preprocess(obj, *pre)
        K = min(int(round(params.search_window / grid.step)), grid.n)
        return _Prepared(
            grid,
            ref_pre,
            obj_pre,
            ref_pre.points(),
            obj_pre.points(),
            np.cumsum(ref_pre.valid) - 1,
            beam_normals(ref_pre) if params.surface_jacobian else None,
            np.where(ref_pre.valid, ref_pre.ranges, np.nan),
            K,
            np.arange(-K, K + 1),
        )

    def pairs(self, proj: np.ndarray, res) -> Correspondences:
        return polar_pairs(self.grid, self.ref, proj, res.i, res.e, res.used, self.ref_point_of)


@dataclass
class _Turn:
    """Sub-bearing orientation steps. Inside one bearing the fit's vertex depends on where the
    samples fall and jumps sign across the answer, so whole steps flip between two phases:
    sub-bearing steps are halved, and halved again at every flip (a bisection onto the answer)."""

    gain: float = 0.5
    last_fraction: float = 0.0

    def bins(self, k_best: float) -> float:
        """How many bins to turn back for a minimum found ``k_best`` bins away."""
        if abs(k_best) >= 1.0:
            return k_best
        if k_best * self.last_fraction < 0:
            self.gain *= 0.5
        self.last_fraction = k_best
        return self.gain * k_best


class _Orientation(NamedTuple):
    cost: np.ndarray  # per shift (PMWN: with the angle term of paper 003's norm)
    range_cost: np.ndarray  # per shift, the range term alone
    k_best: float | None  # the best shift [bins] (None: no orientation step this iteration)
    abc: tuple | None  # the fit around it


def _orientation(strategy: Strategy, s: _Prepared, params, proj_ext, lam, it) -> _Orientation:
    """PSM §3 step 4: the cost of every shift of the projected ranges, and the best one."""
    if not (strategy.orientation_due(it) and s.K > 0):
        no_cost = np.full(len(s.shifts), np.nan)
        return _Orientation(no_cost, no_cost, None, None)
    cap = params.max_error if params.truncated_orientation else None
    range_cost, _ = shift_costs(s.ref_r, proj_ext, s.K, params.min_pairs, cap)
    cost = range_cost + lam * np.abs(s.shifts) * s.grid.step if strategy.metric else range_cost
    return _Orientation(cost, range_cost, *best_shift(s.shifts, cost, strategy.refine, range_cost))


def _polar_step(strategy: Strategy, s: _Prepared, proj0, o: _Orientation, lam, res, step):
    """What the front ends plot of an iteration: ranges, the cost curve and its fit, weights, and
    PMWN's circle picture (which holds for Diosi's model only; his rows are the rays u_i)."""
    circle = strategy.metric and s.normals is None
    return PolarStep(
        s.grid.bearings,
        s.ref_r,
        proj0,
        s.shifts,
        o.cost,
        o.k_best,
        strategy.fit if o.k_best is not None else None,
        o.abc,
        lam,
        res.e,
        res.w,
        step.rhs[:, None] * step.rows if circle else None,
        0.5 * np.array(step.dt) if circle else None,
    )


def _balanced_lambda(s: _Prepared, params, range_cost, mean_abs: float) -> float:
    """Paper 003 eq. 17 (lost): the weight that balances the two terms of the norm at the rotation
    the range term points to, lambda = D / |theta_r|: D the mean |range difference| of this
    iteration, theta_r the shift where the range cost alone is least. (Balancing at the step
    actually taken would lock: a small step raises lambda, which keeps the next step small.)"""
    j = least(range_cost)
    theta_r = abs(float(s.shifts[j])) * s.grid.step if j is not None else 0.0
    return min(mean_abs / max(theta_r, s.grid.step), params.lambda_max)


def run_polar(
    strategy: Strategy, ref: Scan, obj: Scan, guess: Pose2, params, observer: Observer | None
) -> MatchResult:
    """Alternate orientation (shift the projected ranges) and translation (weighted LS) steps."""
    s = _Prepared.of(strategy, ref, obj, params)
    grid, K = s.grid, s.K
    if observer is not None:
        used = np.arange(len(s.obj_pts))
        observer(StartEvent(strategy.name, params, s.ref_pts, s.obj_pts, used, guess, None))
    est, lam = guess, params.lambda0 if strategy.metric else None
    n_small, it, reason, last = 0, 0, Termination.MAX_ITERATIONS, None
    cycles, turn, halt = CycleWatch(params), _Turn(), budget.current()
    for it in range(1, params.MaxIter + 1):
        before = est
        proj_ext = project(grid, s.obj, est, K)
        proj0 = proj_ext[K : K + grid.n]
        o = _orientation(strategy, s, params, proj_ext, lam, it)
        proj = proj0
        if o.k_best is not None:
            # r_proj(i + k) matches r_ref(i): the projection sits k bearings too far; turn it back
            est = Pose2(0.0, 0.0, -turn.bins(o.k_best) * grid.step) @ est
            proj = project(grid, s.obj, est)
        # PSM §3 step 5: the translation, weighted least squares on the range differences
        relaxed = params.min_pairs if params.relaxed_cut else None
        res = translation_residuals(
            s.ref, proj, params.max_error, params.weight_constant(it), relaxed
        )
        if len(res.iu) < params.min_pairs:
            reason, est = Termination.TOO_FEW_PAIRS, before
            if observer is not None:
                moved = before.apply(s.obj_pts)
                no_pose = (float("nan"), Pose2(), None)
                observer(
                    IterationEvent(
                        it, before, before, moved, _NONE, s.pairs(proj, res), None, *no_pose
                    )
                )
            break
        step = translation_step(s.ref, res.iu, res.eu, res.wu, s.normals)
        if step.dt is None:
            reason, est = Termination.SINGULAR, before
            break
        est = Pose2(float(step.dt[0]), float(step.dt[1]), 0.0) @ est
        lam_used = lam
        if strategy.metric:
            lam = _balanced_lambda(s, params, o.range_cost, step.mean_abs)
        inc = est @ before.inverse()
        if observer is not None:
            polar = _polar_step(strategy, s, proj0, o, lam_used, res, step)
            moved, pairs = before.apply(s.obj_pts), s.pairs(proj, res)
            observer(
                IterationEvent(
                    it, before, est, moved, _NONE, pairs, params.max_error, step.error, inc, polar
                )
            )
        last = (step.error, res.iu, len(res.iu), len(res.i) - len(res.iu))
        n_small = n_small + 1 if params.small(inc) else 0
        if n_small >= params.stop_after:
            reason = Termination.CONVERGED
            break
        cycle = cycles.step(before, est, params.stop_after)
        if cycle is not None:
            reason = cycle
            break
        if halt.raised:
            reason = Termination.HALTED
            break
    result = _result(strategy, s, est, reason, it, last)
    if observer is not None:
        observer(FinishEvent(result))
    return result


# An iteration's hidden points: the polar matchers hide none
_NONE = np.empty(0, np.int64)


def _result(strategy: Strategy, s: _Prepared, est: Pose2, reason, it: int, last) -> MatchResult:
    """The estimate, with the last translation step's pairs for the degeneracy indicator."""
    deg = None
    if last is not None:
        j = s.ref_point_of[last[1]]
        tangents = surface_tangents(s.ref_pts, s.grid.full, j)
        deg = degeneracy(s.ref_pts[j], tangents, DEGENERACY_LENGTH_M)
    return MatchResult(
        strategy.name,
        est,
        reason.converged,
        reason,
        it,
        last[0] if last else float("nan"),
        last[2] if last else 0,
        last[3] if last else 0,
        None,
        deg,
    )
