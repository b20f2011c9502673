"""``compare``: every chosen matcher on one pair, one table."""

from __future__ import annotations

import math
import time

from core import Params, Pose2, Scan, match, pose_error
from core.agreement import inlier_fraction

# on_ref_%: object points within INLIER_RADIUS_M of a reference point at the result — a verdict
# from the data alone, for the pairs whose truth nobody knows.
HEADER = (f"{'matcher':<10} {'x_m':>9} {'y_m':>9} {'theta_deg':>10} {'err_mm':>9} {'err_deg':>8} "
          f"{'on_ref_%':>8} {'iters':>5} {'reason':<15} {'time_ms':>8}")


def compare_table(ref: Scan, obj: Scan, guess: Pose2, params: dict[str, Params], truth: Pose2 | None) -> str:
    lines = [HEADER]
    for name, p in params.items():
        t0 = time.perf_counter()
        r = match(ref, obj, guess, p)
        ms = 1000.0 * (time.perf_counter() - t0)
        et, er = pose_error(r.pose, truth) if truth is not None else (math.nan, math.nan)
        lines.append(f"{name:<10} {r.pose.x:>+9.4f} {r.pose.y:>+9.4f} {math.degrees(r.pose.theta):>+10.3f} "
                     f"{et * 1000:>9.1f} {math.degrees(er):>8.3f} {100 * inlier_fraction(ref, obj, r.pose):>8.1f} "
                     f"{r.iterations:>5} {r.reason.value:<15} {ms:>8.1f}")
    return "\n".join(lines)
