"""Correspondence search of the MbICP family: compiled (numba) loops over the object points.

For each object point (already moved into the reference frame) the candidates are the
reference points whose bearing lies within the angular window +/-Bw of the point's bearing
(MbICP §IV); the best is the one of smallest metric distance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .events import PairKind
from .metric import metric_sq
from .scan import Scan


@dataclass(frozen=True, eq=False)
class ReferenceIndex:
    """The reference scan prepared once per match: points in scan order and a bearing index.

    ``ext_bearings`` repeats the bearings shifted by -2pi and +2pi so that a window crossing
    +/-pi (360-degree scanners) is one contiguous slice; ``ext_map`` maps back to point indices.
    """

    points: np.ndarray  # (N, 2)
    bearings: np.ndarray  # (N,) increasing
    ext_bearings: np.ndarray  # (3N,)
    ext_map: np.ndarray  # (3N,)
    ext_x: np.ndarray  # (3N,) x, y and |q|^2 + L^2 (the metric's denominator) of ``ext_map``'s
    ext_y: np.ndarray  # points: the search reads them without a second gather
    ext_sq_norm_L2: np.ndarray
    max_factor: float  # sqrt(max|q|^2 + L^2) / L: the Euclidean radius per unit of metric distance
    max_step: float  # the widest bearing gap between consecutive reference points [rad]
    full_circle: bool
    neighbours: np.ndarray  # (N, 2) scan-order previous and next point, -1 past the ends of a partial scan

    @staticmethod
    def build(scan: Scan, L: float) -> "ReferenceIndex":
        pts = scan.points()
        b = scan.bearings[scan.valid]
        n = len(b)
        ext_b = np.concatenate((b - 2 * np.pi, b, b + 2 * np.pi))
        ext_map = np.tile(np.arange(n), 3)
        full = scan.is_full_circle()
        sq = np.einsum("ij,ij->i", pts, pts)
        k = sq + L * L
        nb = np.arange(n)[:, None] + np.array([-1, 1])
        nb = nb % n if full else np.where((nb >= 0) & (nb < n), nb, -1)
        return ReferenceIndex(pts, b, ext_b, ext_map, np.tile(pts[:, 0], 3), np.tile(pts[:, 1], 3), np.tile(k, 3),
                              float(np.sqrt(k.max()) / L) if n else 1.0,
                              float(np.diff(ext_b).max()) if n else 2 * np.pi, full, nb)


# Candidates tried first around each point's bearing: the K reference beams on either side.
_NEAR_K = 3


def polar(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bearing [rad] and range [m] of each point (computed once per iteration, used twice)."""
    return np.arctan2(points[:, 1], points[:, 0]), np.hypot(points[:, 0], points[:, 1])


@njit(cache=True)
def _first_at_least(eb, a: float, strict: bool) -> int:
    """``np.searchsorted(eb, a, "right" if strict else "left")``: the first index whose bearing is
    above (``strict``) or at least ``a``. Written out: numba's searchsorted costs half a second of
    compilation on a first match, this loop a few milliseconds."""
    lo, hi = 0, len(eb)
    while lo < hi:
        mid = (lo + hi) // 2
        if eb[mid] < a or (strict and eb[mid] == a):
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, inline="always")
def _window_min(px: float, py: float, ex, ey, ek, lo: int, hi: int):
    """Metric-nearest of the reference points ext[lo, hi) to (px, py): (ext index, d^2); (-1, inf) if
    empty; the first of equal minima. ``ek`` holds the metric's denominators |q|^2 + L^2."""
    best, d_best = -1, np.inf
    for j in range(lo, hi):
        d = metric_sq(px, py, ex[j], ey[j], ek[j])
        if d < d_best:
            best, d_best = j, d
    return best, d_best


