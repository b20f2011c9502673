"""Correspondence search of the MbICP family: compiled (numba) loops over the object points.

For each object point (already moved into the reference frame) the candidates are the
reference points whose bearing lies within the angular window +/-Bw of the point's bearing
(MbICP §IV); the best is the one of smallest metric distance.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .events import PairKind
from .metric import metric_sq
from .scan import Scan
from .tiers import kernel, run

# Candidates tried first around each point's bearing: the K reference beams on either side. The
# wider this first window, the fewer points need the second, bounded search (``nearest``): 8 took
# a run at 1081 beams from 1.24 to 1.175 ms a pair (3 and 6 against 8, alternated; 12 and 16 no
# faster), with every row of 16,000 real pairs and 3,000 replayed ones as with 3.
_NEAR_K = 8
# Entries of the extended arrays per block of known ranges (``ReferenceIndex.block_min_r``)
_BLOCK = 16


class ReferenceIndex(NamedTuple):
    """The reference scan prepared once per match: points in scan order and a bearing index.

    A named tuple, not a dataclass: the compiled kernels take it whole and read it by field
    (numba types a named tuple of arrays and scalars; a structured record holds scalars only).
    ``ext_bearings`` repeats the bearings shifted by -2pi and +2pi so that a window crossing
    +/-pi (360-degree scanners) is one contiguous slice; ``ext_map`` maps back to point indices.
    """

    points: np.ndarray  # (N, 2)
    bearings: np.ndarray  # (N,) increasing
    ext_bearings: np.ndarray  # (3N,)
    ext_bins: tuple  # ``bearing_bins(ext_bearings)``: where a bearing falls, in O(1)
    ext_map: np.ndarray  # (3N,)
    ext_x: np.ndarray  # (3N,) x, y and |q|^2 + L^2 (the metric's denominator) of ``ext_map``'s
    ext_y: np.ndarray  # points: the search reads them without a second gather
    ext_sq_norm_L2: np.ndarray
    ext_ux: np.ndarray  # (3N,) the unit direction of each bearing
    ext_uy: np.ndarray
    # (3N / _BLOCK rounded up,) the least and greatest range of each block of _BLOCK consecutive
    # entries of the extended arrays: ``nearest`` skips blocks whose ranges a pair cannot have
    block_min_r: np.ndarray
    block_max_r: np.ndarray
    max_factor: float  # sqrt(max|q|^2 + L^2) / L: the Euclidean radius per unit of metric distance
    max_step: float  # the widest bearing gap between consecutive reference points [rad]
    full_circle: bool
    # (N, 2) scan-order previous and next point, -1 past the ends of a partial scan
    neighbours: np.ndarray

    @staticmethod
    def build(scan: Scan, L: float, max_range: float = np.inf) -> ReferenceIndex:
        """The index of ``scan``'s valid points below ``max_range`` (the matcher's range limit)."""
        pts, b = scan.points_and_bearings(max_range)
        full = scan.is_full_circle()
        ext_b, *extended, neighbours = run(
            _extended, pts, b, *scan.directions(max_range), float(L), full
        )
        return ReferenceIndex(pts, b, ext_b, run(bearing_bins, ext_b), *extended, full, neighbours)


@kernel
def _extended(pts, b, cos_b, sin_b, L: float, full: bool):
    """``ReferenceIndex``'s arrays over the three turns (bearings, point index, x, y, |q|^2 + L^2,
    the bearing's unit direction: ``cos_b``, ``sin_b``), the ranges of their blocks,
    sqrt(max |q|^2 + L^2) / L, the widest bearing step (1 and 2 pi without points) and the scan
    neighbours (-1 past the ends of a partial scan)."""
    n = len(b)
    ext_b, ext_map = np.empty(3 * n), np.empty(3 * n, dtype=np.int64)
    ext_x, ext_y, ext_k, ext_ux, ext_uy = (
        np.empty(3 * n),
        np.empty(3 * n),
        np.empty(3 * n),
        np.empty(3 * n),
        np.empty(3 * n),
    )
    n_blocks = (3 * n + _BLOCK - 1) // _BLOCK
    block_min, block_max = np.empty(n_blocks), np.empty(n_blocks)
    block_min[:], block_max[:] = np.inf, -np.inf
    k_max = 0.0
    for i in range(n):
        sq = pts[i, 0] * pts[i, 0] + pts[i, 1] * pts[i, 1]
        k, r = sq + L * L, np.sqrt(sq)
        c, s = cos_b[i], sin_b[i]
        k_max = max(k_max, k)
        for t in range(3):
            e = t * n + i
            ext_b[e] = b[i] + (t - 1) * (2 * np.pi) if t != 1 else b[i]
            ext_map[e], ext_x[e], ext_y[e], ext_k[e], ext_ux[e], ext_uy[e] = (
                i,
                pts[i, 0],
                pts[i, 1],
                k,
                c,
                s,
            )
            block_min[e // _BLOCK] = min(block_min[e // _BLOCK], r)
            block_max[e // _BLOCK] = max(block_max[e // _BLOCK], r)
    extended = (ext_b, ext_map, ext_x, ext_y, ext_k, ext_ux, ext_uy, block_min, block_max)
    nb = np.empty((n, 2), dtype=np.int64)
    for i in range(n):
        for q, j in enumerate((i - 1, i + 1)):
            nb[i, q] = j % n if full else (j if 0 <= j < n else -1)
    if n == 0:
        return (*extended, 1.0, 2 * np.pi, nb)
    max_step = -np.inf
    for i in range(1, 3 * n):
        max_step = max(max_step, ext_b[i] - ext_b[i - 1])
    return (*extended, np.sqrt(k_max) / L, max_step, nb)


# Bins of a bearing lookup per entry of the bearings it looks up (``bearing_bins``): a regular
# scan's entries fill a quarter of them or less, so a lookup reads about one entry past its bin's.
_BINS_PER_ENTRY = 4


@kernel
def bearing_bins(b):
    """An O(1) lookup of the increasing bearings ``b`` for ``first_at_least``: (origin, bins per
    radian, first), ``first[k]`` the first index whose bearing falls in bin k or a later one.

    The bisection it replaces took 12 steps into the 3N extended bearings, up to three times for
    each object point and iteration: the lookup made the compiled loop 7 % faster at 1081 beams."""
    n = len(b)
    bins = _BINS_PER_ENTRY * n + 1
    origin = b[0] if n else 0.0
    span = b[n - 1] - origin if n else 0.0
    scale = bins / span if span > 0.0 else 0.0
    first = np.empty(bins, dtype=np.int64)
    k = 0
    for i in range(n):
        key = _bin(b[i], origin, scale, bins)
        while k <= key:
            first[k] = i
            k += 1
    while k < bins:
        first[k] = n
        k += 1
    return origin, scale, first


@kernel(inline="always")
def _bin(a: float, origin: float, scale: float, bins: int) -> int:
    """The bin of bearing ``a``: non-decreasing in ``a`` (a float subtraction and a product by a
    positive number keep their order), so a bearing at least ``a`` lies in ``a``'s bin or later."""
    x = (a - origin) * scale
    if not x > 0.0:  # below the first bin, or NaN
        return 0
    if x >= bins - 1:
        return bins - 1
    return int(x)


