"""``bench originals``: this project's MbICP, ICP and PL-ICP against the original C implementations.

The originals are built outside the project by ``tools/originals/build.sh DIR`` (Minguez's MbICP as
Player ships it, Censi's CSM), with two small drivers of this project that read pairs on stdin and
print one pose per pair, and on stderr the seconds spent in the matching calls alone and the count.
Every consecutive pair of a log (the first N) is matched by both from the same guess: the log's
stored relative pose moved within the perturbation (``bench_guesses``, seeded), the issues'
protocol (±0.3 m, ±15°).
"""

from __future__ import annotations

import dataclasses
import math
import re
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mbicp_viz.core import MATCHERS, MbicpParams, Params, Pose2, Scan, match
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ScanLog

from .bench import bench_guesses
from .criteria import PAPER_000, Criteria
from .pairs import stored_truth

# Player's mbicp driver calls its library with MAXLASERPOINTS = 361 rays
MAX_RAYS = 361
# An original that has not answered by then is stuck (300 pairs take seconds)
DRIVER_TIMEOUT_S = 600
# When this project's pose and the original's agree (issue 21: 1 mm and 0.01 deg)
AGREE = Criteria("agreement with the original", 1e-3, math.radians(0.01))
NO_POSES = "no stored poses to count successes"

Pair = tuple[Scan, Scan, Pose2]


@dataclass(frozen=True)
class Original:
    """One original matcher: the driver built by build.sh, its arguments and what it reads."""

    name: str  # this project's matcher of the same algorithm
    driver: str
    args: tuple[str, ...]
    input: Callable[[list[Pair]], str]  # the driver's stdin for these pairs
    max_rays: int | None = None  # the most rays a scan may have for it (None: any)


@dataclass(frozen=True)
class Comparison:
    """One matcher against its original on the same pairs."""

    name: str
    pairs: int
    agree: int  # poses within 1 mm and 0.01 deg of the original's
    # within paper 000's 0.1 m and 3.14 deg of the stored poses (None: no poses)
    successes_original: int | None
    successes_ours: int | None
    ms_original: float  # mean time per match, best of the runs
    ms_ours: float

    def line(self) -> str:
        return (
            f"{self.name:6s} agree within 1 mm / 0.01 deg: {self.agree}/{self.pairs} "
            f"({100 * self.agree / self.pairs:.1f} %); {self.successes()}; "
            f"mean time per match original {self.ms_original:.3f} ms, ours "
            f"{self.ms_ours:.3f} ms (ratio {self.ms_ours / self.ms_original:.2f})"
        )

    def successes(self) -> str:
        if self.successes_ours is None:
            return NO_POSES
        return f"successes original {self.successes_original}, ours {self.successes_ours}"


@dataclass(frozen=True)
class Skipped:
    """An original that cannot take these scans."""

    name: str
    why: str

    def line(self) -> str:
        return f"{self.name:6s} not compared: {self.why}"


def every_kth_beam(log: ScanLog, k: int) -> ScanLog:
    """The log with every k-th beam of each scan (copies: the kernels take contiguous arrays)."""
    if k == 1:
        return log
    scans = [
        dataclasses.replace(
            s,
            ranges=s.ranges[::k].copy(),
            bearings=s.bearings[::k].copy(),
            valid=s.valid[::k].copy(),
            beam_times=None,
        )
        for s in log.scans
    ]
    return dataclasses.replace(log, scans=scans)


def protocol_pairs(log: ScanLog, limit: int, perturb: tuple[float, float], seed: int) -> list[Pair]:
    """The first ``limit`` consecutive pairs with their perturbed guesses (metres, radians)."""
    idx = log.consecutive_pairs(limit)
    guesses = bench_guesses(log, idx, perturb, seed)
    return [(log.scan(i), log.scan(j), g) for (i, j), g in zip(idx, guesses)]


def check_built(built: Path) -> None:
    """Refuse a folder without the drivers build.sh makes."""
    for original in ORIGINALS:
        if not (built / original.driver).is_file():
            raise InputError(
                f"no original built here: run tools/originals/build.sh {built}",
                path=str(built / original.driver),
            )


def compare(built: Path, pairs: list[Pair], repeat: int) -> list[Comparison | Skipped]:
    """Each original against this project's matcher of the same name, with both defaults (or why
    not)."""
    out = []
    rays = max(len(a.bearings) for a, _, _ in pairs)
    for original in ORIGINALS:
        if original.max_rays is not None and rays > original.max_rays:
            k = math.ceil(rays / original.max_rays)
            out.append(
                Skipped(
                    original.name,
                    f"the original takes at most {original.max_rays} rays and these scans "
                    f"have {rays}: --every {k} keeps one beam in {k}",
                )
            )
            continue
        text = original.input(pairs)
        runs = [
            run_driver(built / original.driver, original.args, text, len(pairs))
            for _ in range(repeat)
        ]
        params = MATCHERS[original.name].params_type()
        mine = [time_ours(pairs, params) for _ in range(repeat)]
        theirs, ours = runs[0][0], mine[0][0]
        agree = sum(AGREE.judge(x, y) for x, y in zip(ours, theirs))
        out.append(
            Comparison(
                original.name,
                len(pairs),
                agree,
                successes(pairs, theirs),
                successes(pairs, ours),
                min(r[1] for r in runs),
                min(m[1] for m in mine),
            )
        )
    return out


