"""A live run: a Foxglove server's scans matched against the previous one (or the last key frame,
``keyframes``) as they arrive, as ``eval sequence`` matches a bag's
(``evaluation/sequence.match_row``), with the last seconds of messages kept to be saved as a bag
that every other command reads.

Three threads: the receiver (reconnecting when the connection is lost), the matcher (the scans in
order; when it falls behind it skips, and counts, the scans it would reach too late: ``_ready``)
and the caller's.
Odometry comes from an Odometry topic, else from the base's track on ``/tf`` (``odom`` -> the base),
as a bag's (``readers/rosbag.py``); a scan waits for odometry past its stamp (at most
``ODOMETRY_WAIT_S``) so that its guess is interpolated as a bag's is; the laser's mount from
``/tf_static``.
"""

from __future__ import annotations

import gc
import sys
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mbicp_viz.choices import MATCH_BUDGET_S, Guess
from mbicp_viz.core import Params, Scan, ScanError, UnusableScan
from mbicp_viz.errors import InputError
from mbicp_viz.evaluation.keyframes import KeyFrames
from mbicp_viz.evaluation.run_rows import RunRows
from mbicp_viz.evaluation.sequence import match_row
from mbicp_viz.readers.log import Frames, ScanLog
from mbicp_viz.readers.pair_match import PairMatch
from mbicp_viz.readers.rosbag import (
    LASER_SCAN,
    ODOMETRY,
    TF,
    header_stamp,
    laser_scan,
    odometry_track,
    tf_base,
)
from mbicp_viz.readers.tf import TfTree

from . import client
from .decode import Decoder, kind

ODOMETRY_WAIT_S = 0.5  # a scan waits this long for odometry past its stamp
NO_SCAN_S = 5.0  # a server that advertises no scan topic this long after connecting is refused
RECONNECT_S = (0.2, 0.5, 1.0, 2.0)  # waits between attempts, the last repeated
MAX_BUFFER_BYTES = 512 * 1024 * 1024  # the buffer keeps its seconds, or this much if less
WAITING_MOST = 256  # scans waiting for the matcher, at most (a stalled matcher's memory bound)


@dataclass(frozen=True)
class Raw:
    """A message as it came: kept to be saved."""

    topic: str
    msgtype: str
    encoding: str
    log_time_ns: int
    payload: bytes


@dataclass
class Status:
    """What the run has done, for the status line and the page."""

    connected: bool = False
    scans: int = 0
    matched: int = 0
    skipped: int = 0  # scans the matcher left out to keep up
    unusable: int = 0
    undecodable: int = 0
    lag_s: float | None = None  # from a scan's arrival to its pair's result (the last one)
    reconnects: int = 0
    buffer_s: float = 0.0
    buffer_bytes: int = 0
    notes: list[str] = field(default_factory=list)

    def line(self) -> str:
        lag = "-" if self.lag_s is None else f"{1000 * self.lag_s:.0f} ms"
        return (
            f"{'connected' if self.connected else 'reconnecting'}: {self.scans} scans, "
            f"{self.matched} matched, {self.skipped} skipped to keep up, {self.unusable} unusable; "
            f"result {lag} after the scan arrived; buffer {self.buffer_s:.0f} s, "
            f"{self.buffer_bytes / 1e6:.1f} MB"
        )


