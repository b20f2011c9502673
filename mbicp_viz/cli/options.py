"""What every command shares: option types, choices, and the error handling that turns bad input
into one line and exit code 2. Nothing heavy is imported here (``--help`` answers at once)."""

from __future__ import annotations

import enum
import functools
import math
import os
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from mbicp_viz.choices import Deskew, Guess
from mbicp_viz.core.errors import ScanError
from mbicp_viz.core.matchers import MATCHERS
from mbicp_viz.core.params import ParamError, SearchParams
from mbicp_viz.errors import InputError

MatcherName = enum.Enum("MatcherName", {name: name for name in MATCHERS}, type=str)


class Frame(str, enum.Enum):
    """The frame a match's pose is reported in (``--frame``)."""

    base = "base"
    laser = "laser"


DEFAULT_MATCHER = MatcherName["improved"]
ALL_MATCHERS = ",".join(MATCHERS)
SEARCH = SearchParams().window_text()

FirstArg = Annotated[str, typer.Argument(help="reference scan file, or a log with --pair")]
SecondArg = Annotated[str | None, typer.Argument(help="object scan file")]
MatcherOpt = Annotated[MatcherName, typer.Option("--algo", help="matcher")]
MatchersOpt = Annotated[
    str, typer.Option("--algos", help=f"comma-separated matchers of: {ALL_MATCHERS}")
]
ParamsOpt = Annotated[
    Path | None,
    typer.Option(
        "--params",
        help="TOML file of matcher parameters (and a [search] table for the correlative search), "
        "or the "
        "name of a preset shipped with the tool (mbicp-viz params --presets)",
    ),
]
PairOpt = Annotated[
    tuple[int, int] | None,
    typer.Option(
        "--pair", metavar="I J", help="scan numbers I J of one log (ref obj; -1 is the last)"
    ),
]
InitOpt = Annotated[
    tuple[float, float, float] | None,
    typer.Option(
        "--init",
        metavar="X Y THETA_DEG",
        help="initial guess X Y THETA_DEG: object frame in the reference frame (m, m, "
        "deg); overrides --guess",
    ),
]
GuessOpt = Annotated[
    Guess,
    typer.Option(
        "--guess",
        help="initial guess: stored (the log's scan poses, else its odometry, else the identity), "
        "pose, "
        f"odometry, identity, or search (a correlative search within {SEARCH} of the identity)",
    ),
]
TruthOpt = Annotated[
    tuple[float, float, float] | None,
    typer.Option(
        "--truth",
        metavar="X Y THETA_DEG",
        help="the known answer X Y THETA_DEG (default: the log's scan poses when "
        "the guess is not taken from them)",
    ),
]
TopicOpt = Annotated[
    str | None,
    typer.Option(
        "--topic",
        help="a bag's LaserScan topic, or a CARMEN log's laser "
        "message type (FLASER, ROBOTLASER1, RAWLASER1-4): "
        "needed when it has several",
    ),
]
TypestoreOpt = Annotated[
    str,
    typer.Option(
        "--typestore",
        help="the ROS distro whose message types decode a ROS 2 "
        "bag recorded without them (e.g. ROS2_HUMBLE, "
        "ROS2_FOXY, ROS1_NOETIC)",
    ),
]
MountOpt = Annotated[
    tuple[float, float, float] | None,
    typer.Option(
        "--mount",
        metavar="X Y THETA_DEG",
        help="the laser's pose on the robot X Y THETA_DEG (base frame; m, m, deg), for files "
        "without tf",
    ),
]
DeskewOpt = Annotated[
    Deskew | None,
    typer.Option(
        "--deskew",
        help="correct each scan for the motion while it was measured (bags whose LaserScans give "
        "time_increment): the velocity from the log's odometry, or from matching consecutive scans",
    ),
]
UpsideDownOpt = Annotated[
    bool,
    typer.Option(
        "--upside-down",
        help="the laser is mounted upside down (its z axis points down), for files without tf",
    ),
]
FrameOpt = Annotated[
    Frame,
    typer.Option(
        "--frame",
        help="report motions of the robot's base (its mount from tf, "
        "--mount or the log), or of the laser",
    ),
]
BudgetOpt = Annotated[
    float,
    typer.Option(
        "--budget-s",
        min=0.0,
        help="each match stops after this many seconds and keeps its last finished iteration's "
        "pose, reported 'halted' (0: no limit)",
    ),
]
RrdOpt = Annotated[Path | None, typer.Option("--rrd", help="write the run to this rerun .rrd file")]
TeachOpt = Annotated[
    bool,
    typer.Option("--teach", help="add teaching layers: iso-distance curves, distance histogram"),
]
ConnectOpt = Annotated[
    str | None,
    typer.Option(
        "--connect",
        help="stream into a running rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy",
    ),
]
ServeOpt = Annotated[
    bool, typer.Option("--serve", help="serve rerun's web viewer on 127.0.0.1 with the run")
]
PortOpt = Annotated[
    int, typer.Option("--port", min=1, max=65534, help="web viewer port for --serve (data: PORT+1)")
]
WorkersOpt = Annotated[
    int | None, typer.Option("--workers", min=1, help="processes (default: all cores)")
]
SearchFlag = Annotated[
    bool,
    typer.Option(
        "--search",
        help=f"first search the pose within {SEARCH} of the guess "
        "(correlative search), then match from the best",
    ),
]


