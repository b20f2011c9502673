"""The plain formats for a user's own scans.

Text (``.scans``, ``.txt``): ``#`` starts a comment; every other line is one scan,

    angle_min_rad angle_increment_rad range_1_m ... range_n_m

with NaN, inf or 0 for a reading with no return. ``.npz`` (numpy, loaded without pickle):
``ranges`` (S, N) metres, ``bearings`` (N,) or (S, N) radians, optional ``poses`` (S, 3)
``x y theta`` of each scan in a common world frame (metres, radians).
"""

from __future__ import annotations

import zipfile

import numpy as np

from mbicp_viz.core import Pose2, ScanSource, uniform_bearings
from mbicp_viz.errors import InputError

from .log import ScanLog, scan_or_reason
from .text import token_lines


def read_plain_text(path: str) -> ScanLog:
    log = ScanLog(str(path), [])
    for fields in token_lines(path):
        if len(fields.t) < 4:
            raise fields.error(
                f"expected 'angle_min_rad angle_increment_rad range_1_m ...', got {len(fields.t)} "
                "fields"
            )
        start = fields.take("angle_min_rad")
        inc = fields.take("angle_increment_rad")
        if inc <= 0:
            raise fields.error(f"must be positive, got {inc}", "angle_increment_rad")
        ranges = fields.take_floats(fields.left, "range")
        log.add(
            scan_or_reason(
                ranges,
                uniform_bearings(len(ranges), start, inc),
                path,
                fields.line,
                "ranges",
                source=ScanSource(str(path), log.records, fields.line),
            )
        )
    if not log.records:
        raise InputError("no scan lines", path)
    return log


# Uncompressed size a .npz may announce: a small file must not unpack into gigabytes.
MAX_NPZ_BYTES = 512 * 1024 * 1024


def _load_npz(path: str) -> dict[str, np.ndarray]:
    try:
        with zipfile.ZipFile(path) as zf:
            size = sum(i.file_size for i in zf.infolist())
        if size > MAX_NPZ_BYTES:
            raise InputError(
                f"unpacks to {size / 1e6:.0f} MB, over the {MAX_NPZ_BYTES / 1e6:.0f} MB a scan "
                "file may",
                path,
            )
        with np.load(path, allow_pickle=False) as z:  # never unpickle a user's file
            return {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except IsADirectoryError:
        raise InputError("is a folder, not a file", path) from None
    except InputError:
        raise
    except Exception as e:  # numpy parses a damaged array header with Python's tokenizer: any error
        raise InputError(
            f"not a readable .npz file ({type(e).__name__}: {str(e)[:160]})", path
        ) from None


def _real_array(arrays: dict, name: str, path: str) -> np.ndarray:
    a = arrays[name]
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise InputError(f"expected real numbers, got dtype {a.dtype}", path, field=name)
    return a.astype(float)


def read_npz(path: str) -> ScanLog:
    arrays = _load_npz(path)
    if "ranges" not in arrays or "bearings" not in arrays:
        raise InputError(f"needs arrays 'ranges' and 'bearings', has {sorted(arrays)}", path)
    ranges = np.atleast_2d(_real_array(arrays, "ranges", path))
    if ranges.ndim != 2 or ranges.size == 0:
        raise InputError(
            f"expected an (S, N) array of scans, got shape {ranges.shape}", path, field="ranges"
        )
    bearings = _real_array(arrays, "bearings", path)
    if bearings.shape not in ((ranges.shape[1],), ranges.shape):
        raise InputError(
            f"expected shape ({ranges.shape[1]},) or {ranges.shape}, got {bearings.shape}",
            path,
            field="bearings",
        )
    bearings = np.broadcast_to(bearings, ranges.shape)
    poses = _real_array(arrays, "poses", path) if "poses" in arrays else None
    if poses is not None and (poses.shape != (len(ranges), 3) or not np.all(np.isfinite(poses))):
        raise InputError(
            f"expected a finite ({len(ranges)}, 3) array, got shape {poses.shape}",
            path,
            field="poses",
        )
    log = ScanLog(str(path), [])
    for k in range(len(ranges)):
        log.add(
            scan_or_reason(
                ranges[k],
                bearings[k],
                path,
                None,
                f"scan {k}",
                source=ScanSource(str(path), k),
                pose=Pose2(*poses[k]) if poses is not None else None,
            )
        )
    return log


def write_npz(path: str, scans, with_poses: bool = True) -> None:
    """Write scans of equal beam count in the ``.npz`` layout above (invalid readings as NaN)."""
    ranges = np.array([np.where(s.valid, s.ranges, np.nan) for s in scans])
    arrays = {"ranges": ranges, "bearings": np.array([s.bearings for s in scans])}
    if with_poses and all(s.pose is not None for s in scans):
        arrays["poses"] = np.array([s.pose.as_array() for s in scans])
    np.savez_compressed(path, **arrays)
