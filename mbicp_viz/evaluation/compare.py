"""``compare``: every chosen matcher on one pair, one table."""

from __future__ import annotations

import math

from mbicp_viz.choices import MATCH_BUDGET_S
from mbicp_viz.core import Params
from mbicp_viz.readers.pair_match import PairMatch

from .pairs import ScanPair
from .single import Setup, match_pair

# on_ref_%: object points within INLIER_RADIUS_M of a reference point at the result — a verdict
# from the data alone, for the pairs whose truth nobody knows.
HEADER = (
    f"{'matcher':<10} {'x_m':>9} {'y_m':>9} {'theta_deg':>10} {'err_mm':>9} {'err_deg':>8} "
    f"{'on_ref_%':>8} {'iters':>5} {'reason':<15} {'time_ms':>8}"
)


def compare_matches(
    pair: ScanPair, s: Setup, params: dict[str, Params], budget_s: float | None = MATCH_BUDGET_S
) -> list[PairMatch]:
    """Each matcher on ``pair`` from ``s.guess``, in the laser frame, with its iterations (each
    within ``budget_s``)."""
    i, j = pair.ref.source.index, pair.obj.source.index
    return [
        match_pair(
            pair.ref,
            pair.obj,
            p,
            s,
            pair.log.frames,
            False,
            indices=(i, j),
            record=True,
            budget_s=budget_s,
        )
        for p in params.values()
    ]


def compare_table(matches: list[PairMatch]) -> str:
    """One line per matcher (laser frame); the error columns say ``-`` when the answer is
    unknown."""
    lines = [HEADER]
    for m in matches:
        r, sc = m.result, m.score
        err = (
            f"{sc.error_xy * 1000:>9.1f} {math.degrees(sc.error_theta):>8.3f}"
            if sc is not None
            else f"{'-':>9} {'-':>8}"
        )
        lines.append(
            f"{m.matcher:<10} {r.pose.x:>+9.4f} {r.pose.y:>+9.4f} "
            f"{math.degrees(r.pose.theta):>+10.3f} {err} "
            f"{100 * m.on_ref:>8.1f} {r.iterations:>5} {r.reason.value:<15} {m.time_ms:>8.1f}"
        )
    return "\n".join(lines)
