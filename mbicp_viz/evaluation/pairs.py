"""Scan pairs and their initial guesses: read from files, made from one scan, guessed.

Every pose maps object-frame points into the reference frame (``T_ref_obj``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mbicp_viz.choices import Guess, Thin
from mbicp_viz.core import Pose2, Scan, ScanSource, SearchParams, make_scan, relative
from mbicp_viz.errors import InputError
from mbicp_viz.readers import ReadOptions, ScanLog, read_log


@dataclass(frozen=True)
class ScanPair:
    ref: Scan
    obj: Scan
    label: str
    log: ScanLog  # the file the reference came from: its frames


def load_pair(
    first: str, second: str | None, pair: tuple[int, int] | None, options: ReadOptions | None = None
) -> ScanPair:
    """``REF OBJ`` (the first scan of each file) or ``LOG --pair I J``; the log of the reference
    holds the frames (mount, base frame)."""
    if second is not None and pair is not None:
        raise InputError(
            "give either two files or one log with --pair I J, not both", field="--pair"
        )
    if second is not None:
        if second.lower() in ("true", "false") and not Path(second).exists():
            raise InputError(
                f"{second!r} is no file: flags take no value (write --json, not --json {second})",
                field="SECOND",
            )
        log = read_log(first, options)
        return ScanPair(log.scan(0), read_log(second, options).scan(0), f"{first} -> {second}", log)
    log = read_log(first, options)
    i, j = pair if pair is not None else log.consecutive_pairs(1)[0]
    return ScanPair(
        log.scan(i), log.scan(j), f"{first} scans {i % log.records} -> {j % log.records}", log
    )


# A guess from the log's scan poses: they are then no answer to judge the match against.
SCAN_POSES = "scan poses"
# Where the answer came from when it is the log's scan poses.
STORED_ANSWER = "the log's scan poses"


def stored_guess(ref: Scan, obj: Scan) -> tuple[Pose2, str]:
    """Initial guess from the poses (else odometry) the log stores, identity when it has neither."""
    if ref.pose is not None and obj.pose is not None:
        return relative(ref.pose, obj.pose), SCAN_POSES
    if ref.odometry is not None and obj.odometry is not None:
        return relative(ref.odometry, obj.odometry), "odometry"
    return Pose2(), "identity"


# Where the guess of a pair came from when the source asked for is missing at one of its scans
# (a bag's first scans before its first odometry message): a run goes on from the identity.
MISSING = "identity: no {} at one of the scans"


def missing_guess(source: str) -> bool:
    """Whether a row's guess came from the identity for want of the one asked for (``MISSING``)."""
    head, tail = MISSING.split("{}")
    return source.startswith(head) and source.endswith(tail)


def pair_guess(
    ref: Scan,
    obj: Scan,
    kind: Guess | str,
    search: SearchParams | None = None,
    missing_ok: bool = False,
) -> tuple[Pose2, str]:
    """The initial guess of a pair and where it came from: ``stored`` (poses, else odometry, else
    identity), one stored source explicitly, the identity, or the correlative search around it.
    A source asked for and missing is refused, or with ``missing_ok`` (a run over a whole log)
    the identity, with ``MISSING`` as where it came from."""
    kind = Guess(kind)
    if kind is Guess.stored:
        return stored_guess(ref, obj)
    if kind is Guess.identity:
        return Pose2(), "identity"
    if kind is Guess.search:
        from mbicp_viz.core.search import correlative_search

        return correlative_search(ref, obj, Pose2(), search).pose, "search"
    a, b = (ref.pose, obj.pose) if kind is Guess.pose else (ref.odometry, obj.odometry)
    if (a is None or b is None) and missing_ok:
        return Pose2(), MISSING.format(kind.value)
    if a is None or b is None:
        raise InputError(
            f"the log stores no {kind.value} for scans {ref.source.index} and {obj.source.index}",
            ref.source.path,
            field="--guess",
        )
    return relative(a, b), SCAN_POSES if kind is Guess.pose else kind.value


def known_answer(
    ref: Scan, obj: Scan, guess_source: str, given: Pose2 | None = None
) -> tuple[Pose2 | None, str | None]:
    """What a pair's match is judged against, and where it came from: ``given``, else the log's
    scan poses unless the guess came from them (a match started at its own answer proves
    nothing), else nothing."""
    if given is not None:
        return given, "given"
    stored = stored_truth(ref, obj)
    if stored is not None and guess_source != SCAN_POSES:
        return stored, STORED_ANSWER
    return None, None


def stored_truth(ref: Scan, obj: Scan) -> Pose2 | None:
    """The relative pose of the scan poses a log stores (corrected logs: the truth), or None."""
    return relative(ref.pose, obj.pose) if ref.pose is not None and obj.pose is not None else None


def stored_odometry(ref: Scan, obj: Scan) -> Pose2 | None:
    """The laser's motion by the log's odometry (wheels, or a bag's /odom or /tf), or None."""
    return (
        relative(ref.odometry, obj.odometry)
        if ref.odometry is not None and obj.odometry is not None
        else None
    )


# One scan made into a pair with a known answer (paper 000 §3.1's protocol, curated scenarios).


def seen_from(scan: Scan, T: Pose2, keep: np.ndarray | None = None) -> Scan:
    """The points of ``scan`` as a sensor at pose T (in the scan's frame) sees them."""
    pts = scan.points() if keep is None else scan.points()[keep]
    p = T.inverse().apply(pts)
    b = np.arctan2(p[:, 1], p[:, 0])
    order = np.argsort(b, kind="stable")
    b = b[order]
    unique = np.concatenate(([True], np.diff(b) > 0))
    return make_scan(
        np.hypot(*p[order].T)[unique],
        b[unique],
        source=ScanSource(f"{scan.source.path} (displaced)", scan.source.index),
    )


def thinned(scan: Scan, keep: np.ndarray) -> Scan:
    """``scan`` with the valid readings where ``keep`` is False marked invalid.

    The beams stay (uniform bearings, as PSM's reference needs); ``keep`` runs over the valid
    readings.
    """
    valid = scan.valid.copy()
    valid[scan.valid_indices()[~keep]] = False
    return make_scan(scan.ranges, scan.bearings, valid=valid, source=scan.source)


def displaced_pair(
    scan: Scan, truth: Pose2, keep: np.ndarray | None, thin: Thin | str
) -> tuple[Scan, Scan]:
    """(reference, object) from one scan: the object is the scan seen from ``truth``; ``keep``
    (over the valid readings) thins the reference or the object, as ``thin`` says."""
    if keep is None or Thin(thin) is Thin.object:
        return scan, seen_from(scan, truth, keep)
    return thinned(scan, keep), seen_from(scan, truth)


def block_mask(n: int, a: float, b: float) -> np.ndarray:
    """Keep all of ``n`` readings but those from fraction ``a`` to ``b`` (an occlusion-like
    block)."""
    keep = np.ones(n, dtype=bool)
    keep[int(round(a * n)) : int(round(b * n))] = False
    return keep
