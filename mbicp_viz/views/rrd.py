"""The rerun front end: events -> scene layers -> a rerun recording (stream or .rrd).

rerun is imported here only, and only by the commands that record. Every run lives under its own
entity root (``/improved``, ``/mbicp`` ...) so that several matchers sit side by side; the
``iteration`` timeline orders the steps (0 = the initial guess).

rerun's 2-D views put y down (image convention); the debugger and every plot here put y up. Each
2-D space is therefore logged under a y-flipping transform at its root and viewed from the
parent: the picture is the debugger's, counter-clockwise stays counter-clockwise, histograms stand
upright, and the values a user hovers over are the logged ones.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from mbicp_viz.core import Event, FinishEvent, IterationEvent, Pose2, StartEvent
from mbicp_viz.errors import InputError
from mbicp_viz.outputs import written
from mbicp_viz.readers.pair_match import PairMatch

from . import scene

APP_ID = "mbicp-viz"
ABOUT = "about"
RECORD = "record"  # under each run's root: the match's record (readers/pair_match.py), JSON
_Y_UP = rr.Transform3D(mat3x3=[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])


def new_stream(recording_id: str, live: bool = False) -> rr.RecordingStream:
    """A stream with a fixed recording id and no wall-clock properties, so re-runs compare equal.

    Files are batched into chunks only at the end: chunk boundaries then do not depend on timing
    (``rerun rrd compare`` compares chunks). A live viewer gets rerun's default, timely batching.
    """
    batching = rr.ChunkBatcherConfig.DEFAULT() if live else rr.ChunkBatcherConfig.NEVER()
    return rr.RecordingStream(
        APP_ID, recording_id=recording_id, send_properties=False, batcher_config=batching
    )


@contextmanager
def saving(stream: rr.RecordingStream, path: str, blueprint) -> Iterator[None]:
    """What the block logs to ``stream``, saved to ``path`` whole: into a temporary beside it,
    renamed over ``path`` once the stream is flushed and closed (``outputs.written``)."""
    with written(path) as tmp:
        stream.save(str(tmp), default_blueprint=blueprint)
        try:
            yield
        finally:
            stream.flush()
            stream.disconnect()


# The debugger's light background: black correspondences (paper 000's colour) stay visible.
BACKGROUND = (250, 250, 250)


def y_up_view(space: str, name: str, time_ranges=None) -> rrb.Spatial2DView:
    """A 2-D view of the entity ``space`` (logged under ``log_y_up``), y pointing up, on the
    debugger's light background; ``time_ranges``: what it shows besides the latest at the
    cursor."""
    parent = space.rsplit("/", 1)[0] or "/"
    return rrb.Spatial2DView(
        origin=parent,
        contents=f"{space}/**",
        name=name,
        background=BACKGROUND,
        time_ranges=time_ranges,
    )


def log_y_up(stream: rr.RecordingStream, space: str) -> None:
    stream.log(space, _Y_UP, static=True)


def _spaces(root: str, teaching: bool, polar: bool) -> list[str]:
    """The 2-D spaces of one run."""
    out = [f"{root}/{scene.SCANS}"]
    if teaching:
        out.append(f"{root}/{scene.TEACH}/histogram")
    if polar:
        out += [f"{root}/{scene.POLAR}/cost", f"{root}/{scene.POLAR}/ranges"]
    return out


def blueprint(
    roots: list[str], teaching: bool = False, about: bool = False, polar: set[str] = frozenset()
) -> rrb.Blueprint:
    """Scans side by side, error and threshold plots, the text log; time panel on ``iteration``.

    Polar matchers add their cost-per-shift and range-per-bearing plots (x in degrees)."""
    scans = [y_up_view(f"/{r}/{scene.SCANS}", f"{r}: scans (reference frame, m)") for r in roots]
    polar_views = [
        rrb.Tabs(
            y_up_view(f"/{r}/{scene.POLAR}/cost", f"{r}: cost [cm] per shift [deg]"),
            y_up_view(f"/{r}/{scene.POLAR}/ranges", f"{r}: ranges [dm] per bearing [deg]"),
        )
        for r in roots
        if r in polar
    ]
    log = rrb.TextLogView(origin="/", contents=[f"/{r}/{scene.LOG}" for r in roots], name="log")
    side = [
        rrb.TimeSeriesView(
            origin="/",
            contents=[f"/{r}/{scene.PLOTS}/**" for r in roots],
            name="error [m²] and threshold [m] per iteration",
        ),
        rrb.Tabs(rrb.TextDocumentView(origin=f"/{ABOUT}", name="what to look at"), log)
        if about
        else log,
    ]
    if teaching:
        side.insert(
            1,
            rrb.Tabs(
                *[
                    y_up_view(f"/{r}/{scene.TEACH}/histogram", f"{r}: pair distances [m]")
                    for r in roots
                ]
            ),
        )
    main = scans[0] if len(scans) == 1 else rrb.Horizontal(*scans)
    return rrb.Blueprint(
        rrb.Horizontal(main, rrb.Vertical(*polar_views, *side), column_shares=[3, 2]),
        rrb.TimePanel(timeline="iteration", expanded=True),
        collapse_panels=True,
    )


def _rgb(c):
    return np.asarray(c, dtype=np.uint8)


def _points(layer: scene.Points):
    colors = layer.colors if layer.colors is not None else _rgb(layer.style.color)
    yield (
        "",
        rr.Points2D(
            layer.xy,
            colors=colors,
            radii=layer.radius,
            labels=layer.labels,
            show_labels=False if layer.labels else None,
            draw_order=layer.style.order,
        ),
    )


def _line_strips(layer, strips):
    yield (
        "",
        rr.LineStrips2D(
            strips, colors=_rgb(layer.style.color), radii=layer.width, draw_order=layer.style.order
        ),
    )


def _segments(layer: scene.Segments):
    if not len(layer.starts):
        return _line_strips(layer, np.zeros((0, 2, 2)))
    return _line_strips(layer, np.stack((layer.starts, layer.ends), axis=1))


def _boxes(layer: scene.Boxes):
    yield (
        "",
        rr.Boxes2D(
            centers=layer.centers,
            half_sizes=np.full((len(layer.centers), 2), layer.half_size),
            colors=layer.colors,
            labels=layer.labels,
            show_labels=False,
            radii=0.002,
            draw_order=layer.style.order,
        ),
    )


def _frame(layer: scene.Frame):
    p = layer.pose
    yield (
        "",
        rr.Transform3D(
            translation=[p.x, p.y, 0.0],
            rotation_axis_angle=rr.RotationAxisAngle(axis=[0, 0, 1], radians=p.theta),
        ),
    )
    # the frame's axes as the debugger draws them: x red, y green (the legend says so)
    yield (
        "/heading",
        rr.Arrows2D(
            origins=[[0.0, 0.0]] * 2,
            vectors=[[layer.length, 0.0], [0.0, layer.length]],
            colors=[scene.AXIS_X, scene.AXIS_Y],
            radii=0.025 * layer.length,
            draw_order=layer.style.order,
        ),
    )


# Each layer type as rerun archetypes: (path below the layer's, archetype) pairs
_ARCHETYPES = {
    scene.Points: _points,
    scene.Segments: _segments,
    scene.Strips: lambda layer: _line_strips(layer, layer.strips),
    scene.Boxes: _boxes,
    scene.Scalar: lambda layer: [("", rr.Scalars(layer.value))],
    scene.Text: lambda layer: [("", rr.TextLog(layer.text, level=layer.level))],
    scene.Frame: _frame,
}


def log_layer(
    stream: rr.RecordingStream, root: str, layer: scene.Layer, static: bool = False
) -> None:
    """One layer as rerun archetypes under ``root``; a layer type it does not know is an error."""
    make = next((f for t, f in _ARCHETYPES.items() if isinstance(layer, t)), None)
    if make is None:
        raise TypeError(
            f"the rerun front end cannot draw a {type(layer).__name__} layer ({layer.path})"
        )
    for below, archetype in make(layer):
        stream.log(f"{root}/{layer.path}{below}", archetype, static=static)


class RerunObserver:
    """An observer that writes one run under ``root`` of a rerun stream as it happens."""

    def __init__(
        self,
        stream: rr.RecordingStream,
        root: str,
        teaching: bool = False,
        truth: Pose2 | None = None,
        odometry: Pose2 | None = None,
    ):
        self.stream, self.root, self.teaching, self.truth, self.odometry = (
            stream,
            root,
            teaching,
            truth,
            odometry,
        )
        self.start: StartEvent | None = None
        self.last_iteration = 0
        self.series: set[str] = set()  # plot paths whose line style is logged

    def __call__(self, ev: Event) -> None:
        if isinstance(ev, StartEvent):
            self.start = ev
            self._static_styles()
            for layer in scene.static_layers(ev, self.truth, self.odometry):
                log_layer(self.stream, self.root, layer, static=True)
            self.stream.set_time("iteration", sequence=0)
            for layer in scene.initial_layers(ev):
                log_layer(self.stream, self.root, layer)
        elif isinstance(ev, IterationEvent):
            self.last_iteration = ev.iteration
            self.stream.set_time("iteration", sequence=ev.iteration)
            layers = scene.iteration_layers(self.start, ev)
            if self.teaching:
                layers += scene.teaching_layers(self.start, ev)
            for layer in layers:
                if isinstance(layer, scene.Scalar) and layer.path not in self.series:
                    self._series_style(layer)
                log_layer(self.stream, self.root, layer)
        elif isinstance(ev, FinishEvent):
            self.stream.set_time("iteration", sequence=self.last_iteration)
            for layer in scene.finish_layers(ev.result):
                log_layer(self.stream, self.root, layer)

    def _static_styles(self) -> None:
        for space in _spaces(self.root, self.teaching, polar=True):
            log_y_up(self.stream, space)

    def _series_style(self, layer: scene.Scalar) -> None:
        """A plot line's colour and legend name, logged with its first value."""
        self.series.add(layer.path)
        self.stream.log(
            f"{self.root}/{layer.path}",
            rr.SeriesLines(
                colors=_rgb(layer.style.color),
                names=f"{self.root}: {layer.style.label}",
                widths=2.0,
            ),
            static=True,
        )


