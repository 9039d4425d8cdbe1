"""`GroundLink`: the vehicle's MQTT client for the ground station.

It connects to `ground.broker_url` (MQTT 5, or 3.1.1 when the broker refuses 5), with a
retained Last Will that turns `wireavoid/<id>/status` into `{"online": false}` when the vehicle
drops off, and:

- reads `wireavoid/<id>/cmd`: every payload gets exactly one ack on `.../ack`. Invalid ones
  (`protocol.parse_command`), retained ones and reused ids are rejected here; valid ones go to
  the `CommandHandler` (the mission), whose `Ack` is published. A handler that raises gets
  the command rejected and the link goes on.
- publishes the retained status from `status()` at `status_rate_hz` (paced by a
  `RateKeeper` on the process clock), and the events pushed with `publish_event` (kept while
  the broker is unreachable, the oldest dropped beyond `event_queue_size`).
- reconnects after any failure with a backoff doubling from `reconnect_min_s` to
  `reconnect_max_s`. Connecting, TLS and DNS run on a worker thread (aiomqtt), so a broker
  that is down or slow never blocks the event loop the flight runs on.

`health()` tells the mission whether the ground is reachable (`lost_for_s`) for its
ground-link-lost failsafe. Cancel `run()` to stop: it publishes the offline status itself and
disconnects cleanly.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import deque
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import Any, Protocol

import aiomqtt
from paho.mqtt.subscribeoptions import SubscribeOptions

from companion.clock import Clock, cancel_and_wait, wait_or_timeout
from companion.ground.client import connect_client, first_version
from companion.ground.params import GroundParams, MqttVersion
from companion.ground.protocol import (
    Ack,
    Command,
    Event,
    Rejection,
    Status,
    offline_status,
    parse_command,
    vehicle_topics,
)
from companion.rate import RateKeeper

log = logging.getLogger(__name__)

RECENT_IDS = 1024  # command ids remembered to refuse a reused one
CLOSE_TIMEOUT_S = 1.0  # time for the offline status and the disconnect when stopping


class CommandHandler(Protocol):
    """What the link hands each valid command to (the mission state machine)."""

    def handle(self, command: Command, now_s: float) -> Ack:
        """Carry `command` out or refuse it, at `now_s` (process clock, s): its one `Ack`."""
        ...


@dataclass(frozen=True, slots=True)
class GroundLinkHealth:
    """The link as the mission sees it, on the process clock (s).

    connected: the broker connection is up. since_s: when it came up or went down (the
    link's start before the first connection). last_message_s / last_command_s: when the
    last payload / valid command arrived on the cmd topic (None: never). protocol: "5" or
    "3.1.1" once connected. last_error: why the last connection failed or ended.
    """

    connected: bool
    since_s: float
    last_message_s: float | None
    last_command_s: float | None
    protocol: str | None
    connections: int
    commands_accepted: int
    commands_rejected: int
    events_dropped: int
    last_error: str

    def lost_for_s(self, now_s: float) -> float:
        """How long the ground has been unreachable at `now_s`, s (0 while connected)."""
        return 0.0 if self.connected else max(0.0, now_s - self.since_s)


class GroundLink:
    """The vehicle's side of the ground link; see the module docstring."""

    def __init__(
        self,
        params: GroundParams,
        clock: Clock,
        handler: CommandHandler,
        status: Callable[[], Status],
    ) -> None:
        if not params.enabled:
            raise ValueError("ground.broker_url is empty: there is no ground link to run")
        self.params = params
        self.topics = vehicle_topics(params.vehicle_id)
        self._clock = clock
        self._handler = handler
        self._status = status
        self._events: deque[Event] = deque(maxlen=params.event_queue_size)
        self._events_ready = asyncio.Event()
        self._recent_ids: deque[str] = deque(maxlen=RECENT_IDS)
        self._version = first_version(params)
        self._connected = False
        self._since_s = clock.now_s()
        self._last_message_s: float | None = None
        self._last_command_s: float | None = None
        self._connections = 0
        self._accepted = 0
        self._rejected = 0
        self._events_dropped = 0
        self._last_error = ""
        self._status_failed = False

    # ------------------------------------------------------------------ for the process

    def health(self) -> GroundLinkHealth:
        """The link's state now."""
        return GroundLinkHealth(
            connected=self._connected,
            since_s=self._since_s,
            last_message_s=self._last_message_s,
            last_command_s=self._last_command_s,
            protocol=self._version.value if self._connections else None,
            connections=self._connections,
            commands_accepted=self._accepted,
            commands_rejected=self._rejected,
            events_dropped=self._events_dropped,
            last_error=self._last_error,
        )

    def publish_event(self, event: Event) -> None:
        """Queue `event` for `wireavoid/<id>/events` (never blocks; the oldest is dropped when
        `event_queue_size` are waiting). Call it from the event loop's thread."""
        if len(self._events) == self._events.maxlen:
            self._events_dropped += 1
        stamped = event.stamp_s if event.stamp_s is not None else self._clock.now_s()
        self._events.append(
            event.model_copy(update={"vehicle_id": self.params.vehicle_id, "stamp_s": stamped})
        )
        self._events_ready.set()

    async def run(self) -> None:
        """Connect, serve and reconnect until cancelled; never raises for a network error."""
        failures = 0
        while True:
            try:
                client, self._version = await connect_client(
                    self.params,
                    identifier=self.params.mqtt_client_id,
                    version=self._version,
                    will=aiomqtt.Will(self.topics.status, self._offline(), qos=1, retain=True),
                )
                try:
                    failures = 0
                    self._on_connected()
                    await self._serve(client)
                except asyncio.CancelledError:
                    await self._say_goodbye(client)
                    raise
                finally:  # bounded: a dead network loop never answers the disconnect
                    with contextlib.suppress(aiomqtt.MqttError):
                        await wait_or_timeout(
                            self._clock, client.__aexit__(None, None, None), CLOSE_TIMEOUT_S
                        )
            except aiomqtt.MqttError as e:
                self._on_failure(f"{type(e).__name__}: {e}", failures)
            except (OSError, ValueError) as e:  # unreadable password or TLS files
                self._on_failure(f"{type(e).__name__}: {e}", failures)
            finally:
                self._set_disconnected()
            await self._clock.sleep(reconnect_delay_s(failures, self.params))
            failures += 1

    # ------------------------------------------------------------------ connection state

    def _offline(self) -> bytes:
        return offline_status(self.params.vehicle_id).model_dump_json().encode()

    def _on_connected(self) -> None:
        self._connected, self._since_s = True, self._clock.now_s()
        self._connections += 1
        text = (
            f"connected to {self.params.broker_url} as {self.params.mqtt_client_id} "
            f"(MQTT {self._version.value})"
        )
        log.info("ground link %s", text)
        self.publish_event(Event(kind="ground_link", text=text))

    def _set_disconnected(self) -> None:
        if self._connected:
            self._connected, self._since_s = False, self._clock.now_s()

    def _on_failure(self, error: str, failures: int) -> None:
        was_connected = self._connected
        if was_connected or error != self._last_error:
            log.warning("ground link: %s; reconnecting", error)
        else:
            log.debug("ground link attempt %d: %s", failures + 1, error)
        self._last_error = error

    async def _say_goodbye(self, client: aiomqtt.Client) -> None:
        """Mark the vehicle offline (a clean disconnect does not fire the Last Will), leaving
        its last status retained: a station that looks later sees how the flight ended
        (landed, its position), not only that the vehicle is gone."""
        last = self._current_status().model_copy(update={"online": False})
        payload = last.model_dump_json().encode()
        publish = client.publish(self.topics.status, payload, qos=1, retain=True)
        with contextlib.suppress(aiomqtt.MqttError):
            await wait_or_timeout(self._clock, publish, CLOSE_TIMEOUT_S)

    # ------------------------------------------------------------------ the session

    async def _serve(self, client: aiomqtt.Client) -> None:
        """Commands, status and events on one connection, until one of them fails."""
        if self._version is MqttVersion.V5:  # keep the retain flag of live messages too
            options = SubscribeOptions(qos=1, retainAsPublished=True)
            await client.subscribe(self.topics.cmd, options=options)
        else:  # 3.1.1 shows it only on retained messages replayed at subscription
            await client.subscribe(self.topics.cmd, qos=1)
        await _until_first_ends(
            self._answer_commands(client),
            self._publish_status(client),
            self._publish_events(client),
        )

    async def _answer_commands(self, client: aiomqtt.Client) -> None:
        async for message in client.messages:
            payload = message.payload
            if not isinstance(payload, (bytes, bytearray)):
                payload = b"" if payload is None else str(payload).encode()
            ack = self._answer(bytes(payload), retained=message.retain)
            await client.publish(self.topics.ack, ack.model_dump_json().encode(), qos=1)

    def _answer(self, payload: bytes, *, retained: bool) -> Ack:
        """The one ack of a payload received on the cmd topic."""
        now_s = self._clock.now_s()
        self._last_message_s = now_s
        command = parse_command(payload, max_payload_bytes=self.params.max_payload_bytes)
        if isinstance(command, Rejection):
            ack = Ack.reject(command, command.reason, now_s)
        elif retained:
            ack = Ack.reject(
                command, "retained commands are refused: publish with retain off", now_s
            )
        elif command.id in self._recent_ids:
            ack = Ack.reject(
                command,
                f"command id {command.id!r} was used before: give each command a new id",
                now_s,
            )
        else:
            self._recent_ids.append(command.id)
            self._last_command_s = now_s
            ack = self._handled(command, now_s)
        if ack.accepted:
            self._accepted += 1
        else:
            self._rejected += 1
            log.info("command %s %s rejected: %s", ack.command, ack.id, ack.reason)
        return ack

    def _handled(self, command: Command, now_s: float) -> Ack:
        """The handler's ack, bound to this command; a handler failure rejects it."""
        try:
            ack = self._handler.handle(command, now_s)
        except Exception as e:  # the mission's bug must not take the link down
            log.exception("the command handler failed on %s %s", command.type, command.id)
            return Ack.reject(
                command, f"internal error handling the command ({type(e).__name__})", now_s
            )
        return ack.model_copy(update={"id": command.id, "command": command.type})

    async def _publish_status(self, client: aiomqtt.Client) -> None:
        keeper = RateKeeper(
            self.params.status_rate_hz, clock=self._clock.now_s, sleep=self._clock.sleep
        )
        while True:
            payload = self._current_status().model_dump_json().encode()
            await client.publish(self.topics.status, payload, qos=0, retain=True)
            await keeper.wait()

    def _current_status(self) -> Status:
        """`status()` stamped for this vehicle; a bare online status if it fails."""
        now_s = self._clock.now_s()
        try:
            status = self._status()
            self._status_failed = False
        except Exception:
            if not self._status_failed:
                log.exception("the status callable failed; publishing a bare status")
            self._status_failed = True
            status = Status()
        stamp_s = status.stamp_s if status.stamp_s is not None else now_s
        return status.model_copy(
            update={"vehicle_id": self.params.vehicle_id, "online": True, "stamp_s": stamp_s}
        )

    async def _publish_events(self, client: aiomqtt.Client) -> None:
        while True:
            await self._events_ready.wait()
            while self._events:
                event = self._events[0]
                await client.publish(self.topics.events, event.model_dump_json().encode(), qos=1)
                if self._events and self._events[0] is event:
                    self._events.popleft()
            self._events_ready.clear()


def reconnect_delay_s(failures: int, params: GroundParams) -> float:
    """The pause before the next connection attempt after `failures` failed ones in a row, s:
    `reconnect_min_s`, doubling up to `reconnect_max_s`."""
    return min(params.reconnect_max_s, params.reconnect_min_s * 2.0 ** min(failures, 60))


async def _until_first_ends(*coroutines: Coroutine[Any, Any, None]) -> None:
    """Run the coroutines together until one ends; cancel the others; raise its exception."""
    tasks = [asyncio.ensure_future(c) for c in coroutines]
    try:
        done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        await cancel_and_wait(tasks)
        for task in tasks:  # retrieved: the one that ended first raises below
            if not task.cancelled():
                task.exception()
    for task in done:
        if not task.cancelled() and task.exception() is not None:
            raise task.exception()  # type: ignore[misc]