def finite(value: float) -> float:
    """Typer callback: bounds checks let inf (and NaN, with no lower bound) through."""
    if value is not None and not math.isfinite(value):
        raise typer.BadParameter(f"must be a finite number, got {value}")
    return value


# The cases an evaluation scores (tune, eval covariance; evaluation/cases.py)
CaseTruthOpt = Annotated[
    str,
    typer.Option(
        "--truth",
        help="'pose': the logs' scan poses (corrected logs); 'relations': Kümmerle's (--relations)",
    ),
]
RelationsOpt = Annotated[
    str | None,
    typer.Option("--relations", help="relations file of the (one) log (--truth relations)"),
]
CaseGuessOpt = Annotated[
    str,
    typer.Option(
        "--guess",
        help="'perturb': the truth moved within --perturb (seeded); or identity, odometry, search",
    ),
]
PerturbOpt = Annotated[
    tuple[float, float],
    typer.Option("--perturb", metavar="XY_M THETA_DEG", help="bounds of the perturbed guesses"),
]
SeedOpt = Annotated[
    int,
    typer.Option(
        "--seed", min=0, help="random seed (of perturbed guesses, displacements, removals)"
    ),
]
OffsetOpt = Annotated[
    float,
    typer.Option(
        "--offset",
        callback=finite,
        help="seconds added to the log's stamps to "
        "meet the relations' (Intel corrected: 976052857.337)",
    ),
]
ToleranceOpt = Annotated[
    float, typer.Option("--tolerance", min=0.0, callback=finite, help="largest stamp mismatch [s]")
]


def cases_options(
    truth: str, relations: str | None, guess: str, perturb: tuple[float, float], logs: int = 1
):
    """The checked case options: the perturbation in metres and radians."""
    from mbicp_viz.evaluation.cases import GUESSES

    if (
        truth not in ("pose", "relations")
        or (truth == "relations") != (relations is not None)
        or (truth == "relations" and logs != 1)
    ):
        raise InputError(
            "expected pose, or relations with one log and its --relations FILE", field="--truth"
        )
    if guess not in GUESSES:
        raise InputError(
            f"expected one of {', '.join(GUESSES)} (the truth cannot be the guess)", field="--guess"
        )
    return check_perturb(perturb)


def check_perturb(perturb: tuple[float, float]) -> tuple[float, float]:
    """--perturb XY_M THETA_DEG as (metres, radians), refused unless finite and >= 0."""
    if not all(math.isfinite(v) and v >= 0 for v in perturb):
        raise InputError(
            f"expected two finite numbers >= 0, got {perturb[0]} {perturb[1]}", field="--perturb"
        )
    return perturb[0], math.radians(perturb[1])


# Options that name a file a command writes, by the same names in every command.
OUTPUT_FILES = ("rrd", "out", "png", "tum", "tum_ref", "csv", "save")


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


def cli_name(fn, name: str) -> str:
    """How the command line calls parameter ``name`` of command ``fn``: its option (``--params``)
    or its argument (``LOG``)."""
    import typing

    hint = typing.get_type_hints(fn, include_extras=True).get(name)
    for meta in getattr(hint, "__metadata__", ()):
        if isinstance(meta, typer.models.OptionInfo) and meta.param_decls:
            return meta.param_decls[0]
        if isinstance(meta, typer.models.ArgumentInfo):
            return meta.metavar or name.upper()
    return _option(name)


def _named_files(options: dict) -> dict[str, list[Path]]:
    """The existing files each option names (a path, a name, or a list of them): what a command may
    read."""
    found: dict[str, list[Path]] = {}
    for name, value in options.items():
        for v in value if isinstance(value, (list, tuple)) else (value,):
            if isinstance(v, (str, Path)) and str(v) and Path(v).is_file():
                found.setdefault(name, []).append(Path(v))
    return found


