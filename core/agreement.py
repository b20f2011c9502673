"""How well a pose lays one scan onto another, judged by the points alone (no matcher involved)."""

from __future__ import annotations

import math

import numpy as np

from .correspondence import bearing_bins, first_at_least, turn_mod
from .scan import Scan
from .se2 import Pose2
from .tiers import kernel, run

INLIER_RADIUS_M = 0.05

# A reference segment between neighbouring beams is taken as surface when it is at most this many
# beam spacings long (r * beam step: a surface seen at up to ~70° incidence), plus the radius.
SURFACE_GAP_BEAMS = 3.0


def inlier_fraction(ref: Scan, obj: Scan, pose: Pose2, radius: float = INLIER_RADIUS_M) -> float:
    """Fraction of the object's valid points within ``radius`` [m] of a reference point once moved
    by ``pose`` (object frame -> reference frame). Lets a user compare two candidate poses — a
    matcher's and a stored "truth" — on the data itself."""
    return agreement(ref, obj, pose, radius)[0]


def agreement(
    ref: Scan, obj: Scan, pose: Pose2, radius: float = INLIER_RADIUS_M
) -> tuple[float, float]:
    """(``inlier_fraction``, ``surface_overlap``) from one search (``_agreeing``)."""
    q = obj.points()
    if not len(q):
        return 0.0, 0.0
    p, b = ref.points_and_bearings()
    # the ranges of those points: a valid reading that is no number below inf makes no point
    r = ref.ranges[ref.valid & (ref.ranges < np.inf)]
    on_point, on_surface = run(
        _agreeing,
        p,
        r,
        b,
        *ref.directions(),
        q,
        (pose.x, pose.y, math.cos(pose.theta), math.sin(pose.theta)),
        float(radius),
        SURFACE_GAP_BEAMS,
    )
    n = len(q)
    return on_point / n, on_surface / n


def surface_overlap(ref: Scan, obj: Scan, pose: Pose2, radius: float = INLIER_RADIUS_M) -> float:
    """Share of the object's valid points within ``radius`` [m] of the reference *surface* once
    moved by ``pose``: the polyline through neighbouring valid reference points, a segment kept
    where it is short enough to be one surface (not a jump between depths). Unlike
    ``inlier_fraction`` it does not fall with the beams' spacing: a sparse long-range scan laid
    well on its reference (30 cm between points at 20 m and 1°) scores as high as a dense one."""
    return agreement(ref, obj, pose, radius)[1]


@kernel(inline="always")
def _within(qx, qy, p, k, radius):
    """Whether (qx, qy) lies within ``radius`` of point k of ``p`` (the root taken only near the
    radius: beyond, the squared distance shows it is not)."""
    d = (qx - p[k, 0]) ** 2 + (qy - p[k, 1]) ** 2
    return d <= radius * radius * (1.0 + 1e-9) and math.sqrt(d) <= radius, d


