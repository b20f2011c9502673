"""Turning command-line arguments into scans, pairs, guesses and parameters."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from core import MATCHERS, Params, Pose2, Scan, relative
from core.search import SearchParams

from .errors import InputError
from .params_io import load_params
from .readers import ScanLog, read_log


@dataclass(frozen=True)
class ScanPair:
    ref: Scan
    obj: Scan
    label: str


def load_pair(first: str, second: str | None, pair: tuple[int, int] | None) -> ScanPair:
    """``REF OBJ`` (the first scan of each file) or ``LOG --pair I J``."""
    if second is not None and pair is not None:
        raise InputError("give either two files or one log with --pair I J, not both", field="--pair")
    if second is not None:
        return ScanPair(read_log(first).scan(0), read_log(second).scan(0), f"{first} -> {second}")
    log = read_log(first)
    i, j = pair if pair is not None else (0, 1)
    return ScanPair(log.scan(i), log.scan(j), f"{first} scans {i} -> {j}")


def stored_guess(ref: Scan, obj: Scan) -> tuple[Pose2, str]:
    """Initial guess from the poses (else odometry) the log stores, identity when it has neither."""
    if ref.pose is not None and obj.pose is not None:
        return relative(ref.pose, obj.pose), "scan poses"
    if ref.odometry is not None and obj.odometry is not None:
        return relative(ref.odometry, obj.odometry), "odometry"
    return Pose2(), "identity"


def guess_from_deg(init: tuple[float, float, float] | None, option: str = "--init") -> Pose2 | None:
    """A pose given as X Y THETA_DEG on the command line (``option`` names it in errors)."""
    if init is None:
        return None
    x, y, th = init
    for name, v in (("X", x), ("Y", y), ("THETA_DEG", th)):
        if not math.isfinite(v):
            raise InputError(f"must be finite, got {v}", field=f"{option} {name}")
    return Pose2(x, y, math.radians(th))


def search_window_text(params: SearchParams = SearchParams()) -> str:
    """The correlative search's window as users read it (degrees at the edge)."""
    return f"+/-{params.window_xy:g} m, +/-{math.degrees(params.window_theta):g} deg"


def make_params(algorithm: str, params_file: str | Path | None) -> Params:
    """Defaults of ``algorithm``, or its parameters from a ``--params`` TOML file."""
    if algorithm not in MATCHERS:
        raise InputError(f"unknown algorithm {algorithm!r}; choose one of {', '.join(MATCHERS)}", field="--algo")
    return load_params(str(params_file), algorithm) if params_file else MATCHERS[algorithm].params_type()


def params_for(algos: str, params_file: str | Path | None) -> dict[str, Params]:
    """``--algos a,b,c`` with their parameters (defaults, or the file's table for each)."""
    names = [a.strip() for a in algos.split(",") if a.strip()]
    if not names:
        raise InputError(f"name at least one matcher: {', '.join(MATCHERS)}", field="--algos")
    return {a: make_params(a, params_file) for a in names}


def number_list(text: str, field: str, example: str, kind=float) -> list:
    """``--field 1,2,3`` as numbers of ``kind``; one clear error for anything else."""
    try:
        values = [kind(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"expected numbers like {example}, got {text!r}", field=field) from None
    if not all(math.isfinite(v) for v in values):
        raise InputError(f"expected finite numbers, got {text!r}", field=field)
    return values


def consecutive_pairs(log: ScanLog, limit: int | None = None):
    n = len(log.scans) - 1 if limit is None else min(limit, len(log.scans) - 1)
    if n < 1:
        raise InputError("needs at least two scans", log.path)
    return [(k, k + 1) for k in range(n)]
