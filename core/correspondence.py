"""Correspondence search of the MbICP family, vectorised over object points.

For each object point (already moved into the reference frame) the candidates are the
reference points whose bearing lies within the angular window +/-Bw of the point's bearing
(MbICP §IV); the best is the one of smallest metric distance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .events import PairKind
from .metric import euclidean_project_on_segment, metric_distance_sq, metric_project_on_segment
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
    sq_norm_L2: np.ndarray  # (N,) |q|^2 + L^2, the metric's denominator
    max_sq_norm: float
    full_circle: bool
    tangents: np.ndarray  # (N, 2) unit surface tangent (central differences), for degeneracy
    tree: cKDTree  # Euclidean k-d tree over ``points``

    @staticmethod
    def build(scan: Scan, L: float) -> "ReferenceIndex":
        pts = scan.points()
        b = scan.bearings[scan.valid]
        n = len(b)
        ext_b = np.concatenate((b - 2 * np.pi, b, b + 2 * np.pi))
        ext_map = np.tile(np.arange(n), 3)
        full = scan.is_full_circle()
        if full:
            nxt, prv = np.roll(pts, -1, axis=0), np.roll(pts, 1, axis=0)
        else:
            nxt = np.vstack((pts[1:], pts[-1:]))
            prv = np.vstack((pts[:1], pts[:-1]))
        t = nxt - prv
        norm = np.hypot(t[:, 0], t[:, 1])
        t = np.where(norm[:, None] > 0, t / np.where(norm > 0, norm, 1.0)[:, None], np.array([1.0, 0.0]))
        sq = np.einsum("ij,ij->i", pts, pts)
        return ReferenceIndex(pts, b, ext_b, ext_map, sq + L * L, float(sq.max()), full, t, cKDTree(pts))

    def neighbour(self, j: np.ndarray, step: int) -> np.ndarray:
        """Index of the scan-order neighbour j+step, or -1 past the ends of a partial scan."""
        n = len(self.points)
        k = j + step
        if self.full_circle:
            return k % n
        return np.where((k >= 0) & (k < n), k, -1)


def _windows(ref: ReferenceIndex, moved: np.ndarray, Bw: float, Br: float, L: float, hint: np.ndarray | None):
    """Per point, the slice [lo, hi) of ``ext_bearings`` that can hold its metric-nearest neighbour.

    The angular window +/-Bw of MbICP, narrowed without changing any pair within the radial
    window Br: the metric-nearest point q* is no farther (metrically) than d0 = min(Br, d(h)) for
    any reference point h inside the window; and since d^2(p, q) >= |p - q|^2 L^2 / (|q|^2 + L^2),
    q* lies within the Euclidean radius rho = d0 sqrt(max|q|^2 + L^2) / L of p, i.e. within
    asin(rho / |p|) of its bearing. ``hint`` proposes h per point (the previous iteration's
    nearest point, -1 for none); without it h is the Euclidean-nearest point (k-d tree).
    """
    alpha = np.arctan2(moved[:, 1], moved[:, 0])
    rng = np.hypot(moved[:, 0], moved[:, 1])
    h = ref.tree.query(moved, k=1)[1] if hint is None else hint
    has = h >= 0
    h = np.where(has, h, 0)
    in_window = has & (np.abs((ref.bearings[h] - alpha + np.pi) % (2 * np.pi) - np.pi) <= Bw)
    d_h = np.sqrt(np.maximum(metric_distance_sq(moved, ref.points[h], L), 0.0))
    d0 = np.where(in_window, np.minimum(d_h, Br), Br)
    rho = d0 * np.sqrt(ref.max_sq_norm + L * L) / L
    # no np.errstate here: it costs more than the arithmetic in this hot loop
    half = np.where(rho < rng, np.arcsin(np.minimum(rho / np.maximum(rng, 1e-300), 1.0)), np.pi)
    half = np.minimum(half, Bw) + 1e-12
    lo = np.searchsorted(ref.ext_bearings, alpha - half, side="left")
    hi = np.searchsorted(ref.ext_bearings, alpha + half, side="right")
    return lo, np.minimum(hi, lo + len(ref.points))  # at most one turn: never a point twice


# Rows are grouped by window width so that a few wide windows do not pad every row.
_WIDTH_BUCKETS = np.array([8, 32, 128, 512])


def nearest(ref: ReferenceIndex, moved: np.ndarray, Bw: float, Br: float, L: float,
            hint: np.ndarray | None = None):
    """Metric-nearest reference point of each moved point within the angular window.

    Exact for every pair whose metric distance is at most Br (see ``_windows``); a point with
    no candidate gets index -1 and distance inf. Returns (index, squared metric distance).
    """
    lo, hi = _windows(ref, moved, Bw, Br, L, hint)
    width = hi - lo
    best = np.full(len(moved), -1, dtype=np.int64)
    best_d2 = np.full(len(moved), np.inf)
    by_width = np.argsort(width, kind="stable")
    cuts = np.searchsorted(width[by_width], _WIDTH_BUCKETS, side="right")
    for a, b in zip((np.searchsorted(width[by_width], 1), *cuts), (*cuts, len(width))):
        if b <= a:
            continue
        rows = by_width[a:b]
        w = int(width[rows[-1]])
        ext = lo[rows, None] + np.arange(w)
        idx = ref.ext_map[np.minimum(ext, len(ref.ext_map) - 1)]
        p = moved[rows]
        px, py = p[:, :1], p[:, 1:]
        qx, qy = ref.points[idx, 0], ref.points[idx, 1]
        cross = px * qy - py * qx
        d2 = (px - qx) ** 2 + (py - qy) ** 2 - cross * cross / ref.sq_norm_L2[idx]
        d2[ext >= hi[rows, None]] = np.inf
        k = np.argmin(d2, axis=1)
        r = np.arange(len(rows))
        best[rows] = idx[r, k]
        best_d2[rows] = np.maximum(d2[r, k], 0.0)
    best[~np.isfinite(best_d2)] = -1
    return best, best_d2


@dataclass(frozen=True, eq=False)
class Pairs:
    """Candidate pairs for a subset of the moved object points (``obj`` indexes those points)."""

    obj: np.ndarray  # (K,)
    target: np.ndarray  # (K, 2)
    kind: np.ndarray  # (K,) PairKind
    ref_index: np.ndarray  # (K, 2)
    dist: np.ndarray  # (K,) metric distance [m]


def _nearest_found(ref, moved, rows, Bw, Br, L, hint):
    """Rows of ``moved`` that found a metric-nearest point, their points, the point, and d^2."""
    p = moved[rows]
    best, d2 = nearest(ref, p, Bw, Br, L, None if hint is None else hint[rows])
    found = best >= 0
    return rows[found], p[found], best[found], d2[found]


def _closer_neighbour(ref, p, j, L):
    """The scan neighbour (j - 1 or j + 1) of each j metrically closer to p, or -1 if none."""
    prev, nxt = ref.neighbour(j, -1), ref.neighbour(j, 1)
    d_prev = np.where(prev >= 0, metric_distance_sq(p, ref.points[prev], L), np.inf)
    d_next = np.where(nxt >= 0, metric_distance_sq(p, ref.points[nxt], L), np.inf)
    return np.where(d_prev <= d_next, prev, nxt)


def _segment_candidate(ref, p, j, other, L, max_len):
    """Metric projection of p onto segment (j, other) where it exists and is short enough."""
    ok = other >= 0
    a = ref.points[j]
    b = ref.points[np.where(ok, other, j)]
    ok &= np.einsum("ij,ij->i", b - a, b - a) <= max_len * max_len
    t = metric_project_on_segment(p, a, b, L)
    c = a + t[:, None] * (b - a)
    d2 = np.where(ok, metric_distance_sq(p, c, L), np.inf)
    return c, d2, t


def mbicp_pairs(ref: ReferenceIndex, moved: np.ndarray, rows: np.ndarray, Bw: float, Br: float, L: float,
                max_dist_inter: float, hint: np.ndarray | None = None) -> Pairs:
    """MbICP correspondences: metric-nearest reference point, or a point interpolated on a segment.

    The original searches every segment in the window; here the two segments adjacent to the
    metric-nearest point are tried, which is where the nearest segment lies except at folds.
    Segments longer than MaxDistInter bridge a gap between surfaces and are not interpolated.
    """
    rows, p, best, d2 = _nearest_found(ref, moved, rows, Bw, Br, L, hint)
    target = ref.points[best].copy()
    kind = np.full(len(rows), PairKind.POINT, dtype=np.int8)
    ref_index = np.column_stack((best, np.full(len(best), -1)))
    for step in (-1, 1):
        other = ref.neighbour(best, step)
        c, ds, t = _segment_candidate(ref, p, best, other, L, max_dist_inter)
        better = (ds < d2) & (t > 0.0) & (t < 1.0)
        target[better] = c[better]
        d2 = np.where(better, ds, d2)
        kind[better] = PairKind.INTERPOLATED
        ref_index[better, 1] = other[better]
    return Pairs(rows, target, kind, ref_index, np.sqrt(d2))


def point_line_pairs(ref: ReferenceIndex, moved: np.ndarray, rows: np.ndarray, Bw: float, Br: float, L: float,
                     max_dist_inter: float, hint: np.ndarray | None = None) -> Pairs:
    """Paper 000 §2.4.1: point-to-point pairs, point-to-line for object points sharing a target.

    Every object point takes its metric-nearest reference point m_j. Among the points sharing one
    m_j, the closest keeps it; each other one is paired with the orthogonal projection of itself
    onto the segment from m_j to its second-nearest reference point m'_j (clamped to the
    segment). As in PL-ICP (Censi 2008), m'_j is sought among the scan neighbours of m_j, where
    it lies but at occlusion edges. Segments longer than MaxDistInter would bridge two surfaces:
    such a point keeps m_j.
    """
    rows, p, best, d2 = _nearest_found(ref, moved, rows, Bw, Br, L, hint)
    second = _closer_neighbour(ref, p, best, L)
    target = ref.points[best].copy()
    kind = np.full(len(rows), PairKind.POINT, dtype=np.int8)
    ref_index = np.column_stack((best, np.full(len(best), -1)))
    order = np.lexsort((d2, best))  # by target, then distance
    loser = np.zeros(len(rows), dtype=bool)
    loser[order[1:]] = best[order[1:]] == best[order[:-1]]
    a = ref.points[best]
    b = ref.points[np.where(second >= 0, second, best)]
    short = (second >= 0) & (np.einsum("ij,ij->i", b - a, b - a) <= max_dist_inter * max_dist_inter)
    inter = loser & short
    if inter.any():
        t = euclidean_project_on_segment(p[inter], a[inter], b[inter])
        target[inter] = a[inter] + t[:, None] * (b[inter] - a[inter])
        kind[inter] = PairKind.INTERPOLATED
        ref_index[inter, 1] = second[inter]
        d2[inter] = np.maximum(metric_distance_sq(p[inter], target[inter], L), 0.0)
    return Pairs(rows, target, kind, ref_index, np.sqrt(d2))


def visible_from_reference(moved: np.ndarray, bin_start: float, bin_width: float, margin: float) -> np.ndarray:
    """Projection filter (Lu & Milios 1997, used by MbICP): which moved points the reference sees.

    A z-buffer over bearing bins of the reference viewpoint: in each bin only points within
    ``margin`` of the nearest one are visible; points behind a closer surface are hidden. Bins
    start at the reference scan's first bearing so that turning the scanner turns the bins.
    """
    alpha = np.arctan2(moved[:, 1], moved[:, 0])
    r = np.hypot(moved[:, 0], moved[:, 1])
    bins = np.floor(((alpha - bin_start) % (2 * np.pi)) / bin_width).astype(np.int64)
    order = np.lexsort((r, bins))
    sb = bins[order]
    starts = np.flatnonzero(np.concatenate(([True], sb[1:] != sb[:-1])))
    nearest = np.repeat(r[order][starts], np.diff(np.append(starts, len(sb))))
    vis = np.empty(len(r), dtype=bool)
    vis[order] = r[order] <= nearest + margin
    return vis