@njit(cache=True)
def _nearest_kernel(p, alpha, rng, eb, ex, ey, ek, ext_map, n_ref: int, Bw: float, Br: float, L: float,
                    max_factor: float, max_step: float):
    """The loop of ``nearest`` over the moved points (compiled: a handful of candidates per point,
    where numpy paid a call per step for all points at once)."""
    idx = np.empty(len(alpha), dtype=np.int64)
    out = np.empty(len(alpha))
    clip_to_bw = Bw < _NEAR_K * max_step  # the 2K beams may reach beyond +/-Bw: clip them
    for i in range(len(alpha)):
        a, r, px, py = alpha[i], rng[i], p[i, 0], p[i, 1]
        pos = _first_at_least(eb, a, False)
        lo, hi = pos - _NEAR_K, pos + _NEAR_K
        if clip_to_bw:
            lo = max(lo, _first_at_least(eb, a - Bw, False))
            hi = max(min(hi, _first_at_least(eb, a + Bw, True)), lo)
        best, d2 = _window_min(px, py, ex, ey, ek, lo, min(hi, len(eb)))
        # the window that can hold anything closer (see ``nearest``), never wider than +/-Bw
        d0 = np.sqrt(min(max(d2, 0.0), Br * Br))
        rho = d0 * min((r + L) / max(L - d0, 1e-12), max_factor)
        half = min(np.arcsin(min(rho / r, 1.0)) if rho < r else np.pi, Bw) + 1e-12
        wlo = _first_at_least(eb, a - half, False)
        whi = min(_first_at_least(eb, a + half, True), wlo + n_ref)  # a point once
        if wlo < lo or whi > hi:
            b, d = _window_min(px, py, ex, ey, ek, wlo, min(whi, len(eb)))
            if d < d2:
                best, d2 = b, d
        if d2 < np.inf:
            idx[i], out[i] = ext_map[best], max(d2, 0.0)
        else:
            idx[i], out[i] = -1, np.inf
    return idx, out


def nearest(ref: ReferenceIndex, moved: np.ndarray, Bw: float, Br: float, L: float, moved_polar=None):
    """Metric-nearest reference point of each moved point within MbICP's angular window +/-Bw.

    Exact for every pair whose metric distance is at most Br. First the 2K beams around the
    point's bearing (inside +/-Bw) give a candidate at distance d*; the window that can hold a
    closer point is then bounded: with d0 = min(d*, Br), since d^2(p, q) >= |p - q|^2 L^2 /
    (|q|^2 + L^2), any q with d(p, q) <= d0 has |p - q| <= d0 sqrt(|q|^2 + L^2) / L
    <= d0 (|p| + |p - q| + L) / L, i.e. |p - q| <= d0 (|p| + L) / (L - d0) when d0 < L (and
    always <= d0 sqrt(max|q|^2 + L^2) / L): within the smaller radius rho of the two, so within
    asin(rho / |p|) of p's bearing. Points whose bounded window reaches beyond the 2K beams are
    searched again over the whole bounded window. A point with no candidate gets index -1 and
    distance inf. ``moved_polar``: ``polar(moved)`` when the caller has it. Returns (index, squared
    metric distance).
    """
    alpha, rng = moved_polar if moved_polar is not None else polar(moved)
    return _nearest_kernel(moved, alpha, rng, ref.ext_bearings, ref.ext_x, ref.ext_y, ref.ext_sq_norm_L2,
                           ref.ext_map, len(ref.points), float(Bw), float(Br), float(L), ref.max_factor,
                           ref.max_step)


@dataclass(frozen=True, eq=False)
class Pairs:
    """Candidate pairs for a subset of the moved object points (``obj`` indexes those points)."""

    obj: np.ndarray  # (K,)
    target: np.ndarray  # (K, 2)
    kind: np.ndarray  # (K,) PairKind
    ref_index: np.ndarray  # (K, 2)
    dist: np.ndarray  # (K,) metric distance [m]


def _nearest_found(ref, moved, moved_polar, rows, Bw, Br, L):
    """Rows of ``moved`` that found a metric-nearest point, their points, the point, and d^2."""
    p = moved[rows]
    best, d2 = nearest(ref, p, Bw, Br, L, (moved_polar[0][rows], moved_polar[1][rows]))
    found = best >= 0
    return rows[found], p[found], best[found], d2[found]


