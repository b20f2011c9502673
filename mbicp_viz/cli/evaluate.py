"""``eval``: matchers on whole logs, against stored poses, relations or known displacements."""

from __future__ import annotations

import math
import time
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from mbicp_viz.choices import DEFAULT_TYPESTORE, MATCH_BUDGET_S, Removal, Thin
from mbicp_viz.errors import InputError
from mbicp_viz.outputs import write_text

from .options import (
    ALL_MATCHERS,
    DEFAULT_MATCHER,
    SEARCH,
    BudgetOpt,
    CaseGuessOpt,
    CaseTruthOpt,
    CloseLoopsOpt,
    DeskewOpt,
    FirstArg,
    Frame,
    FrameOpt,
    Guess,
    GuessOpt,
    KeyframeDegOpt,
    KeyframeOpt,
    LoopGapOpt,
    MatcherOpt,
    MatchersOpt,
    MountOpt,
    OffsetOpt,
    PairOpt,
    ParamsOpt,
    PerturbOpt,
    Progress,
    RelationsOpt,
    RrdOpt,
    SecondArg,
    SeedOpt,
    ToleranceOpt,
    TopicOpt,
    TypestoreOpt,
    UpsideDownOpt,
    WorkersOpt,
    cases_options,
    check_perturb,
    closed_run,
    finite,
    number_list,
    params_for,
    pose_from_deg,
    read_log_saying,
    read_options,
    say,
    user_errors,
)
from .resume import Plan, log_identity, matched_rows, settings_of
from .serve import ServePortOpt, started_debugger, until_ctrl_c

LogArg = Annotated[str, typer.Argument(help="scan log")]
LimitOpt = Annotated[int | None, typer.Option("--limit", min=1, help="only the first N pairs")]
MaxXyOpt = Annotated[
    float,
    typer.Option(
        "--max-xy", min=0.0, callback=finite, help="largest |x|, |y| of a random displacement [m]"
    ),
]
MaxThetaDegOpt = Annotated[
    float,
    typer.Option(
        "--max-theta-deg", min=0.0, max=180.0, help="largest |theta| of a random displacement [deg]"
    ),
]


RowsOutOpt = Annotated[
    Path,
    typer.Option(
        "--out",
        help="rows file (JSON lines, one per consecutive pair), written as OUT.partial while "
        "the pairs are matched; a stopped run resumes from it",
    ),
]
PoseTruthOpt = Annotated[
    str | None,
    typer.Option("--truth", help="'pose': score against the log's scan poses (corrected logs)"),
]
PngOpt = Annotated[Path | None, typer.Option("--png", help="plot the trajectories and the map")]
TumOpt = Annotated[
    Path | None, typer.Option("--tum", help="write the trajectory in TUM format (for evo)")
]
TumRefOpt = Annotated[
    Path | None, typer.Option("--tum-ref", help="write the log's scan poses in TUM format")
]
KalmanOpt = Annotated[
    bool,
    typer.Option(
        "--kalman",
        help="fuse the matches with the log's odometry (EKF, paper 003 §5.3); the TUM file and "
        "map then use the fused track",
    ),
]


