"""``bench``: how fast the matchers, the recordings, the debugger and the command itself answer."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from .options import (
    DEFAULT_MATCHER,
    MatcherOpt,
    PairOpt,
    ParamsOpt,
    TeachOpt,
    TopicOpt,
    check_perturb,
    read_log_saying,
    read_options,
    user_errors,
)
from .serve import DEMO_PAIR


def matches(
    log: Annotated[str, typer.Argument(help="scan log")],
    matcher: MatcherOpt = DEFAULT_MATCHER,
    params: ParamsOpt = None,
    limit: Annotated[int, typer.Option("--limit", min=1, help="consecutive pairs to time")] = 50,
    repeat: Annotated[int, typer.Option("--repeat", min=1, help="runs per pair")] = 3,
    rrd: Annotated[
        bool, typer.Option("--rrd", help="also time writing each match to an .rrd")
    ] = False,
    teach: TeachOpt = False,
    perturb: Annotated[
        tuple[float, float] | None,
        typer.Option(
            "--perturb",
            metavar="XY_M THETA_DEG",
            help="move each stored guess uniformly within +/-XY_M in x "
            "and y and +/-THETA_DEG (seeded)",
        ),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="seed of --perturb")] = 0,
    topic: TopicOpt = None,
):
    """Time per match on consecutive pairs: mean, median, p90, matches per second; events off and
    on."""
    import numpy as np

    from mbicp_viz.evaluation.bench import bench, machine_line, probe_line, speed_probe_us
    from mbicp_viz.readers.params_toml import make_params

    lg = read_log_saying(log, read_options(topic))
    p = make_params(matcher.value, params)
    typer.echo(f"{matcher.value} on {log}: {len(lg.scans[0].ranges)} beams; {machine_line()}")
    before = speed_probe_us()
    moved = None
    if perturb is not None:
        moved = check_perturb(perturb)
        typer.echo(
            f"guesses: the stored ones moved within +/-{perturb[0]:g} m, +/-{perturb[1]:g} deg "
            f"(seed {seed})"
        )
    timings = bench(lg, p, limit, repeat, moved, seed)
    after = speed_probe_us()
    for t in timings:
        typer.echo(t.line())
    typer.echo(probe_line(before, after))
    typer.echo(
        f"observer overhead      {100.0 * (timings[1].median / timings[0].median - 1.0):+.0f} % "
        "(median)"
    )
    if rrd:
        from mbicp_viz.views.timing import time_recordings

        t, sizes = time_recordings(lg, p, limit, 1, teach)
        typer.echo(t.line())
        typer.echo(
            f".rrd size              median {np.median(sizes) / 1e6:.2f} MB   max "
            f"{sizes.max() / 1e6:.2f} MB"
        )


def originals(
    built: Annotated[
        Path, typer.Argument(help="the folder tools/originals/build.sh built the C originals in")
    ],
    log: Annotated[str, typer.Argument(help="scan log")],
    limit: Annotated[int, typer.Option("--limit", min=1, help="consecutive pairs")] = 300,
    repeat: Annotated[
        int, typer.Option("--repeat", min=1, help="runs of all the pairs; the best is kept")
    ] = 3,
    perturb: Annotated[
        tuple[float, float],
        typer.Option(
            "--perturb",
            metavar="XY_M THETA_DEG",
            help="move each stored guess uniformly within +/-XY_M in x "
            "and y and +/-THETA_DEG (seeded)",
        ),
    ] = (0.3, 15.0),
    seed: Annotated[int, typer.Option("--seed", help="seed of --perturb")] = 0,
    every: Annotated[
        int,
        typer.Option(
            "--every",
            min=1,
            help="keep one beam in K (the C MbICP takes at "
            "most 361 rays: on more it is not compared)",
        ),
    ] = 1,
    params: Annotated[
        Path | None,
        typer.Option(
            "--params",
            help="improved MbICP's parameters, a TOML file or a preset (mbicp-viz params "
            "--presets): a last line with them",
        ),
    ] = None,
    topic: TopicOpt = None,
):
    """This MbICP, ICP and PL-ICP against the original C code on the same pairs (agreement,
    successes, time per match); improved MbICP against CSM's PL-ICP."""
    from mbicp_viz.evaluation.bench import machine_line, probe_line, speed_probe_us
    from mbicp_viz.evaluation.originals import (
        check_built,
        compare,
        every_kth_beam,
        improved_against_plicp,
        protocol_pairs,
    )
    from mbicp_viz.readers.params_toml import make_params

    check_built(built)  # a missing build or a bad file stops here, before minutes of matching
    improved = make_params("improved", params)
    lg = every_kth_beam(read_log_saying(log, read_options(topic)), every)
    pairs = protocol_pairs(lg, limit, check_perturb(perturb), seed)
    typer.echo(
        f"{log}: {len(pairs)} pairs of {len(pairs[0][0].bearings)} beams, guesses within "
        f"+/-{perturb[0]:g} m, "
        f"+/-{perturb[1]:g} deg (seed {seed}); {machine_line()}"
    )
    before = speed_probe_us()
    rows = compare(built, pairs, repeat)
    for row in rows:
        typer.echo(row.line())
    plicp = next(r for r in rows if r.name == "plicp")
    for label, p in [("as published", make_params("improved", None))] + (
        [(str(params), improved)] if params else []
    ):
        typer.echo(improved_against_plicp(pairs, p, label, plicp, repeat))
    typer.echo(probe_line(before, speed_probe_us()))


