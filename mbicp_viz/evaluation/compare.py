"""``compare``: every chosen matcher on one pair, one table."""

from __future__ import annotations

import math

from mbicp_viz.core import Params, Pose2, Scan, pose_error

from .single import run

# on_ref_%: object points within INLIER_RADIUS_M of a reference point at the result — a verdict
# from the data alone, for the pairs whose truth nobody knows.
HEADER = (
    f"{'matcher':<10} {'x_m':>9} {'y_m':>9} {'theta_deg':>10} {'err_mm':>9} {'err_deg':>8} "
    f"{'on_ref_%':>8} {'iters':>5} {'reason':<15} {'time_ms':>8}"
)


def compare_table(
    ref: Scan, obj: Scan, guess: Pose2, params: dict[str, Params], truth: Pose2 | None
) -> str:
    """One line per matcher; the error columns say ``-`` when the answer is unknown."""
    lines = [HEADER]
    for name, p in params.items():
        o = run(ref, obj, guess, p)
        r = o.result
        if truth is not None:
            et, er = pose_error(r.pose, truth)
            err = f"{et * 1000:>9.1f} {math.degrees(er):>8.3f}"
        else:
            err = f"{'-':>9} {'-':>8}"
        lines.append(
            f"{name:<10} {r.pose.x:>+9.4f} {r.pose.y:>+9.4f} {math.degrees(r.pose.theta):>+10.3f} "
            f"{err} "
            f"{100 * o.on_ref:>8.1f} {r.iterations:>5} {r.reason.value:<15} {o.time_ms:>8.1f}"
        )
    return "\n".join(lines)
