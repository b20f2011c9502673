"""An indexed bag's scans, read when they are asked for: opening an hour-long recording costs its
index, not its messages.

At opening, only what names the frames is decoded: ``/tf_static``, the first seconds of ``/tf``
(a mount published there), and the first message of each LaserScan topic (its frame id). The
scan topic's record stamps come from the bag's own index (ROS 1) or one pass over the topic's raw
messages without decoding them (ROS 2 sqlite3 and MCAP). A scan is then one time query for its
message, and its odometry one query for the odometry messages around its stamp
(``ODOMETRY_WINDOW_S``), interpolated as the whole-bag reader does (``tf.interpolate``, which
refuses gaps longer than half a second, so the window sees every message that could be used).
A whole run reads the bag front to back once (``stream``), keeping only that window.

Record ``k`` is the topic's ``k``-th message in recording order, as for every reader; whether it
is usable is known once it is read, and the log's list of unusable records after one pass
(``ScanLog`` asks for it only when a command needs every record's fate).
"""

from __future__ import annotations

import bisect
import threading
from collections import OrderedDict, deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mbicp_viz.core import Pose2, Scan, UnusableScan
from mbicp_viz.errors import InputError

from .tf import TfTree

ODOMETRY_WINDOW_S = 2.0  # [s] of odometry read either side of a scan's record stamp
TF_AT_OPEN_S = 5.0  # [s] of /tf decoded at opening (a mount published on /tf, odometry on /tf)
CACHED_SCANS = 32  # scans kept decoded: a pair, the run view's neighbours, the debugger's tabs


@dataclass(frozen=True)
class OdometrySource:
    """Where a bag's odometry is: an Odometry topic, or /tf (odom -> ``base``)."""

    topic: str  # "/odom" ..., or "/tf"
    base: str | None = None  # the base frame, for /tf


