"""``tune``: the parameters that work for a robot, found against ground truth with Optuna.

A study searches a matcher's parameter dataclass: the fields named (default: those with a tuning
range in their metadata, ``core/params.py``), each within its tuning range or, for a field
without one, its validation bounds (log scale when they span two decades or more). Each trial
matches every case — a pair of scans of the training logs, its guess and its truth (the logs'
scan poses, or Kümmerle's relations) — spread over the local cores, whose processes read the
logs once. The objective ranks trials by successes (within 0.1 m and 3 deg of the truth), then by
the median translation error. Trials live in Optuna's RDB storage: a SQLite file by default; a
PostgreSQL URL shares one study between processes on any number of machines (Optuna's documented
way to distribute), and a study is resumed by its name.
"""

from __future__ import annotations

import json
import math
import os
import socket
import threading
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from mbicp_viz.core import FieldSpec, ParamError, Params, field_specs, match, pose_error
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ReadOptions, ScanLog, read_log

from .cases import Case
from .criteria import CONSECUTIVE
from .pool import ignore_interrupts, interrupt_taken, stopping


@dataclass(frozen=True)
class Score:
    """How a parameter set did on the cases."""

    successes: int
    n: int
    median_xy: float  # [m]
    median_theta: float  # [rad]

    @staticmethod
    def of(errors: np.ndarray) -> Score:
        ok = sum(CONSECUTIVE.correct(e, r) for e, r in errors)
        return Score(
            int(ok), len(errors), float(np.median(errors[:, 0])), float(np.median(errors[:, 1]))
        )

    @property
    def value(self) -> float:
        """Successes first; below one success, the median error (0.1 m or more adds nothing)."""
        return self.successes + 0.5 * (1.0 - min(self.median_xy / CONSECUTIVE.max_error_m, 1.0))

    def text(self) -> str:
        return (
            f"{self.successes}/{self.n} ({100 * self.successes / self.n:.1f} %), median "
            f"{1000 * self.median_xy:.1f} mm, "
            f"{math.degrees(self.median_theta):.2f} deg"
        )


STUDY_ATTEMPTS = 10  # opening a study that other workers are creating at the same moment

# The logs and cases of a pool's processes, read once when the process starts.
_LOGS: list[ScanLog] = []
_CASES: list[Case] = []
_STOP = threading.Event()  # set by Ctrl-C while optimising


def _load(paths: list[str], options: ReadOptions | None, cases: list[Case]) -> None:
    global _LOGS, _CASES
    _LOGS, _CASES = [read_log(p, options) for p in paths], cases


def _start_worker(paths: list[str], options: ReadOptions | None, cases: list[Case]) -> None:
    ignore_interrupts()  # Ctrl-C is the parent's to handle: it keeps the finished trials
    _load(paths, options, cases)


def _errors(job) -> np.ndarray:
    """(translation, rotation) error of each case in [start, stop); a failed match counts as far
    off."""
    params, start, stop = job
    out = np.empty((stop - start, 2))
    for n, c in enumerate(_CASES[start:stop]):
        if _STOP.is_set():  # Ctrl-C: drop this trial here, between two matches
            raise KeyboardInterrupt
        log = _LOGS[c.log]
        try:
            out[n] = pose_error(
                match(log.scans[c.i], log.scans[c.j], c.guess, params).pose, c.truth
            )
        except (ValueError, FloatingPointError):  # a scan error, or parameters it refuses
            out[n] = (math.inf, math.inf)
    return out