class LiveRun:
    """``url``'s scans on ``topic`` (None: the one LaserScan topic) matched with ``params``."""

    def __init__(
        self,
        url: str,
        params: Params,
        topic: str | None = None,
        buffer_s: float = 60.0,
        typestore: str = "ROS2_HUMBLE",
        guess: Guess = Guess.stored,
        budget_s: float | None = MATCH_BUDGET_S,
        keyframes: KeyFrames | None = None,
    ):
        self.url, self.params, self.topic, self.buffer_s = url, params, topic, buffer_s
        self.guess, self.budget_s, self.keyframes = guess, budget_s, keyframes
        self.decoder = Decoder(url, typestore)
        self.status = Status()
        self.lags: deque[float] = deque(maxlen=100_000)  # [s] each pair's, for bench live
        # (stamp of its object scan, row, lag [s]): the pairs of the buffer's seconds
        self.rows: deque[tuple[float, PairMatch, float]] = deque()
        self.scans: deque[tuple[int, Scan]] = deque()  # the chain's scans (number, scan), for view
        self.buffer: deque[Raw] = deque()
        self._odometry: deque = deque()  # decoded Odometry messages of the buffer's window
        self._tf = TfTree()
        self._scan_channel: client.Channel | None = None
        self._odometry_topic = False  # an Odometry topic is subscribed: scans wait for it
        self._advertised: list[client.Channel] = []
        self._connected_at = time.monotonic()
        self._waiting: deque[tuple[int, object, float]] = deque()  # (number, message, arrival)
        # the scan the next one is matched against: the one before it, or the last key frame
        self._previous: tuple[int, Scan] | None = None
        self._frame_id = ""  # the laser's, as its scans name it
        self._busy = False  # the matcher is matching a scan
        self._lock = threading.Condition()
        self._stop = threading.Event()
        self._error: InputError | None = None
        self._ws = None
        _warm_up(params)  # the robot's first scans are not skipped while kernels load
        self.decoder.warm()  # nor while the decoders are made
        first = client.connect(url)  # a wrong URL or server is refused here, in one line
        self._threads = [
            threading.Thread(target=self._receive, args=(first,), daemon=True),
            threading.Thread(target=self._match, daemon=True),
        ]
        for t in self._threads:
            t.start()

    # --- receiving ---------------------------------------------------------------------------

    def _wanted(self, channel: client.Channel) -> bool:
        k = kind(channel)
        if k == LASER_SCAN:
            if self.topic is not None and channel.topic != self.topic:
                return False
            with self._lock:
                if self._scan_channel is None or self._scan_channel.topic == channel.topic:
                    self._scan_channel = channel
                    return True
            return False
        if k == ODOMETRY:
            with self._lock:
                self._odometry_topic = True
        return k in (ODOMETRY, TF)

    def _receive(self, ws) -> None:
        attempt = 0
        while not self._stop.is_set():
            try:
                if ws is None:
                    ws = client.connect(self.url)
                self._ws, attempt = ws, 0
                with self._lock:
                    self.status.connected = True
                for m in client.messages(ws, self.url, self._wanted, self._on_channels):
                    self._take(m)
            except client.Lost:
                pass
            except InputError as e:
                if self.status.reconnects == 0 and not self.status.scans:
                    self._fail(e)  # never worked: a wrong server, not a dropped one
                    return
            finally:
                if ws is not None:
                    ws.close()
                ws = self._ws = None
            if self._stop.is_set():
                return
            with self._lock:
                if self.status.connected:
                    self.status.reconnects += 1
                    self.status.notes.append(
                        f"the connection to {self.url} was lost: reconnecting (the buffer is kept)"
                    )
                self.status.connected = False
            self._stop.wait(RECONNECT_S[min(attempt, len(RECONNECT_S) - 1)])
            attempt += 1

    def _on_channels(self, channels: list[client.Channel]) -> None:
        with self._lock:
            self._advertised = channels

    def _no_scan_topic(self) -> InputError:
        """What the server offers instead of a scan topic this can read."""
        offered = (
            ", ".join(f"{c.topic} ({c.schema_name}, {c.encoding})" for c in self._advertised)
            or "nothing"
        )
        wanted = (
            f"does not offer the LaserScan topic {self.topic}"
            if self.topic
            else "offers no LaserScan topic"
        )
        return InputError(
            f"{self.url} {wanted} in an encoding this reads (cdr, ros1); it offers: {offered}",
            field="--topic" if self.topic else "URL",
        )

    def _fail(self, e: InputError) -> None:
        with self._lock:
            self._error = e
            self._lock.notify_all()
        self._stop.set()

    def _take(self, m: client.Received) -> None:
        k = kind(m.channel)
        raw = Raw(m.channel.topic, k, m.channel.encoding, m.log_time_ns, m.payload)
        with self._lock:
            self._keep(raw)
            n = self.status.scans if k == LASER_SCAN else len(self.buffer)
        try:
            msg = self.decoder(m.channel, m.payload, n)
        except InputError as e:
            with self._lock:
                self.status.undecodable += 1
                if self.status.undecodable == 1:
                    self.status.notes.append(f"skipped: {e}")
            return
        with self._lock:
            if k == LASER_SCAN:
                self._waiting.append((self.status.scans, msg, time.monotonic()))
                if len(self._waiting) > WAITING_MOST:
                    self._waiting.popleft()
                    self.status.skipped += 1
                self.status.scans += 1
            elif k == ODOMETRY:
                self._odometry.append(msg)
            elif m.channel.topic.lstrip("/") in ("tf", "tf_static"):
                self._tf.add(msg, m.log_time_ns * 1e-9, m.channel.topic.lstrip("/") == "tf_static")
            self._lock.notify_all()

    def _keep(self, raw: Raw) -> None:
        """``raw`` into the buffer, which drops what is older than its seconds (tf_static is kept:
        a bag without it has no mount)."""
        self.buffer.append(raw)
        self.status.buffer_bytes += len(raw.payload)
        newest = raw.log_time_ns
        while self.buffer and (
            newest - self.buffer[0].log_time_ns > self.buffer_s * 1e9
            or self.status.buffer_bytes > MAX_BUFFER_BYTES
        ):
            if self.buffer[0].topic.lstrip("/") == "tf_static":
                self.buffer.rotate(-1)  # moved to the newest end: kept
                if self.buffer[0] is raw:
                    break
                continue
            self.status.buffer_bytes -= len(self.buffer.popleft().payload)
        self.status.buffer_s = (newest - self.buffer[0].log_time_ns) * 1e-9

    # --- matching ----------------------------------------------------------------------------

    def _odometry_ready(self, stamp: float, received: float, track) -> bool:
        """Whether the odometry reaches past ``stamp`` (or there is none to wait for, or the scan
        has waited long enough)."""
        if self.guess not in (Guess.stored, Guess.odometry):
            return True
        if time.monotonic() - received > ODOMETRY_WAIT_S:
            return True
        if track is None:  # none yet: an Odometry topic's first message is awaited
            return not self._odometry_topic
        return track[0][-1] >= stamp

    def _ready(self):
        """The oldest waiting scan whose odometry is in (number, message, arrival, odometry), or
        None. A scan is skipped when the one after it is ready too and it has waited longer than
        the interval between their stamps: the matcher is behind, and would stay a scan period
        late. Scans the network delivers together are all matched (with only the newest kept, 1-3
        in 2,400 were skipped at 40 Hz while every result came within 21 ms of its scan), and a
        scan waiting for its odometry is never skipped for the one behind it."""
        while self._waiting:
            k, msg, received = self._waiting[0]
            stamp, frame_id = header_stamp(msg), msg.header.frame_id.lstrip("/")
            track = self._track(stamp, frame_id)
            if not self._odometry_ready(stamp, received, track):
                return None
            self._waiting.popleft()
            if self._waiting:
                _, after, arrived = self._waiting[0]
                next_stamp = header_stamp(after)
                late = time.monotonic() - received > next_stamp - stamp
                if late and self._odometry_ready(
                    next_stamp, arrived, self._track(next_stamp, frame_id)
                ):
                    self.status.skipped += 1
                    continue
            return k, msg, received, track
        return None

    def _next_scan(self):
        with self._lock:
            while not self._stop.is_set():
                if (ready := self._ready()) is not None:
                    self._busy = True
                    return ready
                if self._scan_channel is None and time.monotonic() - self._connected_at > NO_SCAN_S:
                    raise self._no_scan_topic()
                self._lock.wait(0.05)
        return None

    def _track(self, stamp: float, frame_id: str):
        """The odometry around ``stamp`` (stamps, base poses): an Odometry topic's, else the
        track on /tf of the base the laser ``frame_id`` hangs from; older messages dropped."""
        while len(self._odometry) > 2:
            if header_stamp(self._odometry[1]) >= stamp - 2.0:
                break
            self._odometry.popleft()
        self._tf.drop_before(stamp - 2.0)
        if self._odometry_topic:
            return odometry_track(list(self._odometry)) if self._odometry else None
        base = tf_base(self._tf, self._tf.mount(frame_id, self.url))
        return None if base is None else self._tf.odometry_track(base)[1:]

    def frames(self, frame_id: str) -> Frames:
        with self._lock:
            mount = self._tf.mount(frame_id, self.url) if frame_id else None
        if mount is None:
            return Frames(frame_id=frame_id)
        return Frames(mount.pose, mount.source, mount.base_frame, frame_id)

    def _match(self) -> None:
        try:
            while (nxt := self._next_scan()) is not None:
                try:
                    self._match_one(*nxt)
                finally:
                    with self._lock:
                        self._busy = False
                        self._lock.notify_all()
        except InputError as e:
            self._fail(e)

    def _match_one(self, k: int, msg, received: float, track) -> None:
        frame_id = self._frame_id = msg.header.frame_id.lstrip("/")
        frames = self.frames(frame_id)
        try:
            scan = laser_scan(msg, self.url, k, False, track, frames.mount)
        except ScanError as e:  # inconsistent arrays (a damaged message): counted as unusable
            scan = UnusableScan(e.source, e.reason)
        if isinstance(scan, UnusableScan):
            with self._lock:
                self.status.unusable += 1
            return
        previous = self._previous
        if previous is None:
            self._previous = (k, scan)
            with self._lock:
                self.scans.append((k, scan))
            return
        i, ref = previous
        job = (self.url, i, k, ref, scan, self.params, self.guess, None, None, frames, True)
        m = match_row(job, self.topic or self._scan_channel.topic, self.budget_s)
        if self.keyframes is None or self.keyframes.due(m):
            self._previous = (k, scan)
        with self._lock:
            lag = time.monotonic() - received
            if self.scans and self.scans[0][0] > i:  # the buffer lost its start (numbers ascend)
                self.scans.clear()
            self.scans.extend([previous] * (not self.scans) + [(k, scan)])
            self.rows.append((scan.stamp or 0.0, m, lag))
            while self.rows and self.rows[0][0] < self.rows[-1][0] - self.buffer_s:
                self.rows.popleft()  # the rows of the buffer's seconds
            while self.scans and self.rows and self.scans[0][0] < self.rows[0][1].ref:
                self.scans.popleft()
            self.status.matched += 1
            self.status.lag_s = lag
            self.lags.append(lag)

    # --- the caller's ------------------------------------------------------------------------

    def wait_idle(self, timeout_s: float) -> bool:
        """Until every scan received is matched or skipped (or ``timeout_s``)."""
        with self._lock:
            return self._lock.wait_for(lambda: not self._waiting and not self._busy, timeout_s)

    def error(self) -> InputError | None:
        with self._lock:
            return self._error

    def snapshot(self) -> tuple[Status, list[PairMatch]]:
        with self._lock:
            return replace(self.status, notes=list(self.status.notes)), [r for _, r, _ in self.rows]

    def view(self) -> tuple[Status, ScanLog, Sequence[PairMatch], list[float], list[int]]:
        """What the live page draws: the status, the chain's last unbroken stretch in the buffer
        as a log of its scans (read from memory, not saved) with its rows numbered as that log's
        records, each row's lag [s], and each record's number in the robot's run."""
        with self._lock:
            status = replace(self.status, notes=list(self.status.notes))
            scans, kept = list(self.scans), list(self.rows)
        number = {k: n for n, (k, _) in enumerate(scans)}
        kept = [(r, lag) for _, r, lag in kept if r.ref in number and r.obj in number]
        rows = [r for r, _ in kept]
        if rows:
            rows = RunRows.renumbered(
                rows,
                np.array([number[r.ref] for r in rows]),
                np.array([number[r.obj] for r in rows]),
            )
        log = ScanLog(self.url, [s for _, s in scans], frames=self.frames(self._frame_id))
        return status, log, rows, [lag for _, lag in kept], [k for k, _ in scans]

    def stop(self) -> None:
        self._stop.set()
        ws = self._ws
        if ws is not None:
            ws.close()
        for t in self._threads:
            t.join(timeout=10)

    def freeze(self, folder: Path):
        """The buffer as a log and the rows of its pairs, record numbers the log's: saved in
        ``folder`` as a bag (a ROS 1 bag for ROS 1 messages, else a ROS 2 MCAP bag) and read
        back, for the debugger or any command."""
        from mbicp_viz.readers import read_log

        with self._lock:
            messages, scans = list(self.buffer), self.status.scans
            rows = [r for _, r, _ in self.rows]
        ros1 = any(m.encoding == "ros1" for m in messages)
        path = Path(folder) / ("buffer.bag" if ros1 else "buffer")
        save_bag(messages, path)
        first = scans - sum(m.msgtype == LASER_SCAN for m in messages)  # its first scan's number
        rows = [replace(r, ref=r.ref - first, obj=r.obj - first) for r in rows if r.ref >= first]
        # numbered as a rows file's lines, which the debugger's report names
        return read_log(path), [replace(r, line=k) for k, r in enumerate(rows, 1)]

    def save(self, path: Path) -> int:
        """The buffer as a bag (``.mcap``: ROS 2 MCAP of CDR messages; ``.bag``: ROS 1 of ROS 1
        messages), written whole; the number of messages."""
        with self._lock:
            messages = list(self.buffer)
        return save_bag(messages, Path(path))