@kernel(inline="always")
def first_at_least(b, bins, a: float, strict: bool) -> int:
    """``np.searchsorted(b, a, "right" if strict else "left")``: the first index whose bearing is
    above (``strict``) or at least ``a``, found from ``a``'s bin of ``bins = bearing_bins(b)``:
    the answer lies at or after the first index of that bin (``_bin``), the walk goes on to it."""
    origin, scale, first = bins
    i = first[_bin(a, origin, scale, len(first))]
    while i < len(b) and (b[i] < a or (strict and b[i] == a)):
        i += 1
    return i


@kernel(inline="always")
def turn_mod(x: float, m: float) -> float:
    """Python's ``x % m`` for ``m > 0``, without numba's call to fmod when ``x`` lies within
    (-m, 2m), as a bearing difference does: there fmod is x or x - m exactly (Sterbenz), and the
    sign's correction adds m as Python's does, so the result is the same float (a zero, which
    Python makes +0, takes the general way). The z-buffer's modulo per point and iteration was
    2 % of a run's time at 1081 beams."""
    if 0.0 < x < m:
        return x
    if -m < x < 0.0:
        return x + m
    if m <= x < 2.0 * m:
        return x - m
    return x % m


@kernel(inline="always")
def _window_min(px: float, py: float, ex, ey, ek, lo: int, hi: int):
    """Metric-nearest of the reference points ext[lo, hi) to (px, py): (ext index, d^2); (-1, inf)
    if empty; the first of equal minima. ``ek`` holds the metric's denominators |q|^2 + L^2."""
    best, d_best = -1, np.inf
    for j in range(lo, hi):
        d = metric_sq(px, py, ex[j], ey[j], ek[j])
        if d < d_best:
            best, d_best = j, d
    return best, d_best


