"""Readers for the scan formats users have, chosen by file name; every reader returns a ``ScanLog``.

| format | files | reader |
|---|---|---|
| CARMEN log | ``*.log``, ``*.clf`` (plain, ``.gz``, ``.bz2``, ``.xz``) | :func:`read_carmen` |
| Minguez ``.off`` | ``*.off`` | :func:`read_off` |
| CSM JSON laser_data | ``*.json``, ``*.jsonl`` | :func:`read_csm_json` |
| ROS 1 / ROS 2 bag | ``*.bag``, ``*.db3``, ``*.mcap``, a rosbag2 folder | :func:`read_rosbag` |
| plain text / numpy | ``*.scans``, ``*.txt``, ``*.npz`` | :mod:`.plain` |

Text formats may be compressed whatever their name says (the reader looks at the first bytes);
a compression suffix is looked through to the format's own (``intel.clf.bz2``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from mbicp_viz.choices import DEFAULT_TYPESTORE
from mbicp_viz.core import Pose2
from mbicp_viz.errors import InputError

from .log import ScanLog, mirrored, no_usable_scan

_READERS = {
    ".log": "carmen:read_carmen",
    ".clf": "carmen:read_carmen",
    ".off": "off:read_off",
    ".json": "csm_json:read_csm_json",
    ".jsonl": "csm_json:read_csm_json",
    ".bag": "rosbag:read_rosbag",
    ".db3": "rosbag:read_rosbag",
    ".mcap": "rosbag:read_rosbag",
    ".scans": "plain:read_plain_text",
    ".txt": "plain:read_plain_text",
    ".npz": "plain:read_npz",
}
COMPRESSED = (".gz", ".bz2", ".xz")
FORMATS = sorted(_READERS)


def format_suffix(path: Path) -> str:
    """The suffix that names the format: ``.clf`` for ``a.clf.bz2``; a bare ``.gz`` is a CARMEN log
    (how the corrected logs of the SLAM evaluations ship)."""
    suffixes = [s.lower() for s in path.suffixes]
    while suffixes and suffixes[-1] in COMPRESSED:
        last = suffixes.pop()
        if not suffixes or suffixes[-1] not in _READERS:
            return ".log" if last == ".gz" else ""
    return suffixes[-1] if suffixes else ""


@dataclass(frozen=True)
class ReadOptions:
    """How to read a file beyond its name: its scan stream (a bag's topic, a CARMEN log's laser
    message type), a bag's ROS distro, and the laser's mount for files that do not store it
    (T_base_laser; ``upside_down``: the laser's z axis points down, its bearings run clockwise seen
    from above); ``deskew``: correct each scan for the motion during it (``deskew.py``: "odometry"
    or "velocity")."""

    topic: str | None = None
    typestore: str = DEFAULT_TYPESTORE
    mount: Pose2 | None = None
    upside_down: bool = False
    deskew: str | None = None


def read_log(path: str | Path, options: ReadOptions | None = None) -> ScanLog:
    """All scans of a file, with the reader chosen by its name (a folder: a rosbag2 bag)."""
    import importlib

    o = options or ReadOptions()
    p = Path(path)
    suffix = ".bag" if p.is_dir() else format_suffix(p)
    reader = _READERS.get(suffix)
    if reader is None:
        known = ", ".join(FORMATS + [f"(any){c}" for c in COMPRESSED] + ["a ROS 2 bag's folder"])
        raise InputError(f"unknown file type {''.join(p.suffixes)[-20:]!r}; known: {known}", str(p))
    module, name = reader.split(":")
    fn = getattr(importlib.import_module(f".{module}", __name__), name)
    # the readers whose files hold several
    streams = {
        "rosbag": (o.topic, o.typestore, o.mount),
        "carmen": (o.topic,),
    }
    if o.topic is not None and module not in streams:
        raise InputError(
            "only ROS bags (topics) and CARMEN logs (laser message types) have streams to choose",
            str(p),
            field="--topic",
        )
    args = streams.get(module, ())
    if module == "rosbag" or not p.is_file():  # a bag has an index of its own
        log = fn(str(p), *args)
    else:
        from .log_cache import read_cached

        log = read_cached(str(p), module, args, lambda: fn(str(p), *args))
    if o.mount is not None:
        log.frames = replace(log.frames, mount=o.mount, mount_source="--mount")
    if o.upside_down:
        log = mirrored(log)
    if log.store is None and not log.scans:  # a lazily read log says so when its scans are read
        no_usable_scan(log.path, log.unusable)
    if o.deskew is not None:
        from .deskew import deskew_log

        log = deskew_log(log, o.deskew)
    return log


__all__ = ["ScanLog", "ReadOptions", "read_log", "FORMATS"]
