"""``bench-gui``: the debugger's latency on a real pair, server side (a real ViserServer, no
browser)."""

from __future__ import annotations

import time

import numpy as np

from mbicp_viz.core import Pose2
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.bench import Timing
from mbicp_viz.readers import ReadOptions, read_log

from .app import stop_server, viser_server
from .session import Session
from .state import Source


def gui_latency(
    path: str,
    pair: tuple[int, int],
    options: ReadOptions | None = None,
    steps: int = 3,
    changes: int = 40,
) -> tuple[Timing, Timing]:
    """Iteration step -> redraw, and parameter change -> re-match -> redraw, as a user drives
    them."""
    log = read_log(path, options)
    server = viser_server("127.0.0.1", 0)
    s = Session(server, Source(path, log, pair=pair, guess=Pose2(), options=options))
    try:
        step_ms = []
        for _ in range(steps):
            for k in range(s.state.max_iteration() + 1):
                t0 = time.perf_counter()
                s.playback.slider.value = k
                step_ms.append(1000.0 * (time.perf_counter() - t0))
        change_ms = []
        for v in np.linspace(0.5, 1.5, changes):  # the radial window Br [m], a value a user types
            t0 = time.perf_counter()
            s.matchers.params.boxes["Br"].handle.value = f"{float(v)!r}\n"  # typed, then Enter
            change_ms.append(1000.0 * (time.perf_counter() - t0))
        return (
            Timing("iteration step redraw", np.array(step_ms), "steps"),
            Timing("parameter change", np.array(change_ms), "changes"),
        )
    finally:
        s.close()
        stop_server(server)


def first_result_at(
    path: str, pair: tuple[int, int] | None = None, topic: str | None = None
) -> float:
    """When (``time.monotonic()`` [s]) a tab's first result is drawn, as ``serve PATH [--pair I
    J]`` opens it: the log read, a debugger on its first pair (or ``pair``), its kernels compiled
    (or loaded from numba's cache), one session's match drawn. Printed by a fresh process, it
    times the opening from the process's launch (``bench.run_measured``)."""
    from .app import App
    from .sources import files_source

    app = App(files_source(path, None, pair, options=ReadOptions(topic=topic)), "127.0.0.1", 0)
    try:
        s = Session(app.server, app.source, app.ready)
        s.first_match(app.ready)
        assert s.state.runs
        return time.monotonic()
    finally:
        app.stop()


def run_latency(
    path: str, rows: str, options: ReadOptions | None = None, steps: int = 50
) -> tuple[Timing, Timing]:
    """The run view, server side: from the log and its rows to the run drawn (read, first match,
    the run's trajectories and map sent), and a slider step over the run -> its redraw."""
    from .sources import files_source

    server = viser_server("127.0.0.1", 0)
    t0 = time.perf_counter()
    s = Session(server, files_source(path, None, options=options, rows=rows))
    try:
        if s.run is None:
            raise InputError("these rows are no run (eval sequence writes one)", rows, field="ref")
        opened = 1000.0 * (time.perf_counter() - t0)
        step_ms = []
        for v in np.linspace(1, len(s.run.model.rows), steps).round().astype(int):
            t0 = time.perf_counter()
            s.run.slider.value = int(v)  # the slider's callback redraws, as a user's drag does
            step_ms.append(1000.0 * (time.perf_counter() - t0))
        return (
            Timing("open the run", np.array([opened]), "opens"),
            Timing("run slider step redraw", np.array(step_ms), "steps"),
        )
    finally:
        s.close()
        stop_server(server)