@kernel(inline="always")
def _window_min_in_ranges(px, py, R: ReferenceIndex, lo: int, hi: int, r_lo: float, r_hi: float):
    """``_window_min`` over ext[lo, hi), skipping the blocks whose points all lie outside the
    ranges [r_lo, r_hi] (their points are farther than wanted: see ``nearest``)."""
    best, d_best = -1, np.inf
    j = lo
    while j < hi:
        k = j // _BLOCK
        end = min((k + 1) * _BLOCK, hi)
        if R.block_max_r[k] >= r_lo and R.block_min_r[k] <= r_hi:
            b, d = _window_min(px, py, R.ext_x, R.ext_y, R.ext_sq_norm_L2, j, end)
            if d < d_best:
                best, d_best = b, d
        j = end
    return best, d_best


@kernel(inline="always")
def _reaches(px, py, r, ux, uy, rho):
    """Whether the ray of direction u passes within rho of p (of range r)."""
    if r <= rho:
        return True
    c = px * uy - py * ux
    return px * ux + py * uy > 0.0 and c * c <= rho * rho


@kernel
def nearest(p, alpha, rng, R: ReferenceIndex, Bw: float, Br: float, L: float):
    """Metric-nearest reference point of each moved point within MbICP's angular window +/-Bw.

    Exact for every pair whose metric distance is at most Br. First the 2K beams around the
    point's bearing (inside +/-Bw) give a candidate at distance d*; a closer point must lie within
    d0 = min(d*, Br). The metric distance is the least norm sqrt(|t|^2 + L^2 theta^2) of a
    linearised motion taking q onto p (MbICP eq. 12): p lies within sqrt(d0^2 - L^2 theta^2) of
    q' = q + theta (-q_y, q_x) with |theta| <= d0 / L, and q' is q turned by atan(theta) and
    stretched by sqrt(1 + theta^2). So any q with d(p, q) <= d0

    - lies within atan(d0 / L) + asin(d0 / |p|) of p's bearing;
    - lies on a ray (its bearing's half-line from the origin) that passes within rho of p, the
      smaller of d0 sqrt(1 + (|p| + d0)^2 / L^2) and d0 sqrt(max|q|^2 + L^2) / L, so within
      asin(rho / |p|) of p's bearing. The first: with q = s u (u a unit vector),
      d^2(p, q) = (s - p.u)^2 + (p x u)^2 L^2 / (s^2 + L^2), and s <= |p| + d0 (below); the
      second: d^2(p, q) >= |p - q|^2 L^2 / (|q|^2 + L^2). (The first replaced
      d0 (|p| + L) / (L - d0), always wider: at 1081 beams indoors ``nearest`` took 35 us
      instead of 43 us, the run's rows unchanged);
    - has a range between (|p| - d0) / sqrt(1 + d0^2 / L^2) and |p| + d0.

    Points whose bounded window reaches beyond the 2K beams (a ray just outside them passes within
    rho of the point) are searched again over the narrower of the two windows, block by block,
    skipping the blocks whose ranges all lie outside the third bound: points seen through a gap
    in the reference (d0 = Br) searched their whole window of +/-Bw, most of the search at 1081
    beams. Returns (index, squared metric distance) per point p (of bearing ``alpha`` and range
    ``rng``); a point with no candidate gets index -1 and distance inf.
    """
    eb, ex, ey, ek, bins = R.ext_bearings, R.ext_x, R.ext_y, R.ext_sq_norm_L2, R.ext_bins
    eux, euy, ext_map, n_ref = R.ext_ux, R.ext_uy, R.ext_map, len(R.points)
    max_factor, max_step = R.max_factor, R.max_step
    idx = np.empty(len(alpha), dtype=np.int64)
    out = np.empty(len(alpha))
    clip_to_bw = Bw < _NEAR_K * max_step  # the 2K beams may reach beyond +/-Bw: clip them
    for i in range(len(alpha)):
        a, r, px, py = alpha[i], rng[i], p[i, 0], p[i, 1]
        pos = first_at_least(eb, bins, a, False)
        lo, hi = max(pos - _NEAR_K, 0), min(pos + _NEAR_K, len(eb))
        # clipping to +/-Bw changes the 2K beams only where their first lies below a - Bw or their
        # last above a + Bw (a partial scan's seam makes max_step wide: most points need no clip)
        if clip_to_bw and ((lo < len(eb) and eb[lo] < a - Bw) or (hi > 0 and eb[hi - 1] > a + Bw)):
            lo = max(pos - _NEAR_K, first_at_least(eb, bins, a - Bw, False))
            hi = max(min(pos + _NEAR_K, first_at_least(eb, bins, a + Bw, True)), lo)
            lo, hi = max(lo, 0), min(hi, len(eb))
        best, d2 = _window_min(px, py, ex, ey, ek, lo, hi)
        # the window that can hold anything closer (see above), never wider than +/-Bw: only
        # when a ray just outside the 2K beams passes within rho of the point is it searched
        d0 = np.sqrt(min(max(d2, 0.0), Br * Br))
        rho = d0 * min(np.sqrt(1.0 + ((r + d0) / L) ** 2), max_factor)
        reach = Bw + 1e-12  # the bounded window's own slack: a beam at +/-Bw by round-off is in
        if (
            lo > 0
            and a - eb[lo - 1] <= reach
            and _reaches(px, py, r, eux[lo - 1], euy[lo - 1], rho)
        ) or (hi < len(eb) and eb[hi] - a <= reach and _reaches(px, py, r, eux[hi], euy[hi], rho)):
            half = min(np.arcsin(min(rho / r, 1.0)) if rho < r else np.pi, Bw)
            # the bearing bound only where it can be the narrower: it is at least t - t^3/3 +
            # d0/r (t = d0/L; atan t >= t - t^3/3, asin x >= x), taken a little lower than that
            # so round-off never skips it when it is (a window computed as before; most points
            # are spared an arctan and an arcsin)
            t = d0 / L
            if d0 < r and (t - t * t * t / 3.0 + d0 / r) * (1.0 - 1e-9) < half:
                half = min(half, np.arctan(t) + np.arcsin(d0 / r))
            half += 1e-12
            wlo = first_at_least(eb, bins, a - half, False)
            # each reference point once, however wide the window
            whi = min(first_at_least(eb, bins, a + half, True), wlo + n_ref, len(eb))
            # the ranges a point within d0 can have, widened by round-off
            slack = 1e-9 * (1.0 + r)
            r_lo, r_hi = (r - d0) / np.sqrt(1.0 + (d0 / L) ** 2) - slack, r + d0 + slack
            # [lo, hi) is searched: its two sides only (a tie there keeps the first search's point,
            # as a search of the whole window would)
            for s_lo, s_hi in ((wlo, min(lo, whi)), (max(hi, wlo), whi)):
                b, d = _window_min_in_ranges(px, py, R, s_lo, s_hi, r_lo, r_hi)
                if d < d2:
                    best, d2 = b, d
        if d2 < np.inf:
            idx[i], out[i] = ext_map[best], max(d2, 0.0)
        else:
            idx[i], out[i] = -1, np.inf
    return idx, out


