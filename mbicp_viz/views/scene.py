"""Events -> drawable layers: the one scene mapping both front ends (rerun, the viser debugger)
draw.

A layer is plain data (points, segments, strips, boxes, a pose, a scalar, a text) under a path,
and every drawable layer carries its ``Style``: the legend entry, colour, draw order and whether
it is shown by default. The front ends only translate layers into their own calls, and refuse a
layer they cannot translate. Colours follow paper 000's figures where it has them (reference red,
object blue, correspondences black); every other kind of layer has a colour of its own, so that
the legend is unambiguous. Everything is in the reference frame (``T_ref_obj`` maps object
points there), metres; plots use the units their axes name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from mbicp_viz.core import MATCHERS, IterationEvent, PairKind, PairStatus, Pose2, Scan, StartEvent
from mbicp_viz.core.matchers import RGB
from mbicp_viz.readers.pair_match import PairMatch, Verdict


@dataclass(frozen=True)
class Style:
    """A legend entry: what a kind of layer shows, its colour, where it sits in the draw order
    (higher on top) and whether it is shown before the user asks."""

    label: str
    color: RGB
    order: float = 0.0
    on: bool = True


# Every drawable scene layer has one of these; the legend lists them.
REFERENCE = Style("reference scan", (220, 40, 40), 2.0)
# larger, under the object: seen where it differs
TRUTH = Style("object scan at the known answer", (0, 190, 190), 1.0)
INITIAL = Style("object scan at the initial guess", (165, 165, 165), 0.5)
ODOMETRY = Style("object scan at the odometry", (150, 210, 40), 0.8)
OBJECT = Style("object scan where the pairs were made", (40, 90, 220), 3.0)
OBJECT_AFTER = Style("object scan after the step", (150, 180, 245), 2.5)
HIDDEN = Style("object points hidden by the projection filter", (140, 90, 40), 3.5, on=False)
PAIR_POINT = Style("pairs to a reference point", (20, 20, 20), 4.0)
PAIR_INTERPOLATED = Style("pairs to an interpolated point", (0, 160, 90), 4.0)
# orange, not amber: amber reads yellow in thin lines
PAIR_REJECTED = Style("rejected pairs", (235, 85, 0), 3.8)
GRID = Style("resampling grid (pale: thinned, blue: kept)", (110, 140, 225), -1.0)
ISO_METRIC = Style("MbICP iso-distance ellipse", (130, 60, 200), 4.5, on=False)
ISO_EUCLID = Style("Euclidean circle through the same target", (150, 130, 0), 4.5, on=False)
CIRCLE = Style("PMWN projected circle and its centre", (210, 0, 130), 4.2)
HELD = Style("held direction: left to the guess, the surfaces barely fix it", (120, 0, 60), 4.6)
ESTIMATE = Style("estimate: object frame (x red, y green)", (40, 90, 220), 5.0)
BEAMS = Style(
    "reference beams: bearing and range of every few readings", (200, 200, 200), 0.2, on=False
)
INVALID = Style(
    "reference bearings with no valid reading (short rays)", (190, 150, 230), 0.3, on=False
)
SENSOR = Style("reference sensor frame (x red: bearing 0, y green)", (60, 60, 60), 5.0, on=False)
RAW = Style("scans as measured, before the motion correction (--deskew)", (240, 110, 190), 1.5)
SEAM = Style("360° seam: the first and the last beam of the reference", (0, 0, 0), 4.8)
STYLES = (
    REFERENCE,
    TRUTH,
    INITIAL,
    ODOMETRY,
    OBJECT,
    OBJECT_AFTER,
    HIDDEN,
    PAIR_POINT,
    PAIR_INTERPOLATED,
    PAIR_REJECTED,
    GRID,
    ISO_METRIC,
    ISO_EUCLID,
    CIRCLE,
    HELD,
    ESTIMATE,
    BEAMS,
    INVALID,
    SENSOR,
    RAW,
    SEAM,
)

# Plot series: the legend of the plots.
ERROR = Style("mean squared residual [m²]", (90, 90, 90))
THRESHOLD = Style("rejection threshold [m]", PAIR_REJECTED.color)
HARD_CUT = Style("hard cut [m]", (200, 60, 60))
METRIC_WEIGHT = Style("PMWN metric weight λ [m/rad]", (210, 0, 130))


def threshold_style(params) -> Style:
    """What a matcher's per-iteration threshold (``IterationEvent.threshold``) is, in its plots."""
    return replace(THRESHOLD, label=params.threshold_label())


def hard_cut(params) -> tuple[Style, float] | None:
    """The distance beyond which a matcher never pairs (MbICP's radial window Br, ICP's maximum
    correspondence distance), with its legend entry; None for the polar matchers."""
    cut = params.hard_cut()
    return None if cut is None else (replace(HARD_CUT, label=cut[0]), cut[1])


def run_style(name: str) -> Style:
    """The object scan of one matcher in compare mode."""
    return Style(f"{name}: object scan", MATCHERS[name].colour, OBJECT.order)


@dataclass(frozen=True, eq=False)
class Points:
    path: str
    xy: np.ndarray  # (N, 2)
    style: Style
    radius: float  # [m]
    colors: np.ndarray | None = None  # (N, 3 or 4) per point, instead of the style's colour
    labels: list[str] | None = None


