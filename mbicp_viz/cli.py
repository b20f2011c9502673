"""The ``mbicp-viz`` command line. Thin glue: every command calls a function of the package."""

from __future__ import annotations

import functools
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import numpy as np
import typer

from core import MATCHERS, ParamError, Recorder, ScanError, match

from .errors import InputError
from .inputs import search_window_text

app = typer.Typer(no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False,
                  help="Visual debugger and teaching tool for 2-D laser scan matching (ICP, MbICP, improved MbICP).")
eval_app = typer.Typer(no_args_is_help=True, help="Evaluate matchers on whole logs.")
app.add_typer(eval_app, name="eval")

ALGOS = ", ".join(MATCHERS)
SEARCH = search_window_text()
FirstArg = Annotated[str, typer.Argument(help="reference scan file, or a log with --pair")]
SecondArg = Annotated[Optional[str], typer.Argument(help="object scan file")]
AlgoOpt = Annotated[str, typer.Option("--algo", help=f"matcher: {ALGOS}")]
ParamsOpt = Annotated[Optional[Path], typer.Option("--params", help="TOML file of matcher parameters")]
PairOpt = Annotated[Optional[tuple[int, int]], typer.Option(
    "--pair", help="scan indices I J of one log (ref obj; -1 is the last)")]
InitOpt = Annotated[Optional[tuple[float, float, float]], typer.Option(
    "--init", help="initial guess X Y THETA_DEG: object frame in the reference frame (m, m, deg)")]
RrdOpt = Annotated[Optional[Path], typer.Option("--rrd", help="write the run to this rerun .rrd file")]
TeachOpt = Annotated[bool, typer.Option("--teach", help="add teaching layers: iso-distance curves, distance histogram")]
ConnectOpt = Annotated[Optional[str], typer.Option(
    "--connect", help="stream into a running rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy")]
ServeOpt = Annotated[bool, typer.Option("--serve", help="serve rerun's web viewer on 127.0.0.1 with the run")]
PortOpt = Annotated[int, typer.Option("--port", min=1, max=65534, help="web viewer port for --serve (data: PORT+1)")]
WorkersOpt = Annotated[Optional[int], typer.Option("--workers", min=1, help="processes (default: all cores)")]
EXAMPLES = Path(__file__).parent / "examples"
DEMO_PAIR = EXAMPLES / "hokuyo-125-130.npz"


def finite(value: float) -> float:
    """Typer callback: bounds checks let inf (and NaN, with no lower bound) through."""
    if not math.isfinite(value):
        raise typer.BadParameter(f"must be a finite number, got {value}")
    return value


# Options that name a file a command writes, by the same names in every command.
OUTPUT_FILES = ("rrd", "out", "png", "tum", "tum_ref", "csv")


def check_outputs(options: dict) -> None:
    """Refuse an output file whose folder is missing or read-only before any work is done (a run
    must not end in an error after its work); make ``--out-dir`` when missing."""
    for name in OUTPUT_FILES:
        path, field = options.get(name), "--" + name.replace("_", "-")
        if not isinstance(path, Path):  # unset, or a flag (bench --rrd)
            continue
        if path.is_dir():
            raise InputError(f"{path} is a folder; give a file name", field=field)
        if not path.parent.is_dir():
            raise InputError(f"folder {path.parent} does not exist", field=field)
        if not os.access(path.parent, os.W_OK):
            raise InputError(f"folder {path.parent} is not writable", field=field)
    if isinstance(options.get("out_dir"), Path):
        try:
            options["out_dir"].mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(f"cannot make folder {options['out_dir']}: {e.strerror}", field="--out-dir") from None