def gui(
    scans: Annotated[Path, typer.Argument(help="scan file")] = DEMO_PAIR,
    pair: PairOpt = None,
    topic: TopicOpt = None,
):
    """Latency of the debugger: iteration step -> redraw, parameter change -> re-match -> redraw."""
    from mbicp_viz.evaluation.bench import machine_line
    from mbicp_viz.views.debugger.latency import gui_latency

    typer.echo(f"viser debugger on {scans}; {machine_line()}")
    for t in gui_latency(str(scans), pair or (0, 1), read_options(topic)):
        typer.echo(t.line())


def run(
    log: Annotated[str, typer.Argument(help="the log the run matched")],
    rows: Annotated[str, typer.Argument(metavar="ROWS", help="its rows (eval sequence --out)")],
    steps: Annotated[int, typer.Option("--steps", min=2, help="slider steps over the run")] = 50,
    topic: TopicOpt = None,
):
    """Latency of the run view (serve LOG --rows ROWS), server side: opening it, and a slider step
    -> redraw."""
    from mbicp_viz.evaluation.bench import machine_line
    from mbicp_viz.views.debugger.latency import run_latency

    typer.echo(f"run view of {rows} on {log}; {machine_line()}")
    for t in run_latency(log, rows, read_options(topic), steps):
        typer.echo(t.line())


def page(
    log: Annotated[str, typer.Argument(help="the log the run matched")],
    rows: Annotated[str, typer.Argument(metavar="ROWS", help="its rows (eval sequence --out)")],
    repeat: Annotated[int, typer.Option("--repeat", min=1, help="openings to time")] = 5,
    browser: Annotated[
        str | None, typer.Option("--browser", help="Chromium to drive (default: on the PATH)")
    ] = None,
    topic: TopicOpt = None,
    steps: Annotated[
        int,
        typer.Option("--steps", min=0, help="slider steps of each kind to time at each opening"),
    ] = 10,
):
    """How soon the run view shows: `serve LOG --rows ROWS` started as a command, its page in a
    headless Chromium already running (Playwright, the test extra), until the run's legend shows;
    then how long a step of its slider takes, timed by the page from the key to the pair's words
    and two frames drawn: steps one right after another, and from the page at rest; and the same
    on a bare viser page (this browser's floor)."""
    from mbicp_viz.evaluation.bench import machine_line
    from mbicp_viz.views.debugger.page_timing import page_timings

    typer.echo(f"run view of {rows} on {log}, command to page; {machine_line()}")
    renderer, timings = page_timings(log, rows, repeat, browser, topic, steps)
    typer.echo(f"WebGL drawn by {renderer}")
    for t in timings:
        typer.echo(t.line())