def sequence(
    log: LogArg,
    out: RowsOutOpt,
    matcher: MatcherOpt = DEFAULT_MATCHER,
    params: ParamsOpt = None,
    limit: LimitOpt = None,
    rrd: RrdOpt = None,
    guess: GuessOpt = Guess.stored,
    truth: PoseTruthOpt = None,
    png: PngOpt = None,
    tum: TumOpt = None,
    tum_ref: TumRefOpt = None,
    kalman: KalmanOpt = False,
    workers: WorkersOpt = None,
    frame: FrameOpt = Frame.base,
    topic: TopicOpt = None,
    typestore: TypestoreOpt = DEFAULT_TYPESTORE,
    mount: MountOpt = None,
    upside_down: UpsideDownOpt = False,
    deskew: DeskewOpt = None,
    budget_s: BudgetOpt = MATCH_BUDGET_S,
    keyframe_m: KeyframeOpt = 0.0,
    keyframe_deg: KeyframeDegOpt = 30.0,
    close_loops: CloseLoopsOpt = False,
    loop_gap_m: LoopGapOpt = 10.0,
    serve: Annotated[
        bool,
        typer.Option(
            "--serve",
            help="then open the run in the debugger (its run view) on 127.0.0.1, as `serve LOG "
            "--rows OUT` does",
        ),
    ] = False,
    port: ServePortOpt = 8080,
):
    """Match every consecutive pair of a log (initial guess from its poses or odometry, else
    identity), or each scan against the last key frame (--keyframe-m)."""
    from mbicp_viz.core.warmup import load_kernels
    from mbicp_viz.evaluation.keyframes import KeyFrames
    from mbicp_viz.evaluation.sequence import match_sequence
    from mbicp_viz.readers.pair_match import PairMatch, parse_pair_match
    from mbicp_viz.readers.params_toml import read_params

    if truth not in (None, "pose"):
        raise InputError("the only truth a log carries is 'pose'", field="--truth")
    pf = read_params(params, [matcher.value])
    p, search = pf.matchers[matcher.value], pf.search
    reading = read_options(topic, typestore, mount, upside_down, deskew)
    lg = read_log_saying(log, reading)
    load_kernels(p)  # start-up, as reading the log: not the run's pace
    t0, resumed = time.perf_counter(), []  # the run's pace counts finding its pairs
    plan = Plan.consecutive(lg, limit)
    keyframes = KeyFrames(keyframe_m, math.radians(keyframe_deg)) if keyframe_m > 0 else None
    run = {
        "command": "eval sequence",
        "log": log_identity(log),
        "read": settings_of(reading),
        "algorithm": matcher.value,
        "params": p.as_dict(),
        "search": search.as_dict(),
        "guess": guess.value,
        "truth": truth,
        "frame": frame.value,
        "budget_s": budget_s,
        "keyframes": None if keyframes is None else keyframes.as_dict(),
    }

    def match(on_row, done):
        resumed.append(len(done))
        return match_sequence(
            lg,
            p,
            limit,
            guess,
            truth,
            on_row=on_row,
            workers=workers,
            search=search,
            base=frame is Frame.base,
            done=done,
            budget_s=budget_s,
            keyframes=keyframes,
            keep=False,
        )

    if keyframes is not None:  # its references are decided as it goes: checked on its scans
        plan = replace(plan, first=lambda n, first=plan.first: _any_reference(first(n)))
    with ExitStack() as stack:
        background = follow = None
        if serve:  # the log opens at once, the run view once the run is matched
            background, application = _serving_meanwhile(
                stack, log, lg, guess, reading, budget_s, plan, port
            )

            def follow(bar) -> None:
                background.update(bar.done, bar.total, not plan.exact(), bar.rate_text())

        rows = matched_rows(
            out, run, plan, match, PairMatch.to_json, parse_pair_match, follow, columns=True
        )
        say(_pace(lg, rows, resumed[0], time.perf_counter() - t0))
        halted = int(rows.column("halted").sum())
        typer.echo(
            f"{len(rows)} pairs matched with {matcher.value}: "
            f"{int(rows.column('converged').sum())} converged"
            + (
                f", {halted} stopped by the time budget of {budget_s:g} s (--budget-s)"
                if halted
                else ""
            )
            + f"; written to {out}"
        )
        _sequence_notes(lg, rows, truth, guess, frame)
        if png or tum or tum_ref or kalman:
            _trajectories(lg, rows, png, tum, tum_ref, kalman)
        if close_loops or rrd:  # they read every record: read back from the rows file once
            from mbicp_viz.readers.rows import read_rows

            records = read_rows(out)
        loops = closed_run(lg, records, loop_gap_m, keyframes) if close_loops else None
        if rrd:
            from mbicp_viz.views.rrd import record_sequence

            # each pair is matched again to record its correspondences
            with Progress(len(rows), "recording") as bar:
                record_sequence(lg, records, str(rrd), loops=loops, on_pair=lambda: bar.update(1))
            say(f"sequence recording written to {rrd}")
        _failures(log, out, rows)
        if background is not None:
            from mbicp_viz.views.debugger.sources import log_source

            label = f"{out}: {len(rows)} rows"
            done = log_source(log, lg, guess=guess, options=reading, run=rows, rows_label=label)
            background.finish(replace(done, budget_s=budget_s, loops=loops))
            say("the run view is open in the debugger (Ctrl-C stops)")
            until_ctrl_c(application.server.sleep_forever)


