"""The plain formats for a user's own scans.

Text (``.scans``, ``.txt``): ``#`` starts a comment; every other line is one scan,

    angle_min_rad angle_increment_rad range_1_m ... range_n_m

with NaN, inf or 0 for a reading with no return. ``.npz`` (numpy, loaded without pickle):
``ranges`` (S, N) metres, ``bearings`` (N,) or (S, N) radians, optional ``poses`` (S, 3)
``x y theta`` of each scan in a common world frame (metres, radians).
"""

from __future__ import annotations

import math
import zipfile

import numpy as np

from core import Pose2, ScanError, ScanSource, make_scan, uniform_bearings

from ..errors import InputError
from .log import ScanLog
from .text import open_text


def read_plain_text(path: str) -> ScanLog:
    scans = []
    with open_text(path) as f:
        for line_no, line in enumerate(f, start=1):
            toks = line.split("#", 1)[0].split()
            if not toks:
                continue
            if len(toks) < 4:
                raise InputError(f"expected 'angle_min_rad angle_increment_rad range_1_m ...', got {len(toks)} fields",
                                 path, line_no)
            try:
                values = np.array(toks, dtype=float)
            except ValueError:
                k = next(i for i, t in enumerate(toks) if not _is_float(t))
                name = ("angle_min_rad", "angle_increment_rad")[k] if k < 2 else f"range[{k - 2}]"
                raise InputError(f"expected a number, got {toks[k][:40]!r}", path, line_no, name) from None
            start, inc = values[:2]
            for name, v in (("angle_min_rad", start), ("angle_increment_rad", inc)):
                if not math.isfinite(v):
                    raise InputError(f"not finite: {v}", path, line_no, name)
            if inc <= 0:
                raise InputError(f"must be positive, got {inc}", path, line_no, "angle_increment_rad")
            ranges = values[2:]
            scans.append(_make(ranges, uniform_bearings(len(ranges), start, inc), None,
                               ScanSource(str(path), len(scans), line_no)))
    if not scans:
        raise InputError("no scan lines", path)
    return ScanLog(str(path), scans)


def _is_float(t):
    try:
        float(t)
        return True
    except ValueError:
        return False


def _make(ranges, bearings, pose, src):
    try:
        return make_scan(ranges, bearings, pose=pose, source=src)
    except ScanError as e:
        raise InputError(e.reason, src.path, src.line, "ranges" if src.line else f"scan {src.index}") from None


def read_npz(path: str) -> ScanLog:
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as e:
        raise InputError(f"not a readable .npz file ({e})", path) from None
    if "ranges" not in arrays or "bearings" not in arrays:
        raise InputError(f"needs arrays 'ranges' and 'bearings', has {sorted(arrays)}", path)
    ranges = np.atleast_2d(arrays["ranges"])
    if ranges.ndim != 2 or not np.issubdtype(ranges.dtype, np.number):
        raise InputError(f"expected a numeric (S, N) array, got shape {ranges.shape}", path, field="ranges")
    bearings = arrays["bearings"]
    if not np.issubdtype(bearings.dtype, np.number) or bearings.shape not in ((ranges.shape[1],), ranges.shape):
        raise InputError(f"expected shape ({ranges.shape[1]},) or {ranges.shape}, got {bearings.shape}", path,
                         field="bearings")
    bearings = np.broadcast_to(bearings, ranges.shape)
    poses = arrays.get("poses")
    if poses is not None and (poses.shape != (len(ranges), 3) or not np.all(np.isfinite(poses))):
        raise InputError(f"expected a finite ({len(ranges)}, 3) array, got shape {poses.shape}", path, field="poses")
    scans = [_make(ranges[k], bearings[k], Pose2(*poses[k]) if poses is not None else None,
                   ScanSource(str(path), k)) for k in range(len(ranges))]
    return ScanLog(str(path), scans)


def write_npz(path: str, scans, with_poses: bool = True) -> None:
    """Write scans of equal beam count in the ``.npz`` layout above (invalid readings as NaN)."""
    ranges = np.array([np.where(s.valid, s.ranges, np.nan) for s in scans])
    arrays = {"ranges": ranges, "bearings": np.array([s.bearings for s in scans])}
    if with_poses and all(s.pose is not None for s in scans):
        arrays["poses"] = np.array([s.pose.as_array() for s in scans])
    np.savez_compressed(path, **arrays)