def pair_blueprint(matches: list[PairMatch], teaching: bool = False, about: bool = False):
    """The blueprint of a pair's recording: ``blueprint`` for the matches' roots."""
    from mbicp_viz.core import MATCHERS

    roots = [m.matcher for m in matches]
    return blueprint(roots, teaching, about, {r for r in roots if MATCHERS[r].polar})


def log_matches(
    stream: rr.RecordingStream,
    matches: list[PairMatch],
    teaching: bool = False,
    about: str | None = None,
) -> None:
    """Replay each match's events (``PairMatch.events``) under its matcher's root, with its record
    beside them (``ROOT/record``, JSON); ``about`` (Markdown) as a document beside the runs."""
    if about is not None:
        stream.log(ABOUT, rr.TextDocument(about, media_type=rr.MediaType.MARKDOWN), static=True)
    for m in matches:
        if m.events is None:
            raise InputError(
                f"the match of scans {m.ref} -> {m.obj} kept no iterations: match it with "
                "record=True to record it",
                field="matches",
            )
        observer = RerunObserver(stream, m.matcher, teaching, m.truth, m.odometry)
        for ev in m.events.events:
            observer(ev)
        stream.log(f"{m.matcher}/{RECORD}", rr.TextDocument(record_text(m)), static=True)
    stream.flush()