# [s] how long a thread holding the GIL keeps it from one that waits (Python's default: 5 ms): the
# matcher takes it back after each compiled kernel, a dozen times a match, while the page draws
GIL_SWITCH_S = 0.001


def steady_latency() -> None:
    """Once the run is up: every object made so far (the modules, the compiled kernels, the
    page's server) moved out of the garbage collector's reach, and the GIL handed over sooner.
    A full collection over those objects stopped every thread for 40-80 ms, three scan periods
    at 40 Hz; the page's drawing delayed the matcher by up to 5 ms at each kernel it ran
    (``bench live --page``: the slowest result 114-128 ms after its scan arrived, 20-24 ms with
    both). The run's own objects are still collected, in a few milliseconds."""
    gc.collect()
    gc.freeze()
    sys.setswitchinterval(GIL_SWITCH_S)


def _warm_up(params: Params) -> None:
    """Load the matcher's compiled kernels (numba's cache) with one iteration on a made-up room:
    the first live match then costs what the others do."""
    from mbicp_viz.core import Pose2, make_scan, match
    from mbicp_viz.core.budget import Halt, limited

    bearings = np.linspace(-2.0, 2.0, 361)
    room = make_scan(3.0 / np.maximum(np.abs(np.cos(bearings)), 0.3), bearings)
    done = Halt()
    done.stop("warmed up")
    with limited(None, done):
        match(room, room, Pose2(0.01, 0.0, 0.01), params)


