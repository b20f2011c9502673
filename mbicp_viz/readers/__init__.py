"""Readers for the scan formats users have, chosen by file name or content.

| format | files | reader |
|---|---|---|
| CARMEN log | ``*.log``, ``*.log.gz``, ``*.clf`` | :func:`read_carmen` |
| Minguez ``.off`` | ``*.off`` | :func:`read_off` |
| CSM JSON laser_data | ``*.json``, ``*.jsonl`` | :func:`read_csm_json` |
| ROS 1 / ROS 2 bag | ``*.bag``, ``*.db3``, ``*.mcap``, a rosbag2 folder | :func:`read_rosbag` |
| plain text / numpy | ``*.scans``, ``*.txt``, ``*.npz`` | :mod:`.plain` |
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .carmen import read_carmen
from .csm_json import read_csm_json
from .log import ScanLog
from .off import read_off
from .plain import read_npz, read_plain_text, write_npz
from .rosbag import read_rosbag

_BY_SUFFIX = {
    ".log": read_carmen, ".clf": read_carmen, ".gz": read_carmen,
    ".off": read_off,
    ".json": read_csm_json, ".jsonl": read_csm_json,
    ".bag": read_rosbag, ".db3": read_rosbag, ".mcap": read_rosbag,
    ".scans": read_plain_text, ".txt": read_plain_text,
    ".npz": read_npz,
}

FORMATS = sorted(_BY_SUFFIX)


def read_log(path: str | Path) -> ScanLog:
    """All scans of a file, with the reader chosen by its suffix (a folder: a rosbag2 bag)."""
    p = Path(path)
    if p.is_dir():
        return read_rosbag(str(p))
    reader = _BY_SUFFIX.get(p.suffix.lower())
    if reader is None:
        raise InputError(f"unknown file type {p.suffix!r}; known: {', '.join(FORMATS)}", str(p))
    return reader(str(p))


__all__ = ["ScanLog", "read_log", "read_carmen", "read_csm_json", "read_off", "read_rosbag", "read_plain_text",
           "read_npz", "write_npz", "FORMATS"]
