"""Events -> drawable layers: the one scene mapping both front ends (rerun, viser) draw.

A layer is plain data (points, segments, boxes, scalars, text, a pose) under a path; the front
ends only translate layers into their own calls. Colours follow paper 000's figures: reference
red, object blue, correspondences black; interpolated and rejected pairs get their own colours.
Everything is in the reference frame, metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import numpy as np

from core import FinishEvent, IterationEvent, PairKind, PairStatus, Pose2, StartEvent

RGB = tuple[int, int, int]
REFERENCE: RGB = (220, 40, 40)
OBJECT: RGB = (40, 90, 220)
OBJECT_AFTER: RGB = (150, 180, 245)
PAIR_POINT: RGB = (20, 20, 20)
PAIR_INTERPOLATED: RGB = (0, 160, 90)
PAIR_REJECTED: RGB = (245, 160, 0)
HIDDEN: RGB = (170, 170, 170)
TRUTH: RGB = (120, 200, 120)  # the object scan at the known answer, when there is one
ERROR: RGB = (90, 90, 90)
THRESHOLD: RGB = (245, 160, 0)


@dataclass(frozen=True, eq=False)
class Points:
    path: str
    xy: np.ndarray  # (N, 2)
    color: RGB | np.ndarray  # one colour, or (N, 3)
    radius: float


@dataclass(frozen=True, eq=False)
class Segments:
    path: str
    starts: np.ndarray  # (N, 2)
    ends: np.ndarray  # (N, 2)
    color: RGB
    width: float


@dataclass(frozen=True, eq=False)
class Boxes:
    path: str
    centers: np.ndarray  # (N, 2)
    half_size: float
    colors: np.ndarray  # (N, 3)
    labels: list[str]


@dataclass(frozen=True)
class Scalar:
    path: str
    value: float
    color: RGB


@dataclass(frozen=True)
class Text:
    path: str
    text: str
    level: str = "INFO"


@dataclass(frozen=True)
class Frame:
    """The estimate: the pose of the object frame in the reference frame."""

    path: str
    pose: Pose2


Layer = Union["Points", "Segments", "Boxes", "Scalar", "Text", "Frame", "Strips"]

# Paths, relative to a run's root; the front ends and the blueprint rely on them.
SCANS = "scene"
PLOTS = "plots"
LOG = "log"


def ratio_colors(ratio: np.ndarray) -> np.ndarray:
    """RGBA cell colour by sampling ratio: faint grey for thinned near cells, blue for kept far ones."""
    r = np.clip(ratio, 0.0, 1.0)[:, None]
    rgb = (1 - r) * np.array([200, 200, 200]) + r * np.array(OBJECT)
    alpha = 40 + 100 * r
    return np.round(np.hstack((rgb, alpha))).astype(np.uint8)


def start_layers(ev: StartEvent) -> list[Layer]:
    """Static layers: the reference scan, the object scan at the initial guess, the resampling grid."""
    layers: list[Layer] = [
        Points(f"{SCANS}/reference", ev.ref_points, REFERENCE, 0.02),
        Points(f"{SCANS}/object_initial", ev.initial_guess.apply(ev.obj_points), HIDDEN, 0.01),
    ]
    rs = ev.resampling
    if rs is not None:
        # the grid lives in the object sensor frame: draw it where the initial guess puts it
        centers = rs.origin + (rs.cells[:, ::-1] + 0.5) * rs.cell_size
        layers.append(Boxes(f"{SCANS}/resampling_grid", ev.initial_guess.apply(centers), rs.cell_size / 2,
                            ratio_colors(rs.ratio),
                            [f"eta={e:.2f} kept {k}/{n}" for e, k, n in zip(rs.ratio, rs.kept_count, rs.count)]))
    return layers


def iteration_layers(start: StartEvent, ev: IterationEvent) -> list[Layer]:
    """Layers of one iteration: where the object was, its pairs by kind and status, where it went."""
    p = ev.pairs
    src = p.source
    kept = p.status == PairStatus.KEPT
    point = kept & (p.kind == PairKind.POINT)
    inter = kept & (p.kind == PairKind.INTERPOLATED)
    layers: list[Layer] = [
        Points(f"{SCANS}/object", ev.moved_points, OBJECT, 0.02),
        Points(f"{SCANS}/object_after", ev.estimate_after.apply(start.obj_points[start.used]), OBJECT_AFTER, 0.012),
        Points(f"{SCANS}/hidden", ev.estimate_before.apply(start.obj_points[ev.hidden]), HIDDEN, 0.015),
        Segments(f"{SCANS}/pairs/point", src[point], p.target[point], PAIR_POINT, 0.004),
        Segments(f"{SCANS}/pairs/interpolated", src[inter], p.target[inter], PAIR_INTERPOLATED, 0.004),
        Segments(f"{SCANS}/pairs/rejected", src[~kept], p.target[~kept], PAIR_REJECTED, 0.003),
        Points(f"{SCANS}/interpolated_targets", p.target[inter], PAIR_INTERPOLATED, 0.012),
        Frame(f"{SCANS}/estimate", ev.estimate_after),
        Scalar(f"{PLOTS}/error", ev.error, ERROR),
        Text(f"{LOG}", iteration_text(ev)),
    ]
    if ev.threshold is not None:
        layers.append(Scalar(f"{PLOTS}/threshold", ev.threshold, THRESHOLD))
    return layers + polar_layers(ev)


def iteration_text(ev: IterationEvent) -> str:
    p = ev.pairs
    n_kept = p.count(status=PairStatus.KEPT)
    by = {s.name.lower(): p.count(status=s) for s in PairStatus if s != PairStatus.KEPT}
    rej = ", ".join(f"{v} {k}" for k, v in by.items() if v) or "none"
    thr = f"{ev.threshold:.3f} m" if ev.threshold is not None else "-"
    return (f"iteration {ev.iteration}: {len(p.kind)} pairs ({p.count(kind=PairKind.INTERPOLATED)} interpolated), "
            f"{n_kept} kept, rejected: {rej}; threshold {thr}; error {ev.error:.3e} m^2; "
            f"step ({ev.increment.x:+.4f} m, {ev.increment.y:+.4f} m, {math.degrees(ev.increment.theta):+.3f} deg)")


def finish_layers(ev: FinishEvent) -> list[Layer]:
    r = ev.result
    level = "INFO" if r.converged else "WARN"
    text = (f"{r.algorithm}: {'converged' if r.converged else 'NOT converged (' + r.reason.value + ')'} after "
            f"{r.iterations} iterations; pose {r.pose}; error {r.error:.3e} m^2; "
            f"pairs kept {r.pairs_kept}, rejected {r.pairs_rejected}")
    if r.degeneracy is not None:
        text += (f"; condition number {r.degeneracy.condition_number:.1f}, weakest direction heading "
                 f"{r.degeneracy.weakest_heading_deg:+.0f} deg")
    return [Text(LOG, text, level), Frame(f"{SCANS}/estimate", r.pose)]


# Teaching layers (switchable): paper 000 Fig. 3 and Fig. 9b.
ISO_METRIC: RGB = (40, 90, 220)
ISO_EUCLID: RGB = (220, 40, 40)
HIST_BAR: RGB = (120, 120, 120)
MEDIAN: RGB = (20, 20, 20)
TEACH = "teaching"


def metric_isocurve(p: np.ndarray, target: np.ndarray, L: float, n: int = 72) -> np.ndarray:
    """The iso-distance curve of MbICP's metric through ``target`` around ``p`` (paper 000 Fig. 3).

    d^2 = (delta . u)^2 + (delta . v)^2 L^2 / (|c|^2 + L^2) with u along the ray through c, v
    across it (c = target, as in the distance the matcher scores): an ellipse with semi-axes d
    along the ray and d sqrt(|c|^2 + L^2) / L across it.
    """
    c = np.asarray(target, float)
    r2 = float(c @ c)
    u = c / np.sqrt(r2) if r2 > 0 else np.array([1.0, 0.0])
    v = np.array([-u[1], u[0]])
    delta = np.asarray(p, float) - c
    d = np.sqrt((delta @ u) ** 2 + (delta @ v) ** 2 * L * L / (r2 + L * L))
    t = np.linspace(0, 2 * np.pi, n)
    return c + np.outer(d * np.cos(t), u) + np.outer(d * np.sqrt(r2 + L * L) / L * np.sin(t), v)


def circle(center: np.ndarray, radius: float, n: int = 72) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n)
    return np.asarray(center) + radius * np.column_stack((np.cos(t), np.sin(t)))


@dataclass(frozen=True, eq=False)
class Strips:
    """Closed or open polylines (iso-curves, histogram bars)."""

    path: str
    strips: list[np.ndarray]
    color: RGB
    width: float


def teaching_layers(start: StartEvent, ev: IterationEvent, n_points: int = 6, bins: int = 30,
                    chosen: int | None = None) -> list[Layer]:
    """Iso-distance curves for a few object points and the histogram of pair distances.

    For every chosen point the metric ellipse and the Euclidean circle pass through its target,
    so a user sees why that target won; the histogram shows the distances with the median and
    the rejection threshold (for improved MbICP: median + k MAD, Fig. 9b). ``chosen`` (an index
    into ``start.obj_points``) shows that one point's curves instead of ``n_points`` spread ones.
    """
    layers: list[Layer] = []
    p = ev.pairs
    L = getattr(start.params, "L", None)
    if L is not None and len(p.kind):
        mine = np.flatnonzero(p.obj_index == chosen) if chosen is not None else np.empty(0, np.int64)
        pick = mine[:1] if len(mine) else np.unique(np.linspace(0, len(p.kind) - 1, n_points).round().astype(int))
        src, tgt = p.source[pick], p.target[pick]
        layers.append(Strips(f"{SCANS}/{TEACH}/metric_isocurves",
                             [metric_isocurve(s, t, L) for s, t in zip(src, tgt)], ISO_METRIC, 0.004))
        layers.append(Strips(f"{SCANS}/{TEACH}/euclidean_circles",
                             [circle(t, float(np.linalg.norm(s - t))) for s, t in zip(src, tgt)], ISO_EUCLID, 0.004))
    if len(p.distance):
        layers += histogram_layers(p.distance, ev.threshold, bins)
    return layers


def histogram_layers(distance: np.ndarray, threshold: float | None, bins: int) -> list[Layer]:
    """Distances as bars in a unit-height 2-D plot (x: metres), with median and threshold lines."""
    hi = max(float(distance.max()), threshold or 0.0) * 1.05 or 1.0
    counts, edges = np.histogram(distance, bins=bins, range=(0.0, hi))
    h = counts / max(counts.max(), 1) * hi * 0.6  # bar heights scaled to the axis for a square view
    bars = [np.array([[a, 0.0], [a, y], [b, y], [b, 0.0]]) for a, b, y in zip(edges[:-1], edges[1:], h) if y > 0]
    med = float(np.median(distance))
    top = hi * 0.65
    out: list[Layer] = [Strips(f"{TEACH}/histogram/bars", bars, HIST_BAR, hi * 0.004),
                        Strips(f"{TEACH}/histogram/median", [np.array([[med, 0.0], [med, top]])], MEDIAN, hi * 0.004)]
    if threshold is not None:
        out.append(Strips(f"{TEACH}/histogram/threshold", [np.array([[threshold, 0.0], [threshold, top]])],
                          THRESHOLD, hi * 0.004))
    return out


# Sequence view: one step per scan of a log (``eval sequence --rrd``).
SEQUENCE = "sequence"
TRAJECTORY: RGB = (40, 90, 220)
LOG_TRAJECTORY: RGB = (120, 200, 120)


def sequence_layers(k: int, pose: Pose2, points: np.ndarray, trajectory: np.ndarray,
                    log_trajectory: np.ndarray | None, row: dict | None) -> list[Layer]:
    """Scan ``k`` placed at the pose accumulated from the matches (world = first scan's frame)."""
    layers: list[Layer] = [
        Points(f"{SEQUENCE}/map/scan_{k:05d}", pose.apply(points), REFERENCE, 0.02),
        Points(f"{SEQUENCE}/current", pose.apply(points), OBJECT, 0.03),
        Strips(f"{SEQUENCE}/trajectory", [trajectory], TRAJECTORY, 0.02),
        Frame(f"{SEQUENCE}/robot", pose),
    ]
    if log_trajectory is not None:
        layers.append(Strips(f"{SEQUENCE}/log_trajectory", [log_trajectory], LOG_TRAJECTORY, 0.015))
    if row is not None:
        layers += [Scalar(f"{PLOTS}/iterations", float(row["iterations"]), ERROR),
                   Scalar(f"{PLOTS}/time_ms", float(row["time_ms"]), THRESHOLD),
                   Text(LOG, f"pair {row['ref']} -> {row['obj']}: ({row['x']:+.3f} m, {row['y']:+.3f} m, "
                             f"{math.degrees(row['theta']):+.2f} deg), {row['iterations']} iterations, "
                             f"{row['reason']}", "INFO" if row["converged"] else "WARN")]
    return layers


# Polar matchers (PSM, PMWN): how they think, in plot spaces of their own (x in degrees).
POLAR = "polar"
RANGE_REF: RGB = (220, 40, 40)
RANGE_PROJ: RGB = (40, 90, 220)
FIT: RGB = (0, 160, 90)


def fitted_curve(polar, shift_deg: float, n: int = 21) -> np.ndarray | None:
    """The V (PMWN) or parabola (PSM) through the three cost samples around the minimum."""
    if polar.fit_abc is None or polar.best_shift is None:
        return None
    a, b, c = polar.fit_abc
    k0 = round(polar.best_shift) if abs(polar.best_shift - round(polar.best_shift)) <= 0.5 else polar.best_shift
    x = np.linspace(-1.0, 1.0, n)
    if polar.fit == "V":
        m = max(a, c) - b
        x0 = (a - c) / (2 * m) if m > 0 else 0.0
        y = m * np.abs(x - x0) + (b - m * abs(x0))
    else:
        y = 0.5 * (a - 2 * b + c) * x * x + 0.5 * (c - a) * x + b
    return np.column_stack(((k0 + x) * shift_deg, y))


# Plot scales, so that both axes of a 2-D plot space span similar numbers.
COST_SCALE = 100.0  # cost plot: x shift [deg], y cost [cm]
RANGE_SCALE = 10.0  # range plot: x bearing [deg], y range [dm]


def polar_layers(ev: IterationEvent) -> list[Layer]:
    """Cost per shift with the chosen minimum and its fit; ranges vs bearing; PMWN's projected circle."""
    P = ev.polar
    if P is None:
        return []
    step_deg = math.degrees(float(np.median(np.diff(P.bearings))))
    layers: list[Layer] = []
    ok = np.isfinite(P.cost)
    if ok.any():
        layers.append(Strips(f"{POLAR}/cost/curve",
                             [np.column_stack((P.shifts[ok] * step_deg, P.cost[ok] * COST_SCALE))], HIST_BAR, 0.1))
        fit = fitted_curve(P, step_deg)
        if fit is not None:
            fit = fit * [1.0, COST_SCALE]
            layers.append(Strips(f"{POLAR}/cost/fit", [fit], FIT, 0.12))
            layers.append(Points(f"{POLAR}/cost/minimum", np.array([[P.best_shift * step_deg, fit[:, 1].min()]]),
                                 THRESHOLD, 0.4))
    deg = np.degrees(P.bearings)
    for name, r, color in (("reference", P.ref_ranges, RANGE_REF), ("projected", P.projected_ranges, RANGE_PROJ)):
        pts = np.column_stack((deg, r * RANGE_SCALE))
        layers.append(Points(f"{POLAR}/ranges/{name}", pts[np.isfinite(r)], color, 0.3))
    if P.metric_weight is not None:
        layers.append(Scalar(f"{PLOTS}/metric_weight", P.metric_weight, FIT))
    if P.circle_points is not None:
        layers.append(Points(f"{SCANS}/{POLAR}/circle_points", P.circle_points, FIT, 0.01))
        layers.append(Points(f"{SCANS}/{POLAR}/circle_centre", P.circle_centre[None, :], THRESHOLD, 0.03))
    return layers
