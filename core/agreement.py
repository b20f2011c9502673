"""How well a pose lays one scan onto another, judged by the points alone (no matcher involved)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .scan import Scan
from .se2 import Pose2

INLIER_RADIUS_M = 0.05


def _nearest(ref: Scan, obj: Scan, pose: Pose2):
    """The reference points, the object points moved by ``pose``, and each moved point's distance
    to its nearest reference point and that point's index (one k-d tree, one query)."""
    q = pose.apply(obj.points())
    p = ref.points()
    if not len(q) or not len(p):
        return p, q, np.full(len(q), np.inf), np.zeros(len(q), dtype=int)
    best, nearest = cKDTree(p).query(q)
    return p, q, best, nearest


def inlier_fraction(ref: Scan, obj: Scan, pose: Pose2, radius: float = INLIER_RADIUS_M) -> float:
    """Fraction of the object's valid points within ``radius`` [m] of a reference point once moved
    by ``pose`` (object frame -> reference frame). Lets a user compare two candidate poses — a
    matcher's and a stored "truth" — on the data itself."""
    _, q, best, _ = _nearest(ref, obj, pose)
    return float(np.mean(best <= radius)) if len(q) else 0.0


# A reference segment between neighbouring beams is taken as surface when it is at most this many
# beam spacings long (r * beam step: a surface seen at up to ~70° incidence), plus the radius.
SURFACE_GAP_BEAMS = 3.0


def agreement(
    ref: Scan, obj: Scan, pose: Pose2, radius: float = INLIER_RADIUS_M
) -> tuple[float, float]:
    """(``inlier_fraction``, ``surface_overlap``) from one nearest-point query."""
    p, q, best, nearest = _nearest(ref, obj, pose)
    if not len(q):
        return 0.0, 0.0
    on_points = float(np.mean(best <= radius))
    return on_points, float(np.mean(_to_surface(ref, p, q, best, nearest, radius) <= radius))


def surface_overlap(ref: Scan, obj: Scan, pose: Pose2, radius: float = INLIER_RADIUS_M) -> float:
    """Share of the object's valid points within ``radius`` [m] of the reference *surface* once
    moved by ``pose``: the polyline through neighbouring valid reference points, a segment kept
    where it is short enough to be one surface (not a jump between depths). Unlike
    ``inlier_fraction`` it does not fall with the beams' spacing: a sparse long-range scan laid
    well on its reference (30 cm between points at 20 m and 1°) scores as high as a dense one."""
    return agreement(ref, obj, pose, radius)[1]


def _to_surface(ref: Scan, p, q, best, nearest, radius: float) -> np.ndarray:
    """Each moved object point's distance to the reference surface (``surface_overlap``), from its
    distance ``best`` to the ``nearest`` reference point."""
    if not len(p):
        return best
    idx = ref.valid_indices()
    r, b = ref.ranges[idx], ref.bearings[idx]
    a, ab = p[:-1], np.diff(p, axis=0)
    length = np.hypot(ab[:, 0], ab[:, 1])
    surface = length <= SURFACE_GAP_BEAMS * np.maximum(r[:-1], r[1:]) * np.diff(b) + radius
    # the nearest point's two segments hold the surface's nearest point
    for s in (nearest - 1, nearest):
        use = (s >= 0) & (s < len(a))
        s = np.clip(s, 0, max(len(a) - 1, 0))
        if not len(a):
            break
        t = np.einsum("ij,ij->i", q - a[s], ab[s]) / np.maximum(length[s] ** 2, 1e-12)
        foot = a[s] + np.clip(t, 0.0, 1.0)[:, None] * ab[s]
        d = np.hypot(*(q - foot).T)
        best = np.where(use & surface[s], np.minimum(best, d), best)
    return best