@njit(cache=True)
def _window_kernel(p, alpha, eb, ex, ey, ek, ext_map, n_ref: int, full: bool, Bw: float, L: float,
                   max_inter: float):
    """The loop of ``mbicp_pairs``: per object point the target, d^2, kind and reference indices
    (j, -1) or (j1, j2); d^2 = inf where the window holds no reference point."""
    n = len(alpha)
    target = np.empty((n, 2))
    d2 = np.empty(n)
    kind = np.empty(n, dtype=np.int8)
    ref_index = np.empty((n, 2), dtype=np.int64)
    L2 = L * L
    for i in range(n):
        px, py, a = p[i, 0], p[i, 1], alpha[i]
        lo = _first_at_least(eb, a - Bw, False)  # the C code's L
        hi = min(_first_at_least(eb, a + Bw, False) - 1, lo + n_ref - 1)  # its R: a point once
        d2[i], kind[i], ref_index[i, 0], ref_index[i, 1] = np.inf, PairKind.POINT, -1, -1
        target[i, 0], target[i, 1] = 0.0, 0.0
        if hi < lo:  # no reference point within +/-Bw (the C code pairs it with the origin)
            continue
        if hi == lo:
            target[i, 0], target[i, 1] = ex[lo], ey[lo]
            d2[i], ref_index[i, 0] = metric_sq(px, py, ex[lo], ey[lo], ek[lo]), ext_map[lo]
            continue
        # every segment of the window; lambda minimises the metric of the object point (MbICP §IV-B)
        A = 1.0 / (px * px + py * py + L2)
        B, C, D = 1.0 - A * py * py, 1.0 - A * px * px, A * px * py
        for J in range(lo + 1, hi + 1):
            if not full and ext_map[J] == 0:  # a partial scan has no segment from its last point to its first
                continue
            q1x, q1y, q2x, q2y = ex[J - 1], ey[J - 1], ex[J], ey[J]
            dqx, dqy = q1x - q2x, q1y - q2y
            dqpx, dqpy = q1x - px, q1y - py
            den = B * dqx * dqx + C * dqy * dqy + 2.0 * D * dqx * dqy
            lam = (D * (dqx * dqpy + dqy * dqpx) + B * dqx * dqpx + C * dqy * dqpy) / den if den > 0.0 else 0.0
            j1, j2 = ext_map[J - 1], ext_map[J]
            if lam < 0.0:
                qx, qy, k, j, other = q1x, q1y, ek[J - 1], j1, -1
            elif lam > 1.0:
                qx, qy, k, j, other = q2x, q2y, ek[J], j2, -1
            elif dqx * dqx + dqy * dqy < max_inter:  # the C code compares the squared length
                qx, qy = (1.0 - lam) * q1x + lam * q2x, (1.0 - lam) * q1y + lam * q2y
                k, j, other = qx * qx + qy * qy + L2, j1, j2
            elif lam < 0.5:  # too long to interpolate: the nearer end
                qx, qy, k, j, other = q1x, q1y, ek[J - 1], j1, -1
            else:
                qx, qy, k, j, other = q2x, q2y, ek[J], j2, -1
            d = metric_sq(px, py, qx, qy, k)
            if d < d2[i]:  # the first of equal minima, as the C code keeps it
                d2[i], target[i, 0], target[i, 1], ref_index[i, 0], ref_index[i, 1] = d, qx, qy, j, other
                kind[i] = PairKind.INTERPOLATED if other >= 0 else PairKind.POINT
    return target, d2, kind, ref_index


def mbicp_pairs(ref: ReferenceIndex, moved: np.ndarray, moved_polar, rows: np.ndarray, Bw: float, Br: float,
                L: float, max_dist_inter: float) -> Pairs:
    """MbICP's correspondences as the original C code makes them (Minguez et al. 2006, §IV).

    The window of an object point holds the reference points whose bearing lies in
    [alpha - Bw, alpha + Bw), bearings compared modulo 2 pi. With one point there, that point;
    with more, every segment between consecutive window points is tried: its point metrically
    closest to the object point (the metric of the object point, as the code's lambda), clamped
    to the segment, or the nearer end when the segment's *squared* length is MaxDistInter or
    more (the code compares it so); the candidate of smallest metric distance (the reference
    point's metric) wins. A 360-degree reference is searched across its seam, a partial one has
    no segment from its last point to its first.

    Where this departs from the code, the code is wrong: its atan2 angles wrap at +/-pi (a
    window there misses half its points); a point more than Bw past the scan's end is paired
    with the scan's last point (beyond Br at any range that matters); a window without
    reference points pairs its point with the origin at distance Br. Here such a point gets no
    pair. Pairs at a metric distance above Br are cut later (``rejection.reject``).
    """
    target, d2, kind, ref_index = _window_kernel(
        moved[rows], moved_polar[0][rows], ref.ext_bearings, ref.ext_x, ref.ext_y, ref.ext_sq_norm_L2, ref.ext_map,
        len(ref.points), ref.full_circle, float(Bw), float(L), float(max_dist_inter))
    found = np.isfinite(d2)
    return Pairs(rows[found], target[found], kind[found], ref_index[found], np.sqrt(np.maximum(d2[found], 0.0)))