def user_errors(fn):
    """Bad input ends in one readable line on stderr and exit code 2, never a traceback."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            check_outputs(kwargs)
            return fn(*args, **kwargs)
        except (InputError, ScanError, ParamError) as e:
            typer.echo(f"mbicp-viz: error: {e}", err=True)
            raise typer.Exit(2) from None

    return wrapper


def _print_match(ref, obj, guess, params, label: str, as_json: bool, indices=(0, 0)) -> None:
    from core.agreement import INLIER_RADIUS_M, inlier_fraction

    from .report import ITERATION_HEADER, iteration_line, result_lines
    from .sequence import result_row

    rec = None if as_json else Recorder()
    t0 = time.perf_counter()
    result = match(ref, obj, guess, params, rec)
    ms = 1000.0 * (time.perf_counter() - t0)
    on_ref = inlier_fraction(ref, obj, result.pose)
    if as_json:
        typer.echo(json.dumps(result_row(*indices, result, ms) | result.as_dict() | {"on_ref": on_ref}))
        return
    typer.echo(f"{label}\ninitial guess {guess}\n")
    typer.echo(ITERATION_HEADER)
    for e in rec.iterations:
        typer.echo(iteration_line(e))
    typer.echo("")
    for line in result_lines(result):
        typer.echo(line)
    typer.echo(f"on ref      {100 * on_ref:.1f} % of the object points lie within {100 * INLIER_RADIUS_M:.0f} cm "
               "of a reference point")
    typer.echo(f"time        {ms:.1f} ms (with the recording observer)")


@app.command("match")
@user_errors
def match_cmd(
    first: FirstArg,
    second: SecondArg = None,
    pair: PairOpt = None,
    algo: AlgoOpt = "improved",
    init: InitOpt = None,
    params: ParamsOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object with the result fields")] = False,
    rrd: RrdOpt = None,
    teach: TeachOpt = False,
    connect: ConnectOpt = None,
    serve: ServeOpt = False,
    port: PortOpt = 9090,
    search: Annotated[bool, typer.Option("--search", help=f"first search the pose within {SEARCH} of the guess "
                                         "(correlative search), then match from the best")] = False,
):
    """Match two scans and show every iteration (optionally recorded for rerun's viewer)."""
    from .inputs import guess_from_deg, load_pair, make_params, stored_guess

    p = make_params(algo, params)
    sp = load_pair(first, second, pair)
    guess = guess_from_deg(init) or stored_guess(sp.ref, sp.obj)[0]
    if search:
        from core.search import correlative_search

        found = correlative_search(sp.ref, sp.obj, guess)
        if not as_json:
            typer.echo(f"searched around {guess}: best {found.pose} (score {found.score:.1f})")
        guess = found.pose
    indices = (0, 0) if second else (pair or (0, 1))  # scan index within each file
    _print_match(sp.ref, sp.obj, guess, p, sp.label, as_json, indices)
    if rrd or connect or serve:
        from .rrd import Run
        _record([Run(algo, sp.ref, sp.obj, guess, p)], rrd, connect, serve, port, teach)


def _record(runs, rrd, connect, serve, port, teach) -> None:
    """Write the runs to an .rrd, stream them to a viewer, and/or serve them on 127.0.0.1."""
    import tempfile

    from .rrd import record, serve as serve_rrd

    path = str(rrd) if rrd else (tempfile.mkdtemp(prefix="mbicp-viz-") + "/match.rrd" if serve else None)
    record(runs, path, connect, teach)
    if path:
        typer.echo(f"recording written to {path} (open it with: rerun {path})", err=True)
    if serve:
        typer.echo(f"serving rerun's web viewer on http://127.0.0.1:{port} (Ctrl-C stops)", err=True)
        serve_rrd(path, port)


@app.command()
@user_errors
def serve(
    first: Annotated[Optional[str], typer.Argument(help="a scan log, or the reference scan file")] = None,
    second: Annotated[Optional[str], typer.Argument(help="the object scan file")] = None,
    scenario: Annotated[Optional[str], typer.Option("--scenario", help="a curated scenario of recordings/")] = None,
    host: Annotated[str, typer.Option("--host", help="address to bind; anything but 127.0.0.1 exposes the app")]
    = "127.0.0.1",
    port: Annotated[int, typer.Option("--port", min=0, max=65535, help="port (0: any free port)")] = 8080,
    for_seconds: Annotated[Optional[float], typer.Option("--for-seconds", min=0.0, help="stop after this long")]
    = None,
):
    """The interactive debugger in the browser: step, play, tune live, compare, export."""
    from .viser_app import source_for

    _serve(source_for(first, second, scenario), host, port, for_seconds)


@app.command()
@user_errors
def demo(
    port: Annotated[int, typer.Option("--port", min=0, max=65535, help="port (0: any free port)")] = 8080,
    for_seconds: Annotated[Optional[float], typer.Option("--for-seconds", min=0.0, help="stop after this long")]
    = None,
):
    """The debugger on a bundled real pair: a hand-held Hokuyo turning 17 degrees, from the identity."""
    from core import Pose2

    from .readers import read_log
    from .viser_app import Source

    log = read_log(str(DEMO_PAIR))
    _serve(Source("bundled example: hand-held Hokuyo URG-04LX, scans 125 -> 130", log, guess=Pose2()),
           "127.0.0.1", port, for_seconds)


def _serve(source, host: str, port: int, for_seconds: float | None) -> None:
    from .viser_app import App

    if host != "127.0.0.1":
        typer.echo(f"warning: binding {host}: anyone who can reach this machine can use the app", err=True)
    application = App(source, host, port)
    typer.echo(f"mbicp-viz: open http://{'127.0.0.1' if host in ('127.0.0.1', '0.0.0.0') else host}:"
               f"{application.port} in a browser (Ctrl-C stops)")
    try:
        time.sleep(for_seconds) if for_seconds is not None else application.server.sleep_forever()
    except KeyboardInterrupt:
        pass
    finally:
        application.stop()


@eval_app.command("sequence")
@user_errors
def eval_sequence(
    log: Annotated[str, typer.Argument(help="scan log")],
    out: Annotated[Path, typer.Option("--out", help="JSON file: one object per consecutive pair")],
    algo: AlgoOpt = "improved",
    params: ParamsOpt = None,
    limit: Annotated[Optional[int], typer.Option("--limit", min=1, help="match only the first N pairs")] = None,
    rrd: RrdOpt = None,
    guess: Annotated[str, typer.Option("--guess", help="initial guess: stored (poses, else odometry, else "
                                       "identity), pose, odometry, identity, or search (a correlative search "
                                       f"within {SEARCH} of the identity)")] = "stored",
    truth: Annotated[Optional[str], typer.Option("--truth", help="'pose': score against the log's scan poses "
                                                 "(corrected logs)")] = None,
    png: Annotated[Optional[Path], typer.Option("--png", help="plot the trajectories and the map")] = None,
    tum: Annotated[Optional[Path], typer.Option("--tum", help="write the trajectory in TUM format (for evo)")] = None,
    tum_ref: Annotated[Optional[Path], typer.Option("--tum-ref", help="write the log's scan poses in TUM format")]
    = None,
    kalman: Annotated[bool, typer.Option("--kalman", help="fuse the matches with the log's odometry (EKF, "
                                         "paper 003 §5.3); the TUM file and map then use the fused track")] = False,
    workers: WorkersOpt = None,
):
    """Match every consecutive pair of a log (initial guess from its poses or odometry, else identity)."""
    from core.agreement import INLIER_RADIUS_M

    from .inputs import make_params
    from .readers import read_log
    from .sequence import GUESSES, match_sequence, truth_doubted

    if guess not in GUESSES:
        raise InputError(f"choose one of {', '.join(GUESSES)}", field="--guess")
    if truth not in (None, "pose"):
        raise InputError("the only truth a log carries is 'pose'", field="--truth")
    p = make_params(algo, params)
    lg = read_log(log)
    total = min(limit or len(lg.scans) - 1, len(lg.scans) - 1)
    with typer.progressbar(length=total, label="matching", file=sys.stderr) as bar:
        rows = match_sequence(lg, p, limit, guess, truth, on_row=lambda _: bar.update(1), workers=workers)
    if not rows:
        raise InputError("interrupted before the first pair was matched", log)
    out.write_text(json.dumps(rows, indent=1) + "\n")
    conv = sum(r["converged"] for r in rows)
    cut = "" if len(rows) == total else f" (interrupted after {len(rows)} of {total}: the rows so far are kept)"
    typer.echo(f"{len(rows)} pairs matched with {algo}: {conv} converged; written to {out}{cut}")
    if truth:
        ok = sum(r["success"] for r in rows)
        typer.echo(f"against the scan poses: {ok}/{len(rows)} within 0.1 m and 3 deg ({100.0 * ok / len(rows):.1f} %)")
        doubted = sum(truth_doubted(r) for r in rows)
        typer.echo(f"failures where more object points lie within {100 * INLIER_RADIUS_M:.0f} cm of the reference "
                   f"at the matched pose than at the scan poses: {doubted} of {len(rows) - ok}")
    if png or tum or tum_ref or kalman:
        _trajectories(lg, rows, png, tum, tum_ref, kalman)
    if rrd:
        from .rrd import record_sequence

        record_sequence(lg, rows, str(rrd))
        typer.echo(f"sequence recording written to {rrd}; open a pair's iterations with: "
                   f"mbicp-viz match {log} --pair I J --algo {algo} --rrd pair.rrd", err=True)


def _trajectories(lg, rows, png, tum, tum_ref, use_kalman) -> None:
    from .trajectory import accumulate, kalman, log_poses, plot_png, tum_text

    idx = [rows[0]["ref"]] + [r["obj"] for r in rows]
    tracks = {"matcher": accumulate(rows)}
    ref = log_poses(lg, rows)
    if ref is not None:
        tracks["log poses"] = ref
    main = "matcher"
    if use_kalman:
        odo = [lg.scans[i].odometry for i in idx]
        if any(o is None for o in odo):
            raise InputError("--kalman needs odometry for every scan; this log has none", lg.path, field="--kalman")
        tracks["kalman (matcher + odometry)"] = kalman(rows, odo, (0.05, 0.05, math.radians(2.0)),
                                                       (0.02, 0.02, math.radians(0.5)))
        main = "kalman (matcher + odometry)"
    stamps = [lg.scans[i].stamp if lg.scans[i].stamp is not None else float(i) for i in idx]
    if tum:
        tum.write_text(tum_text(tracks[main], stamps))
    if tum_ref:
        if ref is None:
            raise InputError("the log stores no scan poses to export", lg.path, field="--tum-ref")
        tum_ref.write_text(tum_text(ref, stamps))
    if png:
        plot_png(lg, rows, tracks, str(png), main)


@eval_app.command("protocol")
@user_errors
def eval_protocol(
    log: Annotated[str, typer.Argument(help="scan log")],
    algo: AlgoOpt = "improved",
    params: ParamsOpt = None,
    cases: Annotated[int, typer.Option("--cases", min=1, help="number of random cases")] = 200,
    seed: Annotated[int, typer.Option("--seed", min=0, help="random seed")] = 24,
    max_xy: Annotated[float, typer.Option("--max-xy", min=0.0, callback=finite,
                                          help="largest |x|, |y| of the guess [m]")] = 0.2,
    max_theta_deg: Annotated[float, typer.Option("--max-theta-deg", min=0.0, max=180.0,
                                                 help="largest |theta| of the guess [deg]")] = 45.0,
):
    """MbICP's own protocol: every case matches a scan against itself from a random guess."""
    import math

    from .inputs import make_params
    from .protocols import displaced_self_matches
    from .readers import read_log

    p = make_params(algo, params)
    res = displaced_self_matches(read_log(log).scans, cases, p, seed, max_xy, math.radians(max_theta_deg))
    ok = sum(c.error_m < 0.01 and c.error_rad < math.radians(0.1) for c in res)
    gross = sum(c.error_m > 0.1 or c.error_rad > math.radians(3.0) for c in res)
    its = sorted(c.iterations for c in res)
    typer.echo(f"{algo}: {ok}/{cases} within 1 cm and 0.1 deg ({100.0 * ok / cases:.1f} %); {gross} off by more than "
               f"0.1 m or 3 deg; median {its[len(its) // 2]} iterations")


@eval_app.command("overlap")
@user_errors
def eval_overlap(
    logs: Annotated[list[str], typer.Argument(help="scan logs; scenes are picked evenly from each")],
    scenes_per_log: Annotated[int, typer.Option("--scenes-per-log", min=1, help="scenes taken from each log")] = 1,
    scans: Annotated[Optional[str], typer.Option("--scans", help="explicit scene indices I,J,... (one log)")] = None,
    ratios: Annotated[str, typer.Option("--ratios", help="kept fractions in %")] = "100,90,80,70,60",
    runs: Annotated[int, typer.Option("--runs", min=1, help="random displacements per scene and ratio")] = 10,
    removal: Annotated[str, typer.Option("--removal", help="block (occlusion-like) or random")] = "block",
    thin: Annotated[str, typer.Option("--thin", help="the copy that loses the points: reference (its object "
                                      "points then lack counterparts) or object")] = "reference",
    algos: Annotated[str, typer.Option("--algos", help="comma-separated matchers")] = ",".join(MATCHERS),
    params: ParamsOpt = None,
    seed: Annotated[int, typer.Option("--seed", min=0, help="random seed")] = 0,
    max_xy: Annotated[float, typer.Option("--max-xy", min=0.0, callback=finite,
                                          help="largest |x|, |y| of a displacement [m]")] = 0.5,
    max_theta_deg: Annotated[float, typer.Option("--max-theta-deg", min=0.0, max=180.0,
                                                 help="largest |theta| of a displacement [deg]")] = 15.0,
    csv: Annotated[Optional[Path], typer.Option("--csv", help="write every run as CSV")] = None,
    png: Annotated[Optional[Path], typer.Option("--png", help="write a plot")] = None,
    workers: WorkersOpt = None,
):
    """Paper 000's partial-overlap protocol (§3.1): Tables 1-3 for each matcher, as Markdown."""
    import math

    from .inputs import number_list, params_for
    from .overlap import csv_text, make_cases, markdown, plot_png, run_overlap, tables
    from .scenarios import THIN
    from .readers import read_log

    if removal not in ("block", "random"):
        raise InputError("choose block or random", field="--removal")
    if thin not in THIN:
        raise InputError(f"choose {' or '.join(THIN)}", field="--thin")
    etas = [v / 100.0 for v in number_list(ratios, "--ratios", "100,90,80")]
    if not all(0.0 < e <= 1.0 for e in etas):
        raise InputError("each ratio must lie in (0, 100]", field="--ratios")
    ps = params_for(algos, params)
    scenes = []
    for lg in (read_log(p) for p in logs):
        if scans:
            idx = number_list(scans, "--scans", "3,10,25", int)
        else:
            idx = [int(round(k)) for k in np.linspace(0, len(lg.scans) - 1, scenes_per_log + 2)[1:-1]]
        scenes += [lg.scan(i) for i in idx]
    cases = make_cases(scenes, etas, runs, removal, seed, max_xy, math.radians(max_theta_deg), thin)
    total = len(cases)
    t0 = time.perf_counter()
    with typer.progressbar(length=total, label="matching", file=sys.stderr) as bar:
        done = [0]

        def progress(rows):
            n = len(rows) // len(ps)
            bar.update(n - done[0])
            done[0] = n

        rows = run_overlap(scenes, ps, cases, workers, progress)
    took = time.perf_counter() - t0
    tab = tables(rows)
    typer.echo(markdown(tab))
    typer.echo(f"{len(rows)} matches ({len(rows) // max(len(ps), 1)}/{total} cases) in {took:.1f} s; "
               f"{len(scenes)} scenes, removal {removal} from the {thin}, seed {seed}", err=True)
    if csv:
        csv.write_text(csv_text(rows))
    if png:
        plot_png(tab, str(png))


@eval_app.command("ceiling")
@user_errors
def eval_ceiling(
    log: Annotated[str, typer.Argument(help="scan log whose scan poses are the truth (corrected logs)")],
    algos: Annotated[str, typer.Option("--algos", help="comma-separated matchers")] = ",".join(MATCHERS),
    params: ParamsOpt = None,
    limit: Annotated[Optional[int], typer.Option("--limit", min=1, help="only the first N pairs")] = None,
    workers: WorkersOpt = None,
):
    """How well any guess could do on a log: each matcher started at the truth, and the search alone."""
    from core.agreement import INLIER_RADIUS_M

    from .inputs import params_for
    from .readers import read_log
    from .sequence import ceiling

    by_name = params_for(algos, params)
    names, ps = list(by_name), list(by_name.values())
    lg = read_log(log)
    total = min(limit or len(lg.scans) - 1, len(lg.scans) - 1)
    with typer.progressbar(length=total, label="matching", file=sys.stderr) as bar:
        found, kept, doubted, n = ceiling(lg, ps, limit, workers, on_row=lambda _: bar.update(1))
    if n == 0:
        raise InputError("interrupted before the first pair was matched", log)
    typer.echo(f"correlative search alone: {found}/{n} within 0.1 m and 3 deg ({100 * found / n:.1f} %)")
    for name, k, d in zip(names, kept, doubted):
        typer.echo(f"{name} started at the scan poses: {k}/{n} stay within 0.1 m and 3 deg ({100 * k / n:.1f} %); "
                   f"of the {n - k} it leaves, {d} lay more object points within {100 * INLIER_RADIUS_M:.0f} cm of the "
                   "reference")


@eval_app.command("relations")
@user_errors
def eval_relations(
    log: Annotated[str, typer.Argument(help="scan log with time stamps")],
    relations: Annotated[str, typer.Argument(help="relations file (t1 t2 x y z roll pitch yaw)")],
    algo: AlgoOpt = "improved",
    params: ParamsOpt = None,
    offset: Annotated[float, typer.Option("--offset", callback=finite,
                                          help="seconds added to the log's stamps (Intel corrected: "
                                          "976052857.337)")] = 0.0,
    tolerance: Annotated[float, typer.Option("--tolerance", min=0.0, callback=finite,
                                             help="largest stamp mismatch [s]")] = 0.025,
    guess: Annotated[str, typer.Option("--guess", help="identity, pose, odometry or search (a correlative search "
                                       f"within {SEARCH} of the identity)")] = "identity",
    out: Annotated[Optional[Path], typer.Option("--out", help="JSON file: one object per matched relation")] = None,
):
    """Match the two scans of each relation (Kümmerle et al. 2009) and report the errors."""
    from .inputs import make_params
    from .readers import read_log
    from .relations import match_relations, read_relations, stored_summary, summary

    if guess not in ("identity", "pose", "odometry", "search"):
        raise InputError("choose identity, pose, odometry or search", field="--guess")
    rows, missing = match_relations(read_log(log), read_relations(relations), make_params(algo, params), offset,
                                    tolerance, guess)
    if out:
        out.write_text(json.dumps(rows, indent=1) + "\n")
    typer.echo(f"{algo}: {summary(rows)} ({missing} relations without a scan at both ends)")
    if stored := stored_summary(rows):
        typer.echo(stored)


@eval_app.command("basin")
@user_errors
def eval_basin(
    first: FirstArg,
    second: SecondArg = None,
    pair: PairOpt = None,
    truth: Annotated[Optional[tuple[float, float, float]], typer.Option(
        "--truth", help="the answer X Y THETA_DEG (default: the stored poses, else each matcher's own)")] = None,
    algos: Annotated[str, typer.Option("--algos", help="comma-separated matchers")] = ",".join(MATCHERS),
    params: ParamsOpt = None,
    range_xy: Annotated[float, typer.Option("--range-xy", min=0.0, callback=finite,
                                            help="largest |dx|, |dy| offset [m]")] = 1.0,
    steps: Annotated[int, typer.Option("--steps", min=2, max=201, help="grid points per axis")] = 11,
    thetas_deg: Annotated[str, typer.Option("--thetas-deg", help="theta offsets [deg]")] = "-30,-15,0,15,30",
    png: Annotated[Optional[Path], typer.Option("--png", help="write the atlas as a PNG")] = None,
    rrd: RrdOpt = None,
    workers: WorkersOpt = None,
):
    """A convergence atlas: every matcher from a grid of initial offsets, coloured by outcome."""
    import math

    from .basin import basin, plot_png, record_rrd, summary
    from .inputs import guess_from_deg, load_pair, number_list, params_for

    thetas = [math.radians(v) for v in number_list(thetas_deg, "--thetas-deg", "-15,0,15")]
    ps = params_for(algos, params)
    sp = load_pair(first, second, pair)
    answer = guess_from_deg(truth, "--truth")
    if answer is None and sp.ref.pose is not None and sp.obj.pose is not None:
        from core import relative

        answer = relative(sp.ref.pose, sp.obj.pose)
    t0 = time.perf_counter()
    atlas = basin(sp.ref, sp.obj, ps, answer, range_xy, steps, thetas, workers)
    typer.echo(summary(atlas))
    typer.echo(f"{len(ps) * len(thetas) * steps * steps} matches in {time.perf_counter() - t0:.1f} s", err=True)
    if png:
        plot_png(atlas, str(png))
    if rrd:
        record_rrd(atlas, str(rrd))


@app.command("bench")
@user_errors
def bench_cmd(
    log: Annotated[str, typer.Argument(help="scan log")],
    algo: AlgoOpt = "improved",
    params: ParamsOpt = None,
    limit: Annotated[int, typer.Option("--limit", min=1, help="consecutive pairs to time")] = 50,
    repeat: Annotated[int, typer.Option("--repeat", min=1, help="runs per pair")] = 3,
    rrd: Annotated[bool, typer.Option("--rrd", help="also time writing each match to an .rrd")] = False,
    teach: TeachOpt = False,
):
    """Time per match on consecutive pairs: median, p90, matches per second; events off and on."""
    import numpy as np

    from .bench import bench, machine_line, speed_probe_us
    from .inputs import make_params
    from .readers import read_log

    lg = read_log(log)
    typer.echo(f"{algo} on {log}: {len(lg.scans[0].ranges)} beams; {machine_line()}")
    before = speed_probe_us()
    timings = bench(lg, make_params(algo, params), limit, repeat)
    after = speed_probe_us()
    for t in timings:
        typer.echo(t.line())
    typer.echo(f"machine speed probe    {before:.2f} us before, {after:.2f} us after (a fixed numpy workload; "
               "lower is faster)")
    typer.echo(f"observer overhead      {100.0 * (timings[1].median / timings[0].median - 1.0):+.0f} % (median)")
    if rrd:
        from .bench import time_recordings

        t, sizes = time_recordings(lg, make_params(algo, params), limit, 1, teach)
        typer.echo(t.line())
        typer.echo(f".rrd size              median {np.median(sizes) / 1e6:.2f} MB   max {sizes.max() / 1e6:.2f} MB")


@app.command("record")
@user_errors
def record_cmd(
    names: Annotated[Optional[list[str]], typer.Argument(help="scenario names (default: all)")] = None,
    out_dir: Annotated[Optional[Path], typer.Option("--out-dir",
                                                    help="write the .rrd files here (made if missing)")] = None,
):
    """Regenerate the curated recordings (recordings/*.rrd) from recordings/scenarios/*.toml."""
    from .recordings import record_all

    for s, out, lines in record_all(names, out_dir=out_dir):
        typer.echo(f"{out}  ({s.title})")
        for line in lines:
            typer.echo(f"    {line}")


@app.command("compare")
@user_errors
def compare_cmd(
    first: FirstArg,
    second: SecondArg = None,
    pair: PairOpt = None,
    init: InitOpt = None,
    truth: Annotated[Optional[tuple[float, float, float]], typer.Option(
        "--truth", help="known answer X Y THETA_DEG, to print each matcher's error")] = None,
    params: ParamsOpt = None,
    algos: Annotated[str, typer.Option("--algos", help="comma-separated matchers")] = ",".join(MATCHERS),
    rrd: RrdOpt = None,
    teach: TeachOpt = False,
    connect: ConnectOpt = None,
    serve: ServeOpt = False,
    port: PortOpt = 9090,
):
    """Run several matchers on one pair and print one table (each under its own root in --rrd)."""
    from .compare import compare_table
    from .inputs import guess_from_deg, load_pair, params_for, stored_guess
    from .rrd import Run

    ps = params_for(algos, params)
    sp = load_pair(first, second, pair)
    guess = guess_from_deg(init) or stored_guess(sp.ref, sp.obj)[0]
    known = guess_from_deg(truth, "--truth")
    typer.echo(f"{sp.label}\ninitial guess {guess}\n")
    typer.echo(compare_table(sp.ref, sp.obj, guess, ps, known))
    if rrd or connect or serve:
        _record([Run(a, sp.ref, sp.obj, guess, p, known) for a, p in ps.items()], rrd, connect, serve, port, teach)


@app.command("bench-gui")
@user_errors
def bench_gui_cmd(
    scans: Annotated[Path, typer.Argument(help="scan file")] = DEMO_PAIR,
    pair: PairOpt = None,
):
    """Latency of the debugger: iteration step -> redraw, parameter change -> re-match -> redraw."""
    from .bench import gui_latency, machine_line

    typer.echo(f"viser debugger on {scans}; {machine_line()}")
    for t in gui_latency(str(scans), pair or (0, 1)):
        typer.echo(t.line())


@app.command("params")
@user_errors
def params_cmd(algo: AlgoOpt = "improved",
               out: Annotated[Optional[Path], typer.Option("--out", help="write to this file")] = None):
    """Print (or write) the default parameters of a matcher as a TOML file for --params."""
    from .inputs import make_params
    from .params_io import params_to_toml

    text = params_to_toml(make_params(algo, None))
    if out:
        out.write_text(text)
    else:
        typer.echo(text, nl=False)


def main() -> None:
    app()


if __name__ == "__main__":
    sys.exit(main())
