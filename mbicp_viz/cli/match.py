"""``match`` and ``compare``: one pair, every iteration, optionally recorded for rerun."""

from __future__ import annotations

import tempfile
from typing import Annotated

import typer

from mbicp_viz.choices import DEFAULT_TYPESTORE, MATCH_BUDGET_S

from .options import (
    ALL_MATCHERS,
    DEFAULT_MATCHER,
    BudgetOpt,
    ConnectOpt,
    DeskewOpt,
    FirstArg,
    Frame,
    FrameOpt,
    Guess,
    GuessOpt,
    InitOpt,
    MatcherOpt,
    MatchersOpt,
    MountOpt,
    PairOpt,
    ParamsOpt,
    PortOpt,
    RrdOpt,
    SearchFlag,
    SecondArg,
    ServeOpt,
    TeachOpt,
    TopicOpt,
    TruthOpt,
    TypestoreOpt,
    UpsideDownOpt,
    pose_from_deg,
    read_options,
    say,
    user_errors,
)

JsonOpt = Annotated[
    bool, typer.Option("--json", help="print one JSON object with the result fields")
]


def _pair_and_setup(first, second, pair, reading, guess, init, search, truth, search_params):
    from mbicp_viz.evaluation.pairs import load_pair
    from mbicp_viz.evaluation.single import setup

    sp = load_pair(first, second, pair, reading)
    for note in sp.log.notes:
        say(note)
    return sp, setup(
        sp,
        guess,
        pose_from_deg(init, "--init"),
        search,
        pose_from_deg(truth, "--truth"),
        search_params,
    )


def match_cmd(
    first: FirstArg,
    second: SecondArg = None,
    pair: PairOpt = None,
    matcher: MatcherOpt = DEFAULT_MATCHER,
    guess: GuessOpt = Guess.stored,
    init: InitOpt = None,
    search: SearchFlag = False,
    truth: TruthOpt = None,
    params: ParamsOpt = None,
    as_json: JsonOpt = False,
    frame: FrameOpt = Frame.base,
    rrd: RrdOpt = None,
    teach: TeachOpt = False,
    connect: ConnectOpt = None,
    serve: ServeOpt = False,
    port: PortOpt = 9090,
    topic: TopicOpt = None,
    typestore: TypestoreOpt = DEFAULT_TYPESTORE,
    mount: MountOpt = None,
    upside_down: UpsideDownOpt = False,
    deskew: DeskewOpt = None,
    budget_s: BudgetOpt = MATCH_BUDGET_S,
):
    """Match two scans and show every iteration (optionally recorded for rerun's viewer)."""
    from mbicp_viz.core import tiers
    from mbicp_viz.evaluation import single
    from mbicp_viz.readers.params_toml import read_params
    from mbicp_viz.views.text import match_report

    tiers.quick_start()  # a person waits on this command: never a compile stall
    pf = read_params(params, [matcher.value])
    p = pf.matchers[matcher.value]
    sp, s = _pair_and_setup(
        first,
        second,
        pair,
        read_options(topic, typestore, mount, upside_down, deskew),
        guess,
        init,
        search,
        truth,
        pf.search,
    )
    base, frames = frame is Frame.base, sp.log.frames
    m = single.match_pair(
        sp.ref,
        sp.obj,
        p,
        s,
        frames,
        base,
        # record numbers in the log; two files: the first scan of each
        indices=(0, 0) if second else (pair or sp.log.consecutive_pairs(1)[0]),
        stream=sp.log.topic,
        record=not as_json or bool(rrd or connect or serve),
        budget_s=budget_s,
    )
    _say_if_halted([m], budget_s)
    if as_json:
        typer.echo(m.json_line())
    else:
        truth_pose = frames.reported(s.truth, base) if s.truth is not None else None
        typer.echo("\n".join(match_report(sp.label, m, frames.frame_text(base), truth_pose)))
    _say_if_interpreted()
    if rrd or connect or serve:
        _record([m], rrd, connect, serve, port, teach)


def compare_cmd(
    first: FirstArg,
    second: SecondArg = None,
    pair: PairOpt = None,
    matchers: MatchersOpt = ALL_MATCHERS,
    guess: GuessOpt = Guess.stored,
    init: InitOpt = None,
    search: SearchFlag = False,
    truth: TruthOpt = None,
    params: ParamsOpt = None,
    rrd: RrdOpt = None,
    teach: TeachOpt = False,
    connect: ConnectOpt = None,
    serve: ServeOpt = False,
    port: PortOpt = 9090,
    topic: TopicOpt = None,
    typestore: TypestoreOpt = DEFAULT_TYPESTORE,
    mount: MountOpt = None,
    upside_down: UpsideDownOpt = False,
    deskew: DeskewOpt = None,
    budget_s: BudgetOpt = MATCH_BUDGET_S,
):
    """Run several matchers on one pair and print one table (each under its own root in --rrd)."""
    from mbicp_viz.core import tiers
    from mbicp_viz.evaluation.compare import compare_matches, compare_table

    from .options import params_for

    tiers.quick_start()
    pf = params_for(matchers, params)
    ps = pf.matchers
    sp, s = _pair_and_setup(
        first,
        second,
        pair,
        read_options(topic, typestore, mount, upside_down, deskew),
        guess,
        init,
        search,
        truth,
        pf.search,
    )
    typer.echo(
        f"{sp.label}\ninitial guess {s.guess} (from: {s.guess_source}); poses: the laser frame"
    )
    typer.echo(
        "errors against: "
        f"{s.truth_source or 'nothing (no known answer; give --truth X Y THETA_DEG)'}\n"
    )
    matches = compare_matches(sp, s, ps, budget_s)
    _say_if_halted(matches, budget_s)
    typer.echo(compare_table(matches))
    _say_if_interpreted()
    if rrd or connect or serve:
        _record(matches, rrd, connect, serve, port, teach)


def _say_if_halted(matches, budget_s: float) -> None:
    from mbicp_viz.core import Termination

    for m in matches:
        if m.result.reason is Termination.HALTED:
            say(
                f"{m.matcher}: stopped after {m.result.iterations} iterations by its time budget "
                f"of {budget_s:g} s (--budget-s): the pose is its last finished iteration's"
            )


def _say_if_interpreted() -> None:
    from mbicp_viz.core import tiers

    if tiers.compiling():
        say(tiers.INTERPRETED)


def _record(matches, rrd, connect, serve, port, teach) -> None:
    """Write the matches to an .rrd, stream them to a viewer, and/or serve them on 127.0.0.1."""
    from mbicp_viz.views.rrd import record
    from mbicp_viz.views.rrd import serve as serve_rrd

    path = (
        str(rrd)
        if rrd
        else (tempfile.mkdtemp(prefix="mbicp-viz-") + "/match.rrd" if serve else None)
    )
    record(matches, path, connect, teach)
    if path:
        say(f"recording written to {path} (open it with: rerun {path})")
    if serve:
        say(f"serving rerun's web viewer on http://127.0.0.1:{port} (Ctrl-C stops)")
        serve_rrd(path, port)


def register(app: typer.Typer) -> None:
    app.command("match")(user_errors(match_cmd))
    app.command("compare")(user_errors(compare_cmd))