def startup(repeat: Annotated[int, typer.Option("--repeat", min=3, help="runs of --help")] = 10):
    """How soon the tool answers: --help, the first match with an empty kernel cache, the
    debugger."""
    from mbicp_viz.evaluation.bench import machine_line
    from mbicp_viz.evaluation.bench import startup as startup_times

    from . import app

    script = Path(sys.executable).parent / "mbicp-viz"  # the installed command, as a user runs it
    exe = [str(script)] if script.exists() else [sys.executable, "-m", "mbicp_viz"]
    commands = [exe + ["--help"]] + [exe + name.split() + ["--help"] for name in command_names(app)]
    match = exe + ["match", str(DEMO_PAIR), "--pair", "0", "1", "--guess", "identity", "--json"]
    debugger = [
        sys.executable,
        "-c",
        "from mbicp_viz.views.debugger.latency import first_result_at; "
        f"print(first_result_at({str(DEMO_PAIR)!r}))",
    ]
    typer.echo(f"start-up; {machine_line()}")
    for t in startup_times(commands, match, debugger, repeat):
        typer.echo(t.line())


def bag(
    out: Annotated[Path, typer.Argument(metavar="OUT", help="the bag to write (a file or folder)")],
    source: Annotated[
        str, typer.Option("--from", help="the real recording whose scans are played to and fro")
    ],
    minutes: Annotated[
        float, typer.Option("--minutes", min=0.01, max=24 * 60, help="length of the bag")
    ] = 60.0,
    kind: Annotated[
        str, typer.Option("--kind", help="ros1 (.bag), humble (sqlite3 folder) or mcap (folder)")
    ] = "ros1",
    beams: Annotated[
        int | None,
        typer.Option("--beams", min=2, max=100_000, help="resample each scan to this many beams"),
    ] = None,
    rate_hz: Annotated[
        float | None,
        typer.Option("--rate-hz", min=0.1, max=1000, help="scans per second (default: the real)"),
    ] = None,
    topic: TopicOpt = None,
):
    """Write a long bag from a short real recording, for the benchmarks and big-file tests: its
    scans played forwards and backwards with their real intervals, mount and odometry."""
    import time

    from mbicp_viz.errors import InputError
    from mbicp_viz.outputs import written, written_folder
    from mbicp_viz.writers.bag import KINDS, write
    from mbicp_viz.writers.replay import replayed

    if kind not in KINDS:
        raise InputError(f"unknown bag kind {kind!r}; known: {', '.join(KINDS)}", field="--kind")
    if out.exists():
        raise InputError(f"{out} exists: give a new name", field="OUT")
    try:
        robot = replayed(
            read_log_saying(source, read_options(topic)), 60.0 * minutes, beams, rate_hz
        )
    except ValueError as e:
        raise InputError(str(e), field="--from") from None
    t0 = time.perf_counter()
    with (written if kind == "ros1" else written_folder)(out) as tmp:
        write(tmp, robot, kind)
    size = sum(f.stat().st_size for f in ([out] if out.is_file() else out.rglob("*")))
    scan = robot.topics[0].scans[0]
    typer.echo(
        f"{out}: {len(robot.stamps)} scans of {len(scan.ranges)} beams over "
        f"{robot.stamps[-1] - robot.stamps[0]:.0f} s ({kind}, {size / 1e6:.0f} MB, "
        f"written in {time.perf_counter() - t0:.0f} s)"
    )


