"""An MCAP file cut short (a recorder killed, a robot's power lost): its whole records, read.

An MCAP file ends with a summary and a footer that readers start from; a recording cut short has
neither, and rosbags refuses it ("File end magic is invalid"). Its data section is still a
sequence of whole records up to the cut (the MCAP specification: an opcode, a length, the
content). Those are copied into the cache (``log_cache.cache_root()``, never beside the input) and
closed as a writer closes a file: a data end, a summary of the schemas and channels found in the
chunks and one chunk index per chunk (where its message indexes are, which the copy holds as they
were written after each chunk), and the footer pointing at it. rosbags then reads the copy through
its index, as a whole recording: a scan when it is asked for, the scans' stamps from the message
indexes (``ros2_index.py``). The bytes after the last whole record are lost, and the command says
how many. The copy is keyed by the file's path, size and modification time and removed least
recently used first with the cache's other entries.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

from mbicp_viz.errors import InputError

from .log_cache import CACHE_BYTES, entry, used, write_entry

MAGIC = b"\x89MCAP0\r\n"
_RECORD = struct.Struct("<BQ")  # opcode, content length
_CHUNK_HEAD = struct.Struct("<QQQI")  # message start and end time, uncompressed size and CRC
_HEADER, _FOOTER, _SCHEMA, _CHANNEL, _MESSAGE, _MESSAGE_INDEX = 0x01, 0x02, 0x03, 0x04, 0x05, 0x07
_CHUNK, _CHUNK_INDEX, _DATA_END = 0x06, 0x08, 0x0F


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
    """A closed copy of the cut-short ``mcap``'s whole records in the cache (made here the first
    time), and what to say of it."""
    folder = entry(str(mcap), "mcap cut short", ())
    copy = folder / mcap.name
    if used(folder):
        return copy, f"{mcap}: cut short; read from its closed copy {copy}"
    found = _survey(mcap)
    if found.end > CACHE_BYTES:
        raise InputError(
            f"cut short (no MCAP footer); its {found.end / 1e9:.1f} GB of whole records are more "
            f"than the cache holds ({CACHE_BYTES / 1e9:g} GB) to close a copy of",
            str(mcap),
        )
    try:
        write_entry(folder, lambda tmp: _closed_copy(mcap, found, tmp), {"mcap": str(mcap)})
    except OSError as e:
        raise InputError(f"could not be copied into {folder}: {e}", str(mcap)) from None
    lost = mcap.stat().st_size - found.end
    return copy, (
        f"{mcap}: cut short (no MCAP footer, as a recording stopped by a crash): its "
        f"{found.chunks} whole chunks copied and closed in {copy}, the {lost} bytes after them "
        "lost; the next opening reads the copy"
    )


@dataclass
class _Survey:
    """What the copy holds: its data's end (a byte offset), its summary's records, its chunks."""

    end: int = len(MAGIC)
    chunks: int = 0
    schemas: dict[int, bytes] = field(default_factory=dict)  # id -> the whole record
    channels: dict[int, bytes] = field(default_factory=dict)
    indexes: list[bytes] = field(default_factory=list)  # a chunk index record per chunk


def _survey(mcap: Path) -> _Survey:
    """The whole records of the data section, up to the cut, a record of opcode 0 (zeros after
    the cut), a chunk that does not decompress, or the data end (a summary cut short after it):
    each chunk's schemas and channels, and its chunk index. A last chunk whose message indexes
    the cut went through is left out: its messages could not be found through them."""
    from rosbags.rosbag2.storage_mcap import decompress

    size, out = mcap.stat().st_size, _Survey()
    chunk: list = []  # the last chunk's index fields, its message indexes still to come
    wanted: set[int] = set()  # the channels of the last chunk's messages
    with mcap.open("rb") as f:
        f.seek(out.end)
        while out.end + _RECORD.size <= size:
            op, length = _RECORD.unpack(f.read(_RECORD.size))
            first = out.end == len(MAGIC)
            if op in (0, _DATA_END, _FOOTER) or first != (op == _HEADER):
                break
            if length > size - out.end - _RECORD.size:  # the record the cut went through
                break
            content = f.read(length) if op in (_CHUNK, _MESSAGE_INDEX, _SCHEMA, _CHANNEL) else b""
            if op == _CHUNK:
                try:  # its head, then rosbags' own decompression and check
                    start, end, plain, crc, compression, compressed, at = _chunk_head(content)
                    records = decompress(
                        content[at : at + compressed], compression.decode(), plain, crc
                    )
                except Exception:  # a chunk damaged where the cut left it: the data ends before
                    break
                # its index's fields: the message indexes' offsets and length filled as they come
                whole = _RECORD.size + length
                chunk = [start, end, out.end, whole, {}, 0, compression, compressed, plain]
                wanted = _read_definitions(records, out)
                out.indexes.append(b"")
                out.chunks += 1
            elif op == _MESSAGE_INDEX and chunk and length >= 2:  # after its chunk: where its are
                (channel,) = struct.unpack_from("<H", content)
                chunk[4][channel] = out.end
                chunk[5] += _RECORD.size + length
            elif op in (_SCHEMA, _CHANNEL):
                _read_definitions(_RECORD.pack(op, length) + content, out)
            out.end += _RECORD.size + length
            if chunk:
                out.indexes[-1] = _chunk_index(*chunk)
            f.seek(out.end)
    if chunk and not wanted <= set(chunk[4]):
        out.end, out.chunks = chunk[2], out.chunks - 1
        out.indexes.pop()
    if out.chunks == 0:
        raise InputError(
            "cut short (no MCAP footer) before its first chunk ended: no message to read",
            str(mcap),
        )
    return out


def _chunk_head(content: bytes) -> tuple:
    """A chunk record's head: message start and end time, uncompressed size and CRC, compression
    (bytes), compressed size, and where its compressed records begin."""
    start, end, size, crc = _CHUNK_HEAD.unpack_from(content)
    at = _CHUNK_HEAD.size
    (n,) = struct.unpack_from("<I", content, at)
    compression = content[at + 4 : at + 4 + n]
    (compressed,) = struct.unpack_from("<Q", content, at + 4 + n)
    return start, end, size, crc, compression, compressed, at + 12 + n


def _chunk_index(start, end, offset, length, indexes, index_length, compression, compressed, size):
    """A chunk index record (the MCAP specification's field order)."""
    pairs = b"".join(struct.pack("<HQ", c, at) for c, at in sorted(indexes.items()))
    content = (
        struct.pack("<QQQQI", start, end, offset, length, len(pairs))
        + pairs
        + struct.pack("<QI", index_length, len(compression))
        + compression
        + struct.pack("<QQ", compressed, size)
    )
    return _RECORD.pack(_CHUNK_INDEX, len(content)) + content


def _read_definitions(records: bytes, out: _Survey) -> set[int]:
    """The schema and channel records among ``records`` (whole records end to end) into ``out``,
    the first of each id kept; the channels of their messages."""
    at, channels = 0, set()
    while at + _RECORD.size <= len(records):
        op, length = _RECORD.unpack_from(records, at)
        whole = records[at : at + _RECORD.size + length]
        if op in (_SCHEMA, _CHANNEL, _MESSAGE) and length >= 2:
            (key,) = struct.unpack_from("<H", whole, _RECORD.size)
            if op == _MESSAGE:
                channels.add(key)
            else:
                (out.schemas if op == _SCHEMA else out.channels).setdefault(key, whole)
        at += _RECORD.size + length
    return channels


def _closed_copy(mcap: Path, found: _Survey, tmp: Path) -> None:
    """The data section's whole records of ``mcap``, then a data end, the summary and the footer,
    into ``tmp``."""
    summary = b"".join([*found.schemas.values(), *found.channels.values(), *found.indexes])
    data_end = _RECORD.pack(_DATA_END, 4) + struct.pack("<I", 0)  # no CRC of the data
    summary_start = found.end + len(data_end)
    # no summary offsets, no CRC of the summary
    footer = _RECORD.pack(_FOOTER, 20) + struct.pack("<QQI", summary_start, 0, 0) + MAGIC
    with mcap.open("rb") as src, (tmp / mcap.name).open("wb") as dst:
        left = found.end
        while left and (block := src.read(min(left, 1 << 20))):
            dst.write(block)
            left -= len(block)
        dst.write(data_end + summary + footer)