class BagScans:
    """The scans of one LaserScan topic of an indexed bag. It pickles as its recipe (a worker
    process opens the bag again); one open reader is shared by the threads of a process."""

    random_access = False  # a scan is read by seeking in the bag: the next one reads faster

    def __init__(
        self,
        path: str,
        typestore: str,
        topic: str,
        stamps_ns: np.ndarray,
        static: TfTree,
        odometry: OdometrySource | None,
        upside_down: bool,
        mount: Pose2,
    ):
        self.path, self.typestore, self.topic = path, typestore, topic
        self.stamps_ns, self.static, self.odometry = stamps_ns, static, odometry
        self.upside_down, self.mount = upside_down, mount
        self._reader = None
        self._lock = threading.Lock()
        self._cache: OrderedDict[int, Scan | UnusableScan] = OrderedDict()

    def __getstate__(self):
        state = dict(self.__dict__)
        state.update(_reader=None, _lock=None, _cache=OrderedDict())
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def mirrored(self) -> BagScans:
        """These scans as a laser mounted the other way up sees them."""
        from copy import copy

        out = copy(self)
        out.upside_down, out._cache, out._lock = (
            not self.upside_down,
            OrderedDict(),
            threading.Lock(),
        )
        return out

    def adopt(self, reader) -> None:
        """Use ``reader``, already open on the bag, in this process."""
        self._reader = reader

    @property
    def records(self) -> int:
        return len(self.stamps_ns)

    def poses(self, records: list[int]) -> np.ndarray:
        """(n, 3) NaN: a bag stores no scan poses, only odometry (said without reading a scan)."""
        return np.full((len(records), 3), np.nan)

    def _open(self):
        if self._reader is None:
            from .rosbag import open_bag

            self._reader = open_bag(Path(self.path), self.typestore)  # a worker process
        return self._reader

    def _connections(self, topic: str):
        return [c for c in self._open().connections if c.topic == topic]

    def _decoded(self, topic: str, start_ns: int, stop_ns: int) -> list:
        """(record stamp [s], message) of ``topic`` within [start, stop)."""
        from .rosbag import decoded_messages

        wanted = self._connections(topic)
        msgs = decoded_messages(self._open(), self.path, wanted, start_ns, stop_ns)
        return [(t * 1e-9, m) for _, t, m in msgs]

    def load(self, k: int, odometry: bool = True) -> Scan | UnusableScan:
        """Record ``k``: its scan, or why it cannot be matched (without ``odometry``, its
        odometry may be left unread: a map's scans; such a scan is not kept)."""
        with self._lock:
            if k in self._cache:
                self._cache.move_to_end(k)
                return self._cache[k]
            t = int(self.stamps_ns[k])
            first = bisect.bisect_left(self.stamps_ns, t)  # records sharing this stamp
            msgs = self._decoded(self.topic, t, t + 1)
            if k - first >= len(msgs):  # the index lists a message the bag does not hold
                raise InputError(f"its index lists a scan at {t} ns, where it has none", self.path)
            if not odometry:
                return self._scan(k, msgs[k - first][1], None)
            msg = msgs[k - first][1]
            scan = self._scan(k, msg, self._odometry_around(t, msg))
            self._cache[k] = scan
            if len(self._cache) > CACHED_SCANS:
                self._cache.popitem(last=False)
            return scan

    def _odometry_around(self, t_ns: int, msg):
        """The odometry a scan (record stamp ``t_ns``, message ``msg``) reads: ``bracket`` of
        the samples within the window around its record."""
        from .rosbag import header_stamp

        if self.odometry is None:
            return None
        w = int(ODOMETRY_WINDOW_S * 1e9)
        msgs = self._decoded(self.odometry.topic, t_ns - w, t_ns + w)
        samples = (s for stamp, m in msgs for s in self._samples(stamp, m))
        return bracket(samples, header_stamp(msg))

    def _samples(self, stamp: float, msg) -> list[tuple[float, float, float, float]]:
        """The base's poses (stamp, x, y, theta) one odometry message (record ``stamp``) gives;
        each message is turned into poses once, however many scans' windows it falls in."""
        from .rosbag import header_stamp, planar

        if self.odometry.topic != "/tf":
            return [(header_stamp(msg), *planar(msg.pose.pose))]
        tree = self.static.frames_only()
        tree.add(msg, stamp, False)
        track = tree.odometry_track(self.odometry.base)
        if track is None:
            return []
        # the tree keeps the first value each moving edge had at opening: not this message's
        w = ODOMETRY_WINDOW_S
        return [(t, *p) for t, p in zip(track[1], track[2]) if abs(t - stamp) < w]

    def _scan(self, k: int, msg, odometry) -> Scan | UnusableScan:
        from .rosbag import laser_scan

        return laser_scan(msg, self.path, k, self.upside_down, odometry, self.mount)

    def _locked(self, messages: Iterator) -> Iterator:
        """``messages`` taken one at a time under the reader's lock: a pass and another thread's
        ``load`` share one open reader (its file position, its chunk in hand), and rosbags'
        readers seek again at each message, so their steps may interleave but never overlap."""
        messages = iter(messages)
        while True:
            with self._lock:
                item = next(messages, None)
            if item is None:
                return
            yield item

    def stream(
        self, start: int = 0, odometry: bool = True
    ) -> Iterator[tuple[int, Scan | UnusableScan]]:
        """Records ``start`` ... in order, read front to back once: each scan leaves once the
        odometry a window past it has been read (``odometry``: False, the scans without it)."""
        from .rosbag import decode, header_stamp, raw_messages

        if start >= self.records:
            return
        with self._lock:
            reader = self._open()
            wanted = self._connections(self.topic)
        with_odometry = odometry and self.odometry is not None
        if with_odometry:
            wanted += self._connections(self.odometry.topic)
        first = int(self.stamps_ns[start])
        begin = first - int(ODOMETRY_WINDOW_S * 1e9) if start else None
        # records before ``start`` recorded at its very stamp, to pass over
        same = start - bisect.bisect_left(self.stamps_ns, first)
        w = ODOMETRY_WINDOW_S
        odometry = OdometryWindow()  # the samples within the waiting scans' window
        # (record, record stamp [s] and [ns], connection, raw message): a scan is decoded as it
        # leaves, so a stream stopped early decodes none of the window read past it (nor any scan
        # of the window read before its start)
        waiting: deque = deque()
        k, path = start, Path(self.path)

        def ready(now: float) -> Iterator[tuple[int, Scan | UnusableScan]]:
            while waiting and waiting[0][1] + w < now:
                r, t, t_ns, c, raw = waiting.popleft()
                msg = decode(reader.deserialize, raw, c.msgtype, path, f"at {t_ns} ns")
                track = odometry.around(t - w, t + w, header_stamp(msg)) if with_odometry else None
                yield r, self._scan(r, msg, track)
            odometry.drop_before((waiting[0][1] if waiting else now) - w)

        for c, t, raw in self._locked(raw_messages(reader, self.path, wanted, begin)):
            stamp = t * 1e-9
            if c.topic == self.topic:
                if t < first or (t == first and same > 0):
                    same -= t == first
                    continue
                if k >= self.records or t != self.stamps_ns[k]:  # a damaged index
                    raise InputError(
                        f"its index lists its scans otherwise than its messages hold them "
                        f"(scan {k} recorded at {t} ns)",
                        self.path,
                    )
                waiting.append((k, stamp, t, c, raw))
                k += 1
            else:
                msg = decode(reader.deserialize, raw, c.msgtype, path, f"at {t} ns")
                odometry.add(stamp, self._samples(stamp, msg))
            yield from ready(stamp)
        yield from ready(np.inf)


