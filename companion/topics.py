"""The flight process' messages on named topics, each with its expected rate and maximum age.

Like openpilot's service registry (`cereal/services.py`): one table declares every topic the
stages exchange, how often it should arrive and how old it may get before its consumers treat
it as stale. The `Bus` keeps the latest message of each topic with a sequence number and the
time it was published; a stage waits for a newer one than it saw last (the newest wins: a
stage that is busy when several arrive takes only the latest, and the gap in sequence numbers
counts the dropped ones). Subscribers see every message as it is published: the recorder
and the live view hang there, never in a stage.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, slots=True)
class TopicSpec:
    """A topic: its name, expected rate (Hz, 0 = on change) and maximum age (s)."""

    name: str
    rate_hz: float
    max_age_s: float
    description: str


TOPICS: dict[str, TopicSpec] = {
    spec.name: spec
    for spec in (
        TopicSpec("camera", 10.0, 0.5, "camera frames (colour, disparity), stamped at exposure"),
        TopicSpec("vehicle", 30.0, 0.5, "vehicle pose from telemetry (world_from_body, velocity)"),
        TopicSpec("perception", 10.0, 0.5, "wire masks of the CNN (thesis 4.4.1), per frame"),
        TopicSpec("map", 10.0, 0.5, "frames fused into DROAN (4.4.6), with the pose used"),
        TopicSpec("plan", 10.0, 0.5, "planner outputs (4.5): state, chosen trajectory, costs"),
        TopicSpec("setpoint", 20.0, 0.3, "setpoints handed to the link (planning.types.Setpoint)"),
        TopicSpec("mission", 0.0, math.inf, "mission state transitions and events"),
    )
}


@dataclass(frozen=True, slots=True)
class Stamped:
    """A message as published: `seq` counts the topic's messages from 1, `stamp_s` is the
    process clock at publication."""

    topic: str
    seq: int
    stamp_s: float
    message: Any


Subscriber = Callable[[Stamped], None]


class Bus:
    """Latest message per topic, waits for newer ones, and synchronous subscribers."""

    def __init__(self, clock_now_s: Callable[[], float]) -> None:
        self._now_s = clock_now_s
        self._latest: dict[str, Stamped] = {}
        self._changed: dict[str, asyncio.Event] = {name: asyncio.Event() for name in TOPICS}
        self._subscribers: list[Subscriber] = []

    def publish(self, topic: str, message: Any) -> Stamped:
        """Publish `message` on `topic` (a name in `TOPICS`)."""
        if topic not in TOPICS:
            raise KeyError(f"unknown topic {topic!r}; topics: {sorted(TOPICS)}")
        previous = self._latest.get(topic)
        stamped = Stamped(
            topic, 1 if previous is None else previous.seq + 1, self._now_s(), message
        )
        self._latest[topic] = stamped
        event = self._changed[topic]
        event.set()
        self._changed[topic] = asyncio.Event()
        for subscriber in self._subscribers:
            subscriber(stamped)
        return stamped

    def latest(self, topic: str) -> Stamped | None:
        """The newest message of `topic`, or None before the first."""
        return self._latest.get(topic)

    async def newer(self, topic: str, than_seq: int) -> Stamped:
        """The newest message of `topic` with a sequence number above `than_seq` (waits)."""
        while True:
            stamped = self._latest.get(topic)
            if stamped is not None and stamped.seq > than_seq:
                return stamped
            await self._changed[topic].wait()

    def subscribe(self, subscriber: Subscriber) -> None:
        """Call `subscriber` with every message published from now on (keep it fast)."""
        self._subscribers.append(subscriber)

    def age_s(self, topic: str) -> float:
        """Time since `topic` was last published, s (inf before the first)."""
        stamped = self._latest.get(topic)
        return math.inf if stamped is None else self._now_s() - stamped.stamp_s
