"""A robot as the live command meets one, for ``bench live`` and the tests: the official Foxglove
SDK's WebSocket server (``pip install foxglove-sdk``) publishing a bag's messages, raw as the bag
holds them (CDR from a ROS 2 bag, ROS 1 from a ROS 1 bag), with their original stamps as log
times."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from mbicp_viz.errors import InputError

try:
    import foxglove
    from foxglove import Channel, Schema
    from foxglove.websocket import ServerListener
except ImportError:  # bench live says what to install
    foxglove = None
    ServerListener = object


class _Subscriptions(ServerListener):
    def __init__(self):
        self.topics: set[str] = set()
        self.changed = threading.Condition()

    def on_subscribe(self, client, channel) -> None:
        with self.changed:
            self.topics.add(channel.topic)
            self.changed.notify_all()

    @staticmethod
    def settled(received, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not received():
            if time.monotonic() > deadline:
                return False
            threading.Event().wait(0.01)
        return True

    def wait(self, topics, timeout_s: float) -> bool:
        with self.changed:
            return self.changed.wait_for(lambda: set(topics) <= self.topics, timeout_s)


class FoxgloveRobot:
    """Serves ``bag`` on 127.0.0.1 (``port`` 0: a free one); ``publish`` sends its messages once
    the client subscribed to ``topics``, ``rate`` times faster than they were recorded."""

    def __init__(self, bag: Path, port: int = 0):
        from rosbags.highlevel import AnyReader

        if foxglove is None:
            raise InputError("publishing a bag needs the Foxglove SDK: pip install foxglove-sdk")
        self.bag, self.ros1 = bag, bag.suffix == ".bag"
        self.listener = _Subscriptions()
        self.server = self._start(port)
        self.port = self.server.port
        with AnyReader([bag]) as reader:
            self.channels = {c.topic: self._channel(c) for c in reader.connections}
            self.scan_topics = {c.topic for c in reader.connections if c.msgtype.endswith("Scan")}
            self.messages = [(c.topic, t, raw) for c, t, raw in reader.messages()]

    def _start(self, port: int, timeout_s: float = 10.0):
        """The server on ``port``. The SDK's ``stop()`` returns before its listening socket is
        closed (a restart on the same port failed 238 times in 300 at once, never after 2 ms), so
        a bridge coming back on its old port tries again until that socket is gone."""
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                return foxglove.start_server(port=port, server_listener=self.listener)
            except RuntimeError as e:
                if port == 0 or "in use" not in str(e) or time.monotonic() > deadline:
                    raise
            threading.Event().wait(0.01)

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    def _channel(self, c) -> Channel:
        name = c.msgtype.replace("/msg/", "/") if self.ros1 else c.msgtype
        return Channel(
            c.topic,
            message_encoding="ros1" if self.ros1 else "cdr",
            schema=Schema(
                name=name,
                encoding="ros1msg" if self.ros1 else "ros2msg",
                data=c.msgdef.data.encode(),
            ),
        )

    def publish(
        self,
        topics=("/scan",),
        rate: float = 10.0,
        first: int = 0,
        count=None,
        before_scan=None,
        received=None,
    ) -> None:
        """Send the messages once the client subscribed to ``topics``, ``rate`` times faster than
        they were recorded. ``received()``, when given, says whether the client has the first
        message: it is sent again until it does (a subscription the server has announced may take
        effect a moment later). ``before_scan(n)`` is called before the n-th scan message (from 0)
        is sent: a test waits there for the client to have taken the scans before it."""
        if not self.listener.wait(topics, 60.0):
            raise InputError(f"nobody subscribed to {', '.join(topics)} within 60 s", self.url)
        messages = self.messages[first : None if count is None else first + count]
        if received is not None:
            topic, t, raw = messages[0]
            for _ in range(100):
                self.channels[topic].log(raw, log_time=t)
                if self.listener.settled(received, 0.5):
                    break
            messages = messages[1:]
        t0, start, scans = messages[0][1], time.monotonic(), 0
        for topic, t, raw in messages:
            if topic in self.scan_topics and before_scan is not None:
                before_scan(scans)
                scans += 1
            due = start + (t - t0) * 1e-9 / rate  # the robot's own pace, sped up
            while (now := time.monotonic()) < due:
                threading.Event().wait(due - now)
            self.channels[topic].log(raw, log_time=t)

    def stop(self) -> None:
        self.server.stop()
        for ch in self.channels.values():
            ch.close()
