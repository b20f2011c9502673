"""Correspondence search of the MbICP family, vectorised over object points.

For each object point (already moved into the reference frame) the candidates are the
reference points whose bearing lies within the angular window +/-Bw of the point's bearing
(MbICP §IV); the best is the one of smallest metric distance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
                              float(np.sqrt(k.max()) / L), float(np.diff(ext_b).max()), full, nb)


# Candidates tried first around each point's bearing: the K reference beams on either side.
_NEAR_K = 3
# Windows are searched in one pass padded to the widest while that pads to at most this many
# candidates (a numpy call costs about as much as a few thousand); otherwise (a large Br, a poor
# guess) rows are grouped by width so that a few wide windows do not pad every row.
_ONE_PASS_CANDIDATES = 4096
_WIDTH_BUCKETS = np.array([64, 512])


def _width_groups(width: np.ndarray):
    """Row groups of similar window width (one group, no sorting, in the common case)."""
    if width.max(initial=0) * len(width) <= _ONE_PASS_CANDIDATES:
        yield slice(None)  # empty windows too: _best_in gives them inf
        return
    by_width = np.argsort(width, kind="stable")
    cuts = np.searchsorted(width[by_width], _WIDTH_BUCKETS, side="right")
    for a, b in zip((np.searchsorted(width[by_width], 1), *cuts), (*cuts, len(width))):
        if b > a:
            yield by_width[a:b]


def _best_in(ref: ReferenceIndex, p: np.ndarray, lo: np.ndarray, hi: np.ndarray, w: int):
    """Metric-nearest of the reference points ext[lo, hi) for each row of ``p`` (w >= hi - lo).

    Returns (ext index, squared metric distance), inf where the slice is empty.
    """
    ext = lo[:, None] + np.arange(w)
    # past the end of its slice a row repeats the slice's last point, which leaves its minimum as it is
    np.minimum(ext, np.minimum(hi, len(ref.ext_map))[:, None] - 1, out=ext)
    px, py = p[:, :1], p[:, 1:]
    qx, qy = ref.ext_x[ext], ref.ext_y[ext]
    # d^2 = |p - q|^2 - (p x q)^2 / (|q|^2 + L^2) (see metric_distance_sq), in place: the hot loop
    cross = px * qy
    cross -= py * qx
    cross *= cross
    cross /= ref.ext_sq_norm_L2[ext]
    qx -= px
    qy -= py
    qx *= qx
    qy *= qy
    d2 = qx
    d2 += qy
    d2 -= cross
    k = np.argmin(d2, axis=1)
    r = np.arange(len(p))
    return ext[r, k], np.where(hi > lo, d2[r, k], np.inf)


def polar(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bearing [rad] and range [m] of each point (computed once per iteration, used twice)."""
    return np.arctan2(points[:, 1], points[:, 0]), np.hypot(points[:, 0], points[:, 1])


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
    eb = ref.ext_bearings
    pos = np.searchsorted(eb, alpha)
    lo, hi = pos - _NEAR_K, pos + _NEAR_K
    if Bw < _NEAR_K * ref.max_step:  # the 2K beams may reach beyond +/-Bw: clip them
        lo = np.maximum(lo, np.searchsorted(eb, alpha - Bw, side="left"))
        hi = np.maximum(np.minimum(hi, np.searchsorted(eb, alpha + Bw, side="right")), lo)
    best, d2 = _best_in(ref, moved, lo, hi, 2 * _NEAR_K)
    # the window that can hold anything closer (see above), never wider than +/-Bw
    d0 = np.sqrt(np.clip(d2, 0.0, Br * Br))
    rho = d0 * np.minimum((rng + L) / np.maximum(L - d0, 1e-12), ref.max_factor)
    # no np.errstate here: it costs more than the arithmetic in this hot loop
    half = np.minimum(np.where(rho < rng, np.arcsin(np.minimum(rho / rng, 1.0)), np.pi), Bw) + 1e-12
    wlo = np.searchsorted(eb, alpha - half, side="left")
    whi = np.minimum(np.searchsorted(eb, alpha + half, side="right"), wlo + len(ref.points))  # a point once
    again = np.flatnonzero((wlo < lo) | (whi > hi))
    if len(again):
        width = whi[again] - wlo[again]
        for g in _width_groups(width):
            rows = again[g]
            b, d = _best_in(ref, moved[rows], wlo[rows], whi[rows], int(width[g].max()))
            better = d < d2[rows]
            best[rows[better]], d2[rows[better]] = b[better], d[better]
    found = d2 < np.inf
    return np.where(found, ref.ext_map[best], -1), np.where(found, np.maximum(d2, 0.0), np.inf)


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


def _closer_neighbour(ref, p, j, L):
    """The scan neighbour (j - 1 or j + 1) of each j metrically closer to p, or -1 if none."""
    both = ref.neighbours[j]  # (K, 2): previous, next
    d = np.where(both >= 0, metric_distance_sq(p[:, None, :], ref.points[both], L), np.inf)
    return np.where(d[:, 0] <= d[:, 1], both[:, 0], both[:, 1])


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


def mbicp_pairs(ref: ReferenceIndex, moved: np.ndarray, moved_polar, rows: np.ndarray, Bw: float, Br: float,
                L: float, max_dist_inter: float) -> Pairs:
    """MbICP correspondences: metric-nearest reference point, or a point interpolated on a segment.

    The original searches every segment in the window; here the two segments adjacent to the
    metric-nearest point are tried, which is where the nearest segment lies except at folds.
    Segments longer than MaxDistInter bridge a gap between surfaces and are not interpolated.
    """
    rows, p, best, d2 = _nearest_found(ref, moved, moved_polar, rows, Bw, Br, L)
    target = ref.points[best].copy()
    kind = np.full(len(rows), PairKind.POINT, dtype=np.int8)
    ref_index = np.column_stack((best, np.full(len(best), -1)))
    for other in ref.neighbours[best].T:
        c, ds, t = _segment_candidate(ref, p, best, other, L, max_dist_inter)
        better = (ds < d2) & (t > 0.0) & (t < 1.0)
        target[better] = c[better]
        d2 = np.where(better, ds, d2)
        kind[better] = PairKind.INTERPOLATED
        ref_index[better, 1] = other[better]
    return Pairs(rows, target, kind, ref_index, np.sqrt(d2))


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
    target = ref.points[best]
    kind = np.zeros(len(rows), dtype=np.int8)  # PairKind.POINT
    ref_index = np.full((len(best), 2), -1)
    ref_index[:, 0] = best
    order = np.lexsort((d2, best))  # by target, then distance: the first of each run keeps m_j
    losers = order[1:][best[order[1:]] == best[order[:-1]]]
    if len(losers):
        pl, a = p[losers], target[losers]
        second = _closer_neighbour(ref, pl, best[losers], L)
        b = ref.points[second]
        e = b - a
        ok = (second >= 0) & (e[:, 0] ** 2 + e[:, 1] ** 2 <= max_dist_inter * max_dist_inter)
        inter, pl, a, b = losers[ok], pl[ok], a[ok], b[ok]
        c = a + euclidean_project_on_segment(pl, a, b)[:, None] * (b - a)
        target[inter] = c
        kind[inter] = PairKind.INTERPOLATED
        ref_index[inter, 1] = second[ok]
        d2[inter] = np.maximum(metric_distance_sq(pl, c, L), 0.0)
    return Pairs(rows, target, kind, ref_index, np.sqrt(d2))


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