def _any_reference(pairs: list[tuple[int, int]]) -> list[tuple[int | None, int]]:
    """A key-frame run's pairs as its resumed rows are checked: the first as planned, each later
    one by its second scan only (its reference is the key frame of its time)."""
    return pairs[:1] + [(None, j) for _, j in pairs[1:]]


def _serving_meanwhile(stack, log, lg, guess, reading, budget_s, plan, port: int):
    """The debugger on the log while its run is matched (``stack`` stops it): any pair opens at
    once, each tab follows the run's progress (the ``Background`` returned) and opens its run view
    when it is done."""
    from mbicp_viz.views.debugger.background import Background
    from mbicp_viz.views.debugger.sources import log_source

    background = Background(plan.total(), at_most=not plan.exact())
    pending = replace(
        log_source(log, lg, guess=guess, options=reading), budget_s=budget_s, background=background
    )
    return background, stack.enter_context(started_debugger(pending, "127.0.0.1", port))


def _pace(lg, rows, resumed: int, seconds: float) -> str:
    """How fast this run matched the rows after the first ``resumed``: pairs a second, and against
    the recording's own time when its scans are stamped (the real-time factor `bench throughput`
    measures)."""
    n = len(rows) - resumed
    text = f"{n} pairs matched in {seconds:.1f} s ({n / max(seconds, 1e-9):.1f}/s"
    if n:
        ref, obj = rows.column("ref")[resumed], rows.column("obj")[-1]
        a, b = lg.scan(int(ref)).stamp, lg.scan(int(obj)).stamp
        if a is not None and b is not None and b > a:
            text += f"; the recording's {b - a:.1f} s at {(b - a) / seconds:.1f}x real time"
    return text + ")"


def _failures(log: str, out: Path, rows) -> None:
    """The rows' failures and suspicious pairs, named by their lines in ``out`` (a ``RunRows``
    over it), as ``serve --rows`` will open them."""
    from mbicp_viz.evaluation.failures import failure_summary
    from mbicp_viz.evaluation.health import ranked, suspect_summary

    failures = failure_summary(rows)
    typer.echo("\n".join(failures + suspect_summary(rows)))
    if failures or ranked(rows):
        typer.echo(f"open them as they ran: mbicp-viz serve {log} --rows {out}")


def _sequence_notes(lg, rows, truth, guess: Guess, frame: Frame) -> None:
    """The scores against the truth and the odometry, the frame of the poses, and the pairs
    matched from the identity for want of a guess."""
    from mbicp_viz.evaluation.pairs import MISSING
    from mbicp_viz.evaluation.sequence import odometry_summary, truth_summary

    if lg.store is not None and (skipped := lg.unusable_summary()):
        say(skipped)  # a bag read through its index knows its unusable scans once it is read
    if truth:
        typer.echo("\n".join(truth_summary(rows)))
    if odometry := odometry_summary(rows):
        typer.echo(odometry)
    say(f"poses: motions of {lg.frames.frame_text(frame is Frame.base)}")
    if without := int(rows.column("guess_missing").sum()):
        say(
            f"{without} pair(s) with no {guess.value} at one of their scans: matched from the "
            f"identity (their rows' guess says '{MISSING.format(guess.value)}')"
        )