def record(
    matches: list[PairMatch],
    path: str | None = None,
    connect: str | None = None,
    teaching: bool = False,
    recording_id: str = "mbicp-viz",
    about: str | None = None,
) -> None:
    """``log_matches`` into ``path`` (.rrd, written whole) and/or streamed to ``connect``, with
    ``pair_blueprint``."""
    stream = new_stream(recording_id, live=connect is not None)
    bp = pair_blueprint(matches, teaching, about is not None)
    with ExitStack() as stack:
        if path is not None:
            stack.enter_context(saving(stream, path, bp))
        else:
            stack.callback(stream.disconnect)
        if connect is not None:
            stream.connect_grpc(connect, default_blueprint=bp)
        log_matches(stream, matches, teaching, about)


def record_text(m: PairMatch) -> str:
    """The record a recording keeps of a match: its JSON without the wall times (a recording is
    the same every time it is made)."""
    return json.dumps(m.to_json(timings=False), indent=1)


def _record_to(path: str, matches: list[PairMatch], kw: dict) -> None:
    record(matches, path, **kw)


# One recording process for a server's exports, replaced after RECORDINGS_PER_PROCESS of them.
RECORDINGS_PER_PROCESS = 25
_recorder = None


def recorded_bytes(matches: list[PairMatch], **kw) -> bytes:
    """``record(matches, path, **kw)``'s file as bytes, recorded in another process: rerun-sdk
    (0.41) keeps about 2.5 MB of every recording stream until its process ends, so a server
    recording on demand (the debugger's "export .rrd") would grow with every export. The process
    is started (spawned: the server's threads are not forked along) at the first export and
    replaced after ``RECORDINGS_PER_PROCESS``; ``stop_recorder`` ends it."""
    import multiprocessing
    import tempfile
    from concurrent.futures import ProcessPoolExecutor
    from pathlib import Path

    global _recorder
    if _recorder is None:
        import atexit

        atexit.register(stop_recorder)  # ended before the interpreter's own teardown
        spawn = multiprocessing.get_context("spawn")
        _recorder = ProcessPoolExecutor(
            1, mp_context=spawn, max_tasks_per_child=RECORDINGS_PER_PROCESS
        )
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "session.rrd")
        _recorder.submit(_record_to, path, matches, kw).result()
        return Path(path).read_bytes()