@kernel(inline="always")
def _segment_candidate(px, py, J, ex, ey, ek, ext_map, L2, A, B, C, D, max_inter):
    """The C code's candidate on segment (J - 1, J): (d^2, x, y, j, other). lambda minimises the
    metric of the object point (MbICP §IV-B); the candidate is scored in the reference point's."""
    q1x, q1y, q2x, q2y = ex[J - 1], ey[J - 1], ex[J], ey[J]
    dqx, dqy = q1x - q2x, q1y - q2y
    dqpx, dqpy = q1x - px, q1y - py
    den = B * dqx * dqx + C * dqy * dqy + 2.0 * D * dqx * dqy
    lam = (
        (D * (dqx * dqpy + dqy * dqpx) + B * dqx * dqpx + C * dqy * dqpy) / den
        if den > 0.0
        else 0.0
    )
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
    return metric_sq(px, py, qx, qy, k), qx, qy, j, other


@kernel(inline="always")
def _ray_bound(px, py, ux, uy, mf2):
    """A lower bound of the squared metric distance from p to any reference point on the ray of
    direction u: Euclidean |p| sin(angle) (|p| past 90 degrees), shrunk by the metric's largest
    stretch sqrt(max |q|^2 + L^2) / L (``nearest``'s bound)."""
    if px * ux + py * uy > 0.0:
        c = px * uy - py * ux
        return c * c / mf2
    return (px * px + py * py) / mf2