def _trajectories(lg, rows, png, tum, tum_ref, fuse) -> None:
    from mbicp_viz.evaluation.trajectory import (
        MATCHED,
        STORED,
        plot_png,
        sequence_tracks,
        stamps,
        tum_text,
    )

    tracks = sequence_tracks(lg, rows, fuse)
    main = list(tracks)[-1] if fuse else MATCHED
    times = stamps(lg, rows)
    if tum:
        write_text(tum, tum_text(tracks[main], times))
    if tum_ref:
        if STORED not in tracks:
            raise InputError("the log stores no scan poses to export", lg.path, field="--tum-ref")
        write_text(tum_ref, tum_text(tracks[STORED], times))
    if png:
        plot_png(lg, rows, tracks, str(png), main)


def protocol(
    log: LogArg,
    matcher: MatcherOpt = DEFAULT_MATCHER,
    params: ParamsOpt = None,
    cases: Annotated[int, typer.Option("--cases", min=1, help="number of random cases")] = 200,
    seed: SeedOpt = 24,
    max_xy: MaxXyOpt = 0.2,
    max_theta_deg: MaxThetaDegOpt = 45.0,
    topic: TopicOpt = None,
):
    """MbICP's own protocol: every case matches a scan against itself from a random guess."""
    from mbicp_viz.evaluation.protocols import displaced_self_matches, protocol_summary
    from mbicp_viz.readers.params_toml import make_params

    scans = read_log_saying(log, read_options(topic)).scans
    res = displaced_self_matches(
        scans, cases, make_params(matcher.value, params), seed, max_xy, math.radians(max_theta_deg)
    )
    typer.echo(protocol_summary(matcher.value, res))


ScenesPerLogOpt = Annotated[
    int, typer.Option("--scenes-per-log", min=1, help="scenes taken from each log")
]
ScansOpt = Annotated[
    str | None, typer.Option("--scans", help="explicit scene numbers I,J,... (one log)")
]
RatiosOpt = Annotated[str, typer.Option("--ratios", help="kept fractions in %")]
RunsOpt = Annotated[
    int, typer.Option("--runs", min=1, help="random displacements per scene and ratio")
]
RemovalOpt = Annotated[
    Removal, typer.Option("--removal", help="one block (occlusion-like) or random points")
]
ThinOpt = Annotated[
    Thin,
    typer.Option(
        "--thin",
        help="the copy that loses the points: reference (its object points then lack "
        "counterparts) or object",
    ),
]
CsvOpt = Annotated[Path | None, typer.Option("--csv", help="write every run as CSV")]
PlotOpt = Annotated[Path | None, typer.Option("--png", help="write a plot")]


def overlap(
    logs: Annotated[
        list[str], typer.Argument(help="scan logs; scenes are picked evenly from each")
    ],
    scenes_per_log: ScenesPerLogOpt = 1,
    scans: ScansOpt = None,
    ratios: RatiosOpt = "100,90,80,70,60",
    runs: RunsOpt = 10,
    removal: RemovalOpt = Removal.block,
    thin: ThinOpt = Thin.reference,
    matchers: MatchersOpt = ALL_MATCHERS,
    params: ParamsOpt = None,
    seed: SeedOpt = 0,
    max_xy: MaxXyOpt = 0.5,
    max_theta_deg: MaxThetaDegOpt = 15.0,
    csv: CsvOpt = None,
    png: PlotOpt = None,
    workers: WorkersOpt = None,
    topic: TopicOpt = None,
):
    """Paper 000's partial-overlap protocol (§3.1): Tables 1-3 for each matcher, as Markdown."""
    from mbicp_viz.evaluation.overlap import (
        csv_text,
        make_cases,
        markdown,
        plot_png,
        run_overlap,
        scene_scans,
        tables,
    )

    etas = [v / 100.0 for v in number_list(ratios, "--ratios", "100,90,80")]
    if not all(0.0 < e <= 1.0 for e in etas):
        raise InputError("each ratio must lie in (0, 100]", field="--ratios")
    ps = params_for(matchers, params).matchers
    picked = number_list(scans, "--scans", "3,10,25", int) if scans else None
    scenes = [
        s
        for log in logs
        for s in scene_scans(read_log_saying(log, read_options(topic)), scenes_per_log, picked)
    ]
    cases = make_cases(scenes, etas, runs, removal, seed, max_xy, math.radians(max_theta_deg), thin)
    t0 = time.perf_counter()
    with Progress(len(cases)) as bar:
        done = [0]

        def progress(rows):
            n = len(rows) // len(ps)
            bar.update(n - done[0])
            done[0] = n

        rows = run_overlap(scenes, ps, cases, workers, progress)
    tab = tables(rows)
    typer.echo(markdown(tab))
    say(
        f"{len(rows)} matches ({len(rows) // max(len(ps), 1)}/{len(cases)} cases) in "
        f"{time.perf_counter() - t0:.1f} s; "
        f"{len(scenes)} scenes, removal {removal.value} from the {thin.value}, seed {seed}"
    )
    if csv:
        write_text(csv, csv_text(rows))
    if png:
        plot_png(tab, str(png))