@dataclass(frozen=True, eq=False)
class Segments:
    path: str
    starts: np.ndarray  # (N, 2)
    ends: np.ndarray  # (N, 2)
    style: Style
    width: float  # [m]


@dataclass(frozen=True, eq=False)
class Strips:
    """Closed or open polylines (iso-curves, histogram bars, trajectories)."""

    path: str
    strips: list[np.ndarray]
    style: Style
    width: float  # [m]


@dataclass(frozen=True, eq=False)
class Boxes:
    path: str
    centers: np.ndarray  # (N, 2)
    half_size: float  # [m]
    style: Style
    colors: np.ndarray  # (N, 4) RGBA per box
    labels: list[str]


# a drawn frame: x axis red, y axis green, as viser draws it
AXIS_X, AXIS_Y = (
    (220, 30, 30),
    (30, 160, 30),
)


@dataclass(frozen=True)
class Frame:
    """A pose drawn as axes: the object frame in the reference frame."""

    path: str
    pose: Pose2
    style: Style = ESTIMATE
    length: float = 0.4  # [m]


@dataclass(frozen=True)
class Scalar:
    path: str
    value: float
    style: Style


@dataclass(frozen=True)
class Text:
    path: str
    text: str
    level: str = "INFO"


Layer = Points | Segments | Strips | Boxes | Frame | Scalar | Text
# layers of the 2-D scene (the rest are plots and logs)
DRAWN = (
    Points,
    Segments,
    Strips,
    Boxes,
    Frame,
)

# Paths, relative to a run's root; the front ends and the blueprints rely on them.
SCANS = "scene"
PLOTS = "plots"
LOG = "log"
TEACH = "teaching"
POLAR = "polar"
SEQUENCE = "sequence"
HEALTH = "health"  # a run's per-pair health plots
RUN = "run"  # the debugger's run view, in the world frame (the first scan's)


def scene_scale(points: np.ndarray) -> float:
    """How much to enlarge dots and lines so that they stay visible on a large scene: 1 for a
    scene up to 5 m across, its extent / 5 m above (a view fitted to the scene shows dots of about
    the same size on the screen)."""
    if len(points) < 2:
        return 1.0
    return max(1.0, float(np.ptp(points, axis=0).max()) / 5.0)


def ratio_colors(ratio: np.ndarray) -> np.ndarray:
    """RGBA cell colour by sampling ratio: pale grey for thinned near cells (fainter the more they
    are thinned), solid blue for the cells kept whole: two kinds a student tells apart at a
    glance."""
    r = np.clip(ratio, 0.0, 1.0)
    kept = r >= 1.0
    rgb = np.where(kept[:, None], np.array(GRID.color), np.array([165, 165, 165]))
    alpha = np.where(kept, 170.0, 35.0 + 60.0 * r)
    return np.round(np.hstack((rgb, alpha[:, None]))).astype(np.uint8)


def static_layers(
    start: StartEvent, truth: Pose2 | None = None, odometry: Pose2 | None = None
) -> list[Layer]:
    """What every iteration shows: the reference scan, the object scan at the initial guess, the
    resampling grid (improved MbICP), and the object scan at the known answer and at the log's
    odometry when there are some (the odometry unless it is the guess itself)."""
    s = scene_scale(start.ref_points)
    layers: list[Layer] = [
        Points(f"{SCANS}/reference", start.ref_points, REFERENCE, 0.02 * s),
        Points(
            f"{SCANS}/object_initial",
            start.initial_guess.apply(start.obj_points),
            INITIAL,
            0.01 * s,
        ),
    ]
    if truth is not None:
        layers.append(Points(f"{SCANS}/truth", truth.apply(start.obj_points), TRUTH, 0.03 * s))
    if odometry is not None and odometry != start.initial_guess:
        layers.append(
            Points(f"{SCANS}/odometry", odometry.apply(start.obj_points), ODOMETRY, 0.02 * s)
        )
    rs = start.resampling
    if rs is not None:
        # the grid lives in the object sensor frame: draw it where the initial guess puts it
        centers = rs.origin + (rs.cells[:, ::-1] + 0.5) * rs.cell_size
        layers.append(
            Boxes(
                f"{SCANS}/resampling_grid",
                start.initial_guess.apply(centers),
                rs.cell_size / 2,
                GRID,
                ratio_colors(rs.ratio),
                [f"eta={e:.2f} kept {k}/{n}" for e, k, n in zip(rs.ratio, rs.kept_count, rs.count)],
            )
        )
    return layers