class Scorer:
    """Scores parameter sets on the cases over ``workers`` processes that read the logs once."""

    def __init__(
        self, paths: list[str], options: ReadOptions | None, cases: list[Case], workers: int | None
    ):
        self.n, self.workers = len(cases), workers or os.cpu_count() or 1
        self.pool = None
        if self.workers > 1:
            self.pool = ProcessPoolExecutor(
                self.workers, initializer=_start_worker, initargs=(paths, options, cases)
            )
        else:
            _load(paths, options, cases)

    def errors(self, params: Params) -> np.ndarray:
        if self.pool is None:
            return _errors((params, 0, self.n))
        bounds = np.linspace(0, self.n, 4 * self.workers + 1).astype(int)
        jobs = [(params, a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
        out = np.vstack(list(self.pool.map(_errors, jobs)))
        if _STOP.is_set():
            raise KeyboardInterrupt
        return out

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(cancel_futures=True)


@dataclass(frozen=True)
class Dimension:
    """One searched field: its range and scale in the field's own unit (radians stay radians)."""

    spec: FieldSpec
    lo: float
    hi: float
    log: bool


def search_space(params_type: type, fields: list[str] | None) -> list[Dimension]:
    """The fields named, else the ones with a tuning range: each within that range, or within its
    validation bounds (log scale when they span two decades); a refusal names the field."""
    specs = {s.name: s for s in field_specs(params_type)}
    names = fields if fields else [n for n, s in specs.items() if s.tune is not None]
    out = []
    for name in names:
        spec = specs.get(name)
        if spec is None:
            raise InputError(
                f"unknown parameter {name!r}; known: {', '.join(specs)}", field="--fields"
            )
        if spec.type is bool:
            out.append(Dimension(spec, 0.0, 1.0, False))
            continue
        lo, hi, log = spec.tune if spec.tune is not None else (spec.lo, spec.hi, None)
        if lo is None or hi is None or not hi > lo:
            raise InputError(f"{name} has no bounded range to search", field="--fields")
        out.append(Dimension(spec, lo, hi, log if log is not None else lo > 0 and hi / lo >= 100))
    return out


def suggested(trial, base: Params, space: list[Dimension]) -> Params:
    """The trial's parameter set: ``base`` with each searched field drawn from its dimension."""
    values = {}
    for d in space:
        if d.spec.type is bool:
            values[d.spec.name] = trial.suggest_categorical(d.spec.name, [False, True])
        elif d.spec.type is int:
            values[d.spec.name] = trial.suggest_int(d.spec.name, int(d.lo), int(d.hi), log=d.log)
        else:
            values[d.spec.name] = trial.suggest_float(d.spec.name, d.lo, d.hi, log=d.log)
    return base.replace(**values)


SQLITE_WAIT_S = 60.0
# A trial's process says it is alive this often; a RUNNING trial silent for GRACE_S is a stopped
# run's (kill -9, power loss) and is failed, so that a study never holds a trial RUNNING forever.
HEARTBEAT_S, GRACE_S = 10, 60
# PostgreSQL's errors for an object another worker created first: duplicate type, duplicate table
RACED = {"42710", "42P07"}


def open_study(storage: str, name: str):
    """The study ``name`` in ``storage`` (an Optuna RDB URL), created if new, resumed if not."""
    import optuna
    import sqlalchemy.exc

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    if storage.startswith(("postgresql://", "postgres://")):  # the driver installed with the tool
        storage = "postgresql+psycopg://" + storage.split("://", 1)[1]
    for attempt in range(STUDY_ATTEMPTS):
        try:
            # SQLite: a writer waits up to SQLITE_WAIT_S for a reader (another worker, a progress
            # query) to let go of the file instead of failing at once with "database is locked"
            engine = (
                {"connect_args": {"timeout": SQLITE_WAIT_S}} if storage.startswith("sqlite") else {}
            )
            with warnings.catch_warnings():  # heartbeats are "experimental" since Optuna 2.9
                warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                rdb = optuna.storages.RDBStorage(
                    storage,
                    engine_kwargs=engine,
                    heartbeat_interval=HEARTBEAT_S,
                    grace_period=GRACE_S,
                )
            return optuna.create_study(
                storage=rdb, study_name=name, direction="maximize", load_if_exists=True
            )
        except (sqlalchemy.exc.IntegrityError, sqlalchemy.exc.ProgrammingError) as e:
            # workers started together race to create the tables (PostgreSQL: also their enum types)
            # or the study: the loser tries again; any other programming error is the user's URL
            if (
                isinstance(e, sqlalchemy.exc.ProgrammingError)
                and getattr(e.orig, "sqlstate", None) not in RACED
            ):
                raise InputError(
                    f"cannot open the study {name!r} there: {type(e).__name__}: "
                    f"{str(e).splitlines()[0][:200]}",
                    field="--storage",
                ) from None
            time.sleep(0.2 * (attempt + 1))
        # a URL nothing answers at, a driver missing, a file that is no database
        except Exception as e:
            raise InputError(
                f"cannot open the study {name!r} there: {type(e).__name__}: "
                f"{str(e).splitlines()[0][:200]}",
                field="--storage",
            ) from None
    raise InputError(
        f"cannot open the study {name!r} there: other workers kept creating it", field="--storage"
    )


SETTINGS = "objective"  # the study's user attribute: what its trials were scored on


def check_settings(study, settings: dict) -> bool:
    """Refuse to add trials scored on other settings than the study's own (logs, pairs, truth,
    guesses, searched fields ...): its best would compare different objectives. A new study, or one
    made before the settings were recorded, takes these; returns whether it had none."""
    settings = json.loads(json.dumps(settings))  # as the storage gives it back
    theirs = study.user_attrs.get(SETTINGS)
    if theirs is None:
        study.set_user_attr(SETTINGS, settings)
        return True
    for key in sorted(set(theirs) | set(settings)):
        if theirs.get(key) != settings.get(key):
            raise InputError(
                f"study {study.study_name!r} was scored with {key} {json.dumps(theirs.get(key))}, "
                f"this run with {json.dumps(settings.get(key))}: resuming would mix objectives; "
                "give another --study (or the same settings)",
                field=f"--{key.replace('_', '-')}",
            )
    return False


def _dead_here(trial) -> bool:
    """A trial this machine ran whose process is gone."""
    host, _, pid = str(trial.user_attrs.get("worker", "")).rpartition(":")
    if host != socket.gethostname() or not pid.isdigit() or int(pid) == os.getpid():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


def fail_stale_trials(study) -> int:
    """Fail the RUNNING trials of stopped runs: those of a process of this machine that is gone,
    and those whose heartbeat stopped more than ``GRACE_S`` ago. Returns how many."""
    import optuna

    running = optuna.trial.TrialState.RUNNING
    gone = [t for t in study.get_trials(deepcopy=False, states=(running,)) if _dead_here(t)]
    for t in gone:
        study._storage.set_trial_state_values(t._trial_id, optuna.trial.TrialState.FAIL)
    before = len(study.get_trials(deepcopy=False, states=(running,)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        optuna.storages.fail_stale_trials(study)
    return len(gone) + before - len(study.get_trials(deepcopy=False, states=(running,)))


def enqueue_defaults(study, defaults: dict) -> bool:
    """Queue the defaults unless a trial holds them already (scored, queued or running): the best
    is then never worse on the training pairs, whatever stopped an earlier run. Returns whether it
    queued them."""
    import optuna

    states = (
        optuna.trial.TrialState.COMPLETE,
        optuna.trial.TrialState.WAITING,
        optuna.trial.TrialState.RUNNING,
    )
    if any(t.params == defaults for t in study.get_trials(deepcopy=False, states=states)):
        return False
    study.enqueue_trial(defaults)
    return True


def optimise(
    study, scorer: Scorer, base: Params, space: list[Dimension], trials: int, on_trial=None
) -> int:
    """Run ``trials`` more trials; Ctrl-C stops after the running one is dropped (the finished
    ones are stored). Returns how many finished here."""
    import optuna

    worker = f"{socket.gethostname()}:{os.getpid()}"
    done = 0

    def objective(trial) -> float:
        trial.set_user_attr("worker", worker)  # first: a stopped run's trial is known by it
        params = suggested(trial, base, space)
        score = Score.of(scorer.errors(params))
        trial.set_user_attr("successes", score.successes)
        trial.set_user_attr("pairs", score.n)
        trial.set_user_attr("median_xy", score.median_xy)
        return score.value

    def finished(study, trial) -> None:
        nonlocal done
        done += trial.state == optuna.trial.TrialState.COMPLETE
        if on_trial is not None:
            on_trial(trial)

    _STOP.clear()
    try:
        with stopping(_STOP):  # Ctrl-C: the trial under way is dropped between two matches
            study.optimize(objective, n_trials=trials, callbacks=[finished], catch=(ParamError,))
    except KeyboardInterrupt:
        interrupt_taken()
    finally:
        _STOP.clear()  # the scores computed after the study (defaults, best, holdout) run in full
    return done


def best_params(study, base: Params, space: list[Dimension]) -> Params:
    names = {d.spec.name for d in space}
    return base.replace(**{k: v for k, v in study.best_trial.params.items() if k in names})


def history_png(study, path: str) -> None:
    """Each trial's success rate, and the best so far."""
    from mbicp_viz.pyplot import pyplot, save_png

    plt = pyplot()

    done = [t for t in study.trials if t.value is not None]
    x = [t.number for t in done]
    rate = [100.0 * t.user_attrs["successes"] / t.user_attrs["pairs"] for t in done]
    fig, ax = plt.subplots(figsize=(7, 4), dpi=100)
    ax.plot(x, rate, "o", ms=3, color="#888888", label="trial")
    ax.plot(x, np.maximum.accumulate(rate), "-", color="#cc3333", label="best so far")
    ax.set_xlabel("trial")
    ax.set_ylabel(f"pairs within {CONSECUTIVE.text()} [%]")
    ax.set_title(f"study {study.study_name}: optimisation history")
    ax.legend(loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, path)


def importance(study) -> dict[str, float]:
    """Each searched field's share of the objective's variance (Optuna's fANOVA)."""
    import optuna

    return optuna.importance.get_param_importances(study) if len(study.trials) >= 2 else {}


def importance_png(shares: dict[str, float], study_name: str, path: str) -> None:
    from mbicp_viz.pyplot import pyplot, save_png

    plt = pyplot()

    names = list(shares)[::-1]
    fig, ax = plt.subplots(figsize=(7, 0.4 * len(names) + 1.5), dpi=100)
    ax.barh(names, [shares[n] for n in names], color="#3366aa")
    ax.set_xlabel("share of the objective's variance (fANOVA)")
    ax.set_title(f"study {study_name}: parameter importance")
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    save_png(fig, path)