def point_line_pairs(ref: ReferenceIndex, moved: np.ndarray, moved_polar, rows: np.ndarray, Bw: float,
                     Br: float, L: float, max_dist_inter: float) -> Pairs:
    """Paper 000 §2.4.1: point-to-point pairs, point-to-line for object points sharing a target.

    Every object point takes its metric-nearest reference point m_j. Among the points sharing one
    m_j, the closest keeps it; each other one is paired with the orthogonal projection of itself
    onto the segment from m_j to its second-nearest reference point m'_j (clamped to the
    segment). As in PL-ICP (Censi 2008), m'_j is sought among the scan neighbours of m_j, where
    it lies but at occlusion edges. Segments longer than MaxDistInter would bridge two surfaces:
    such a point keeps m_j.
    """
    rows, p, best, d2 = _nearest_found(ref, moved, moved_polar, rows, Bw, Br, L)
    target, kind, second, d2 = _share_targets(p, best, d2, ref.points, ref.ext_sq_norm_L2, ref.neighbours,
                                              float(L), float(max_dist_inter))
    return Pairs(rows, target, kind, np.column_stack((best, second)), np.sqrt(d2))


@njit(cache=True)
def _share_targets(p, best, d2, points, sq_norm_L2, neighbours, L: float, max_len: float):
    """The loop of ``point_line_pairs``: target, kind, second reference point (-1: none) and d^2 per pair.

    ``sq_norm_L2[j]`` = |q_j|^2 + L^2 for reference point j (ReferenceIndex.ext_sq_norm_L2).
    """
    n = len(best)
    winner = np.empty(len(points), dtype=np.int64)  # per reference point: the closest object point, first of ties
    winner[:] = -1
    for i in range(n):
        w = winner[best[i]]
        if w < 0 or d2[i] < d2[w]:
            winner[best[i]] = i
    target = points[best]
    kind = np.empty(n, dtype=np.int8)
    kind[:] = PairKind.POINT
    second = np.empty(n, dtype=np.int64)  # (np.full costs a quarter second of compilation)
    second[:] = -1
    d2 = d2.copy()
    for i in range(n):
        j = best[i]
        if winner[j] == i:
            continue
        px, py = p[i, 0], p[i, 1]
        # m'_j: the scan neighbour of m_j metrically closer to p (the previous one on a tie)
        s, d_s = -1, np.inf
        for nb in neighbours[j]:
            if nb >= 0:
                d = metric_sq(px, py, points[nb, 0], points[nb, 1], sq_norm_L2[nb])
                if s < 0 or d < d_s:
                    s, d_s = nb, d
        if s < 0:
            continue
        ax, ay = points[j, 0], points[j, 1]
        ex, ey = points[s, 0] - ax, points[s, 1] - ay
        ee = ex * ex + ey * ey
        if ee > max_len * max_len:
            continue
        t = min(max(((px - ax) * ex + (py - ay) * ey) / ee, 0.0), 1.0) if ee > 1e-18 else 0.0
        cx, cy = ax + t * ex, ay + t * ey
        target[i, 0], target[i, 1] = cx, cy
        kind[i] = PairKind.INTERPOLATED
        second[i] = s
        d2[i] = max(metric_sq(px, py, cx, cy, cx * cx + cy * cy + L * L), 0.0)
    return target, kind, second, d2


def visible_in_order(moved_polar) -> np.ndarray:
    """The original MbICP's projection filter: walking the object points in scan order, a point
    whose bearing falls below that of the last point kept is hidden (it went behind a surface
    seen before it). Bearings are unwrapped along the scan (the code's atan2 angles jump at
    +/-pi, which it warns about); a 360-degree scanner still wants the z-buffer
    (``visible_from_reference``)."""
    alpha = np.unwrap(moved_polar[0])
    return alpha >= np.maximum.accumulate(alpha)


def visible_from_reference(moved_polar, bin_start: float, bin_width: float, margin: float) -> np.ndarray:
    """Projection filter (Lu & Milios 1997, used by MbICP): which moved points the reference sees.

    A z-buffer over bearing bins of the reference viewpoint: in each bin only points within
    ``margin`` of the nearest one are visible; points behind a closer surface are hidden. Bins
    start at the reference scan's first bearing so that turning the scanner turns the bins.
    ``moved_polar``: ``polar`` of the moved points.
    """
    alpha, r = moved_polar
    bins = ((alpha - bin_start) % (2 * np.pi) / bin_width).astype(np.int64)  # non-negative: truncation floors
    zbuf = np.full(int(2 * np.pi / bin_width) + 2, np.inf)
    np.minimum.at(zbuf, bins, r)
    return r <= zbuf[bins] + margin
