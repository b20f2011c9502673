"""The rerun front end: events -> scene layers -> a rerun recording (stream or .rrd).

rerun is imported here only, and only by the commands that record. Every run lives under its own
entity root (``/improved``, ``/mbicp`` ...) so that several matchers sit side by side; the
``iteration`` timeline orders the steps (0 = the initial guess).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core import (Event, FinishEvent, IterationEvent, MatchResult, Observer, Params, Pose2, Scan, StartEvent,
                  broadcast, match, relative)

from . import scene
from .errors import InputError

APP_ID = "mbicp-viz"


def new_stream(recording_id: str, live: bool = False) -> rr.RecordingStream:
    """A stream with a fixed recording id and no wall-clock properties, so re-runs compare equal.

    Files are batched into chunks only at the end: chunk boundaries then do not depend on timing
    (``rerun rrd compare`` compares chunks). A live viewer gets rerun's default, timely batching.
    """
    batching = rr.ChunkBatcherConfig.DEFAULT() if live else rr.ChunkBatcherConfig.NEVER()
    return rr.RecordingStream(APP_ID, recording_id=recording_id, send_properties=False, batcher_config=batching)


ABOUT = "about"


POLAR_ROOTS = ("psm", "pmwn")


def blueprint(roots: list[str], teaching: bool = False, about: bool = False) -> rrb.Blueprint:
    """Scans side by side, error and threshold plots, the text log; time panel on ``iteration``.

    Polar matchers add their cost-per-shift and range-per-bearing plots (x in degrees).
    """
    scans = [rrb.Spatial2DView(origin=f"/{r}/{scene.SCANS}", name=f"{r}: scans") for r in roots]
    polar = [rrb.Tabs(rrb.Spatial2DView(origin=f"/{r}/{scene.POLAR}/cost", name=f"{r}: cost per shift"),
                      rrb.Spatial2DView(origin=f"/{r}/{scene.POLAR}/ranges", name=f"{r}: ranges per bearing"))
             for r in roots if r in POLAR_ROOTS]
    log = rrb.TextLogView(origin="/", contents=[f"/{r}/{scene.LOG}" for r in roots], name="log")
    side = [rrb.TimeSeriesView(origin="/", contents=[f"/{r}/{scene.PLOTS}/**" for r in roots],
                               name="error and threshold"),
            rrb.Tabs(rrb.TextDocumentView(origin=f"/{ABOUT}", name="what to look at"), log) if about else log]
    if teaching:
        side.insert(1, rrb.Tabs(*[rrb.Spatial2DView(origin=f"/{r}/{scene.TEACH}/histogram",
                                                    name=f"{r}: pair distances") for r in roots]))
    side = polar + side
    main = scans[0] if len(scans) == 1 else rrb.Horizontal(*scans)
    return rrb.Blueprint(rrb.Horizontal(main, rrb.Vertical(*side), column_shares=[3, 2]),
                         rrb.TimePanel(timeline="iteration", expanded=True), collapse_panels=True)


def _rgb(c):
    return np.asarray(c, dtype=np.uint8)


def log_layer(stream: rr.RecordingStream, root: str, layer, static: bool = False) -> None:
    path = f"{root}/{layer.path}"
    if isinstance(layer, scene.Points):
        stream.log(path, rr.Points2D(layer.xy, colors=_rgb(layer.color), radii=layer.radius), static=static)
    elif isinstance(layer, scene.Segments):
        strips = np.stack((layer.starts, layer.ends), axis=1) if len(layer.starts) else np.zeros((0, 2, 2))
        stream.log(path, rr.LineStrips2D(strips, colors=_rgb(layer.color), radii=layer.width), static=static)
    elif isinstance(layer, scene.Strips):
        stream.log(path, rr.LineStrips2D(layer.strips, colors=_rgb(layer.color), radii=layer.width), static=static)
    elif isinstance(layer, scene.Boxes):
        stream.log(path, rr.Boxes2D(centers=layer.centers, half_sizes=np.full((len(layer.centers), 2), layer.half_size),
                                    colors=layer.colors, labels=layer.labels, show_labels=False, radii=0.002,
                                    draw_order=-10.0), static=static)
    elif isinstance(layer, scene.Scalar):
        stream.log(path, rr.Scalars(layer.value), static=static)
    elif isinstance(layer, scene.Text):
        stream.log(path, rr.TextLog(layer.text, level=layer.level), static=static)
    elif isinstance(layer, scene.Frame):
        p = layer.pose
        stream.log(path, rr.Transform3D(translation=[p.x, p.y, 0.0],
                                        rotation_axis_angle=rr.RotationAxisAngle(axis=[0, 0, 1], radians=p.theta)),
                   static=static)
        stream.log(f"{path}/heading", rr.Arrows2D(origins=[[0.0, 0.0]], vectors=[[0.5, 0.0]],
                                                  colors=_rgb(scene.OBJECT), radii=0.01), static=static)
    else:  # pragma: no cover - a new layer type must be mapped here
        raise TypeError(f"unmapped layer {type(layer).__name__}")


class RerunObserver:
    """An observer that writes one run under ``root`` of a rerun stream as it happens."""

    def __init__(self, stream: rr.RecordingStream, root: str, teaching: bool = False):
        self.stream, self.root, self.teaching = stream, root, teaching
        self.start: StartEvent | None = None
        self.last_iteration = 0

    def __call__(self, ev: Event) -> None:
        if isinstance(ev, StartEvent):
            self.start = ev
            self._static_styles()
            for layer in scene.start_layers(ev):
                log_layer(self.stream, self.root, layer, static=True)
            self.stream.set_time("iteration", sequence=0)
            log_layer(self.stream, self.root, scene.Frame(f"{scene.SCANS}/estimate", ev.initial_guess))
            log_layer(self.stream, self.root,
                      scene.Points(f"{scene.SCANS}/object", ev.initial_guess.apply(ev.obj_points[ev.used]),
                                   scene.OBJECT, 0.02))
            log_layer(self.stream, self.root, scene.Text(scene.LOG, f"{ev.algorithm}: initial guess {ev.initial_guess}"))
        elif isinstance(ev, IterationEvent):
            self.last_iteration = ev.iteration
            self.stream.set_time("iteration", sequence=ev.iteration)
            layers = scene.iteration_layers(self.start, ev)
            if self.teaching:
                layers += scene.teaching_layers(self.start, ev)
            for layer in layers:
                log_layer(self.stream, self.root, layer)
        elif isinstance(ev, FinishEvent):
            self.stream.set_time("iteration", sequence=self.last_iteration)
            for layer in scene.finish_layers(ev):
                log_layer(self.stream, self.root, layer)

    def _static_styles(self) -> None:
        for name, color in (("error", scene.ERROR), ("threshold", scene.THRESHOLD)):
            self.stream.log(f"{self.root}/{scene.PLOTS}/{name}",
                            rr.SeriesLines(colors=_rgb(color), names=f"{self.root} {name}", widths=2.0), static=True)


@dataclass(frozen=True)
class Run:
    """One matcher run to record under ``root``; ``truth`` (if known) is drawn as a frame."""

    root: str
    ref: Scan
    obj: Scan
    guess: Pose2
    params: Params
    truth: Pose2 | None = None


def record(runs: list[Run], path: str | None = None, connect: str | None = None, teaching: bool = False,
           recording_id: str = "mbicp-viz", extra_observer: Observer | None = None,
           about: str | None = None) -> list[MatchResult]:
    """Match every run with a rerun observer attached; write ``path`` (.rrd) and/or stream to ``connect``.

    ``about`` (Markdown) is stored as a document beside the runs: what the recording shows.
    """
    stream = new_stream(recording_id, live=connect is not None)
    bp = blueprint([r.root for r in runs], teaching, about is not None)
    if path is not None:
        stream.save(path, default_blueprint=bp)
    if connect is not None:
        stream.connect_grpc(connect, default_blueprint=bp)
    if about is not None:
        stream.log(ABOUT, rr.TextDocument(about, media_type=rr.MediaType.MARKDOWN), static=True)
    results = []
    for r in runs:
        if r.truth is not None:
            log_layer(stream, r.root, scene.Points(f"{scene.SCANS}/truth", r.truth.apply(r.obj.points()),
                                                   scene.TRUTH, 0.008), static=True)
        obs = RerunObserver(stream, r.root, teaching)
        results.append(match(r.ref, r.obj, r.guess, r.params, obs if extra_observer is None
                             else broadcast(obs, extra_observer)))
    stream.flush()
    stream.disconnect()
    return results


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
    cmd = [exe, "--serve-web", "--bind", host, "--web-viewer-port", str(port), "--port", str(port + 1), path]
    return subprocess.call(cmd)


def record_sequence(log, rows: list[dict], path: str, recording_id: str = "mbicp-viz/sequence") -> None:
    """The matches of ``eval sequence`` on a ``scan`` timeline: trajectory, accumulated map, per-pair log."""
    stream = new_stream(recording_id)
    root = "sequence"
    bp = rrb.Blueprint(
        rrb.Horizontal(rrb.Spatial2DView(origin=f"/{root}/{scene.SEQUENCE}", name="trajectory and map"),
                       rrb.Vertical(rrb.TimeSeriesView(origin=f"/{root}/{scene.PLOTS}", name="iterations, time"),
                                    rrb.TextLogView(origin=f"/{root}/{scene.LOG}", name="pairs")),
                       column_shares=[3, 2]),
        rrb.TimePanel(timeline="scan", expanded=True), collapse_panels=True)
    stream.save(path, default_blueprint=bp)
    pose = Pose2()
    poses = [pose]
    for row in rows:
        poses.append(poses[-1] @ Pose2(row["x"], row["y"], row["theta"]))
    first = log.scans[rows[0]["ref"]].pose if rows and log.scans[rows[0]["ref"]].pose is not None else None
    by_obj = {row["obj"]: row for row in rows}
    indices = [rows[0]["ref"]] + [row["obj"] for row in rows] if rows else []
    for n, k in enumerate(indices):
        stream.set_time("scan", sequence=k)
        scan = log.scans[k]
        traj = np.array([[p.x, p.y] for p in poses[: n + 1]])
        log_traj = None
        if first is not None and all(log.scans[i].pose is not None for i in indices[: n + 1]):
            log_traj = np.array([[q.x, q.y] for q in (relative(first, log.scans[i].pose) for i in indices[: n + 1])])
        for layer in scene.sequence_layers(k, poses[n], scan.points(), traj, log_traj, by_obj.get(k)):
            log_layer(stream, root, layer)
    stream.flush()
    stream.disconnect()