def ceiling(
    log: Annotated[
        str, typer.Argument(help="scan log whose scan poses are the truth (corrected logs)")
    ],
    matchers: MatchersOpt = ALL_MATCHERS,
    params: ParamsOpt = None,
    limit: LimitOpt = None,
    workers: WorkersOpt = None,
    topic: TopicOpt = None,
):
    """How well any guess could do on a log: each matcher started at the truth, and the search
    alone."""
    from mbicp_viz.evaluation.sequence import ceiling as ceiling_of
    from mbicp_viz.evaluation.sequence import ceiling_summary

    by_name = params_for(matchers, params).matchers
    lg = read_log_saying(log, read_options(topic))
    with Progress(len(lg.consecutive_pairs(limit))) as bar:
        found, kept, doubted, n = ceiling_of(
            lg, list(by_name.values()), limit, workers, on_row=lambda _: bar.update(1)
        )
    if n == 0:
        raise InputError("interrupted before the first pair was matched", log)
    typer.echo("\n".join(ceiling_summary(list(by_name), found, kept, doubted, n)))


def corridor(
    log: Annotated[
        str, typer.Argument(help="scan log whose scan poses are the truth (corrected logs)")
    ],
    matchers: MatchersOpt = ALL_MATCHERS,
    params: ParamsOpt = None,
    perturb: Annotated[
        tuple[float, float],
        typer.Option(
            "--perturb",
            metavar="XY_M THETA_DEG",
            help="guesses: the stored pose moved uniformly within "
            "+/-XY_M in x and y and +/-THETA_DEG (seeded)",
        ),
    ] = (0.3, 15.0),
    seed: SeedOpt = 0,
    condition: Annotated[
        float,
        typer.Option(
            "--condition",
            min=1.0,
            callback=finite,
            help="a pair is degenerate above this surface condition number at its true pose",
        ),
    ] = 30.0,
    workers: WorkersOpt = None,
    topic: TopicOpt = None,
):
    """Successes where the scene leaves a direction free (corridors) and elsewhere, from perturbed
    guesses."""
    from mbicp_viz.evaluation.corridor import corridor as corridor_of
    from mbicp_viz.evaluation.corridor import corridor_summary

    moved = check_perturb(perturb)
    ps = params_for(matchers, params).matchers
    lg = read_log_saying(log, read_options(topic))
    t0 = time.perf_counter()
    with Progress(len(lg.consecutive_pairs(None))) as bar:
        rows = corridor_of(lg, ps, moved, seed, workers, on_row=lambda _: bar.update(1))
    if not rows:
        raise InputError("interrupted before the first pair was matched", log)
    typer.echo("\n".join(corridor_summary(rows, condition)))
    say(
        f"{len(rows) * len(ps)} matches in {time.perf_counter() - t0:.1f} s; guesses within "
        f"+/-{perturb[0]:g} m, "
        f"+/-{perturb[1]:g} deg, seed {seed}"
    )