def check_outputs(options: dict, name=_option) -> None:
    """Before any work is done (a run must not end in an error after its work): refuse an output
    file whose folder is missing or read-only, one that is also an input of the command (it would
    be destroyed) or another of its outputs; make ``--out-dir`` when missing. ``name`` says how the
    command line calls a parameter."""
    outputs = {n: options[n] for n in OUTPUT_FILES if isinstance(options.get(n), Path)}
    inputs = {n: p for n, p in _named_files(options).items() if n not in outputs}
    seen: dict[Path, str] = {}
    for option, path in outputs.items():  # unset options and flags (bench --rrd) are not paths
        field = name(option)
        if path.is_dir():
            raise InputError(f"{path} is a folder; give a file name", field=field)
        if not path.parent.is_dir():
            raise InputError(f"folder {path.parent} does not exist", field=field)
        if not os.access(path.parent, os.W_OK):
            raise InputError(f"folder {path.parent} is not writable", field=field)
        for other, files in inputs.items():
            if path.exists() and any(os.path.samefile(path, f) for f in files):
                raise InputError(
                    f"{path} is also this command's input ({name(other)}): writing it would "
                    "destroy it; give another file",
                    field=field,
                )
        key = path.resolve()
        if key in seen:
            raise InputError(
                f"{path} is also {seen[key]}: give each output its own file", field=field
            )
        seen[key] = field
    if isinstance(options.get("out_dir"), Path):
        try:
            options["out_dir"].mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(
                f"cannot make folder {options['out_dir']}: {e.strerror}", field="--out-dir"
            ) from None


INTERRUPTED_CODE = 130  # the shell's code for a command ended by Ctrl-C