def stop_recorder() -> None:
    """End the recording process of ``recorded_bytes``, if one runs."""
    global _recorder
    if _recorder is not None:
        _recorder.shutdown(cancel_futures=True)
        _recorder = None


def serve(path: str, port: int, host: str = "127.0.0.1") -> int:
    """Serve ``path`` in rerun's web viewer from the wheel's own CLI, bound to ``host`` (loopback).

    The web viewer listens on ``port``, its gRPC data server on ``port + 1``.
    """
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    beside = Path(sys.executable).parent / "rerun"  # the wheel's CLI, in the same environment
    exe = str(beside) if beside.exists() else shutil.which("rerun")
    if exe is None:
        raise InputError("the rerun viewer command is not installed (pip install rerun-sdk)")
    cmd = [
        exe,
        "--serve-web",
        "--bind",
        host,
        "--web-viewer-port",
        str(port),
        "--port",
        str(port + 1),
        path,
    ]
    return subprocess.call(cmd)


SEQUENCE_ROOT = "sequence"


MAP_POINTS = 1_000_000  # the most map points a run's recording holds: its scans thinned evenly
FLAGGED_VIEWS = 10  # the flagged pairs whose iterations get a view (the most suspicious first)
FLUSH_PAIRS = 200  # a run's recording is written out every this many pairs


