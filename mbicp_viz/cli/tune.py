"""``tune``: search a matcher's parameters against ground truth (Optuna), check them on a held-out
log."""

from __future__ import annotations

import math
from contextlib import closing
from pathlib import Path
from typing import Annotated

import typer

from mbicp_viz.choices import DEFAULT_TYPESTORE
from mbicp_viz.errors import InputError
from mbicp_viz.outputs import write_text

from .options import (
    DEFAULT_MATCHER,
    CaseGuessOpt,
    CaseTruthOpt,
    DeskewOpt,
    MatcherOpt,
    MountOpt,
    OffsetOpt,
    ParamsOpt,
    PerturbOpt,
    Progress,
    RelationsOpt,
    SeedOpt,
    ToleranceOpt,
    TopicOpt,
    TypestoreOpt,
    UpsideDownOpt,
    WorkersOpt,
    cases_options,
    read_log_saying,
    read_options,
    say,
    user_errors,
)
from .resume import log_identity, settings_of

LogsArg = Annotated[list[str], typer.Argument(metavar="LOG...", help="training logs with a truth")]
LimitOpt = Annotated[
    int | None, typer.Option("--limit", min=1, help="the first N pairs of each log")
]
TrialsOpt = Annotated[int, typer.Option("--trials", min=1, help="trials to run now")]
HoldoutOpt = Annotated[
    str | None, typer.Option("--holdout", help="a log kept out of the search: the honest figure")
]
FieldsOpt = Annotated[
    str | None,
    typer.Option(
        "--fields", help="comma-separated parameters to search (default: those with a tuning range)"
    ),
]
StorageOpt = Annotated[
    str,
    typer.Option(
        "--storage",
        help="Optuna storage: a SQLite file (default) or a postgresql:// URL shared by several "
        "machines",
    ),
]
StudyOpt = Annotated[
    str | None,
    typer.Option("--study", help="study name (default: ALGO-FIRSTLOG); an existing study resumes"),
]
OutOpt = Annotated[Path, typer.Option("--out", help="the best parameters as a --params TOML")]
PngDirOpt = Annotated[
    Path | None,
    typer.Option("--png-dir", help="optimisation history and parameter importance as PNGs here"),
]
RowsDirOpt = Annotated[
    Path | None,
    typer.Option(
        "--rows-dir",
        help="each training log's pairs under the best parameters as a rows file (serve LOG "
        "--rows)",
    ),
]


def tune(
    logs: LogsArg,
    matcher: MatcherOpt = DEFAULT_MATCHER,
    params: ParamsOpt = None,
    truth: CaseTruthOpt = "pose",
    relations: RelationsOpt = None,
    offset: OffsetOpt = 0.0,
    tolerance: ToleranceOpt = 0.025,
    guess: CaseGuessOpt = "perturb",
    perturb: PerturbOpt = (0.3, 15.0),
    seed: SeedOpt = 0,
    limit: LimitOpt = None,
    trials: TrialsOpt = 100,
    holdout: HoldoutOpt = None,
    fields: FieldsOpt = None,
    storage: StorageOpt = "sqlite:///tune.db",
    study: StudyOpt = None,
    out: OutOpt = Path("tuned.toml"),
    png_dir: PngDirOpt = None,
    rows_dir: RowsDirOpt = None,
    workers: WorkersOpt = None,
    topic: TopicOpt = None,
    typestore: TypestoreOpt = DEFAULT_TYPESTORE,
    mount: MountOpt = None,
    upside_down: UpsideDownOpt = False,
    deskew: DeskewOpt = None,
):
    """Search a matcher's parameters on training logs against their truth; defaults and best side
    by side."""
    from mbicp_viz.evaluation import tune as t
    from mbicp_viz.readers.params_toml import params_to_toml, read_params
    from mbicp_viz.readers.relations import read_relations

    moved = cases_options(truth, relations, guess, perturb, len(logs))
    pf = read_params(params, [matcher.value])
    base, search = pf.matchers[matcher.value], pf.search
    space = _space(t, base, matcher.value, fields)
    reading = read_options(topic, typestore, mount, upside_down, deskew)
    rels = read_relations(relations) if relations else None
    # how the pairs of a log are made, alike for the training and the held-out logs
    pairs = (truth, rels, offset, tolerance, guess, moved, seed, search, limit)
    cases = _cases(logs, reading, pairs)
    name = study or f"{matcher.value}-{Path(logs[0]).name.split('.')[0]}"
    st = t.open_study(storage, name)
    settings = {
        "logs": [log_identity(p) for p in logs],
        "limit": limit,
        "truth": truth,
        "relations": relations and log_identity(relations),
        "offset": offset,
        "tolerance": tolerance,
        "guess": guess,
        "perturb": list(perturb),
        "seed": seed,
        "fields": [d.spec.name for d in space],
        "algo": matcher.value,
        "params": base.as_dict(),
        "read": settings_of(reading),
    }
    before = _resume(t, st, name, settings)
    _header(settings, len(cases), name, storage, before)
    if t.enqueue_defaults(st, {d.spec.name: getattr(base, d.spec.name) for d in space}) and before:
        say("the defaults were never scored in this study: they are its next trial")
    with closing(t.Scorer(logs, reading, cases, workers)) as scorer:
        with Progress(trials, "trials") as bar:
            ran = t.optimise(st, scorer, base, space, trials, on_trial=lambda _: bar.update(1))
        if not any(tr.value is not None for tr in st.trials):
            raise InputError("interrupted before the first trial finished", field="--trials")
        best = t.best_params(st, base, space)
        rows = [_scores(t, "training", scorer, cases, base, best)]
    if holdout:
        held = _cases([holdout], reading, pairs)
        with closing(t.Scorer([holdout], reading, held, workers)) as check:
            rows.append(_scores(t, "holdout", check, held, base, best))
    _table(st, ran, rows, [(d.spec, getattr(best, d.spec.name)) for d in space])
    write_text(out, params_to_toml(best, search))
    typer.echo(f"written to {out} (read it back with --params {out})")
    _importance(t, st, name, png_dir)
    if rows_dir:
        _worst_rows(rows_dir, logs, cases, best, reading)