def save_bag(messages: list[Raw], path: Path) -> int:
    """``messages`` as a ROS 1 bag (``path`` ending ``.bag``: ROS 1 messages) or else a ROS 2 bag
    folder in MCAP storage (CDR messages; a ROS 1 robot's converted), written whole; how many."""
    from rosbags.typesys import Stores, get_typestore

    from mbicp_viz.outputs import written, written_folder
    from mbicp_viz.writers.bag import ros1_as_cdr, ros1_typestore

    ros1 = path.suffix == ".bag"
    if ros1 and (wrong := {m.encoding for m in messages} - {"ros1"}):
        raise InputError(
            f"the robot sends {', '.join(sorted(wrong))} messages: save them as a ROS 2 bag (a "
            "name without .bag)",
            str(path),
            field="--save",
        )
    messages = sorted(messages, key=lambda m: m.log_time_ns)
    if ros1:
        from rosbags.rosbag1 import Writer

        ts, open_writer, output = ros1_typestore(), Writer, written
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        ts, output = get_typestore(Stores.ROS2_HUMBLE), written_folder

        def open_writer(p):
            return Writer(p, version=8, storage_plugin=StoragePlugin.MCAP)

    noetic = ros1_typestore()

    def payload(m: Raw) -> bytes:
        if ros1 or m.encoding == "cdr":
            return m.payload
        try:
            return ros1_as_cdr(m.payload, m.msgtype, noetic, ts)
        except InputError as e:
            raise InputError(
                f"{e.message}: save it as a ROS 1 bag (NAME.bag)", str(path), field="--save"
            ) from None

    with output(path) as tmp, open_writer(tmp) as w:
        conns = {}
        for m in messages:
            if m.topic not in conns:
                conns[m.topic] = w.add_connection(m.topic, m.msgtype, typestore=ts)
            w.write(conns[m.topic], m.log_time_ns, payload(m))
    return len(messages)
