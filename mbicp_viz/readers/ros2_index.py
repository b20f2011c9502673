"""The record stamps of a ROS 2 bag's topic from its storage's own index, no message read.

Opening a bag lists its scans by their record stamps (``bag_index.BagScans``). rosbags gives them
only by reading every message: on an hour of 1081-beam scans at 40 Hz, 0.40 s from sqlite3 and
0.50 s from MCAP (each chunk decompressed), a quarter of a first result's 2 s. Both storages
index the stamps themselves: sqlite3's ``messages`` table has them in a column of their own, and
an MCAP file with a summary has, after each chunk, a message index per channel: (log time,
offset) for each of its messages. ``topic_stamps`` reads those; a storage it does not know (an
MCAP file without chunk indexes, a future plugin) leaves the answer to the pass over the messages.
"""

from __future__ import annotations

import io
import struct

import numpy as np

from mbicp_viz.errors import InputError

# An MCAP message index record's head: opcode (0x07), record length, channel id, byte length of
# its (log time, offset) pairs (the MCAP specification, "Message Index")
_MESSAGE_INDEX = struct.Struct("<BQHI")
_MESSAGE_INDEX_OP = 0x07


def topic_stamps(reader, topic: str, path: str) -> np.ndarray | None:
    """The record stamps [ns] of ``topic``'s messages in time order, as rosbags' ``messages``
    yields them, from the index of every storage file of ``reader`` (rosbags' AnyReader, open on
    ROS 2 bags); None when one of them has no index read here."""
    from rosbags.rosbag2.storage_mcap import McapReader
    from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

    parts = []
    for bag in getattr(reader, "readers", ()):
        storage = getattr(bag, "storage", None)
        for f in getattr(storage, "storages", [storage]):
            ids = [c.id for c in getattr(f, "connections", ()) if c.topic == topic]
            if isinstance(f, Sqlite3Reader) and f.dbconn is not None:
                parts.append(_sqlite_stamps(f.dbconn, ids, path))
            elif isinstance(f, McapReader) and f.chunks and f.bio is not None:
                parts.append(_mcap_stamps(f, ids, path))
            else:
                return None
    if not parts:
        return None
    return np.sort(np.concatenate(parts), kind="stable")


def _sqlite_stamps(dbconn, ids: list[int], path: str) -> np.ndarray:
    """The stamps of the topics ``ids`` from the ``messages`` table's timestamp column (the
    rows' data, on pages of their own, is not read)."""
    if not ids:
        return np.empty(0, np.int64)
    query = f"SELECT timestamp FROM messages WHERE topic_id IN ({','.join('?' * len(ids))})"
    try:
        return np.fromiter((t for (t,) in dbconn.execute(query, ids)), dtype=np.int64)
    except (TypeError, ValueError, OverflowError) as e:  # a damaged row: NULL, text, a blob
        raise InputError(f"a message has no record stamp ({e})", path) from None


def _mcap_stamps(storage, ids: list[int], path: str) -> np.ndarray:
    """The log times of the channels ``ids`` from the message index records after each chunk,
    where the chunk index (read by rosbags from the summary) points."""
    bio, parts = storage.bio, []
    end = bio.seek(0, io.SEEK_END)
    for chunk in storage.chunks:
        for cid in ids:
            if (at := chunk.message_index_offsets.get(cid)) is None:
                continue
            head, records = b"", b""
            if 0 <= at <= end - _MESSAGE_INDEX.size:  # an offset in the file, or none
                bio.seek(at)
                head = bio.read(_MESSAGE_INDEX.size)
                op, _, channel, size = _MESSAGE_INDEX.unpack(head)
                records = bio.read(size)
            if not head or op != _MESSAGE_INDEX_OP or channel != cid or len(records) % 16:
                raise InputError(
                    f"the chunk index points at byte {at}, where no message index of channel "
                    f"{cid} is",
                    path,
                )
            times = np.frombuffer(records, dtype="<u8")[0::2]
            lo, hi = chunk.message_start_time, chunk.message_end_time
            if len(times) and (times.min() < lo or times.max() > hi):
                raise InputError(
                    f"the message index at byte {at} lists a message outside its chunk's time "
                    f"({lo} to {hi} ns)",
                    path,
                )
            parts.append(times.astype(np.int64))
    return np.concatenate(parts) if parts else np.empty(0, np.int64)