def _space(t, base, matcher: str, fields: str | None) -> list:
    """The parameters searched: ``--fields``, else those with a tuning range."""
    space = t.search_space(type(base), [f.strip() for f in fields.split(",")] if fields else None)
    if not space:
        raise InputError(
            f"{matcher} has no parameter with a tuning range: name some", field="--fields"
        )
    return space


def _cases(paths: list[str], reading, pairs: tuple) -> list:
    """The pairs of each log (``cases_for``'s arguments after the log: ``pairs``)."""
    from mbicp_viz.evaluation.cases import cases_for

    return [
        c
        for k, path in enumerate(paths)
        for c in cases_for(k, read_log_saying(path, reading), *pairs)
    ]


def _resume(t, st, name: str, settings: dict) -> int:
    """Check a resumed study's settings against this run's and fail the trials a stopped run
    left running; how many trials it holds."""
    if t.check_settings(st, settings) and st.trials:
        say(f"study {name!r} recorded no settings (an earlier version): it takes this run's")
    if stale := t.fail_stale_trials(st):
        say(f"{stale} trial(s) left running by a stopped run marked failed")
    return len(st.trials)


def _header(settings: dict, n_cases: int, name: str, storage: str, before: int) -> None:
    """What is tuned, on what, against which truth and from which guesses; where the study is."""
    perturb = settings["perturb"]
    guesses = (
        f"the stored pose moved within +/-{perturb[0]:g} m, +/-{perturb[1]:g} deg "
        f"(seed {settings['seed']})"
        if settings["guess"] == "perturb"
        else settings["guess"]
    )
    truth = "scan poses" if settings["truth"] == "pose" else "relations"
    typer.echo(
        f"tuning {settings['algo']} on {len(settings['logs'])} log(s), {n_cases} pairs; truth: "
        f"{truth}; guesses: {guesses}"
    )
    typer.echo(
        f"searching {', '.join(settings['fields'])}; study {name!r} in {storage} "
        f"({before} trials before)"
    )


def _table(st, ran: int, rows: list, best: list) -> None:
    """The defaults and the best parameters side by side, on training (and held-out) pairs."""
    typer.echo(
        f"{ran} trials ran now, {len(st.trials)} in the study; best: trial {st.best_trial.number}"
    )
    typer.echo(f"{'':<22}{'defaults':<46}best")
    for label, n, a, b in rows:
        typer.echo(f"{label + f' ({n} pairs)':<22}{a.text():<46}{b.text()}")
    typer.echo("best parameters: " + ", ".join(_shown(spec, value) for spec, value in best))


def _scores(t, label: str, scorer, cases, base, best):
    """A row of the table: the defaults' and the best parameters' scores on ``cases``."""
    return label, len(cases), t.Score.of(scorer.errors(base)), t.Score.of(scorer.errors(best))


def _importance(t, st, name: str, png_dir: Path | None) -> None:
    """Each searched parameter's share of the score's variance, and the pictures when asked."""
    shares = t.importance(st)
    if shares:
        typer.echo("importance: " + ", ".join(f"{k} {v:.2f}" for k, v in shares.items()))
    if png_dir:
        png_dir.mkdir(parents=True, exist_ok=True)
        t.history_png(st, str(png_dir / "history.png"))
        if shares:
            t.importance_png(shares, name, str(png_dir / "importance.png"))
        say(f"pictures in {png_dir}: history.png" + (", importance.png" if shares else ""))


def _shown(spec, value) -> str:
    if spec.unit == "rad":
        return f"{spec.name}_deg {math.degrees(value):.4g}"
    return f"{spec.name} {value:.4g}" if isinstance(value, float) else f"{spec.name} {value}"


def _worst_rows(rows_dir: Path, logs: list[str], cases, best, reading) -> None:
    """Each training log's pairs under the best parameters, as rows: the debugger lists their
    failures worst first and opens each as it ran."""
    from mbicp_viz.evaluation.failures import worst_first
    from mbicp_viz.evaluation.pairs import STORED_ANSWER
    from mbicp_viz.evaluation.single import Setup, match_pair
    from mbicp_viz.readers import read_log
    from mbicp_viz.readers.rows import read_rows, rows_text

    rows_dir.mkdir(parents=True, exist_ok=True)
    for k, path in enumerate(logs):
        lg = read_log(path, reading)
        records = lg.record_numbers()
        rows = [
            match_pair(
                lg.scans[c.i],
                lg.scans[c.j],
                best,
                Setup(c.guess, "tune's guess", c.truth, STORED_ANSWER),
                lg.frames,
                False,
                indices=(records[c.i], records[c.j]),
                stream=lg.topic,
            ).to_json()
            for c in cases
            if c.log == k
        ]
        target = rows_dir / f"{Path(path).name.split('.')[0]}-rows.json"
        write_text(target, rows_text(rows))
        bad = worst_first(read_rows(target))
        typer.echo(
            f"{len(bad)} failures of {len(rows)} pairs in {target}: open them with "
            f"mbicp-viz serve {path} --rows {target}"
        )


def register(app: typer.Typer) -> None:
    app.command("tune")(user_errors(tune))