@kernel
def _window_kernel(p, alpha, R: ReferenceIndex, Bw: float, L: float, max_inter: float):
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

    Every segment of the window is a candidate, as in the C code; this walks them outwards from
    the object point's bearing and stops on each side where a bound shows that no segment beyond
    can be nearer (the segment's points lie between its ends' bearings). Equal distances go to the
    lower segment, the first the C code meets: the answer is the C code's.

    Per object point: the target, d^2, kind and reference indices (j, -1) or (j1, j2); d^2 = inf
    where the window holds no reference point.
    """
    eb, ex, ey, ek, bins = R.ext_bearings, R.ext_x, R.ext_y, R.ext_sq_norm_L2, R.ext_bins
    eux, euy, ext_map, n_ref = R.ext_ux, R.ext_uy, R.ext_map, len(R.points)
    full, max_factor = R.full_circle, R.max_factor
    n = len(alpha)
    target = np.empty((n, 2))
    d2 = np.empty(n)
    kind = np.empty(n, dtype=np.int8)
    ref_index = np.empty((n, 2), dtype=np.int64)
    L2, mf2 = L * L, max_factor * max_factor
    for i in range(n):
        px, py, a = p[i, 0], p[i, 1], alpha[i]
        lo = first_at_least(eb, bins, a - Bw, False)  # the C code's L
        hi = min(first_at_least(eb, bins, a + Bw, False) - 1, lo + n_ref - 1)  # its R: a point once
        d2[i], kind[i], ref_index[i, 0], ref_index[i, 1] = np.inf, PairKind.POINT, -1, -1
        target[i, 0], target[i, 1] = 0.0, 0.0
        if hi < lo:  # no reference point within +/-Bw (the C code pairs it with the origin)
            continue
        if hi == lo:
            target[i, 0], target[i, 1] = ex[lo], ey[lo]
            d2[i], ref_index[i, 0] = metric_sq(px, py, ex[lo], ey[lo], ek[lo]), ext_map[lo]
            continue
        A = 1.0 / (px * px + py * py + L2)
        B, C, D = 1.0 - A * py * py, 1.0 - A * px * px, A * px * py
        # the segment across the point's bearing
        start = min(max(first_at_least(eb, bins, a, False), lo + 1), hi)
        best_J = -1
        for J in range(start, hi + 1):  # up, then down
            if J > start and _ray_bound(px, py, eux[J - 1], euy[J - 1], mf2) > d2[i] * (
                1.0 + 1e-12
            ):
                break
            # a partial scan has no segment from its last point to its first
            if not full and ext_map[J] == 0:
                continue
            d, qx, qy, j, other = _segment_candidate(
                px, py, J, ex, ey, ek, ext_map, L2, A, B, C, D, max_inter
            )
            if d < d2[i] or (d == d2[i] and J < best_J):
                d2[i], target[i, 0], target[i, 1], ref_index[i, 0], ref_index[i, 1], best_J = (
                    d,
                    qx,
                    qy,
                    j,
                    other,
                    J,
                )
        for J in range(start - 1, lo, -1):
            if _ray_bound(px, py, eux[J], euy[J], mf2) > d2[i] * (1.0 + 1e-12):
                break
            if not full and ext_map[J] == 0:
                continue
            d, qx, qy, j, other = _segment_candidate(
                px, py, J, ex, ey, ek, ext_map, L2, A, B, C, D, max_inter
            )
            if d < d2[i] or (d == d2[i] and J < best_J):
                d2[i], target[i, 0], target[i, 1], ref_index[i, 0], ref_index[i, 1], best_J = (
                    d,
                    qx,
                    qy,
                    j,
                    other,
                    J,
                )
        kind[i] = PairKind.INTERPOLATED if ref_index[i, 1] >= 0 else PairKind.POINT
    return target, d2, kind, ref_index


@kernel
def candidates(
    point_line: bool, p, alpha, rng, R: ReferenceIndex, Bw: float, Br: float, L: float, max_inter
):
    """The pairs of the points p (moved into the reference frame, with their bearings and ranges)
    that find a target: (rows of p, target, kind, reference indices (K, 2), squared metric
    distance). ``point_line``: paper 000 §2.4.1 (``_share_targets``), else MbICP's
    (``_window_kernel``)."""
    if point_line:
        best, d2 = nearest(p, alpha, rng, R, Bw, Br, L)
        rows = np.flatnonzero(best >= 0)
        target, kind, second, d2f = _share_targets(p[rows], best[rows], d2[rows], R, L, max_inter)
        ref_index = np.empty((len(rows), 2), dtype=np.int64)
        for k in range(len(rows)):  # element by element: slice assignments are slow to compile
            ref_index[k, 0], ref_index[k, 1] = best[rows[k]], second[k]
        return rows, target, kind, ref_index, d2f
    target, d2, kind, ref_index = _window_kernel(p, alpha, R, Bw, L, max_inter)
    rows = np.flatnonzero(d2 < np.inf)
    return rows, target[rows], kind[rows], ref_index[rows], d2[rows]


@kernel
def _share_targets(p, best, d2, R: ReferenceIndex, L: float, max_len: float):
    """Paper 000 §2.4.1: point-to-point pairs, point-to-line for object points sharing a target.

    Every object point takes its metric-nearest reference point m_j. Among the points sharing one
    m_j, the closest keeps it; each other one is paired with the orthogonal projection of itself
    onto the segment from m_j to its second-nearest reference point m'_j (clamped to the
    segment). As in PL-ICP (Censi 2008), m'_j is sought among the scan neighbours of m_j, where
    it lies but at occlusion edges. Segments longer than MaxDistInter would bridge two surfaces:
    such a point keeps m_j.

    Per pair: target, kind, second reference point (-1: none) and d^2; ``sq_norm_L2[j]`` =
    |q_j|^2 + L^2 for reference point j (``ReferenceIndex.ext_sq_norm_L2``).
    """
    points, sq_norm_L2, neighbours = R.points, R.ext_sq_norm_L2, R.neighbours
    n = len(best)
    # per reference point: the closest object point, first of ties
    winner = np.empty(len(points), dtype=np.int64)
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


@kernel
def visible_in_order(alpha: np.ndarray) -> np.ndarray:
    """The original MbICP's projection filter: walking the object points in scan order, a point
    whose bearing ``alpha`` falls below that of the last point kept is hidden (it went behind a
    surface seen before it). Bearings are unwrapped along the scan (the code's atan2 angles jump
    at +/-pi, which it warns about); a 360-degree scanner still wants the z-buffer
    (``visible_from_reference``)."""
    vis = np.empty(len(alpha), dtype=np.bool_)
    a_prev, unwrapped, highest = 0.0, 0.0, -np.inf
    for i in range(len(alpha)):
        step = alpha[i] - a_prev if i > 0 else 0.0
        unwrapped = unwrapped + (turn_mod(step + np.pi, 2.0 * np.pi) - np.pi) if i > 0 else alpha[i]
        a_prev = alpha[i]
        vis[i] = unwrapped >= highest
        highest = max(highest, unwrapped)
    return vis


@kernel
def visible_from_reference(
    alpha: np.ndarray, r: np.ndarray, bin_start: float, bin_width: float, margin: float
) -> np.ndarray:
    """Projection filter (Lu & Milios 1997, used by MbICP): which moved points the reference sees.

    A z-buffer over bearing bins of the reference viewpoint: in each bin only points within
    ``margin`` of the nearest one are visible; points behind a closer surface are hidden. Bins
    start at the reference scan's first bearing so that turning the scanner turns the bins.
    """
    zbuf = np.full(int(2 * np.pi / bin_width) + 2, np.inf)
    bins = np.empty(len(alpha), dtype=np.int64)
    for i in range(len(alpha)):
        # non-negative: truncation floors
        bins[i] = int(turn_mod(alpha[i] - bin_start, 2 * np.pi) / bin_width)
        zbuf[bins[i]] = min(zbuf[bins[i]], r[i])
    vis = np.empty(len(alpha), dtype=np.bool_)
    for i in range(len(alpha)):
        vis[i] = r[i] <= zbuf[bins[i]] + margin
    return vis
