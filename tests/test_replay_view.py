"""The live view speaks Foxglove's WebSocket protocol: a client is greeted, told the channels
(the recording's own, the map cloud and the plan scene) and sent their messages."""

from __future__ import annotations

import base64
import os
import socket
import time
from pathlib import Path

from companion.record.replay import recording_settings, replay
from companion.view.live import LiveView

BLESSED = Path(__file__).parent / "data" / "replay" / "hop.mcap"


def _connect(port: int) -> socket.socket:
    client = socket.create_connection(("127.0.0.1", port), timeout=5.0)
    key = base64.b64encode(os.urandom(16)).decode()
    client.sendall(
        (
            "GET / HTTP/1.1\r\nHost: localhost\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
            "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
        ).encode()
    )
    return client


def _read_for(client: socket.socket, seconds: float) -> bytes:
    client.settimeout(0.2)
    data, end = b"", time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            chunk = client.recv(1 << 16)
        except TimeoutError:
            continue
        if not chunk:
            break
        data += chunk
    return data


def test_a_replay_is_shown_live_to_a_foxglove_client() -> None:
    settings = recording_settings(BLESSED)
    view = LiveView.start(settings, 0)
    client = _connect(view.port)
    try:
        greeting = _read_for(client, 0.5)
        assert greeting.startswith(b"HTTP/1.1 101") and b'"op":"serverInfo"' in greeting
        result, _ = replay([BLESSED], settings, on_replayed=view.on_replayed)
        assert result.divergences == 0
        streamed = _read_for(client, 1.0)
    finally:
        shown = view.close()
        client.close()
    published = shown["published"]
    for channel in ("/camera/image", "/perception/wire_mask", "/vehicle", "/plan", "/map"):
        assert published[channel] > 10, (channel, published)
    assert published["/scene/plan"] > 3 and published["/scene/map"] > 3
    assert shown["dropped"] == 0
    advertised = greeting + streamed
    for topic in (b'"topic":"/camera/image"', b'"topic":"/scene/map"', b'"topic":"/scene/plan"'):
        assert topic in advertised
    assert b"foxglove.PointCloud" in advertised and b"foxglove.SceneUpdate" in advertised
