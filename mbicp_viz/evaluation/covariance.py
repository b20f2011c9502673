"""``eval covariance``: is the covariance a matcher reports consistent with its real errors?

For each consecutive pair of a corrected log the match's error against the stored pose,
e = (x, y, theta) of the estimate minus the truth's, is weighed by the covariance the matcher
reports, NEES = e^T Sigma^-1 e (normalised estimation error squared; Bar-Shalom et al. 2001,
§5.4). A consistent covariance gives NEES ~ chi^2(3): the mean over N pairs lies within the
two-sided 95 % bounds chi^2_3N(0.025, 0.975) / N. A mean above them means the matcher is more
confident than its errors allow; the factor mean / 3 scales its covariance to consistency. The
test is split along the result's weakest direction (in x, y, L theta; 1 degree of freedom, where
a corridor leaves the motion free) and across it (2 degrees of freedom). Only the pairs the
matcher got right (within 0.1 m and 3 deg) are weighed: a wrong basin is no covariance's to explain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mbicp_viz.core import Params, match
from mbicp_viz.readers import ScanLog

from .criteria import CONSECUTIVE
from .pool import ordered_map
from .tune import Case

CHI2_3_MEDIAN = 2.365973884375338  # the median of chi^2(3)


@dataclass(frozen=True)
class Nees:
    """One pair's normalised errors: all three, along the weakest direction, across it."""

    total: float
    along: float
    across: float


def nees(error: np.ndarray, cov: np.ndarray, weakest: np.ndarray, L: float) -> Nees:
    """``error`` (x, y, theta) and ``cov`` (3x3) in (x, y, theta); ``weakest`` a unit vector in
    (x, y, L theta)."""
    D = np.diag([1.0, 1.0, L])
    e, S = D @ error, D @ cov @ D
    total = float(e @ np.linalg.solve(S, e))
    v = weakest / np.linalg.norm(weakest)
    along = float((v @ e) ** 2 / (v @ S @ v))
    U = np.linalg.svd(np.eye(3) - np.outer(v, v))[0][:, :2]  # an orthonormal basis across v
    eu, Su = U.T @ e, U.T @ S @ U
    return Nees(total, along, float(eu @ np.linalg.solve(Su, eu)))


def chi2_mean_bounds(dof: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Where the mean of n chi^2(dof) samples lies with probability ``level`` (two-sided)."""
    from scipy.stats import chi2

    a = (1.0 - level) / 2.0
    return float(chi2.ppf(a, dof * n) / n), float(chi2.ppf(1.0 - a, dof * n) / n)


def _pair(job) -> tuple[bool, Nees | None]:
    """Whether the match is right, and its NEES when it is and reports a covariance."""
    ref, obj, guess, truth, params = job
    r = match(ref, obj, guess, params)
    e = np.array(
        [
            r.pose.x - truth.x,
            r.pose.y - truth.y,
            (r.pose.theta - truth.theta + math.pi) % (2 * math.pi) - math.pi,
        ]
    )
    right = CONSECUTIVE.judge(r.pose, truth)
    if not right or r.covariance is None or r.degeneracy is None:
        return right, None
    return right, nees(
        e, np.asarray(r.covariance), np.asarray(r.degeneracy.weakest_direction), r.degeneracy.length
    )


@dataclass(frozen=True)
class Consistency:
    pairs: int
    right: int
    weighed: list[Nees]  # the right pairs whose matcher reported a covariance

    def mean(self, part: str) -> float:
        return float(np.mean([getattr(n, part) for n in self.weighed]))


def covariance_consistency(
    log: ScanLog, cases: list[Case], params: Params, workers: int | None = None, on_row=None
) -> Consistency:
    jobs = [(log.scans[c.i], log.scans[c.j], c.guess, c.truth, params) for c in cases]
    out = ordered_map(_pair, jobs, workers, on_row)
    return Consistency(len(out), sum(r for r, _ in out), [n for _, n in out if n is not None])


def consistency_lines(name: str, c: Consistency) -> list[str]:
    """The report of one matcher: means against their bounds, and the scale factor."""
    if not c.weighed:
        return [f"{name}: no covariance reported ({c.right}/{c.pairs} pairs right)"]
    n = len(c.weighed)
    lines = [f"{name}: {c.right}/{c.pairs} pairs right, {n} weighed"]
    for part, dof, label in (
        ("total", 3, "NEES"),
        ("along", 1, "along the weakest direction"),
        ("across", 2, "across it"),
    ):
        lo, hi = chi2_mean_bounds(dof, n)
        m = c.mean(part)
        verdict = (
            "consistent" if lo <= m <= hi else ("overconfident" if m > hi else "underconfident")
        )
        lines.append(
            f"  {label:<28} mean {m:9.2f}   chi2({dof}) 95 % bounds for the mean [{lo:.2f}, "
            f"{hi:.2f}]: "
            f"{verdict}"
        )
    med = float(np.median([w.total for w in c.weighed]))
    lines.append(
        f"  scale the covariance by {c.mean('total') / 3.0:.3g} to make the mean NEES 3 (by "
        f"{med / CHI2_3_MEDIAN:.3g} for the median: a few large errors weigh on the mean)"
    )
    return lines


def nees_png(results: dict[str, Consistency], path: str) -> None:
    """Each matcher's NEES distribution against chi^2(3)."""
    from scipy.stats import chi2

    from mbicp_viz.pyplot import pyplot, save_png

    plt = pyplot()

    shown = {k: c for k, c in results.items() if c.weighed}
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=100)
    edges = np.linspace(-2, 5, 71)  # in log10(NEES): densities per decade, true on a log axis
    for name, c in shown.items():
        h, _ = np.histogram(np.log10([n.total for n in c.weighed]), bins=edges, density=True)
        ax.stairs(h, 10**edges, lw=1.5, label=f"{name} (mean {c.mean('total'):.3g})")
    x = np.logspace(-2, 5, 400)
    ax.plot(
        x, chi2.pdf(x, 3) * x * np.log(10), "k--", lw=1.2, label="chi²(3): a consistent covariance"
    )
    ax.set_xscale("log")
    ax.set_xlabel("NEES = eᵀ Σ⁻¹ e (pose error weighed by the reported covariance)")
    ax.set_ylabel("density per decade")
    ax.set_title("covariance consistency on the pairs each matcher got right")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, path)