def sequence_blueprint(rows: list[PairMatch], loops: bool = False) -> rrb.Blueprint:
    """The run up to the time cursor (trajectory and map) beside the pair up close (and a tab per
    flagged pair showing its iterations, the most suspicious first), the health plots and the
    per-pair log; with ``loops``, the run with its loops closed under the run. Time panel on
    ``pair``."""
    from mbicp_viz.evaluation.run_rows import RunRows

    flagged = (RunRows.of(rows).ranked().index + 1).tolist()  # their numbers on the timeline
    root = SEQUENCE_ROOT
    so_far = rrb.VisibleTimeRange(
        "pair", start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.cursor_relative()
    )
    run = y_up_view(
        f"/{root}/{scene.SEQUENCE}",
        "the run up to this pair: trajectory and map (first scan's frame, m)",
        time_ranges=so_far,
    )
    if loops:
        run = rrb.Vertical(
            run,
            y_up_view(
                f"/{root}/{scene.LOOPS}",
                "loops closed: pose graph, key frames, candidates by verdict (same frame, m)",
            ),
        )
    closeups = [
        y_up_view(
            f"/{root}/{scene.PAIR}/{scene.SCANS}",
            "this pair where its match ended: correspondences (its reference scan's frame, m)",
        ),
        *(
            y_up_view(
                f"/{root}/{scene.FLAGGED}/pair_{n:05d}/{scene.SCANS}",
                f"flagged pair {n}: its iterations (timeline 'iteration')",
            )
            for n in flagged[:FLAGGED_VIEWS]
        ),
    ]
    return rrb.Blueprint(
        rrb.Horizontal(
            run,
            rrb.Vertical(
                rrb.Tabs(*closeups),
                rrb.TimeSeriesView(
                    origin=f"/{root}/{scene.HEALTH}",
                    name="health: overlap [%], condition number, from odometry [mm]",
                ),
                rrb.TimeSeriesView(origin=f"/{root}/{scene.PLOTS}", name="iterations, time [ms]"),
                rrb.TextLogView(origin=f"/{root}/{scene.LOG}", name="pairs (flagged: WARN)"),
                row_shares=[3, 1, 1, 1],
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline="pair", expanded=True),
        collapse_panels=True,
    )


def log_sequence(
    stream: rr.RecordingStream, log, rows: list[PairMatch], loops=None, on_pair=None
) -> None:
    """A run (``eval sequence``'s rows) on a ``pair`` timeline (and ``scan``: the record each pair
    placed). Each pair adds its step of the trajectory, the scan it placed (the map thinned to
    ``MAP_POINTS``), the log's own step, its health and log line, and its match up close where it
    ended (matched again from its own guess and parameters to record its correspondences); the
    flagged pairs' every iteration (timeline ``iteration``) under ``flagged/pair_N``. With
    ``loops`` (a ``LoopRun``), the run with its loops closed and every candidate, a static layer
    of its own. ``on_pair()`` is called after each pair (progress)."""
    from mbicp_viz.choices import MATCH_BUDGET_S
    from mbicp_viz.core import match
    from mbicp_viz.core.budget import limited
    from mbicp_viz.core.events import Recorder
    from mbicp_viz.evaluation.trajectory import accumulate, log_poses, map_step, scan_indices

    root = SEQUENCE_ROOT
    for space in (scene.SEQUENCE, f"{scene.PAIR}/{scene.SCANS}"):
        log_y_up(stream, f"/{root}/{space}")
    records = scan_indices(rows)
    poses, stored = accumulate(rows), log_poses(log, records)
    mount = log.frames.mount if rows[0].frame != "laser" else Pose2()
    every = map_step(log, records, MAP_POINTS)
    scans = log.scans_of(records, odometry=False)
    stream.set_time("pair", sequence=0)
    stream.set_time("scan", sequence=records[0])
    first = (poses[0] @ mount).apply(next(scans).points())
    for layer in scene.run_step_layers(poses[0], poses[0], first, None, False):
        log_layer(stream, root, layer)
    shown: set[str] = set()  # the close-up's entities, as the last pair drew them
    for n, (row, obj) in enumerate(zip(rows, scans), start=1):
        stream.set_time("pair", sequence=n)
        stream.set_time("scan", sequence=row.obj)
        placed = (poses[n] @ mount).apply(obj.points()) if n % every == 0 else None
        step = (stored[n - 1], stored[n]) if stored is not None else None
        for layer in [
            *scene.run_step_layers(poses[n - 1], poses[n], placed, step, bool(row.flags)),
            *scene.pair_health_layers(row),
        ]:
            log_layer(stream, root, layer)
        rec = Recorder()
        with limited(MATCH_BUDGET_S):
            match(log.scan(row.ref), obj, row.guess, row.params, rec)
        closeup = scene.closeup_layers(rec.start, rec.iterations)
        for layer in closeup:
            log_layer(stream, f"{root}/{scene.PAIR}", layer)
        now = {f"/{root}/{scene.PAIR}/{layer.path}" for layer in closeup}
        for gone in shown - now:  # a layer the last pair had and this one has not
            stream.log(gone, rr.Clear(recursive=True))
        shown = now
        if row.flags:
            observer = RerunObserver(stream, f"{root}/{scene.FLAGGED}/pair_{n:05d}")
            for ev in rec.events:
                observer(ev)
            stream.disable_timeline("iteration")
        if n % FLUSH_PAIRS == 0:  # to the file: memory stays bounded, the chunks deterministic
            stream.flush()
        if on_pair is not None:
            on_pair()
    if loops is not None:
        log_y_up(stream, f"/{root}/{scene.LOOPS}")
        ends = [(c.verdict, *loops.ends(c)) for c in loops.closures]
        for layer in scene.loop_layers(loops.optimised, loops.key_points(log), ends):
            log_layer(stream, root, layer, static=True)
    stream.flush()


def record_sequence(
    log,
    rows: list[PairMatch],
    path: str,
    recording_id: str = "mbicp-viz/sequence",
    loops=None,
    on_pair=None,
) -> None:
    """``log_sequence`` into ``path`` (.rrd, written whole) with ``sequence_blueprint``."""
    stream = new_stream(recording_id)
    with saving(stream, path, sequence_blueprint(rows, loops is not None)):
        log_sequence(stream, log, rows, loops, on_pair)


def record_basin(atlas, path: str) -> None:
    """Outcome points per matcher in the (dx, dy) plane, one ``theta_offset`` step per slice."""
    import math

    from mbicp_viz.evaluation.basin import OUTCOME_COLORS, OUTCOME_NAMES

    stream = new_stream("mbicp-viz/basin")
    names = list(atlas.outcome)
    bp = rrb.Blueprint(
        rrb.Horizontal(
            *[
                y_up_view(f"/basin/{n}", f"{n}: outcome per initial offset (dx, dy) [m]")
                for n in names
            ]
        ),
        rrb.TimePanel(timeline="theta_offset", expanded=True),
        collapse_panels=True,
    )
    with saving(stream, path, bp):
        for n in names:
            log_y_up(stream, f"basin/{n}")
        for t, th in enumerate(atlas.thetas):
            stream.set_time("theta_offset", sequence=t)
            for n in names:
                for layer in scene.basin_layers(
                    n,
                    atlas.offsets_xy,
                    atlas.outcome[n][t],
                    OUTCOME_NAMES,
                    OUTCOME_COLORS,
                    math.degrees(th),
                ):
                    log_layer(stream, "", layer)
