"""Experiment protocols on real scans with a known answer."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbicp_viz.core import Params, Pose2, Scan, match, pose_error

from .criteria import CONSECUTIVE, MBICP_PROTOCOL


@dataclass(frozen=True)
class DisplacedCase:
    scan: int
    displacement: Pose2  # the initial guess; the truth is the identity
    error_m: float
    error_rad: float
    iterations: int
    converged: bool


def displaced_self_matches(
    scans: list[Scan],
    n_cases: int,
    params: Params,
    seed: int = 0,
    max_xy_m: float = 0.2,
    max_theta_rad: float = np.pi / 4,
) -> list[DisplacedCase]:
    """MbICP's own protocol (T-RO 2006 §V; CSM's ``mbicp_tro_experiment``): a scan matched against
    itself from a random initial guess uniform in (+/-max_xy, +/-max_xy, +/-max_theta), seeded."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_cases):
        k = int(rng.integers(len(scans)))
        d = Pose2(
            *rng.uniform(
                [-max_xy_m, -max_xy_m, -max_theta_rad], [max_xy_m, max_xy_m, max_theta_rad]
            )
        )
        r = match(scans[k], scans[k], d, params)
        et, er = pose_error(r.pose, Pose2())
        out.append(DisplacedCase(k, d, et, er, r.iterations, r.converged))
    return out


def protocol_summary(name: str, cases: list[DisplacedCase]) -> str:
    """One line: how many cases met MbICP's criteria, how many were off grossly, the median
    iterations."""
    ok = sum(MBICP_PROTOCOL.correct(c.error_m, c.error_rad) for c in cases)
    gross = sum(not CONSECUTIVE.correct(c.error_m, c.error_rad) for c in cases)
    its = sorted(c.iterations for c in cases)
    n = len(cases)
    return (
        f"{name}: {ok}/{n} within {MBICP_PROTOCOL.text()} ({100.0 * ok / n:.1f} %); {gross} off by "
        "more than "
        f"{CONSECUTIVE.text().replace(' and ', ' or ')}; median {its[len(its) // 2]} iterations"
    )