def covariance(
    log: Annotated[
        str, typer.Argument(help="scan log with a truth (its scan poses, or --relations)")
    ],
    matchers: MatchersOpt = ALL_MATCHERS,
    params: ParamsOpt = None,
    truth: CaseTruthOpt = "pose",
    relations_file: RelationsOpt = None,
    offset: OffsetOpt = 0.0,
    tolerance: ToleranceOpt = 0.025,
    guess: CaseGuessOpt = "perturb",
    perturb: PerturbOpt = (0.3, 15.0),
    seed: SeedOpt = 0,
    limit: LimitOpt = None,
    png: Annotated[
        Path | None, typer.Option("--png", help="the NEES distributions against chi2(3)")
    ] = None,
    workers: WorkersOpt = None,
    topic: TopicOpt = None,
):
    """Whether each matcher's reported covariance fits its errors against the truth (NEES, chi2
    bounds)."""
    from mbicp_viz.evaluation.cases import cases_for
    from mbicp_viz.evaluation.covariance import consistency_lines, covariance_consistency, nees_png
    from mbicp_viz.readers.relations import read_relations

    moved = cases_options(truth, relations_file, guess, perturb)
    pf = params_for(matchers, params)
    ps = pf.matchers
    lg = read_log_saying(log, read_options(topic))
    cases = cases_for(
        0,
        lg,
        truth,
        read_relations(relations_file) if relations_file else None,
        offset,
        tolerance,
        guess,
        moved,
        seed,
        pf.search,
        limit,
    )
    results = {}
    with Progress(len(cases) * len(ps)) as bar:
        for name, p in ps.items():
            results[name] = covariance_consistency(
                lg, cases, p, workers, on_row=lambda _: bar.update(1)
            )
    for name, c in results.items():
        typer.echo("\n".join(consistency_lines(name, c)))
    if png:
        nees_png(results, str(png))


def relations(
    log: Annotated[str, typer.Argument(help="scan log with time stamps")],
    relations_file: Annotated[
        str, typer.Argument(metavar="RELATIONS", help="relations file (t1 t2 x y z roll pitch yaw)")
    ],
    matcher: MatcherOpt = DEFAULT_MATCHER,
    params: ParamsOpt = None,
    offset: OffsetOpt = 0.0,
    tolerance: ToleranceOpt = 0.025,
    guess: Annotated[
        Guess,
        typer.Option(
            "--guess",
            help="identity, pose, odometry or search (a correlative "
            f"search within {SEARCH} of the identity)",
        ),
    ] = Guess.identity,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help="rows file (JSON lines, one per matched relation), written as OUT.partial while "
            "they are matched; a stopped run resumes from it",
        ),
    ] = None,
    topic: TopicOpt = None,
    workers: WorkersOpt = None,
    run_rows: Annotated[
        str | None,
        typer.Option(
            "--run",
            metavar="ROWS",
            help="score the run of an `eval sequence --out ROWS` instead (Kümmerle et al.'s own "
            "measure): the matches chained, their Kalman fusion with odometry and the raw "
            "odometry, beside the published figures",
        ),
    ] = None,
    close_loops: CloseLoopsOpt = False,
    loop_gap_m: LoopGapOpt = 10.0,
):
    """Match the two scans of each relation (Kümmerle et al. 2009) and report the errors; or, with
    --run, score a whole run's trajectory on the relations."""
    from mbicp_viz.evaluation.relations import (
        match_relations,
        relation_pairs,
        stored_summary,
        summary,
    )
    from mbicp_viz.readers.params_toml import read_params
    from mbicp_viz.readers.relations import read_relations

    reading = read_options(topic)
    lg = read_log_saying(log, reading)
    if run_rows is not None:
        _score_run(lg, run_rows, relations_file, offset, tolerance, close_loops, loop_gap_m)
        return
    if close_loops:
        raise InputError("--close-loops closes the loops of a run: give --run ROWS", field="--run")
    pf = read_params(params, [matcher.value])
    p, search = pf.matchers[matcher.value], pf.search
    found, missing = relation_pairs(lg, read_relations(relations_file), offset, tolerance)
    records = lg.record_numbers()
    run = {
        "command": "eval relations",
        "log": log_identity(log),
        "relations": log_identity(relations_file),
        "read": settings_of(reading),
        "offset": offset,
        "tolerance": tolerance,
        "algorithm": matcher.value,
        "params": p.as_dict(),
        "search": search.as_dict(),
        "guess": guess.value,
    }
    pairs = [(records[i], records[j]) for i, j, _ in found]
    rows = matched_rows(
        out,
        run,
        Plan.of(pairs),
        lambda on_row, done: match_relations(
            lg, found, p, guess, search, on_row=on_row, skip=len(done), workers=workers
        ),
    )
    typer.echo(
        f"{matcher.value}: {summary(rows)} ({missing} relations without a scan at both ends)"
    )
    if stored := stored_summary(rows):
        typer.echo(stored)