def live(
    source: Annotated[
        str, typer.Option("--from", help="the real recording whose scans are played to and fro")
    ],
    seconds: Annotated[
        float, typer.Option("--seconds", min=1.0, help="length of the drive")
    ] = 30.0,
    beams: Annotated[
        int | None,
        typer.Option("--beams", min=2, max=100_000, help="resample each scan to this many beams"),
    ] = 1081,
    rate_hz: Annotated[float, typer.Option("--rate-hz", min=0.1, max=1000)] = 40.0,
    matcher: MatcherOpt = DEFAULT_MATCHER,
    params: ParamsOpt = None,
    topic: TopicOpt = None,
    page: Annotated[
        bool,
        typer.Option(
            "--page",
            help="with the live page's work alongside (drawn as for a tab, on a server no browser "
            "opens): how long each refresh of it takes",
        ),
    ] = False,
):
    """Does `live` keep up? A robot played by the Foxglove SDK's server at its own pace (a ROS 2
    MCAP bag written from a real recording: its scans resampled, odometry and mount), matched
    live: scans sent, matched and skipped, and how long after each scan arrived its result was
    ready."""
    import tempfile
    import time

    import numpy as np

    from mbicp_viz.core import tiers
    from mbicp_viz.errors import InputError
    from mbicp_viz.evaluation.bench import machine_line
    from mbicp_viz.live.publisher import FoxgloveRobot
    from mbicp_viz.live.run import LiveRun, steady_latency
    from mbicp_viz.readers.params_toml import read_params
    from mbicp_viz.writers.bag import write
    from mbicp_viz.writers.replay import replayed

    tiers.quick_start()
    p = read_params(params, [matcher.value]).matchers[matcher.value]
    try:
        robot = replayed(read_log_saying(source, read_options(topic)), seconds, beams, rate_hz)
    except ValueError as e:
        raise InputError(str(e), field="--from") from None
    with tempfile.TemporaryDirectory(prefix="mbicp-viz-bench-live-") as folder:
        bag = write(Path(folder) / "robot", robot, "mcap")
        server = FoxgloveRobot(next(bag.glob("*.mcap")))
        run = LiveRun(server.url, p, buffer_s=seconds + 10.0)
        tab = _live_page(run, Path(folder)) if page else None
        steady_latency()  # as `live` does
        try:
            # at the robot's own pace, once the run has subscribed to what it reads
            server.publish(tuple(t for t in server.channels if t in ("/scan", "/odom")), 1.0)
            deadline = time.monotonic() + 10.0  # the last frames still on the wire
            while run.snapshot()[0].scans < len(robot.stamps) and time.monotonic() < deadline:
                run.wait_idle(timeout_s=0.1)
            run.wait_idle(timeout_s=60.0)
            status, _ = run.snapshot()
            lags = np.array(run.lags) * 1000.0
        finally:
            if tab is not None:
                from mbicp_viz.views.debugger.app import stop_server

                tab.close()
                stop_server(tab.client)
            run.stop()
            server.stop()
    sent = len(robot.stamps)
    typer.echo(
        f"bench live: {sent} scans of {len(robot.topics[0].scans[0].ranges)} beams at "
        f"{rate_hz:g} Hz over {seconds:g} s, {matcher.value}; {machine_line()}"
    )
    typer.echo(
        f"received {status.scans}, matched {status.matched}, skipped {status.skipped} to keep up "
        f"({100.0 * status.skipped / max(status.scans, 1):.1f} %), unusable {status.unusable}"
    )
    if len(lags):
        typer.echo(
            f"result after the scan arrived: median {np.median(lags):.1f} ms, 95th percentile "
            f"{np.percentile(lags, 95):.1f} ms, max {lags.max():.1f} ms (a scan every "
            f"{1000.0 / rate_hz:.1f} ms)"
        )
    if tab is not None and tab.refresh_s:
        took = np.array(tab.refresh_s) * 1000.0
        typer.echo(
            f"the live page: {len(took)} refreshes, median {np.median(took):.1f} ms, max "
            f"{took.max():.1f} ms (one every {1000.0 * tab.every_s:.0f} ms)"
        )


def _live_page(run, folder: Path):
    """The live page's work for ``bench live --page``: a tab's drawing, on a server of its own."""
    from mbicp_viz.views.debugger.app import viser_server
    from mbicp_viz.views.debugger.live import LiveTab

    return LiveTab(viser_server("127.0.0.1", 0), run, folder, None)