def beam_layers(scan: Scan, most: int = 90) -> list[Layer]:
    """The reference scan as the sensor measured it (its own frame, which is the reference frame):
    a ray from the sensor to every few valid readings (at most ``most`` of them), a short ray along
    each bearing that returned nothing usable, and the sensor frame (x along bearing 0)."""
    s = scene_scale(scan.points())
    pts = scan.points()
    every = max(1, -(-len(pts) // most))
    bad = scan.bearings[~scan.valid]
    ends = 1.0 * s * np.column_stack((np.cos(bad), np.sin(bad)))
    return [
        Segments(
            f"{SCANS}/beams/valid", np.zeros((len(pts[::every]), 2)), pts[::every], BEAMS, 0.003 * s
        ),
        Segments(f"{SCANS}/beams/invalid", np.zeros((len(bad), 2)), ends, INVALID, 0.004 * s),
        Frame(f"{SCANS}/sensor", Pose2(), SENSOR, length=0.5 * s),
    ]


def deskew_layers(ref: Scan, obj: Scan, pose: Pose2) -> list[Layer]:
    """Scans corrected for motion (``Scan.raw``): both as measured (the object at ``pose``), and
    for a 360° reference the seam between its first and last beams, which the motion opens."""
    s = scene_scale(ref.points())
    layers: list[Layer] = []
    if ref.raw is not None or obj.raw is not None:
        measured = [
            ref.raw.points() if ref.raw is not None else np.zeros((0, 2)),
            pose.apply(obj.raw.points()) if obj.raw is not None else np.zeros((0, 2)),
        ]
        layers.append(Points(f"{SCANS}/as_measured", np.vstack(measured), RAW, 0.012 * s))
    if ref.is_full_circle() and ref.n_valid >= 2:
        first_last = ref.points()[[0, -1]]
        layers.append(Segments(f"{SCANS}/seam", np.zeros((2, 2)), first_last, SEAM, 0.006 * s))
    return layers


def initial_layers(start: StartEvent) -> list[Layer]:
    """Iteration 0: the object scan at the initial guess, before any pairing."""
    s = scene_scale(start.ref_points)
    return [
        Points(
            f"{SCANS}/object",
            start.initial_guess.apply(start.obj_points[start.used]),
            OBJECT,
            0.02 * s,
        ),
        Frame(f"{SCANS}/estimate", start.initial_guess, length=0.4 * s),
        Text(LOG, f"{start.algorithm}: initial guess {start.initial_guess}"),
    ]


def iteration_layers(start: StartEvent, ev: IterationEvent) -> list[Layer]:
    """Layers of one iteration: where the object was, its pairs by kind and status, where it
    went."""
    from .text import iteration_text

    s = scene_scale(start.ref_points)
    p = ev.pairs
    src = p.source
    kept = p.status == PairStatus.KEPT
    point = kept & (p.kind == PairKind.POINT)
    inter = kept & (p.kind == PairKind.INTERPOLATED)
    layers: list[Layer] = [
        Points(f"{SCANS}/object", ev.moved_points, OBJECT, 0.02 * s),
        Points(
            f"{SCANS}/object_after",
            ev.estimate_after.apply(start.obj_points[start.used]),
            OBJECT_AFTER,
            0.012 * s,
        ),
        Points(
            f"{SCANS}/hidden",
            ev.estimate_before.apply(start.obj_points[ev.hidden]),
            HIDDEN,
            0.015 * s,
        ),
        Segments(f"{SCANS}/pairs/point", src[point], p.target[point], PAIR_POINT, 0.004 * s),
        Segments(
            f"{SCANS}/pairs/interpolated", src[inter], p.target[inter], PAIR_INTERPOLATED, 0.004 * s
        ),
        Segments(f"{SCANS}/pairs/rejected", src[~kept], p.target[~kept], PAIR_REJECTED, 0.004 * s),
        Points(f"{SCANS}/interpolated_targets", p.target[inter], PAIR_INTERPOLATED, 0.012 * s),
        Frame(f"{SCANS}/estimate", ev.estimate_after, length=0.4 * s),
        Scalar(f"{PLOTS}/error", ev.error, ERROR),
        Text(LOG, iteration_text(ev)),
    ]
    if ev.threshold is not None:
        layers.append(Scalar(f"{PLOTS}/threshold", ev.threshold, threshold_style(start.params)))
    if ev.held is not None:
        layers.append(held_layer(ev, s))
    return layers + polar_layers(ev, s)


def held_layer(ev: IterationEvent, s: float) -> Segments:
    """The axis an iteration's step left alone (improved MbICP's ``hold_weak``), through the object
    frame's origin where the step took it, along the translational part of the direction."""
    d = np.array(ev.held.direction[:2])
    u = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9 else np.array([1.0, 0.0])
    o = np.array([ev.estimate_after.x, ev.estimate_after.y])
    return Segments(
        f"{SCANS}/held", (o - 1.5 * s * u)[None], (o + 1.5 * s * u)[None], HELD, 0.012 * s
    )


def finish_layers(result) -> list[Layer]:
    from .text import result_sentence

    return [
        Text(LOG, result_sentence(result), "INFO" if result.converged else "WARN"),
        Frame(f"{SCANS}/estimate", result.pose),
    ]


def layers_at(
    start: StartEvent,
    iterations: list[IterationEvent],
    k: int,
    truth: Pose2 | None = None,
    teaching: bool = False,
    chosen: int | None = None,
    odometry: Pose2 | None = None,
) -> list[Layer]:
    """Every layer of a recorded run at iteration ``k`` (0: the initial guess; past the last: the
    last)."""
    layers = static_layers(start, truth, odometry)
    if k == 0 or not iterations:
        return layers + initial_layers(start)
    ev = iterations[min(k, len(iterations)) - 1]
    layers += iteration_layers(start, ev)
    return layers + teaching_layers(start, ev, chosen=chosen) if teaching else layers


def pair_layers(
    ref: Scan,
    obj: Scan,
    name: str,
    start: StartEvent,
    iterations: list[IterationEvent],
    k: int,
    truth: Pose2 | None,
    odometry: Pose2 | None,
    several: bool = False,
    chosen: int | None = None,
) -> list[Layer]:
    """Everything the views draw of one matcher's run (``name``) on the scans ``ref`` and ``obj`` at
    iteration ``k``: the reference as measured (beams, invalid bearings, sensor frame), the scans
    before a motion correction, the run's layers with the teaching ones; among ``several``
    matchers its object scan takes the matcher's colour (compare mode)."""
    ev = iterations[min(k, len(iterations)) - 1] if k > 0 and iterations else None
    layers = (
        beam_layers(ref)
        + deskew_layers(ref, obj, ev.estimate_before if ev is not None else start.initial_guess)
        + layers_at(start, iterations, k, truth, teaching=True, chosen=chosen, odometry=odometry)
    )
    return compared(layers, name) if several else layers


def has_content(layer: Layer) -> bool:
    """Whether a drawable layer draws anything (an empty one gets no legend entry)."""
    for name in ("xy", "starts", "strips", "centers"):
        if hasattr(layer, name):
            return len(getattr(layer, name)) > 0
    return True


def compared(layers: list[Layer], name: str) -> list[Layer]:
    """A run's layers among several matchers' (compare mode): its object scan in the matcher's
    colour."""
    return [
        replace(ly, style=run_style(name)) if ly.path == f"{SCANS}/object" else ly for ly in layers
    ]


# Teaching layers (switchable): paper 000 Fig. 3 and Fig. 9b.


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


def teaching_layers(
    start: StartEvent,
    ev: IterationEvent,
    n_points: int = 6,
    bins: int = 30,
    chosen: int | None = None,
) -> list[Layer]:
    """Iso-distance curves for a few object points and the histogram of pair distances.

    For every chosen point the metric ellipse and the Euclidean circle pass through its target,
    so a user sees why that target won; the histogram shows the distances with the median and
    the rejection threshold (for improved MbICP: median + k MAD, Fig. 9b). ``chosen`` (an index
    into ``start.obj_points``) shows that one point's curves instead of ``n_points`` spread ones.
    """
    layers: list[Layer] = []
    p = ev.pairs
    L = getattr(start.params, "L", None)
    w = 0.004 * scene_scale(start.ref_points)
    if L is not None and len(p.kind):
        mine = (
            np.flatnonzero(p.obj_index == chosen) if chosen is not None else np.empty(0, np.int64)
        )
        pick = (
            mine[:1]
            if len(mine)
            else np.unique(np.linspace(0, len(p.kind) - 1, n_points).round().astype(int))
        )
        src, tgt = p.source[pick], p.target[pick]
        layers.append(
            Strips(
                f"{SCANS}/{TEACH}/metric_isocurves",
                [metric_isocurve(s, t, L) for s, t in zip(src, tgt)],
                ISO_METRIC,
                w,
            )
        )
        layers.append(
            Strips(
                f"{SCANS}/{TEACH}/euclidean_circles",
                [circle(t, float(np.linalg.norm(s - t))) for s, t in zip(src, tgt)],
                ISO_EUCLID,
                w,
            )
        )
    if len(p.distance):
        layers += histogram_layers(
            histogram(p.distance, ev.threshold, bins), threshold_style(start.params)
        )
    return layers


@dataclass(frozen=True, eq=False)
class Histogram:
    """The pair distances of one iteration (paper 000 Fig. 9b): bins [m], counts, their median and
    the rejection threshold (None when the matcher applies none beyond its radial window)."""

    edges: np.ndarray  # (B + 1,) [m]
    counts: np.ndarray  # (B,)
    median: float
    threshold: float | None

    @property
    def centers(self) -> np.ndarray:
        return 0.5 * (self.edges[1:] + self.edges[:-1])


def histogram(distance: np.ndarray, threshold: float | None, bins: int = 30) -> Histogram:
    hi = max(float(distance.max()), threshold or 0.0) * 1.05 or 1.0
    counts, edges = np.histogram(distance, bins=bins, range=(0.0, hi))
    return Histogram(edges, counts, float(np.median(distance)), threshold)


HIST_BARS = Style("pairs per distance bin", (120, 120, 120))
MEDIAN = Style("median distance", (20, 20, 20))


def histogram_layers(h: Histogram, threshold: Style = THRESHOLD) -> list[Layer]:
    """The histogram as bars in a 2-D plot (x: metres, bar heights scaled to about 0.6 of the x
    range, so that the view is square), with median and threshold lines."""
    hi = float(h.edges[-1])
    heights = h.counts / max(h.counts.max(), 1) * hi * 0.6
    bars = [
        np.array([[a, 0.0], [a, y], [b, y], [b, 0.0]])
        for a, b, y in zip(h.edges[:-1], h.edges[1:], heights)
        if y > 0
    ]
    top, w = hi * 0.65, hi * 0.004
    out: list[Layer] = [
        Strips(f"{TEACH}/histogram/bars", bars, HIST_BARS, w),
        Strips(
            f"{TEACH}/histogram/median", [np.array([[h.median, 0.0], [h.median, top]])], MEDIAN, w
        ),
    ]
    if h.threshold is not None:
        out.append(
            Strips(
                f"{TEACH}/histogram/threshold",
                [np.array([[h.threshold, 0.0], [h.threshold, top]])],
                threshold,
                w,
            )
        )
    return out


# A run in rerun (``eval sequence --rrd``), one step per pair on a ``pair`` timeline: the run up to
# the pair, in a view that shows everything logged up to the time cursor, so each step logs only
# what it adds (the data grows with the run, not with its square); beside it, the pair up close.
MAP = Style("map: scans at the matched poses", REFERENCE.color, 1.0)
TRAJECTORY = Style("trajectory from the matches", (40, 90, 220), 3.0)
LOG_TRAJECTORY = Style("trajectory of the log's poses", (0, 190, 190), 2.5)
ITERATIONS = Style("iterations", (90, 90, 90))
TIME = Style("match time [ms]", (245, 160, 0))
# a pair's health (evaluation/health.py), one point per pair on the run's timeline
SUSPECT = Style("flagged pairs (suspicious, found without truth)", (240, 110, 0), 4.0)
SURFACE = Style("overlap: object points on the reference's surface [%]", (30, 150, 60))
CONDITION = Style("condition number", (150, 60, 170))
FROM_ODOMETRY = Style("difference from odometry [mm]", (120, 120, 0))
RESIDUAL = Style("residual: RMS of the kept pairs' distances [mm]", (90, 90, 90))
PAIR = "pair"  # the pair up close: its scans and final correspondences (its reference's frame)
FLAGGED = "flagged"  # every iteration of each flagged pair, one entity per pair


def run_step_layers(
    before: Pose2,
    pose: Pose2,
    points: np.ndarray | None,
    log_step: tuple[Pose2, Pose2] | None,
    flagged: bool,
) -> list[Layer]:
    """What one pair adds to the run (world frame: the first scan's): the trajectory's step from
    ``before`` to ``pose``, the scan it placed (its points already in the world frame; None: not
    in the thinned map), the log's own step, and a mark where a flagged pair ends."""
    layers: list[Layer] = [
        Strips(f"{SEQUENCE}/trajectory", [_track([before, pose])], TRAJECTORY, 0.02)
    ]
    if points is not None:
        layers.append(Points(f"{SEQUENCE}/map", points, MAP, 0.02))
    if log_step is not None:
        layers.append(
            Strips(f"{SEQUENCE}/log_trajectory", [_track(list(log_step))], LOG_TRAJECTORY, 0.015)
        )
    if flagged:
        layers.append(Points(f"{SEQUENCE}/suspects", _track([pose]), SUSPECT, 0.08))
    return layers


# what a pair up close keeps of the debugger's layers (a recording holds one per pair)
CLOSEUP = {f"{SCANS}/{name}" for name in ("reference", "object", "estimate")} | {
    f"{SCANS}/pairs/{kind}" for kind in ("point", "interpolated", "rejected")
}


def closeup_layers(start: StartEvent, iterations: list[IterationEvent]) -> list[Layer]:
    """A pair of a run up close, where its match ended, in its reference scan's frame: the two
    scans and the correspondences the last iteration made, interpolated and rejected."""
    return [
        layer for layer in layers_at(start, iterations, len(iterations)) if layer.path in CLOSEUP
    ]


def pair_health_layers(row: PairMatch) -> list[Layer]:
    """One pair of a run: its iterations, time, overlap, condition and distance from odometry as
    plot points, and a log line (a warning with its signs when it is flagged)."""
    from mbicp_viz.evaluation.health import flags_text

    r = row.result
    layers: list[Layer] = [
        Scalar(f"{PLOTS}/iterations", float(r.iterations), ITERATIONS),
        Scalar(f"{PLOTS}/time_ms", float(row.time_ms), TIME),
    ]
    if row.overlap is not None:
        layers.append(Scalar(f"{HEALTH}/overlap", 100.0 * row.overlap, SURFACE))
    if r.degeneracy is not None and math.isfinite(r.degeneracy.condition_number):
        layers.append(Scalar(f"{HEALTH}/condition", r.degeneracy.condition_number, CONDITION))
    if row.odometry_xy is not None:
        layers.append(Scalar(f"{HEALTH}/odometry_mm", 1000.0 * row.odometry_xy, FROM_ODOMETRY))
    words = (
        f"pair {row.ref} -> {row.obj}: ({r.pose.x:+.3f} m, {r.pose.y:+.3f} m, "
        f"{math.degrees(r.pose.theta):+.2f} deg), {r.iterations} iterations, {r.reason.value}"
    )
    if row.flags:
        words += f"; flagged: {flags_text(row)}"
    layers.append(Text(LOG, words, "WARN" if row.flags or not r.converged else "INFO"))
    return layers


# A run with its loops closed (evaluation/loops.py), a space of its own beside the chained run's:
# the pose graph's trajectory, its key frames' scans, and each loop candidate between where the
# optimised run puts its two key frames, coloured by its verdict.
LOOPS = "loops"
LOOP_TRAJECTORY = Style("trajectory with the loops closed (pose graph)", (0, 130, 110), 3.5)
LOOP_MAP = Style("map: the key frames at their optimised poses", REFERENCE.color, 1.0)
CLOSURE = {
    Verdict.ACCEPTED: Style("loop closure accepted", (0, 200, 0), 4.0),
    Verdict.AMBIGUOUS: Style("loop candidate: response surface ambiguous", (255, 0, 200), 3.6),
    Verdict.LOW_OVERLAP: Style("loop candidate: low overlap", (170, 170, 170), 3.2),
    Verdict.WEAK: Style("loop candidate: weak direction", (150, 60, 170), 3.4),
    Verdict.NOT_CONVERGED: Style("loop candidate: match did not converge", (140, 90, 40), 3.3),
    Verdict.INCONSISTENT: Style("loop closure inconsistent with the others", (255, 140, 0), 3.8),
    Verdict.SET_ASIDE: Style("loop closure rejected by hand", (220, 30, 30), 3.7),
}


# A candidate's correlative response over rotation (the debugger's loop panel): the best score of
# each rotation over the best, the peak its match started from, the highest one far from it.
RESPONSE = Style("best score at each rotation / the best", (30, 30, 30), 1.0)
CHOSEN_PEAK = Style("the best peak: the match starts here", CLOSURE[Verdict.ACCEPTED].color, 1.0)
SECOND_PEAK = Style("the second peak", CLOSURE[Verdict.AMBIGUOUS].color, 1.0)
AMBIGUOUS_FROM = Style("ambiguous from here", (130, 130, 130), 1.0)


def loop_layers(
    optimised: list[Pose2],
    key_points: np.ndarray,
    closures: list[tuple[Verdict, Pose2, Pose2]],
) -> list[Layer]:
    """The run with its loops closed: its trajectory, the key frames' points (world frame) and
    each candidate (verdict, old key frame, newer one) as a segment between the two, one layer
    per verdict."""
    return [
        Points(f"{LOOPS}/map", key_points, LOOP_MAP, 0.02),
        Strips(f"{LOOPS}/trajectory", [_track(optimised)], LOOP_TRAJECTORY, 0.03),
        *closure_layers(LOOPS, closures, 0.03),
    ]


def closure_layers(
    under: str, closures: list[tuple[Verdict, Pose2, Pose2]], width: float
) -> list[Layer]:
    """Each loop candidate (verdict, old key frame, newer one) as a segment between the two, one
    layer per verdict, under ``under``."""
    layers: list[Layer] = []
    for verdict, style in CLOSURE.items():
        ends = [(a, b) for v, a, b in closures if v is verdict]
        if ends:
            starts = np.array([[a.x, a.y] for a, _ in ends])
            stops = np.array([[b.x, b.y] for _, b in ends])
            layers.append(Segments(f"{under}/{verdict.name.lower()}", starts, stops, style, width))
    return layers


# The debugger's run view: the whole run in the world frame (its first scan's), one pair in view.
RUN_MAP = Style("map: the scans up to this pair at the chained poses", (150, 150, 150), 0.5)
RUN_LOOP_MAP = Style("map: the scans up to this pair with the loops closed", (80, 165, 155), 0.5)
RUN_TRAJECTORY = Style("trajectory from the chained matches", (30, 30, 30), 3.0)
RUN_REFERENCE = Style("this pair: its reference scan", REFERENCE.color, 2.0)
RUN_OBJECT = Style("this pair: its object scan", OBJECT.color, 2.5)
RUN_ODOMETRY = Style("trajectory of the odometry", (150, 210, 40), 2.2)
RUN_OTHER = Style("trajectory of run B", (200, 0, 160), 2.9)
RELATION = Style(
    "relation: from its earlier scan to where it puts the later one", (255, 190, 0), 4.5
)
ROBOT = Style("this pair's pose (x red, y green)", (40, 90, 220), 5.0)


@dataclass(frozen=True)
class RunTracks:
    """What the run view draws once, in the world frame: the run's trajectories and where its
    flagged pairs end."""

    poses: list[Pose2]  # one per scan the run visits
    stored: list[Pose2] | None = None  # the log's scan poses (its truth), same world frame
    odometry: list[Pose2] | None = None  # the odometry's, same world frame
    suspects: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    other: list[Pose2] | None = None  # a second configuration's run of the same pairs
    other_label: str = ""
    loops: list[Pose2] | None = None  # the run with its loops closed (pose graph)
    # each loop candidate: its verdict, where the drawn poses (chained, or with the loops closed)
    # put its old and its newer key frame
    closures: list[tuple[Verdict, Pose2, Pose2]] = field(default_factory=list)


@dataclass(frozen=True)
class RunPair:
    """What the run view draws at one pair: the map's last part up to it (the rest are whole
    chunks, ``run_map_layers``), its two scans, the pose it reached, a chosen relation."""

    # each map's last part (its name, its (M, 2) points, its legend entry: the poses it is at)
    maps: list[tuple[str, np.ndarray, Style]]
    ref_xy: np.ndarray
    obj_xy: np.ndarray
    pose: Pose2
    # a relation (Kümmerle et al.): the earlier end's pose and where it puts the later one
    relation: tuple[Pose2, Pose2] | None = None


def _track(poses: list[Pose2]) -> np.ndarray:
    return np.array([[p.x, p.y] for p in poses]).reshape(-1, 2)


# The most vertices a run's trajectory is drawn with: an hour at 40 Hz (144,000 poses) is drawn
# through every 8th, 0.2 s apart, finer than a pixel of the whole run, and a page in software
# WebGL no longer takes a minute a frame. The flagged pairs are drawn each at its own pose.
RUN_TRACK_VERTICES = 20_000
# ... and of those, the ones a line of width w needs: every pose left out lies within this share
# of w of the line drawn (the full Intel run: 2,436 vertices for its three tracks, not 40,890; a
# slider step on its page, drawing WebGL in software, took 3.4-3.7 s, most of it those lines)
RUN_TRACK_TOLERANCE = 0.25
SIMPLIFIED_SPAN = 256


def simplified(xy: np.ndarray, tol: float) -> np.ndarray:
    """The indices of the vertices of the polyline ``xy`` (N, 2) that Douglas and Peucker's
    simplification (1973) keeps: every vertex left out lies within ``tol`` of the segment between
    the kept vertices around it. The first and last are kept."""
    n = len(xy)
    keep = np.zeros(n, dtype=bool)
    # spans of at most SIMPLIFIED_SPAN vertices, their ends kept: a track whose every vertex is
    # needed (jitter wider than the line) costs n * SIMPLIFIED_SPAN, not n^2 (5.6 s at 20,000)
    ends = np.unique(np.r_[np.arange(0, n, SIMPLIFIED_SPAN), n - 1]) if n else []
    keep[ends] = True
    spans = [(int(a), int(b)) for a, b in zip(ends[:-1], ends[1:]) if b - a > 1]
    while spans:
        a, b = spans.pop()
        d = xy[b] - xy[a]
        v = xy[a + 1 : b] - xy[a]
        t = np.clip(v @ d / max(float(d @ d), 1e-300), 0.0, 1.0)
        off = np.hypot(*(v - t[:, None] * d).T)
        k = int(np.argmax(off))
        if off[k] > tol:
            m = a + 1 + k
            keep[m] = True
            spans += [(i, j) for i, j in ((a, m), (m, b)) if j - i > 1]
    return np.flatnonzero(keep)


def _drawn_track(poses: list[Pose2], width: float) -> np.ndarray:
    """``_track`` of evenly spaced poses, at most ``RUN_TRACK_VERTICES``, the last one kept, and
    of those the vertices a line ``width`` wide needs (``RUN_TRACK_TOLERANCE``)."""
    step = max(1, -(-len(poses) // RUN_TRACK_VERTICES))
    even = [*poses[::step], *poses[-1:]] if (len(poses) - 1) % step else poses[::step]
    xy = _track(even)
    return xy[simplified(xy, RUN_TRACK_TOLERANCE * width)]


def run_track_layers(r: RunTracks, scale: float = 1.0) -> list[Layer]:
    """The run's trajectories and flagged pairs; dots and lines ``scale`` times their size
    (``scene_scale`` of the whole run)."""
    wide, thin = 0.01 * scale, 0.006 * scale

    def track(path: str, poses: list[Pose2], style: Style, width: float) -> Strips:
        return Strips(f"{RUN}/{path}", [_drawn_track(poses, width)], style, width)

    layers: list[Layer] = [
        track("trajectory", r.poses, RUN_TRAJECTORY, wide),
        Points(f"{RUN}/suspects", r.suspects, SUSPECT, 0.04 * scale),
    ]
    if r.stored is not None:
        layers.append(track("stored", r.stored, LOG_TRAJECTORY, thin))
    if r.odometry is not None:
        layers.append(track("odometry", r.odometry, RUN_ODOMETRY, thin))
    if r.other is not None:
        style = replace(RUN_OTHER, label=f"{RUN_OTHER.label}: {r.other_label}")
        layers.append(track("other", r.other, style, wide))
    if r.loops is not None:
        layers.append(track("loops_closed", r.loops, LOOP_TRAJECTORY, wide))
        layers += closure_layers(f"{RUN}/{LOOPS}", r.closures, 0.008 * scale)
    return layers


def run_map_layers(
    chunks: list[np.ndarray], scale: float = 1.0, style: Style = RUN_MAP, name: str = "map"
) -> list[Layer]:
    """A map in chunks of consecutive scans, each shown once the pair in view has passed it."""
    return [Points(f"{RUN}/{name}/{c:05d}", xy, style, 0.01 * scale) for c, xy in enumerate(chunks)]


def run_pair_layers(r: RunPair, scale: float = 1.0) -> list[Layer]:
    """The pair in view: the map's part since the last whole chunk, its two scans highlighted,
    the pose it reached and a chosen relation."""
    layers: list[Layer] = [
        *(Points(f"{RUN}/{name}_last", xy, style, 0.01 * scale) for name, xy, style in r.maps),
        Points(f"{RUN}/reference", r.ref_xy, RUN_REFERENCE, 0.015 * scale),
        Points(f"{RUN}/object", r.obj_xy, RUN_OBJECT, 0.015 * scale),
        Frame(f"{RUN}/robot", r.pose, ROBOT, 0.15 * scale),
    ]
    if r.relation is not None:
        layers += [
            Strips(f"{RUN}/relation", [_track(list(r.relation))], RELATION, 0.012 * scale),
            Points(f"{RUN}/relation_end", _track([r.relation[1]]), RELATION, 0.05 * scale),
        ]
    return layers


# Convergence atlas (``eval basin --rrd``): outcome per initial offset.
def basin_layers(
    name: str,
    offsets_xy: np.ndarray,
    outcome: np.ndarray,
    names: tuple[str, ...],
    colors: tuple[RGB, ...],
    theta_deg: float,
) -> list[Layer]:
    """One matcher's outcomes over the (dx, dy) grid of one theta offset, coloured by outcome."""
    gx, gy = np.meshgrid(offsets_xy, offsets_xy)
    o = outcome.ravel()
    step = float(offsets_xy[1] - offsets_xy[0]) if len(offsets_xy) > 1 else 0.1
    style = Style(f"{name}: outcome per initial offset [m]", colors[0])
    return [
        Points(
            f"basin/{name}/outcome",
            np.column_stack((gx.ravel(), gy.ravel())),
            style,
            step * 0.4,
            colors=np.array(colors, dtype=np.uint8)[o],
            labels=[names[k] for k in o],
        ),
        Text(
            f"basin/{name}/note",
            f"dtheta {theta_deg:+.1f} deg: {np.mean(o == 0) * 100:.0f} % correct",
        ),
    ]


# Polar matchers (PSM, PMWN): how they think, in plot spaces of their own (x in degrees).
RANGE_REF = Style("reference ranges [dm] per bearing [deg]", (220, 40, 40))
RANGE_PROJ = Style("projected object ranges [dm] per bearing [deg]", (40, 90, 220))
COST = Style("cost [cm] per shift [deg]", (120, 120, 120))
FIT = Style("fit through the three least costs", (0, 160, 90))
MINIMUM = Style("chosen rotation", (245, 160, 0))


def fitted_curve(polar, shift_deg: float, n: int = 21) -> np.ndarray | None:
    """The V (PMWN) or parabola (PSM) through the three cost samples around the minimum."""
    if polar.fit_abc is None or polar.best_shift is None:
        return None
    a, b, c = polar.fit_abc
    k0 = (
        round(polar.best_shift)
        if abs(polar.best_shift - round(polar.best_shift)) <= 0.5
        else polar.best_shift
    )
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


def polar_step_deg(polar) -> float:
    return math.degrees(float(np.median(np.diff(polar.bearings))))


def polar_layers(ev: IterationEvent, scale: float = 1.0) -> list[Layer]:
    """Cost per shift with the chosen minimum and its fit; ranges vs bearing; PMWN's projected
    circle."""
    P = ev.polar
    if P is None:
        return []
    step_deg = polar_step_deg(P)
    layers: list[Layer] = []
    ok = np.isfinite(P.cost)
    if ok.any():
        layers.append(
            Strips(
                f"{POLAR}/cost/curve",
                [np.column_stack((P.shifts[ok] * step_deg, P.cost[ok] * COST_SCALE))],
                COST,
                0.1,
            )
        )
        fit = fitted_curve(P, step_deg)
        if fit is not None:
            fit = fit * [1.0, COST_SCALE]
            layers.append(Strips(f"{POLAR}/cost/fit", [fit], FIT, 0.12))
            layers.append(
                Points(
                    f"{POLAR}/cost/minimum",
                    np.array([[P.best_shift * step_deg, fit[:, 1].min()]]),
                    MINIMUM,
                    0.4,
                )
            )
    deg = np.degrees(P.bearings)
    for name, r, style in (
        ("reference", P.ref_ranges, RANGE_REF),
        ("projected", P.projected_ranges, RANGE_PROJ),
    ):
        pts = np.column_stack((deg, r * RANGE_SCALE))
        layers.append(Points(f"{POLAR}/ranges/{name}", pts[np.isfinite(r)], style, 0.3))
    if P.metric_weight is not None:
        layers.append(Scalar(f"{PLOTS}/metric_weight", P.metric_weight, METRIC_WEIGHT))
    if P.circle_points is not None:
        layers.append(
            Points(f"{SCANS}/{POLAR}/circle_points", P.circle_points, CIRCLE, 0.01 * scale)
        )
        layers.append(
            Points(f"{SCANS}/{POLAR}/circle_centre", P.circle_centre[None, :], CIRCLE, 0.03 * scale)
        )
    return layers


# Lesson: paper 000's rejection example (§2.4.2, Fig. 9), a dot plot of distances on a line.
LESSON = "lesson"
DOT_KEPT = Style("distances kept", (20, 20, 20))
DOT_REJECTED = Style("distances beyond median + k MAD: rejected", PAIR_REJECTED.color)
MAD_LINE = Style("median + k MAD (paper 000 eq. 5)", PAIR_REJECTED.color)
SIGMA_LINE = Style("mean + 2 standard deviations", (90, 90, 220))


def distance_layers(d: np.ndarray, threshold: float, sigma_threshold: float) -> list[Layer]:
    """The distances as dots on the x axis (kept black, rejected orange) with the median, the MAD
    threshold and the mean + 2 sigma threshold as vertical lines; x in the distances' own unit."""
    hi = float(max(d.max(), sigma_threshold)) * 1.05
    r, top = hi / 150, hi * 0.12

    def vline(x: float) -> list[np.ndarray]:
        return [np.array([[x, -top], [x, top]])]

    return [
        Points(
            f"{LESSON}/distances/kept",
            np.column_stack((d[d <= threshold], np.zeros(np.sum(d <= threshold)))),
            DOT_KEPT,
            r,
        ),
        Points(
            f"{LESSON}/distances/rejected",
            np.column_stack((d[d > threshold], np.zeros(np.sum(d > threshold)))),
            DOT_REJECTED,
            r,
        ),
        Strips(f"{LESSON}/distances/median", vline(float(np.median(d))), MEDIAN, r / 4),
        Strips(f"{LESSON}/distances/mad_threshold", vline(threshold), MAD_LINE, r / 4),
        Strips(f"{LESSON}/distances/sigma_threshold", vline(sigma_threshold), SIGMA_LINE, r / 4),
    ]