def _score_run(
    lg,
    rows_path: str,
    relations_file: str,
    offset: float,
    tolerance: float,
    loops: bool,
    gap_m: float,
) -> None:
    """``eval relations LOG RELATIONS --run ROWS [--close-loops]``: each trajectory of the run,
    scored."""
    from mbicp_viz.evaluation.run_score import (
        LOOPS_CLOSED,
        published_line,
        run_tracks,
        score_track,
    )
    from mbicp_viz.readers.relations import read_relations
    from mbicp_viz.readers.rows import rows_of_log

    relations = read_relations(relations_file)
    rows = rows_of_log(rows_path, lg)
    tracks = run_tracks(lg, rows, rows_path, offset)
    if loops:
        tracks[LOOPS_CLOSED] = (tracks["matches chained"][0], closed_run(lg, rows, gap_m).optimised)
    typer.echo(
        f"{rows_path}: {rows[0].matcher}, {len(rows)} pairs chained ({rows[0].frame} motions); "
        f"{len(relations)} relations of {relations_file}"
    )
    scores = [
        score_track(name, t, poses, relations, tolerance) for name, (t, poses) in tracks.items()
    ]
    for s in scores:
        typer.echo(f"  {s.line()}")
    if published := published_line(relations_file):
        typer.echo(f"  {published}")
    chained = scores[0]
    if chained.relations:
        typer.echo(f"the relations that cost {chained.track} most (translational error):")
        for k, et, er in chained.worst:
            rel = relations[k]
            typer.echo(
                f"  relation {k + 1} ({rel.t1:.3f} s -> {rel.t2:.3f} s): {et:.3f} m, "
                f"{math.degrees(er):.2f} deg"
            )