def user_errors(fn):
    """Bad input ends in one readable line on stderr and exit code 2, Ctrl-C in ``interrupted``
    and 130, never a traceback."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from mbicp_viz.evaluation.pool import from_interrupt, interrupt_taken, one_command

        result = None
        with one_command() as interrupted:
            try:
                check_outputs(kwargs, functools.partial(cli_name, fn))
                result = fn(*args, **kwargs)
            except (InputError, ScanError, ParamError) as e:
                if not interrupted.is_set():  # else: a result of the stop, said below
                    typer.echo(f"mbicp-viz: error: {e}", err=True)
                    raise typer.Exit(2) from None
            except (KeyboardInterrupt, SystemError) as e:  # Ctrl-C where no run keeps rows
                if not from_interrupt(e):  # numba's SystemError: an interrupt in compiled code
                    raise
                interrupt_taken()
                interrupted.set()
            if interrupted.is_set():  # what was printed is of the part finished before Ctrl-C
                typer.echo("mbicp-viz: interrupted", err=True)
                raise typer.Exit(INTERRUPTED_CODE) from None
        return result

    return wrapper


def say(text: str) -> None:
    """A line for the user beside the results (stderr, so that stdout stays the results)."""
    typer.echo(text, err=True)


def pose_from_deg(value: tuple[float, float, float] | None, option: str):
    """A pose given as X Y THETA_DEG on the command line (``option`` names it in errors)."""
    if value is None:
        return None
    from mbicp_viz.core import Pose2

    x, y, th = value
    for name, v in (("X", x), ("Y", y), ("THETA_DEG", th)):
        if not math.isfinite(v):
            raise InputError(f"must be finite, got {v}", field=f"{option} {name}")
    return Pose2(x, y, math.radians(th))


def number_list(text: str, field: str, example: str, kind=float) -> list:
    """``--field 1,2,3`` as numbers of ``kind``; one clear error for anything else."""
    try:
        values = [kind(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"expected numbers like {example}, got {text!r}", field=field) from None
    if not all(math.isfinite(v) for v in values):
        raise InputError(f"expected finite numbers, got {text!r}", field=field)
    return values


def params_for(matchers: str, params_file: Path | None):
    """``--algos a,b,c`` with their parameters (defaults, or the file's table for each) and the
    search's: a ``ParamsFile``, the file read once."""
    from mbicp_viz.readers.params_toml import read_params

    names = [a.strip() for a in matchers.split(",") if a.strip()]
    if not names:
        raise InputError(f"name at least one matcher: {ALL_MATCHERS}", field="--algos")
    return read_params(params_file, names)


class Progress:
    """A progress bar on a terminal (position and time left); elsewhere (a log, a pipe) a line
    after the first item and then every tenth, with the rate and the time left, so that a log shows
    the run moving as well. ``resumed`` counts items done by an earlier run (not in the rate)."""

    def __init__(self, total: int, label: str = "matching"):
        import sys
        import time

        self.total, self.label, self.done, self.shown, self.before = total, label, 0, 0, 0
        self.t0 = time.monotonic()
        self.bar = (
            typer.progressbar(length=total, label=label, file=sys.stderr, show_pos=True)
            if sys.stderr.isatty()
            else None
        )

    def __enter__(self):
        if self.bar is not None:
            self.bar.__enter__()
        return self

    def resumed(self, n: int) -> None:
        self.before += n
        self.done += n
        self.shown = self.done
        if self.bar is not None and n:
            self.bar.update(n)

    def rate_text(self) -> str:
        """'12.5/s, 40 s left' from the items done here, or '' before any."""
        import time

        done, spent = self.done - self.before, time.monotonic() - self.t0
        if done <= 0 or spent <= 0:
            return ""
        rate = done / spent
        return f"{rate:.3g}/s, {(self.total - self.done) / rate:.0f} s left"

    def update(self, n: int = 1, total: int | None = None) -> None:
        """``n`` more items done; ``total``: the count there are, when it was not known exactly
        (a run that finds its pairs as it reads its log)."""
        self.done += n
        if total is not None and total != self.total:
            self.total = total
            if self.bar is not None:
                self.bar.length = total
        if self.bar is not None:
            self.bar.update(n)
        elif (
            self.done == self.before + 1
            or self.done >= self.shown + max(1, self.total // 10)
            or self.done == self.total
        ):
            self.shown = self.done
            rate = self.rate_text()
            say(f"{self.label}: {self.done}/{self.total}" + (f" ({rate})" if rate else ""))

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.__exit__(*exc)


def read_log_saying(log: str, reading=None):
    """A log, with a line on stderr for each note of how it was read and for the scans skipped as
    unusable."""
    from mbicp_viz.readers import read_log

    lg = read_log(log, reading)
    for note in lg.notes + [lg.unusable_summary()]:
        if note:
            say(note)
    return lg


def read_options(
    topic: str | None,
    typestore: str | None = None,
    mount=None,
    upside_down: bool = False,
    deskew=None,
):
    """How to read the files a command names (``--topic``, ``--typestore``, ``--mount``,
    ``--upside-down``, ``--deskew``; a command without ``--typestore`` reads with ``ReadOptions``'
    own)."""
    from mbicp_viz.readers import ReadOptions

    return ReadOptions(
        topic,
        typestore or ReadOptions.typestore,
        pose_from_deg(mount, "--mount"),
        upside_down,
        None if deskew is None else deskew.value,
    )


CloseLoopsOpt = Annotated[
    bool,
    typer.Option(
        "--close-loops",
        help="close the run's loops (evaluation/loops.py: key frames matched against old ones "
        "with the run's matcher and parameters, a pose graph on GTSAM), what it did on stderr: "
        "eval sequence records them in --rrd, eval relations --run scores the optimised run, "
        "serve draws and lists every candidate in the run view",
    ),
]
LoopGapOpt = Annotated[
    float,
    typer.Option(
        "--loop-gap-m",
        min=0.0,
        callback=finite,
        help="with --close-loops: a key frame this far back along the run [m] is old enough to "
        "close a loop with",
    ),
]


def closed_run(lg, rows: list, gap_m: float, keyframes=None):
    """The run with its loops closed (evaluation/loops.py: a ``LoopRun``), old key frames being
    ``gap_m`` back along the run or more, its key frames ``keyframes`` (a ``KeyFrames``; None:
    the default spacing); what an earlier command found for the same run is read from the cache
    (evaluation/loop_cache.py); what it did said on stderr."""
    from mbicp_viz.evaluation import loop_cache
    from mbicp_viz.evaluation.loops import LoopParams, find_closures, plan, solved

    p = LoopParams(min_path_m=gap_m)
    p = p if keyframes is None else replace(p, keyframes=keyframes)
    folder = loop_cache.entry(lg, rows, p)
    found = loop_cache.load(folder) if folder is not None else None
    if found is not None:
        say(f"loops: what an earlier command found, read from the cache {folder}")
    else:
        with Progress(len(plan(rows, p)[1]) - 1, "closing loops") as bar:
            found = find_closures(lg, rows, rows[0].params, p, on_key=lambda: bar.update(1))
        if folder is not None:
            loop_cache.save(folder, found, lg)
    closed = solved(rows, p, found)
    for line in closed.summary():
        say(line)
    return closed


KeyframeOpt = Annotated[
    float,
    typer.Option(
        "--keyframe-m",
        min=0.0,
        callback=finite,
        help="a key-frame run: match each scan against the last key frame, a new one once the "
        "robot has moved this far [m] or turned --keyframe-deg from it (or its match failed); "
        "one process; 0.6 did best on the full Intel and ACES logs. 0: each scan against the one "
        "before",
    ),
]
KeyframeDegOpt = Annotated[
    float,
    typer.Option(
        "--keyframe-deg",
        min=0.0,
        max=180.0,
        callback=finite,
        help="with --keyframe-m: the turn [deg] from the key frame that makes a new one",
    ),
]