class OdometryWindow:
    """The odometry samples (stamp, x, y, theta) of a bag read front to back, with the record
    stamps of their messages (which every reader yields in record order), kept while a waiting
    scan's window may hold them. The two around a scan (``bracket``) are found by bisection where
    the samples' own stamps increase, as a robot's odometry's do, else by a pass over the
    window's samples."""

    def __init__(self, compact_after: int = 4096):
        self.compact_after = compact_after  # dropped samples kept in the lists until this many
        self.records: list[float] = []  # the record stamp of each sample's message
        self.samples: list[tuple] = []
        # per sample, the first of the run of non-decreasing sample stamps that ends at it
        self.runs: list[int] = []
        self.first = 0  # the samples before it are dropped

    def add(self, record: float, samples: list[tuple]) -> None:
        for x in samples:
            k = len(self.samples)
            rising = k > 0 and x[0] >= self.samples[-1][0]
            self.runs.append(self.runs[-1] if rising else k)
            self.records.append(record)
            self.samples.append(x)

    def drop_before(self, record: float) -> None:
        """The samples of messages recorded before ``record`` are no longer needed."""
        while self.first < len(self.records) and self.records[self.first] < record:
            self.first += 1
        if self.first > self.compact_after and self.first > len(self.records) // 2:
            f = self.first  # the dropped samples leave the lists once they are most of them
            del self.records[:f], self.samples[:f], self.runs[:f]
            self.runs = [max(r - f, 0) for r in self.runs]
            self.first = 0

    def around(self, lo_record: float, hi_record: float, t: float):
        """``bracket`` at time ``t`` of the samples whose messages were recorded within
        [``lo_record``, ``hi_record``)."""
        lo = bisect.bisect_left(self.records, lo_record, self.first)
        hi = bisect.bisect_left(self.records, hi_record, lo)
        if hi == lo or self.runs[hi - 1] > lo:  # none, or their stamps do not increase
            return bracket(self.samples[lo:hi], t)
        k = bisect.bisect_right(self.samples, t, lo, hi, key=_stamp)  # the first after t
        return bracket(self.samples[max(k - 1, lo) : min(k + 1, hi)], t)


def _stamp(sample: tuple) -> float:
    return sample[0]


def bracket(samples: Iterable, t: float) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, base poses) of the odometry ``samples`` (stamp, x, y, theta) that ``interpolate``
    reads at time ``t``: the last at or before it and the first after it, equal stamps taken in
    arrival order as a stable sort by stamp leaves them. ``interpolate`` answers on them as on the
    whole window sorted (no stamp is NaN: headers hold whole seconds and nanoseconds), and one pass
    costs less than sorting the window's samples for every scan (a tenth of a bag's stream)."""
    before = after = None
    for s in samples:
        if s[0] <= t:
            if before is None or s[0] >= before[0]:
                before = s
        elif after is None or s[0] < after[0]:
            after = s
    a = np.array([s for s in (before, after) if s is not None], dtype=float).reshape(-1, 4)
    return a[:, 0], a[:, 1:]


def records_with_stamps(reader, topic: str, connections, path: str) -> np.ndarray:
    """The record stamps [ns] of ``topic``'s messages (its ``connections``) in recording order:
    from a ROS 1 bag's index, a ROS 2 bag's storage index (``ros2_index``), else one pass over
    the raw messages (nothing decoded)."""
    from .ros2_index import topic_stamps

    if hasattr(reader, "stamps"):
        return reader.stamps(connections)
    if (stamps := topic_stamps(reader, topic, path)) is not None:
        return stamps
    return np.fromiter((t for _, t, _ in reader.messages(connections)), dtype=np.int64)
