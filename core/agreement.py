"""How well a pose lays one scan onto another, judged by the points alone (no matcher involved)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .scan import Scan
from .se2 import Pose2

INLIER_RADIUS_M = 0.05


def inlier_fraction(ref: Scan, obj: Scan, pose: Pose2, radius: float = INLIER_RADIUS_M) -> float:
    """Fraction of the object's valid points within ``radius`` [m] of a reference point once moved
    by ``pose`` (object frame -> reference frame). Lets a user compare two candidate poses — a
    matcher's and a stored "truth" — on the data itself."""
    d, _ = cKDTree(ref.points()).query(pose.apply(obj.points()), distance_upper_bound=radius)
    return float(np.mean(d <= radius))
