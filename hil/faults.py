"""Faults the simulator injects into a flight: what a broken camera, link or machine does.

`FaultSpec` is one fault as `wireavoid sim --fault NAME` and a world file's `[[fault]]` give it:
its kind, when it starts (simulated seconds after offboard is first engaged, so the vehicle is
flying) and how long it lasts. The injectors work on the simulator's side of each interface,
so the flight process sees what a real failure would show it:

- `FaultyCamera` wraps a camera source (duck-typed: `open`, `next_frame`, `close`; frames are
  dataclasses with `stamp_s` and `sequence`): **camera_freeze** delivers the last good frame's
  pixels again with new stamps (a driver re-sending its last buffer), **camera_drop** delivers
  nothing, **camera_delay** delivers each frame `delay_s` late (its exposure stamp unchanged),
  **camera_reorder** swaps each pair of frames.
- `MavlinkRelay` sits on the UDP path between the vehicle and the companion: **link_loss**
  drops every datagram both ways, **pose_jump** shifts the local frame by `jump_ned_m` (an EKF
  reset: LOCAL_POSITION_NED jumps and position setpoints are read in the shifted frame).
- `CpuHog`: **cpu_hog** runs `processes` busy processes beside the flight.
- `BrokerRestart`: **mqtt_restart** stops the ground link's broker (`hil.broker.Mosquitto`,
  one the simulation runs itself) when the fault begins and starts it again on the same port
  when it ends.
- **cnn_stall** and **planner_stall** are the composition's to inject (it wraps the stage
  callables of the flight process, `companion.cli.sim_faults`).

Each injector logs what it did (`FaultLog`: when the fault began and ended, the last good
input before it) for the fault matrix to judge the process' reaction against.
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import math
import select
import socket
import subprocess
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

FaultKind = Literal[
    "camera_freeze",
    "camera_drop",
    "camera_delay",
    "camera_reorder",
    "pose_jump",
    "link_loss",
    "cnn_stall",
    "planner_stall",
    "cpu_hog",
    "mqtt_restart",
]
FAULT_KINDS: tuple[str, ...] = FaultKind.__args__  # type: ignore[attr-defined]
CAMERA_FAULTS = frozenset({"camera_freeze", "camera_drop", "camera_delay", "camera_reorder"})
RELAY_FAULTS = frozenset({"link_loss", "pose_jump"})

FAULT_DESCRIPTIONS = {
    "camera_freeze": "the camera repeats its last frame's pixels (new stamps)",
    "camera_drop": "the camera delivers no frames",
    "camera_delay": "frames arrive delay_s late (exposure stamps unchanged)",
    "camera_reorder": "frames arrive with each pair swapped",
    "pose_jump": "the autopilot's local frame jumps by jump_ned_m (an EKF reset)",
    "link_loss": "every MAVLink datagram is lost, both ways",
    "cnn_stall": "the wire CNN does not return",
    "planner_stall": "the planner does not return",
    "cpu_hog": "busy processes beside the flight take the CPU",
    "mqtt_restart": "the ground link's MQTT broker stops and starts again",
}


class FaultSpec(BaseModel):
    """One injected fault (`--fault NAME`, or a `[[fault]]` table of a world file)."""

    model_config = ConfigDict(extra="forbid")

    kind: FaultKind = Field(description="what fails (see `wireavoid faults --list`)")
    start_s: float = Field(
        3.0, ge=0.0, le=3600.0, description="simulated s after offboard is first engaged"
    )
    duration_s: float = Field(
        2.0, gt=0.0, le=3600.0, description="how long it lasts, s (pose_jump: the jump stays)"
    )
    delay_s: float = Field(0.8, gt=0.0, le=30.0, description="camera_delay: extra latency, s")
    jump_ned_m: tuple[float, float, float] = Field(
        (3.0, 0.0, 0.0), description="pose_jump: shift of the local frame, NED m"
    )
    processes: int = Field(2, ge=1, le=64, description="cpu_hog: busy processes")


@dataclass
class FaultLog:
    """What an injector did for one fault, in simulated seconds (NaN: did not happen).

    last_good_stamp_s: the stamp of the last input delivered unaffected before the fault (a
    frame's exposure, a datagram's time). first_effect_s: when the fault first changed what
    the process received. cleared_s: when the injector undid it (the restarted broker
    listening again; NaN for the faults that simply end at `end_s`).
    """

    spec: FaultSpec
    start_s: float = math.nan
    end_s: float = math.nan
    last_good_stamp_s: float = math.nan
    first_effect_s: float = math.nan
    cleared_s: float = math.nan
    affected: int = 0  # frames / datagrams the fault changed or swallowed
    notes: list[str] = field(default_factory=list)

    def effect(self, now_s: float) -> None:
        """Count one input the fault changed at `now_s`."""
        self.affected += 1
        if math.isnan(self.first_effect_s):
            self.first_effect_s = now_s


class FaultSchedule:
    """The faults of one flight on simulated time; the origin is set when offboard engages."""

    def __init__(self, specs: list[FaultSpec], now_s: Callable[[], float]) -> None:
        self.logs = [FaultLog(spec) for spec in specs]
        self._now_s = now_s
        self.origin_s = math.nan

    def start(self, origin_s: float) -> None:
        """Offboard engaged at `origin_s`: fault windows count from here."""
        if math.isnan(self.origin_s):
            self.origin_s = origin_s
            for log in self.logs:
                log.start_s = origin_s + log.spec.start_s
                log.end_s = log.start_s + log.spec.duration_s

    def now_s(self) -> float:
        """The simulated time now, s."""
        return self._now_s()

    def active(
        self, kinds: frozenset[str] | set[str], now_s: float | None = None
    ) -> list[FaultLog]:
        """The faults of `kinds` in effect at `now_s` (default: now)."""
        t = self._now_s() if now_s is None else now_s
        return [log for log in self.logs if log.spec.kind in kinds and log.start_s <= t < log.end_s]

    def of(self, kinds: frozenset[str] | set[str]) -> list[FaultLog]:
        """Every fault of `kinds`."""
        return [log for log in self.logs if log.spec.kind in kinds]


# ---------------------------------------------------------------------------- the camera


class FaultyCamera:
    """A camera source whose frames go through the camera faults of a `FaultSchedule`.

    A pump task reads the inner source at its own pace; each frame is given a delivery time
    (now, or later for a delay or a swap), and `next_frame` hands them out in that order.
    clock: the flight's clock (`now_s`, `sleep`).
    """

    def __init__(self, inner: Any, clock: Any, schedule: FaultSchedule) -> None:
        self._inner, self._clock, self._schedule = inner, clock, schedule
        self._due: list[tuple[float, int, Any]] = []
        self._order = itertools.count()
        self._ready = asyncio.Event()
        self._pump: asyncio.Task[None] | None = None
        self._last_good: Any = None
        self._held: Any = None  # a frame waiting for its successor (reorder)

    async def open(self) -> None:
        await self._inner.open()
        self._due.clear()
        self._pump = asyncio.create_task(self._run(), name="faulty-camera")

    async def close(self) -> None:
        if self._pump is not None:
            self._pump.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._pump
            self._pump = None
        await self._inner.close()

    async def next_frame(self) -> Any:
        while True:
            if self._due:
                due_s, _, item = self._due[0]
                wait_s = due_s - self._clock.now_s()
                if wait_s <= 1e-9:
                    heapq.heappop(self._due)
                    if isinstance(item, BaseException):
                        raise item
                    return item
                self._ready.clear()
                sleeper = asyncio.ensure_future(self._clock.sleep(wait_s))
                waiter = asyncio.ensure_future(self._ready.wait())
                try:
                    await asyncio.wait((sleeper, waiter), return_when=asyncio.FIRST_COMPLETED)
                finally:
                    for task in (sleeper, waiter):
                        task.cancel()
                continue
            self._ready.clear()
            await self._ready.wait()

    def _deliver(self, due_s: float, item: Any) -> None:
        heapq.heappush(self._due, (due_s, next(self._order), item))
        self._ready.set()

    async def _run(self) -> None:
        while True:
            try:
                frame = await self._inner.next_frame()
            except Exception as e:  # the inner source died: hand its error to the reader
                self._deliver(self._clock.now_s(), e)
                return
            self._route(frame, self._clock.now_s())

    def _route(self, frame: Any, now_s: float) -> None:
        active = {log.spec.kind: log for log in self._schedule.active(CAMERA_FAULTS, now_s)}
        if self._held is not None and "camera_reorder" not in active:
            self._deliver(now_s, self._held)  # the swap ends: the held frame goes first
            self._held = None
        if not active:
            self._last_good = frame
            for log in self._schedule.of(CAMERA_FAULTS):
                if now_s < log.start_s:
                    log.last_good_stamp_s = frame.stamp_s
            self._deliver(now_s, frame)
            return
        if "camera_drop" in active:
            active["camera_drop"].effect(now_s)
            return
        if "camera_freeze" in active and self._last_good is not None:
            active["camera_freeze"].effect(now_s)
            frozen = replace(self._last_good, stamp_s=frame.stamp_s, sequence=frame.sequence)
            self._deliver(now_s, frozen)
            return
        if "camera_delay" in active:
            log = active["camera_delay"]
            log.effect(now_s)
            self._deliver(now_s + log.spec.delay_s, frame)
            return
        if "camera_reorder" in active:
            log = active["camera_reorder"]
            if self._held is None:
                self._held = frame  # wait for the next frame, then deliver both swapped
                return
            log.effect(now_s)
            self._deliver(now_s, frame)
            self._deliver(now_s, self._held)
            self._held = None
            return
        self._deliver(now_s, frame)


# ---------------------------------------------------------------------------- the MAVLink path

_HEARTBEAT = 0
_PX4_OFFBOARD_MAIN_MODE = 6  # PX4's custom_mode main mode (bits 16-23) for offboard
_LOCAL_POSITION_NED = 32
_SET_POSITION_TARGET_LOCAL_NED = 84
_POSITION_IGNORED = 0b111  # type_mask bits: x, y, z ignored


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class MavlinkRelay:
    """A UDP relay between the vehicle (which sends to `port`) and the companion (listening
    on `link_port`), applying the link_loss and pose_jump faults of a `FaultSchedule`.

    A thread forwards datagrams both ways; during a link loss it drops them. After a pose
    jump it adds `jump_ned_m` to every LOCAL_POSITION_NED the vehicle sends and takes it off
    the position of every SET_POSITION_TARGET_LOCAL_NED the companion sends.
    """

    def __init__(self, link_port: int, schedule: FaultSchedule) -> None:
        from pymavlink.dialects.v20 import common

        self._mavlink = common
        self.link_port = link_port
        self.port = _free_port()
        self._schedule = schedule
        self._stop = threading.Event()
        self._vehicle_side = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._vehicle_side.bind(("127.0.0.1", self.port))
        self._link_side = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._link_side.bind(("127.0.0.1", 0))
        self._vehicle_address: tuple[str, int] | None = None
        self._thread = threading.Thread(target=self._run, name="mavlink-relay", daemon=True)
        self.dropped = 0
        self.offboard_changes: list[tuple[float, bool]] = []  # the vehicle's HEARTBEATs, seen

    def start(self) -> MavlinkRelay:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._vehicle_side.close()
        self._link_side.close()

    def _run(self) -> None:
        sockets = [self._vehicle_side, self._link_side]
        while not self._stop.is_set():
            readable, _, _ = select.select(sockets, [], [], 0.05)
            for sock in readable:
                try:
                    data, address = sock.recvfrom(65536)
                except OSError:
                    return
                now_s = self._schedule.now_s()
                if sock is self._vehicle_side:
                    self._vehicle_address = address
                    out = self._from_vehicle(data, now_s)
                    target, via = ("127.0.0.1", self.link_port), self._link_side
                else:
                    out = self._from_link(data, now_s)
                    target, via = self._vehicle_address, self._vehicle_side
                if out is None or target is None:
                    continue
                with contextlib.suppress(OSError):
                    via.sendto(out, target)

    def _lost(self, now_s: float) -> bool:
        lost = self._schedule.active({"link_loss"}, now_s)
        for log in lost:
            log.effect(now_s)
        if not lost:
            for log in self._schedule.of({"link_loss"}):
                if now_s < log.start_s:
                    log.last_good_stamp_s = now_s
        return bool(lost)

    def _jump(self, now_s: float) -> tuple[float, float, float] | None:
        for log in self._schedule.of({"pose_jump"}):
            if log.start_s <= now_s:
                return log.spec.jump_ned_m
        return None

    def _from_vehicle(self, data: bytes, now_s: float) -> bytes | None:
        if _message_id(data) == _HEARTBEAT:
            msg = self._parse(data)
            if msg is not None and msg.get_srcComponent() == 1:
                offboard = (msg.custom_mode >> 16) & 0xFF == _PX4_OFFBOARD_MAIN_MODE
                if not self.offboard_changes or self.offboard_changes[-1][1] != offboard:
                    self.offboard_changes.append((now_s, offboard))
        if self._lost(now_s):
            self.dropped += 1
            return None
        jump = self._jump(now_s)
        if jump is None or _message_id(data) != _LOCAL_POSITION_NED:
            return data
        msg = self._parse(data)
        if msg is None:
            return data
        for log in self._schedule.of({"pose_jump"}):
            log.effect(now_s)
        msg.x, msg.y, msg.z = msg.x + jump[0], msg.y + jump[1], msg.z + jump[2]
        return self._pack(msg)

    def _from_link(self, data: bytes, now_s: float) -> bytes | None:
        if self._lost(now_s):
            self.dropped += 1
            return None
        jump = self._jump(now_s)
        if jump is None or _message_id(data) != _SET_POSITION_TARGET_LOCAL_NED:
            return data
        msg = self._parse(data)
        if msg is None or msg.type_mask & _POSITION_IGNORED == _POSITION_IGNORED:
            return data
        msg.x, msg.y, msg.z = msg.x - jump[0], msg.y - jump[1], msg.z - jump[2]
        return self._pack(msg)

    def _parse(self, data: bytes) -> Any:
        parser = self._mavlink.MAVLink(None)
        try:
            messages = parser.parse_buffer(data)
        except Exception:
            return None
        return messages[0] if messages and len(messages) == 1 else None

    def _pack(self, msg: Any) -> bytes:
        mav = self._mavlink.MAVLink(None, msg.get_srcSystem(), msg.get_srcComponent())
        mav.seq = msg.get_seq()
        return msg.pack(mav)


def _message_id(data: bytes) -> int | None:
    """The message id of a datagram holding one unsigned MAVLink 2 frame, else None."""
    if len(data) < 12 or data[0] != 0xFD or data[2] & 0x01:
        return None
    if len(data) != 12 + data[1]:
        return None
    return int.from_bytes(data[7:10], "little")


# ---------------------------------------------------------------------------- the machine


class CpuHog:
    """`processes` busy Python processes while a cpu_hog fault is active (checked each tick)."""

    def __init__(self, schedule: FaultSchedule) -> None:
        self._schedule = schedule
        self._children: list[subprocess.Popen[bytes]] = []

    def tick(self) -> None:
        """Start or stop the hog processes for the current time."""
        active = self._schedule.active({"cpu_hog"})
        if active and not self._children:
            log = active[0]
            log.effect(self._schedule.now_s())
            self._children = [
                subprocess.Popen([sys.executable, "-c", "while True: pass"])
                for _ in range(log.spec.processes)
            ]
        elif not active and self._children:
            self.stop()

    def stop(self) -> None:
        """End the hog processes (by their ids)."""
        for child in self._children:
            child.terminate()
        for child in self._children:
            with contextlib.suppress(subprocess.TimeoutExpired):
                child.wait(timeout=2.0)
        self._children = []


class BrokerRestart:
    """**mqtt_restart**: the broker is stopped when the fault begins and started again on the
    same port when it ends (checked each `tick`).

    broker: duck-typed `stop()` and `start()`, blocking (`hil.broker.Mosquitto`); they run on a
    worker thread so the flight's event loop (and simulated time) goes on meanwhile. The log's
    `first_effect_s` is when the broker began to stop, `cleared_s` when it listened again.
    """

    def __init__(self, schedule: FaultSchedule, broker: Any) -> None:
        self._schedule = schedule
        self._broker = broker
        self._down: FaultLog | None = None

    async def tick(self) -> None:
        """Stop or start the broker for the current time."""
        active = self._schedule.active({"mqtt_restart"})
        if active and self._down is None:
            log = active[0]
            log.effect(self._schedule.now_s())
            self._down = log
            await asyncio.to_thread(self._broker.stop)
        elif not active and self._down is not None:
            await asyncio.to_thread(self._broker.start)
            self._down.cleared_s = self._schedule.now_s()
            self._down = None
