"""Plain-text summaries of a match for the terminal."""

from __future__ import annotations

import math

from core import IterationEvent, MatchResult, PairKind, PairStatus


def result_lines(r: MatchResult) -> list[str]:
    lines = [
        f"algorithm   {r.algorithm}",
        f"pose        {r.pose}   (object frame in the reference frame)",
        f"status      {'converged' if r.converged else 'NOT converged: ' + r.reason.value} after {r.iterations} iterations",
        f"error       {r.error:.3e} m^2 mean squared residual; pairs kept {r.pairs_kept}, rejected {r.pairs_rejected}",
    ]
    if r.covariance is not None:
        sx, sy, st = (math.sqrt(max(r.covariance[i, i], 0.0)) for i in range(3))
        lines.append(f"1-sigma     x {sx * 1000:.2f} mm, y {sy * 1000:.2f} mm, theta {math.degrees(st):.3f} deg")
    if r.degeneracy is not None:
        d = r.degeneracy
        lines.append(f"degeneracy  condition number {d.condition_number:.1f}; weakest direction "
                     f"(x, y, L*theta) = ({d.weakest_direction[0]:+.2f}, {d.weakest_direction[1]:+.2f}, "
                     f"{d.weakest_direction[2]:+.2f}), heading {d.weakest_heading_deg:+.0f} deg")
    return lines


ITERATION_HEADER = (f"{'it':>3} {'pairs':>5} {'interp':>6} {'kept':>5} {'rejected':>8} {'threshold_m':>11} "
                    f"{'error_m2':>10} {'dx_m':>9} {'dy_m':>9} {'dtheta_deg':>10}")


def iteration_line(e: IterationEvent) -> str:
    p = e.pairs
    thr = f"{e.threshold:.4f}" if e.threshold is not None else "-"
    n = len(p.kind)
    kept = p.count(status=PairStatus.KEPT)
    return (f"{e.iteration:>3} {n:>5} {p.count(kind=PairKind.INTERPOLATED):>6} {kept:>5} {n - kept:>8} {thr:>11} "
            f"{e.error:>10.3e} {e.increment.x:>+9.4f} {e.increment.y:>+9.4f} {math.degrees(e.increment.theta):>+10.4f}")