def throughput(
    source: Annotated[
        str, typer.Option("--from", help="the real recording whose scans are played to and fro")
    ],
    beams: Annotated[
        str, typer.Option("--beams", help="beam counts to resample to, comma-separated")
    ] = "180,361,681,1081,1947",
    rate_hz: Annotated[float, typer.Option("--rate-hz", min=0.1, max=1000)] = 40.0,
    pairs: Annotated[
        int,
        typer.Option(
            "--pairs", min=2, help="consecutive pairs per run (a pool takes a while to start)"
        ),
    ] = 1000,
    repeat: Annotated[
        int,
        typer.Option(
            "--repeat", min=1, help="runs of each core count, alternated; the median is kept"
        ),
    ] = 3,
    matcher: MatcherOpt = DEFAULT_MATCHER,
    params: ParamsOpt = None,
    topic: TopicOpt = None,
):
    """A whole run's real-time factor (the recording's duration over the matching time) per beam
    count, on one core and on every core, the median of alternated runs: matched in memory as
    `eval sequence` matches it (with the pairs split between separate processes too: how far
    the cores scale by themselves), then `eval sequence` itself on a bag of the same run (its own
    pace: reading the bag, writing the rows)."""
    import os

    from mbicp_viz.errors import InputError
    from mbicp_viz.evaluation.bench import machine_line, probe_line, speed_probe_us
    from mbicp_viz.evaluation.throughput import from_bag
    from mbicp_viz.evaluation.throughput import throughput as run_throughput
    from mbicp_viz.readers.params_toml import make_params

    try:
        counts = [int(b) for b in beams.split(",")]
    except ValueError:
        raise InputError(
            f"expected whole numbers separated by commas, got {beams!r}", field="--beams"
        ) from None
    if any(not 2 <= b <= 100_000 for b in counts):
        raise InputError("each beam count must be 2 .. 100000", field="--beams")
    lg = read_log_saying(source, read_options(topic))
    p = make_params(matcher.value, params)
    cores = sorted({1, os.cpu_count() or 1})
    typer.echo(f"{matcher.value} on {source} played to and fro at {rate_hz:g} Hz; {machine_line()}")
    before = speed_probe_us()
    cli_params = ["--algo", matcher.value] + (["--params", params] if params else [])
    for b in counts:
        typer.echo(run_throughput(lg, p, b, pairs, rate_hz, cores, repeat).line())
        typer.echo(from_bag(lg, cli_params, b, pairs, rate_hz, cores, repeat).line())
    typer.echo(probe_line(before, speed_probe_us()))


def opening(
    log: Annotated[str, typer.Argument(help="the recording to open")],
    pair: PairOpt = None,
    repeat: Annotated[
        int, typer.Option("--repeat", min=1, help="runs of each; the best is kept")
    ] = 3,
    topic: TopicOpt = None,
):
    """How soon a recording opens, each in a fresh process: `match LOG --pair I J`, and the
    debugger to its first result; with each one's peak memory."""
    from mbicp_viz.evaluation.bench import machine_line
    from mbicp_viz.evaluation.throughput import opening as measure

    typer.echo(f"opening {log}; {machine_line()}")
    for t in measure(log, pair or (0, 1), repeat, topic):
        typer.echo(t.line())


def command_names(app: typer.Typer) -> list[str]:
    """Every command of the CLI as typed (``eval sequence``, ``bench startup`` ...)."""
    out = []
    for c in app.registered_commands:
        out.append(c.name)
    for group in app.registered_groups:
        out += [f"{group.name} {c.name}" for c in group.typer_instance.registered_commands]
    return out


def register(app: typer.Typer) -> None:
    group = typer.Typer(
        no_args_is_help=True, help="Time the matchers, the debugger and the start-up."
    )
    for name, fn in (
        ("matches", matches),
        ("originals", originals),
        ("gui", gui),
        ("run", run),
        ("page", page),
        ("startup", startup),
        ("bag", bag),
        ("throughput", throughput),
        ("live", live),
        ("open", opening),
    ):
        group.command(name)(user_errors(fn))
    app.add_typer(group, name="bench")
