"""An MCAP file cut short (a recorder killed, a robot's power lost): its whole records, read.

An MCAP file ends with a summary and a footer that readers start from; a recording cut short has
neither, and rosbags refuses it ("File end magic is invalid"). Its data section is still a
sequence of whole records up to the cut (the MCAP specification: records of an opcode, a length
and their content). Those are copied into the cache (``log_cache.cache_root()``, never beside the
input) and closed with a data-end record and a footer that names no summary: a valid MCAP file,
which rosbags reads by walking its records (a query decompresses only the chunks of its time
range). The bytes after the last whole record are lost, and the command says how many. The copy
is keyed by the file's path, size and modification time and removed least recently used first
with the cache's other entries.
"""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

from mbicp_viz.errors import InputError

from .log_cache import CACHE_BYTES, entry, prune

MAGIC = b"\x89MCAP0\r\n"
_RECORD = struct.Struct("<BQ")  # opcode, content length
_HEADER, _FOOTER, _DATA_END = 0x01, 0x02, 0x0F
# the records that close the copy: a data end (its data section's CRC, 0: none) and a footer (no
# summary, no summary offsets, no CRC), then the magic again
_CLOSING = (
    _RECORD.pack(_DATA_END, 4)
    + struct.pack("<I", 0)
    + _RECORD.pack(_FOOTER, 20)
    + struct.pack("<QQI", 0, 0, 0)
    + MAGIC
)


def cut_short(path: Path) -> Path | None:
    """The MCAP file of ``path`` (the file, or a folder's only ``.mcap``) when it begins as MCAP
    and does not end as MCAP: cut short. None otherwise."""
    files = sorted(path.glob("*.mcap")) if path.is_dir() else [path]
    if len(files) != 1 or not files[0].is_file():
        return None
    size = files[0].stat().st_size
    with files[0].open("rb") as f:
        head = f.read(len(MAGIC))
        f.seek(max(size - len(MAGIC), 0))
        tail = f.read(len(MAGIC))
    return files[0] if head == MAGIC and tail != MAGIC else None


def recovered(mcap: Path) -> tuple[Path, str]:
    """A whole copy of the cut-short ``mcap``'s whole records in the cache (made here the first
    time), and what to say of it."""
    folder = entry(str(mcap), "mcap cut short", ())
    copy = folder / mcap.name
    if (folder / "meta.json").is_file():
        (folder / "meta.json").touch()  # used: the last to be removed
        return copy, f"{mcap}: cut short; read from its closed copy {copy}"
    end, records = _whole_records(mcap)
    if end > CACHE_BYTES:
        raise InputError(
            f"cut short (no MCAP footer); its {end / 1e9:.1f} GB of whole records are more than "
            f"the cache holds ({CACHE_BYTES / 1e9:g} GB) to close a copy of",
            str(mcap),
        )
    _write(mcap, folder, end)
    prune(folder.parent, CACHE_BYTES, keep=folder)
    lost = mcap.stat().st_size - end
    return copy, (
        f"{mcap}: cut short (no MCAP footer, as a recording stopped by a crash): its {records} "
        f"whole records copied and closed in {copy}, the {lost} bytes after them lost; the next "
        "opening reads the copy"
    )


def _whole_records(mcap: Path) -> tuple[int, int]:
    """Where the data section's whole records end (a byte offset), and how many there are: up to
    the cut, a record of opcode 0 (zeros after the cut), or the data end (a cut summary after)."""
    size = mcap.stat().st_size
    with mcap.open("rb") as f:
        f.seek(len(MAGIC))
        at, n = len(MAGIC), 0
        while at + _RECORD.size <= size:
            op, length = _RECORD.unpack(f.read(_RECORD.size))
            if op in (0, _DATA_END, _FOOTER) or (n == 0 and op != _HEADER):
                break
            if length > size - at - _RECORD.size:  # the record the cut went through
                break
            at += _RECORD.size + length
            n += 1
            f.seek(at)
    if n < 2:  # the header alone: the cut went through the first chunk
        raise InputError(
            "cut short (no MCAP footer) before its first record after the header ended: no "
            "message to read",
            str(mcap),
        )
    return at, n


def _write(mcap: Path, folder: Path, end: int) -> None:
    """The first ``end`` bytes of ``mcap`` and the closing records into ``folder``, whole or not
    at all."""
    from mbicp_viz.outputs import written_folder

    shutil.rmtree(folder, ignore_errors=True)  # an entry left incomplete
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        with written_folder(folder) as tmp:
            tmp.mkdir()
            with mcap.open("rb") as src, (tmp / mcap.name).open("wb") as dst:
                left = end
                while left and (block := src.read(min(left, 1 << 20))):
                    dst.write(block)
                    left -= len(block)
                dst.write(_CLOSING)
            (tmp / "meta.json").write_text(json.dumps({"mcap": str(mcap)}))
    except OSError as e:
        raise InputError(f"could not be copied into {folder}: {e}", str(mcap)) from None