def improved_against_plicp(
    pairs: list[Pair], params: Params, label: str, plicp: Comparison, repeat: int
) -> str:
    """Improved MbICP's time per match against CSM's PL-ICP's on the same pairs (issue 21's
    ratio)."""
    runs = [time_ours(pairs, params) for _ in range(repeat)]
    ms, ok = min(r[1] for r in runs), successes(pairs, runs[0][0])
    return (
        f"improved MbICP ({label}) {ms:.3f} ms against CSM's PL-ICP {plicp.ms_original:.3f} ms per "
        "match "
        f"(ratio {ms / plicp.ms_original:.2f}); {NO_POSES if ok is None else f'successes {ok}'}"
    )


def successes(pairs: list[Pair], poses: list[Pose2]) -> int | None:
    """Poses within paper 000's success bounds of the log's stored relative poses (None without
    them)."""
    truths = [stored_truth(a, b) for a, b, _ in pairs]
    if all(t is None for t in truths):
        return None
    return sum(t is not None and PAPER_000.judge(p, t) for p, t in zip(poses, truths))


def time_ours(pairs: list[Pair], params: Params) -> tuple[list[Pose2], float]:
    """This project's poses and its mean time per match [ms], every call timed as a user makes
    it."""
    for a, b, g in pairs[:3]:  # compiled kernels loaded
        match(a, b, g, params)
    t0 = time.perf_counter()
    poses = [match(a, b, g, params).pose for a, b, g in pairs]
    return poses, 1000.0 * (time.perf_counter() - t0) / len(pairs)


def run_driver(exe: Path, args: tuple[str, ...], text: str, n: int) -> tuple[list[Pose2], float]:
    """The original's poses and its mean time per match [ms] (timed by the driver around its
    call)."""
    try:
        out = subprocess.run(
            [str(exe), *args], input=text, capture_output=True, text=True, timeout=DRIVER_TIMEOUT_S
        )
    except OSError as e:
        raise InputError(f"cannot run it: {e.strerror}", path=str(exe)) from None
    except subprocess.TimeoutExpired:
        raise InputError(
            f"no answer within {DRIVER_TIMEOUT_S} s for {n} pairs", path=str(exe)
        ) from None
    lines = [line.split() for line in out.stdout.splitlines() if line.strip()]
    # CSM logs to stderr in colour, its reset code not followed by a newline
    times = re.sub(r"\x1b\[[0-9;]*m", " ", out.stderr).split()[-2:]
    if out.returncode != 0 or len(lines) != n or len(times) != 2:
        raise InputError(
            f"exit code {out.returncode}, {len(lines)} poses for {n} pairs; expected one pose per "
            "pair and 'seconds count' on stderr (a driver of tools/originals)",
            path=str(exe),
        )
    try:
        poses = [Pose2(*(float(v) for v in fields[1:4])) for fields in lines]
        return poses, 1000.0 * float(times[0]) / int(times[1])
    except (ValueError, TypeError, ZeroDivisionError) as e:
        raise InputError(f"unreadable output ({e})", path=str(exe)) from None


def _mbicp_input(pairs: list[Pair], p: MbicpParams) -> str:
    """mbicp_pairs.c's stdin: the parameters, then per pair the ray count, both scans (no-return
    rays beyond range) and the guess."""
    head = [
        p.max_range,
        p.Bw,
        p.Br,
        p.L,
        p.laserStep,
        p.MaxDistInter,
        p.filter,
        int(p.ProjectionFilter),
        p.AsocError,
        p.MaxIter,
        p.errorRatio,
        p.errx_out,
        p.erry_out,
        p.errt_out,
        p.IterSmoothConv,
    ]
    lines = [" ".join(str(v) for v in head)]
    for a, b, g in pairs:
        lines.append(str(len(a.bearings)))
        # the C code reads the reference's bearings from the object scan: the same grid
        for s in (
            a,
            b,
        ):
            lines += [
                f"{r if v else 1e6:.6f} {t:.9f}" for r, t, v in zip(s.ranges, s.bearings, s.valid)
            ]
        lines.append(f"{float(g.x)!r} {float(g.y)!r} {float(g.theta)!r}")
    return "\n".join(lines) + "\n"


def _csm_input(pairs: list[Pair]) -> str:
    """csm_pairs.c's stdin: per pair the ray count, both scans with validity, and the guess."""
    lines = []
    for a, b, g in pairs:
        lines.append(str(len(a.bearings)))
        for s in (a, b):
            lines += [
                f"{r if v else 0.0:.6f} {t:.9f} {int(v)}"
                for r, t, v in zip(s.ranges, s.bearings, s.valid)
            ]
        lines.append(f"{float(g.x)!r} {float(g.y)!r} {float(g.theta)!r}")
    return "\n".join(lines) + "\n"


ORIGINALS = (
    Original(
        "mbicp", "mbicp_pairs", (), lambda pairs: _mbicp_input(pairs, MbicpParams()), MAX_RAYS
    ),
    Original("icp", "csm_pairs", ("0",), _csm_input),
    Original("plicp", "csm_pairs", ("1",), _csm_input),
)
