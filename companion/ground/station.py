"""`GroundStation`: the operator's MQTT client (`wireavoid gcs`, and the tests' ground side).

It subscribes to a vehicle's ack, status and events, publishes commands on its cmd topic and
waits for the ack that answers each one (matched by command id).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import uuid
from types import TracebackType
from typing import Self

import aiomqtt
from pydantic import ValidationError

from companion.ground.client import connect_client, first_version
from companion.ground.params import GroundParams
from companion.ground.protocol import Ack, Command, Event, Status, vehicle_topics

log = logging.getLogger(__name__)


def new_command_id() -> str:
    """A fresh command id (`gcs-` and 12 hex digits)."""
    return f"gcs-{uuid.uuid4().hex[:12]}"


class GroundStation:
    """Commands one vehicle and follows what it publishes; `async with` connects.

    `params` describes the station's connection (its own username and password file; the
    vehicle to talk to is `params.vehicle_id`).
    """

    def __init__(self, params: GroundParams) -> None:
        self.params = params
        self.topics = vehicle_topics(params.vehicle_id)
        self.acks: list[Ack] = []
        self.events: list[Event] = []
        self.status: Status | None = None
        self.status_count = 0
        self._client: aiomqtt.Client | None = None
        self._reader: asyncio.Task[None] | None = None
        self._changed = asyncio.Condition()

    async def __aenter__(self) -> Self:
        identifier = f"wireavoid-gcs-{uuid.uuid4().hex[:8]}"
        client, _ = await connect_client(
            self.params, identifier=identifier, version=first_version(self.params)
        )
        self._client = client
        for topic in (self.topics.ack, self.topics.status, self.topics.events):
            await client.subscribe(topic, qos=1)
        self._reader = asyncio.create_task(self._read())
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._reader is not None:
            self._reader.cancel()
            with contextlib.suppress(asyncio.CancelledError, aiomqtt.MqttError):
                await self._reader
        if self._client is not None:
            with contextlib.suppress(aiomqtt.MqttError):
                await self._client.__aexit__(exc_type, exc, tb)

    async def _read(self) -> None:
        assert self._client is not None
        async for message in self._client.messages:
            payload = message.payload if isinstance(message.payload, (bytes, bytearray)) else b""
            try:
                if message.topic.matches(self.topics.ack):
                    self.acks.append(Ack.model_validate_json(payload))
                elif message.topic.matches(self.topics.status):
                    self.status = Status.model_validate_json(payload)
                    self.status_count += 1
                elif message.topic.matches(self.topics.events):
                    self.events.append(Event.model_validate_json(payload))
            except ValidationError as e:
                log.warning("unreadable message on %s: %s", message.topic, e)
                continue
            async with self._changed:
                self._changed.notify_all()

    async def wait_for(self, predicate: object, timeout_s: float) -> bool:
        """Wait until `predicate()` is true (checked after each message): False on timeout."""
        assert callable(predicate)

        async def until() -> None:
            async with self._changed:
                await self._changed.wait_for(predicate)

        try:
            await asyncio.wait_for(until(), timeout_s)
        except TimeoutError:
            return False
        return True

    async def publish(self, payload: bytes, *, retain: bool = False) -> None:
        """Publish raw bytes on the vehicle's cmd topic (QoS 1)."""
        assert self._client is not None, "use `async with GroundStation(...)`"
        await self._client.publish(self.topics.cmd, payload, qos=1, retain=retain)

    async def send(self, command: Command, timeout_s: float = 5.0) -> Ack | None:
        """Send `command` and wait for its ack (None: no ack within `timeout_s`)."""
        await self.publish(command.model_dump_json(exclude_none=True).encode())
        return await self.ack_for(command.id, timeout_s)

    async def send_raw(self, payload: bytes, timeout_s: float = 5.0) -> Ack | None:
        """Publish `payload` as is and wait for the next ack (for payloads without a readable
        id; answer one payload at a time)."""
        seen = len(self.acks)
        await self.publish(payload)
        if await self.wait_for(lambda: len(self.acks) > seen, timeout_s):
            return self.acks[seen]
        return None

    async def ack_for(self, command_id: str, timeout_s: float) -> Ack | None:
        """The ack of `command_id` once it arrives (None after `timeout_s`)."""

        def answered() -> bool:
            return any(a.id == command_id for a in self.acks)

        if not await self.wait_for(answered, timeout_s):
            return None
        return next(a for a in self.acks if a.id == command_id)

    async def next_status(self, timeout_s: float) -> Status | None:
        """The next status to arrive (the retained one first after connecting)."""
        seen = self.status_count
        if await self.wait_for(lambda: self.status_count > seen, timeout_s):
            return self.status
        return None
