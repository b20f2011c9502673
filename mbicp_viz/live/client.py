"""The client side of the Foxglove WebSocket protocol (what foxglove_bridge and the Foxglove SDK
serve): JSON text frames (``serverInfo``, ``advertise``, ``unadvertise``, ``status``) and binary
message-data frames (opcode 1, subscription id u32, log time u64 [ns], payload; little-endian).

Both subprotocols are offered: ``foxglove.sdk.v1``, the only one the current SDK server accepts,
and ``foxglove.websocket.v1``, which bridges built before the SDK speak.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from mbicp_viz.errors import InputError

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
MESSAGE_DATA = 0x01
_HEADER = struct.Struct("<BIQ")
MAX_MESSAGE_BYTES = 64 * 1024 * 1024  # a frame larger is no laser scan (or hostile)


@dataclass(frozen=True)
class Channel:
    id: int
    topic: str
    encoding: str  # "cdr" (ROS 2) or "ros1"
    schema_name: str  # e.g. "sensor_msgs/msg/LaserScan" or "sensor_msgs/LaserScan"


@dataclass(frozen=True)
class Received:
    channel: Channel
    log_time_ns: int
    payload: bytes


class Lost(Exception):
    """The connection ended after it was made: the server stopped, or the network dropped."""


def connect(url: str, timeout_s: float = 5.0):
    """A websocket to ``url`` speaking one of ``SUBPROTOCOLS``; every way it fails is one
    ``InputError`` naming the URL."""
    from websockets.exceptions import InvalidHandshake, InvalidURI
    from websockets.sync.client import connect as ws_connect

    try:
        return ws_connect(
            url,
            subprotocols=list(SUBPROTOCOLS),
            open_timeout=timeout_s,
            max_size=MAX_MESSAGE_BYTES,
            compression=None,
        )
    except InvalidURI:
        raise InputError("not a websocket URL (ws://HOST:PORT)", field="URL") from None
    except InvalidHandshake as e:
        raise InputError(
            f"{url}: not a Foxglove WebSocket server (the handshake failed: {e})", field="URL"
        ) from None
    except (OSError, TimeoutError) as e:
        raise InputError(f"{url}: cannot connect ({e})", field="URL") from None


def _channel(obj) -> Channel | None:
    try:
        return Channel(
            int(obj["id"]), str(obj["topic"]), str(obj["encoding"]), str(obj["schemaName"])
        )
    except (KeyError, TypeError, ValueError):
        return None


def messages(ws, url: str, wanted: Callable[[Channel], bool], on_channels=None) -> Iterator:
    """The messages of the channels ``wanted`` accepts, subscribed to as they are advertised;
    ``on_channels`` sees every advertised channel. The first frame must be the server's
    ``serverInfo``; a lost connection raises ``Lost``."""
    from websockets.exceptions import ConnectionClosed

    subscribed: dict[int, Channel] = {}
    advertised: dict[int, Channel] = {}
    try:
        first = ws.recv(timeout=10.0)
        if not isinstance(first, str) or '"serverInfo"' not in first:
            raise InputError(f"{url}: not a Foxglove WebSocket server (no serverInfo)", field="URL")
        while True:
            frame = ws.recv()
            if isinstance(frame, str):
                _text_frame(ws, frame, advertised, subscribed, wanted, on_channels)
                continue
            if len(frame) < _HEADER.size or frame[0] != MESSAGE_DATA:
                continue  # other binary frames (time, service responses) are not ours
            _, sub, t = _HEADER.unpack_from(frame)
            if sub in subscribed:
                yield Received(subscribed[sub], t, bytes(frame[_HEADER.size :]))
    except ConnectionClosed as e:
        raise Lost(str(e)) from None
    except TimeoutError:
        raise InputError(f"{url}: the server said nothing for 10 s", field="URL") from None


def _text_frame(ws, frame: str, advertised, subscribed, wanted, on_channels) -> None:
    try:
        msg = json.loads(frame)
    except json.JSONDecodeError:
        return
    if not isinstance(msg, dict):
        return
    if msg.get("op") == "advertise":
        new = [c for c in map(_channel, msg.get("channels") or []) if c is not None]
        advertised.update({c.id: c for c in new})
        if on_channels is not None:
            on_channels(list(advertised.values()))
        subs = [c for c in new if c.id not in subscribed and wanted(c)]
        if subs:
            ws.send(
                json.dumps(
                    {
                        "op": "subscribe",
                        "subscriptions": [{"id": c.id, "channelId": c.id} for c in subs],
                    }
                )
            )
            subscribed.update({c.id: c for c in subs})
    elif msg.get("op") == "unadvertise":
        for cid in msg.get("channelIds") or []:
            advertised.pop(cid, None)
            subscribed.pop(cid, None)