@kernel
def _agreeing(p, r, b, ux, uy, q, pose, radius: float, gap_beams: float):
    """How many points of ``q`` moved by ``pose`` (x, y and the cosine and sine of theta) lie within
    ``radius`` of a point of ``p`` (the reference's valid points in scan order, of ranges ``r``,
    increasing bearings ``b`` and their directions ``ux``, ``uy``), and how many within
    ``radius`` of the reference surface: the nearest point's two segments where they are surface
    (``SURFACE_GAP_BEAMS``), else the point itself.

    A point within ``radius`` of any reference point is within it of its nearest and of the
    surface: it is counted at once, its nearest never sought (most points of a good match). The
    object's points come in scan order, so the reference point the point before was found near,
    and the next one, are tried first, before the point's bearing is computed. At 1081 beams a
    pair's agreement took 135 us when every nearest was sought, 99 us with the early count, and
    the first try took it from 137 us to 106-109 us on a slower day. The points are moved here, as
    they are counted: numpy's product and sum took 20-28 us more a pair, and the directions are
    the scan's own (``Scan.directions``, kept with its points).

    Else its nearest is sought within ``reach``: a segment of length l whose ends are both farther
    than d from q passes no nearer than sqrt(d^2 - l^2 / 4), so with reach^2 = radius^2 + l_max^2
    / 4 a point farther is within ``radius`` of neither. The search walks the reference's bearings
    outwards from q's, both ways round, and stops each way where the bearings left cannot hold a
    nearer point: a point at bearing difference D from q lies at least |q| sin D from it (|q| past
    90 degrees). A k-d tree's build and query took a third of a run's time per pair at 1081 beams;
    a sine and a modulo at each step of the walk, 0.44 ms a pair against 0.25 ms. Equal distances
    go to the lower index."""
    n, m = len(p), max(len(p) - 1, 0)
    on_point, on_surface = 0, 0
    if n == 0:
        return on_point, on_surface
    surface = np.zeros(m, dtype=np.bool_)
    longest = 0.0
    for i in range(m):
        dx, dy = p[i + 1, 0] - p[i, 0], p[i + 1, 1] - p[i, 1]
        length = math.sqrt(dx * dx + dy * dy)  # metres: no overflow for hypot to guard against
        if length <= gap_beams * max(r[i], r[i + 1]) * (b[i + 1] - b[i]) + radius:
            surface[i] = True
            longest = max(longest, length)
    reach2 = radius * radius + 0.25 * longest * longest
    turn = 2.0 * math.pi
    x, y, c_th, s_th = pose
    bins = bearing_bins(b)
    last = -1  # the reference point the last point found within radius
    for i in range(len(q)):
        qx, qy = x + c_th * q[i, 0] - s_th * q[i, 1], y + s_th * q[i, 0] + c_th * q[i, 1]
        # the object's points come in scan order: most points of a good match lie within radius
        # of the reference point the point before them was found within radius of, or the next
        hit = -1
        for k in (last, last + 1):
            if 0 <= k < n and _within(qx, qy, p, k, radius)[0]:
                hit = k
                break
        if hit >= 0:
            last = hit
            on_point += 1
            on_surface += 1
            continue
        norm = math.sqrt(qx * qx + qy * qy)
        if not math.isfinite(norm):
            continue
        # q's bearing as one of the reference's turn [b[0], b[0] + 2 pi), and where it falls
        a = b[0] + turn_mod(math.atan2(qy, qx) - b[0], turn)
        s = first_at_least(b, bins, a, False)
        best, j, near = reach2, -1, False
        for way in (1, -1):
            for step in range(n):
                # the next point this way round and its bearing difference, 0 to 2 pi (a turn
                # added past the scan's end: s is where a falls, so at most one)
                kk = s + step if way == 1 else s - 1 - step
                if kk >= n:
                    kk -= n
                    d_b = b[kk] + turn - a
                elif kk < 0:
                    kk += n
                    d_b = a - b[kk] + turn
                else:
                    d_b = b[kk] - a if way == 1 else a - b[kk]
                if d_b > math.pi:
                    break
                if d_b < 0.5 * math.pi:
                    c = qx * uy[kk] - qy * ux[kk]
                    low2 = c * c
                else:
                    low2 = norm * norm
                if low2 > best:
                    break
                near, d = _within(qx, qy, p, kk, radius)
                if near:
                    last = kk
                    break
                if d < best or (d == best and (j < 0 or kk < j)):
                    best, j = d, kk
            if near:
                break
        if near:
            on_point += 1
            on_surface += 1
            continue
        if j < 0:
            continue
        for s in (j - 1, j):  # the nearest point's two segments hold the surface's nearest point
            if 0 <= s < m and surface[s]:
                ax, ay = p[s, 0], p[s, 1]
                abx, aby = p[s + 1, 0] - ax, p[s + 1, 1] - ay
                t = ((qx - ax) * abx + (qy - ay) * aby) / max(abx * abx + aby * aby, 1e-12)
                t = min(max(t, 0.0), 1.0)
                if math.hypot(qx - ax - t * abx, qy - ay - t * aby) <= radius:
                    on_surface += 1
                    break
    return on_point, on_surface
