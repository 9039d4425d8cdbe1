"""The live view: the flight (or its replay) published to Foxglove over its WebSocket protocol.

`LiveView.start(settings, port)` opens a Foxglove WebSocket server (the `foxglove-sdk`
package, the optional extra `wireavoid[view]`) on localhost; connect Foxglove to
`ws://localhost:PORT`. It hangs on the bus like the recorder (`on_message`, fast: it only
queues) and a thread publishes the recording's own channels (the same JSON and schemas as a
recording, `companion.record.codec`: the image, the wire mask, the disparity preview, poses,
plans, setpoints, mission events) plus `/scene/map` (the DROAN map around the vehicle as a
point cloud, wires red) and `/scene/plan` (the library, the chosen trajectory, the goal, the
flown path), at most `SCENE_RATE_HZ`. A replay feeds it with `on_replayed`.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
from collections import deque
from typing import Any

import numpy as np

from companion.config import Settings
from companion.record.codec import (
    CHANNELS,
    ENCODERS,
    Encoded,
    encode_camera,
    encode_static,
    stamp_ns,
)
from companion.topics import Stamped
from companion.view.scene import (
    frame_points_ned_m,
    placed_library_ned_m,
    plan_scene,
    point_cloud,
)
from geometry.camera import stereo_rig_from_params
from planning.library import generate_library

log = logging.getLogger(__name__)

SCENE_RATE_HZ = 2.0
_KEYFRAMES_SHOWN = 24  # fused frames whose points make up the map cloud
_PATH_POINTS = 4000
_SCENE_SCHEMAS = {
    "/scene/map": "foxglove.PointCloud",
    "/scene/plan": "foxglove.SceneUpdate",
}


class ViewUnavailable(RuntimeError):
    """The live view needs the `foxglove-sdk` package (`pip install 'wireavoid[view]'`)."""


class LiveView:
    """A Foxglove WebSocket server fed from the bus (see the module docstring)."""

    def __init__(self, settings: Settings, server: Any, foxglove: Any) -> None:
        self.settings = settings
        self.port = int(server.port)
        self._server, self._fox = server, foxglove
        self._channels: dict[str, Any] = {}
        self._queue: queue.Queue[tuple[str, float, Any] | None] = queue.Queue(256)
        self._rig = stereo_rig_from_params(settings.mapping.camera)
        self._library = generate_library(settings.planning)
        self._frames: dict[int, Any] = {}
        self._masks: dict[int, np.ndarray | None] = {}
        self._clouds: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=_KEYFRAMES_SHOWN)
        self._path: deque[np.ndarray] = deque(maxlen=_PATH_POINTS)
        self._next_scene_s = -np.inf
        self.published: dict[str, int] = {}
        self.dropped = 0
        self._thread = threading.Thread(target=self._run, name="live-view", daemon=True)
        self._thread.start()
        self._publish(encode_static(0.0))

    @classmethod
    def start(cls, settings: Settings, port: int = 8765, host: str = "127.0.0.1") -> LiveView:
        """Open the WebSocket server on `host:port` (0: any free port)."""
        try:
            import foxglove
        except ImportError as e:
            raise ViewUnavailable(
                "the live view needs foxglove-sdk: pip install 'wireavoid[view]'"
            ) from e
        server = foxglove.start_server(name="wireavoid", host=host, port=port)
        log.warning("live view: connect Foxglove to ws://%s:%d", host, server.port)
        return cls(settings, server, foxglove)

    # ------------------------------------------------------------------ feeding

    def on_message(self, stamped: Stamped) -> None:
        """The bus' subscriber: queue the message (dropped when the view is behind)."""
        self._put((stamped.topic, stamped.stamp_s, stamped.message))

    def on_replayed(self, topic: str, stamp_s: float, message: Any) -> None:
        """A replayed stage output (perception, map, plan) at its recorded time."""
        self._put((topic, stamp_s, message))

    def _put(self, item: tuple[str, float, Any]) -> None:
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.dropped += 1

    def close(self) -> dict[str, Any]:
        """Publish what is queued, stop the server; what was published, per channel."""
        self._queue.put(None)
        self._thread.join()
        self._server.stop()
        return {"port": self.port, "published": dict(self.published), "dropped": self.dropped}

    # ------------------------------------------------------------------ the thread

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                self._handle(*item)
            except Exception:  # the view must never take the flight down
                log.exception("live view: cannot show %s", item[0])

    def _handle(self, topic: str, stamp_s: float, message: Any) -> None:
        if topic == "camera":
            self._frames[message.sequence] = message
            for old in [s for s in self._frames if s < message.sequence - 64]:
                del self._frames[old]
            preview = float(self.settings.mapping.camera_max_disparity_px)
            encoded = encode_camera(message, stamp_s, preview)
            self._publish([e for e in encoded if e.channel != "/camera/disparity"])
            return
        if topic == "perception":
            self._masks[message.sequence] = message.wire_mask
            for old in [s for s in self._masks if s < message.sequence - 64]:
                del self._masks[old]
        elif topic == "map" and message.world_from_camera is not None:
            frame = self._frames.get(message.sequence)
            if frame is not None and frame.disparity_px is not None:
                self._clouds.append(
                    frame_points_ned_m(
                        self._rig,
                        message.world_from_camera,
                        frame.disparity_px,
                        self._masks.get(message.sequence),
                    )
                )
        elif topic == "vehicle" and message.pose is not None:
            self._path.append(np.asarray(message.pose.position_ned_m, dtype=np.float64))
        if topic in ENCODERS:
            self._publish(ENCODERS[topic](message, stamp_s))
        if topic == "plan" and stamp_s >= self._next_scene_s:
            self._next_scene_s = stamp_s + 1.0 / SCENE_RATE_HZ
            self._publish_scene(stamp_s, message)

    def _publish_scene(self, stamp_s: float, plan: Any) -> None:
        vehicle = plan.vehicle
        library = placed_library_ned_m(
            self._library,
            vehicle.position_ned_m,
            vehicle.yaw_rad,
            float(np.linalg.norm(vehicle.velocity_ned_mps[:2])),
        )
        scene = plan_scene(
            stamp_s,
            library,
            np.asarray(plan.output.reference.positions_ned_m),
            plan.goal_ned_m,
            np.array(self._path).reshape(-1, 3),
        )
        encoded = [Encoded("/scene/plan", stamp_s, scene)]
        if self._clouds:
            points = np.concatenate([c[0] for c in self._clouds])
            wire = np.concatenate([c[1] for c in self._clouds])
            encoded.append(Encoded("/scene/map", stamp_s, point_cloud(stamp_s, points, wire)))
        self._publish(encoded)

    def _channel(self, topic: str) -> Any:
        channel = self._channels.get(topic)
        if channel is None:
            if topic in CHANNELS:
                name, body = CHANNELS[topic].schema_name, CHANNELS[topic].schema
            else:  # Foxglove knows its own schemas by name
                name = _SCENE_SCHEMAS[topic]
                body = {"title": name, "type": "object"}
            schema = self._fox.Schema(
                name=name, encoding="jsonschema", data=json.dumps(body).encode()
            )
            channel = self._channels[topic] = self._fox.Channel(
                topic, schema=schema, message_encoding="json"
            )
        return channel

    def _publish(self, encoded: list[Encoded]) -> None:
        for e in encoded:
            self._channel(e.channel).log(e.data(), log_time=stamp_ns(e.stamp_s))
            self.published[e.channel] = self.published.get(e.channel, 0) + 1
