"""Files the tool writes: whole or not at all, and said when they replace an earlier file.

Every output is written to a temporary file beside its target and renamed over it only once
complete (``os.replace`` is atomic within a folder): a failed, interrupted or killed write leaves
the earlier file as it was, and a reader never sees half a file. The temporary keeps the target's
suffix, so writers that choose their format by it (matplotlib, rerun) write the right one.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def temporary_beside(path: Path) -> Path:
    """A hidden name beside ``path``, unique to this process, with ``path``'s suffix."""
    return path.with_name(f".{path.name}.{os.getpid()}.tmp{path.suffix}")


def say_replaced(path: Path) -> None:
    print(f"mbicp-viz: replaced {path}", file=sys.stderr)


@contextmanager
def written(path: str | Path, say: bool = True) -> Iterator[Path]:
    """A temporary path to write ``path`` at; renamed over ``path`` when the block ends, removed
    when it raises (Ctrl-C included). ``say``: a replaced file is said."""
    path = Path(path)
    tmp = temporary_beside(path)
    existed = say and path.exists()
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    if existed:
        say_replaced(path)


@contextmanager
def written_folder(path: str | Path) -> Iterator[Path]:
    """``written`` for an output that is a folder (a ROS 2 bag): a path of the same name inside a
    hidden folder beside ``path``, moved to ``path`` when the block ends (which must not exist),
    removed with its folder when it raises. The folder's files keep the names they were written
    with."""
    import shutil

    path = Path(path)
    tmp = temporary_beside(path)
    tmp.mkdir()
    try:
        yield tmp / path.name
        os.replace(tmp / path.name, path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def write_text(path: str | Path, text: str) -> None:
    with written(path) as tmp:
        tmp.write_text(text)


def write_bytes(path: str | Path, data: bytes) -> None:
    with written(path) as tmp:
        tmp.write_bytes(data)