def basin(
    first: FirstArg,
    second: SecondArg = None,
    pair: PairOpt = None,
    truth: Annotated[
        tuple[float, float, float] | None,
        typer.Option(
            "--truth",
            metavar="X Y THETA_DEG",
            help="the answer X Y THETA_DEG (default: the stored poses, else each matcher's own)",
        ),
    ] = None,
    matchers: MatchersOpt = ALL_MATCHERS,
    params: ParamsOpt = None,
    range_xy: Annotated[
        float,
        typer.Option("--range-xy", min=0.0, callback=finite, help="largest |dx|, |dy| offset [m]"),
    ] = 1.0,
    steps: Annotated[
        int, typer.Option("--steps", min=2, max=201, help="grid points per axis")
    ] = 11,
    thetas_deg: Annotated[
        str, typer.Option("--thetas-deg", help="theta offsets [deg]")
    ] = "-30,-15,0,15,30",
    png: Annotated[Path | None, typer.Option("--png", help="write the atlas as a PNG")] = None,
    rrd: RrdOpt = None,
    workers: WorkersOpt = None,
    topic: TopicOpt = None,
    typestore: TypestoreOpt = DEFAULT_TYPESTORE,
    mount: MountOpt = None,
    upside_down: UpsideDownOpt = False,
    deskew: DeskewOpt = None,
):
    """A convergence atlas: every matcher from a grid of initial offsets, coloured by outcome."""
    from mbicp_viz.evaluation.basin import basin as atlas_of
    from mbicp_viz.evaluation.basin import plot_png, summary
    from mbicp_viz.evaluation.pairs import load_pair, stored_truth

    thetas = [math.radians(v) for v in number_list(thetas_deg, "--thetas-deg", "-15,0,15")]
    ps = params_for(matchers, params).matchers
    sp = load_pair(first, second, pair, read_options(topic, typestore, mount, upside_down, deskew))
    answer = pose_from_deg(truth, "--truth") or stored_truth(sp.ref, sp.obj)
    t0 = time.perf_counter()
    atlas = atlas_of(sp.ref, sp.obj, ps, answer, range_xy, steps, thetas, workers)
    typer.echo(summary(atlas))
    say(f"{len(ps) * len(thetas) * steps * steps} matches in {time.perf_counter() - t0:.1f} s")
    if png:
        plot_png(atlas, str(png))
    if rrd:
        from mbicp_viz.views.rrd import record_basin

        record_basin(atlas, str(rrd))


def flags(
    log: Annotated[str, typer.Argument(help="the log the run matched")],
    rows_path: Annotated[
        str,
        typer.Argument(
            metavar="ROWS", help="rows of `eval sequence --out` (with --truth pose: pair by pair)"
        ),
    ],
    relations_file: Annotated[
        str | None,
        typer.Option(
            "--relations",
            metavar="FILE",
            help="judge against a relations file's short relations (Kümmerle et al. 2009) instead",
        ),
    ] = None,
    offset: OffsetOpt = 0.0,
    tolerance: ToleranceOpt = 0.025,
    topic: TopicOpt = None,
):
    """How far the run's flags (suspicious pairs, found without truth) can be trusted: how often a
    flagged pair is a real failure, and how many failures go unflagged."""
    from mbicp_viz.evaluation.flag_check import (
        LOCAL_S,
        check_relations,
        check_scored,
        odometry_is_truth,
    )
    from mbicp_viz.evaluation.trajectory import stamps
    from mbicp_viz.readers.relations import read_relations
    from mbicp_viz.readers.rows import rows_of_log

    lg = read_log_saying(log, read_options(topic))
    rows = rows_of_log(rows_path, lg)
    if relations_file is None:
        if not any(r.score is not None for r in rows):
            raise InputError(
                "no row is scored: run eval sequence with --truth pose, or give --relations",
                rows_path,
                field="success",
            )
        checks, basis = check_scored(rows), "against each pair's own truth"
        if odometry_is_truth(rows):
            basis += (
                " (the log's odometry is its truth: the signs read from the odometry are left out)"
            )
    else:
        t = [s + offset for s in stamps(lg, rows)]
        checks = check_relations(rows, t, read_relations(relations_file), tolerance)
        basis = f"against the relations up to {LOCAL_S:g} s long (a failure: a stretch of pairs)"
    typer.echo(f"{len(rows)} pairs, {basis}:")
    for c in checks:
        typer.echo(f"  {c.line()}")


def register(app: typer.Typer) -> None:
    group = typer.Typer(no_args_is_help=True, help="Evaluate matchers on whole logs.")
    for name, fn in (
        ("sequence", sequence),
        ("protocol", protocol),
        ("overlap", overlap),
        ("ceiling", ceiling),
        ("relations", relations),
        ("basin", basin),
        ("corridor", corridor),
        ("covariance", covariance),
        ("flags", flags),
    ):
        group.command(name)(user_errors(fn))
    app.add_typer(group, name="eval")
