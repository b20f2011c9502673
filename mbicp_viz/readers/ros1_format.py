"""ROS bag format 2.0, record by record: what the walker of a damaged bag (``rosbag.py``) and the
index reader (``ros1_index.py``) both parse. A record is a header (length-prefixed ``name=value``
fields, ``op`` naming its kind) followed by its length-prefixed data."""

from __future__ import annotations

import bz2
import struct
from pathlib import Path

from mbicp_viz.errors import InputError

MAGIC = b"#ROSBAG V2.0\n"
OP_MSG, OP_HEADER, OP_INDEX, OP_CHUNK, OP_CHUNK_INFO, OP_CONN = 2, 3, 4, 5, 6, 7
MAX_CHUNK_BYTES = 256 * 1024 * 1024  # a chunk unpacking to more is damaged (or hostile)


def header(buf: bytes, path) -> dict[str, bytes]:
    fields, i = {}, 0
    while i < len(buf):
        if i + 4 > len(buf):
            raise InputError("truncated record header", str(path))
        (n,) = struct.unpack_from("<I", buf, i)
        key, sep, value = buf[i + 4 : i + 4 + n].partition(b"=")
        if not sep:
            raise InputError("malformed record header field", str(path))
        fields[key.decode("ascii", "replace")] = value
        i += 4 + n
    return fields


def op_of(fields: dict[str, bytes]) -> int:
    """The kind of record a header is (0, none, when it has no ``op`` or an empty one)."""
    return fields["op"][0] if fields.get("op") else 0


class CutShort(Exception):
    """A record runs past the end of the data: the bag was cut short there. ``header`` and ``data``
    are what the cut record holds so far (its data cut short)."""

    def __init__(self, at: int, header: dict | None = None, data: bytes = b""):
        self.at, self.header, self.data = at, header, data


def records(buf: bytes, start: int, path):
    """(op, header, data) of each record in ``buf`` from ``start`` (ROS bag 2.0 layout)."""
    pos = start
    while pos + 4 <= len(buf):
        (hlen,) = struct.unpack_from("<I", buf, pos)
        if pos + 8 + hlen > len(buf):
            raise CutShort(pos)
        h = header(buf[pos + 4 : pos + 4 + hlen], path)
        (dlen,) = struct.unpack_from("<I", buf, pos + 4 + hlen)
        data_at = pos + 8 + hlen
        op = op_of(h)
        if op == OP_INDEX and "count" in h:
            # The length field of damaged index records is wrong; the count is not (12 bytes/entry).
            dlen = 12 * struct.unpack("<I", h["count"])[0]
        if data_at + dlen > len(buf):
            raise CutShort(pos, h, buf[data_at:])
        yield op, h, buf[data_at : data_at + dlen]
        pos = data_at + dlen


def decompress(kind: bytes, data: bytes, size: int, path) -> bytes:
    if size > MAX_CHUNK_BYTES:
        raise InputError(f"a chunk announces {size} bytes unpacked: damaged", str(path))
    try:
        if kind == b"none":
            return data
        if kind == b"bz2":
            return bz2.BZ2Decompressor().decompress(data, max_length=size)
        if kind == b"lz4":
            import lz4.frame

            return lz4.frame.decompress(data)[:size]
    except ImportError:
        raise InputError(
            "the bag's chunks are lz4-compressed: pip install lz4", str(path)
        ) from None
    except (OSError, ValueError, EOFError, RuntimeError) as e:
        raise InputError(
            f"a damaged compressed chunk ({type(e).__name__}: {e})", str(path)
        ) from None
    raise InputError(f"unknown chunk compression {kind[:20]!r}", str(path))


def register(store, definition: bytes, msgtype: str, p: Path) -> None:
    """The types a ROS 1 connection defines (its message definition travels with it)."""
    from rosbags.typesys import get_types_from_msg

    if not definition or msgtype in store.types:
        return
    try:
        store.register(get_types_from_msg(definition.decode("utf-8"), msgtype))
    except Exception as e:  # a damaged definition
        raise InputError(
            f"the definition of {msgtype} cannot be read ({type(e).__name__}: {str(e)[:120]})",
            str(p),
        ) from None


def ros2_type(msgtype: str) -> str:
    """ROS 1 names types ``pkg/Type``; rosbags uses ``pkg/msg/Type``."""
    pkg, _, name = msgtype.rpartition("/")
    return msgtype if pkg.endswith("/msg") else f"{pkg}/msg/{name}"
