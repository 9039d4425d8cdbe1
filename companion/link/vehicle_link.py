"""The flight link to PX4 through MAVSDK 4 (in-process C library): telemetry, commands, offboard.

Data flow: MAVSDK telemetry streams -> `TelemetryCache` -> `TelemetrySnapshot` (typed,
monotonic stamps). The planner publishes `Setpoint`s into `link.setpoints`; while offboard is
engaged a streamer task sends the latest one at `setpoint_rate_hz`, judged by the
`SetpointWatchdog` (stale plan: brake, then Hold). A supervisor task watches the telemetry age:
on loss it forgets the vehicle state, waits for MAVSDK to recover the link by itself, and
rebuilds the MAVSDK instance when it does not. MAVSDK runs as a companion computer (onboard
controller), so its heartbeat lets PX4 detect our death (COM_OBC_LOSS_T).

Background tasks never let an exception escape: they log it, record a `LinkEvent` and go on.
Commands raise `LinkError` with a readable reason; the caller (mission) decides what to do.
Frames: NED from the autopilot's local origin (m, m/s); yaw in NED, rad (0 north, clockwise).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections import deque
from collections.abc import Awaitable, Callable, Coroutine, Iterable
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np

from companion.clock import Clock, WallClock, wait_or_timeout
from companion.link.calls import MavsdkCalls, returned_within
from companion.link.events import arming_report_detail, event_detail
from companion.link.parameters import read_parameters
from companion.link.params import LinkParams
from companion.link.setpoints import SetpointSource
from companion.link.telemetry import (
    FlightMode,
    Health,
    LandedState,
    TelemetryCache,
    TelemetrySnapshot,
)
from companion.link.watchdog import SetpointWatchdog, WatchdogAction
from companion.rate import RateKeeper
from planning.types import Setpoint, SetpointKind

log = logging.getLogger(__name__)

_SUPERVISE_RATE_HZ = 10.0  # how often the link health is checked; well above 1/link_loss


_mavsdk_log_routed = False


def route_mavsdk_logs() -> None:
    """Send MAVSDK's C++ log lines to Python logging (logger `mavsdk`) instead of stdout."""
    global _mavsdk_log_routed
    if _mavsdk_log_routed:
        return
    from mavsdk import LogLevel, log_subscribe

    mavsdk_log = logging.getLogger("mavsdk")
    levels = {
        LogLevel.DEBUG: logging.DEBUG,
        LogLevel.INFO: logging.INFO,
        LogLevel.WARN: logging.WARNING,
        LogLevel.ERROR: logging.ERROR,
    }

    def forward(level: LogLevel, message: str, file: str | None, line: int) -> bool:
        mavsdk_log.log(levels.get(level, logging.INFO), "%s", message)
        return True  # suppress MAVSDK's own printing

    log_subscribe(forward)
    _mavsdk_log_routed = True


EVENT_HISTORY = 1000  # LinkEvents kept in `VehicleLink.events`


class LinkError(RuntimeError):
    """A link operation failed; the message says why."""


class LinkDownError(LinkError):
    """A command was refused locally: the link is not connected (lost, failed or closed)."""


class LinkState(Enum):
    """Where the link stands."""

    DISCONNECTED = "disconnected"  # before connect()
    CONNECTED = "connected"  # telemetry fresh
    LOST = "lost"  # telemetry stale; recovering
    FAILED = "failed"  # gave up rebuilding (reconnect_max_attempts)
    CLOSED = "closed"  # after close()


class LinkEventKind(Enum):
    """What a `LinkEvent` reports."""

    CONNECTED = "connected"
    LINK_LOST = "link_lost"
    RECONNECTED = "reconnected"
    REBUILT = "rebuilt"
    REBUILD_FAILED = "rebuild_failed"
    ARM_DENIED = "arm_denied"
    OFFBOARD_STARTED = "offboard_started"
    OFFBOARD_RETRY = "offboard_retry"
    OFFBOARD_LOST = "offboard_lost"
    OFFBOARD_STOPPED = "offboard_stopped"
    WATCHDOG_BRAKE = "watchdog_brake"
    WATCHDOG_HOLD = "watchdog_hold"
    VEHICLE_TEXT = "vehicle_text"  # a STATUSTEXT from the autopilot: "severity: text"
    VEHICLE_EVENT = "vehicle_event"  # a PX4 event: "level: message (namespace/name)"
    ARMING_CHECK = "arming_check"  # PX4's health/arming report, when it changes
    ERROR = "error"


@dataclass(frozen=True)
class LinkEvent:
    """Something the link did or saw, at `stamp_s` (monotonic, s)."""

    stamp_s: float
    kind: LinkEventKind
    detail: str


class VehicleLink:
    """Async MAVSDK link to one PX4 autopilot. No I/O until `await connect()`.

    `clock` gives the time all stamps use and paces every wait (setpoints published into
    `setpoints` must be stamped with `link.now_s()`); the wall clock by default.
    """

    def __init__(self, params: LinkParams, *, clock: Clock | None = None):
        self.params = params
        self.clock: Clock = WallClock() if clock is None else clock
        self.now_s = self.clock.now_s
        self.setpoints = SetpointSource()
        self.watchdog = SetpointWatchdog(
            params.setpoint_max_age_s, params.brake_timeout_s, params.brake_speed_mps
        )
        # Bounded: the service runs for hours; the newest events are the ones worth keeping.
        self.events: deque[LinkEvent] = deque(maxlen=EVENT_HISTORY)
        self.state = LinkState.DISCONNECTED
        self.setpoints_sent = 0
        self._cache = TelemetryCache()
        self._updated = asyncio.Event()
        self._mavsdk: Any = None
        self._connection: Any = None  # the handle of MAVSDK's connection to the vehicle
        self._system: Any = None
        self._action: Any = None
        self._offboard: Any = None
        self._telemetry: Any = None
        self._events: Any = None
        self._arming_report = ""
        self._connection_tasks: set[asyncio.Task[None]] = set()
        self._calls = MavsdkCalls()
        self._supervisor: asyncio.Task[None] | None = None
        self._streamer: asyncio.Task[None] | None = None
        self._stream_keeper: RateKeeper | None = None
        self._offboard_engaged = False
        self._engaged_since_s = math.nan
        self._lost_since_s = math.nan
        self._opened_at_s = -math.inf

    # ------------------------------------------------------------------ lifecycle

    async def connect(self) -> None:
        """Open the connection, find the autopilot and start telemetry and supervision.

        Raises `LinkError` when no autopilot is heard within `connect_timeout_s`.
        """
        if self.state is not LinkState.DISCONNECTED:
            raise LinkError(f"connect() on a link that is {self.state.value}")
        await self._open(self.params.connect_timeout_s)
        self.state = LinkState.CONNECTED
        self._event(LinkEventKind.CONNECTED, self.params.connection_url)
        self._supervisor = asyncio.create_task(self._supervise(), name="link-supervisor")

    async def close(self) -> None:
        """Stop streaming and supervision and release MAVSDK. Idempotent."""
        if self.state is LinkState.CLOSED:
            return
        self.state = LinkState.CLOSED
        self._offboard_engaged = False
        await self._stop_streaming()
        # The supervisor may be mid-rebuild inside a MAVSDK call running in a thread: let it
        # finish (bounded by the rebuild's own timeout) rather than destroy MAVSDK under it.
        supervisor, self._supervisor = self._supervisor, None
        if supervisor is not None:
            try:
                await asyncio.wait_for(
                    asyncio.shield(supervisor), self.params.reconnect_interval_s + 2.0
                )
            except TimeoutError:
                supervisor.cancel()
            except Exception as e:
                self._error(f"supervisor ended with {e!r}")
        await self._close_connection()

    async def __aenter__(self) -> VehicleLink:
        await self.connect()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def _open(self, timeout_s: float) -> None:
        """Create the MAVSDK instance, add the connection and wait for the autopilot."""
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk, MavsdkError
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.events import EventsAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        route_mavsdk_logs()
        # A companion computer: MAVSDK always sends a MAV_TYPE_ONBOARD_CONTROLLER heartbeat
        # (component 195), which PX4 watches for COM_OBC_LOSS_T.
        config = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
        self._mavsdk = Mavsdk(config)
        try:
            self._connection = await self._calls.call(
                self._mavsdk.add_any_connection(self.params.connection_url)
            )
            system = await self._mavsdk.first_autopilot(timeout_s=timeout_s)
        except MavsdkError as e:
            await self._close_connection()
            raise LinkError(f"cannot open {self.params.connection_url}: {e}") from e
        if system is None:
            await self._close_connection()
            raise LinkError(
                f"no autopilot heard on {self.params.connection_url} within {timeout_s:.1f} s"
            )
        self._system = system
        self._action = ActionAsync(system)
        self._offboard = OffboardAsync(system)
        self._telemetry = TelemetryAsync(system)
        self._events = EventsAsync(system)
        self._opened_at_s = self.now_s()
        self._start_subscriptions()
        self._spawn(self._request_rates(), "link-rates")

    async def _close_connection(self) -> None:
        """Cancel this connection's tasks and destroy the MAVSDK instance."""
        tasks = list(self._connection_tasks)
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._connection_tasks.clear()
        still_running = await self._calls.drained(self.params.call_drain_timeout_s)
        if still_running:
            self._error(
                f"{still_running} MAVSDK call(s) still running after "
                f"{self.params.call_drain_timeout_s:.1f} s; destroying MAVSDK under them"
            )
        plugins = [self._action, self._offboard, self._telemetry, self._events]
        mavsdk, connection = self._mavsdk, self._connection
        self._action = self._offboard = self._telemetry = self._events = self._system = None
        self._mavsdk = self._connection = None
        if mavsdk is None:
            return
        # Stop receiving before the plugins go: MAVSDK's events plugin deadlocks when destroyed
        # while its receive thread hands it an event (its deinit waits for that handler, the
        # handler for the lock deinit holds), and then the process cannot exit either.
        if connection is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(
                    self._calls.call(mavsdk.remove_connection(connection)),
                    self.params.call_drain_timeout_s,
                )

        def release() -> None:
            for plugin in plugins:
                if plugin is not None:
                    with contextlib.suppress(Exception):
                        plugin.destroy()
            mavsdk.destroy()

        if not await returned_within(release, self.params.call_drain_timeout_s, "mavsdk-release"):
            self._error(
                f"MAVSDK not released within {self.params.call_drain_timeout_s:.1f} s; "
                "left to its thread"
            )

    def _spawn(self, coro: Coroutine[Any, Any, None], name: str) -> None:
        task = asyncio.create_task(coro, name=name)
        self._connection_tasks.add(task)
        task.add_done_callback(self._connection_tasks.discard)

    # ------------------------------------------------------------------ telemetry

    def telemetry(self) -> TelemetrySnapshot:
        """The current telemetry snapshot."""
        return self._cache.snapshot(self.now_s())

    @property
    def offboard_engaged(self) -> bool:
        """Whether offboard was confirmed by the vehicle and our streamer is in control."""
        return self._offboard_engaged

    async def wait_until(
        self,
        predicate: Callable[[TelemetrySnapshot], bool],
        timeout_s: float,
        what: str,
    ) -> TelemetrySnapshot:
        """The first snapshot satisfying `predicate`; `LinkError` naming `what` on timeout."""
        deadline_s = self.now_s() + timeout_s
        while True:
            snap = self.telemetry()
            if predicate(snap):
                return snap
            remaining_s = deadline_s - self.now_s()
            if remaining_s <= 0:
                raise LinkError(f"timed out after {timeout_s:.1f} s waiting for {what}")
            await wait_or_timeout(self.clock, self._updated.wait(), remaining_s)

    async def wait_healthy(self) -> TelemetrySnapshot:
        """Wait until the vehicle reports local position, home and armable (`health_timeout_s`)."""
        try:
            return await self.wait_until(
                lambda s: s.pose is not None and s.health is not None and s.health.ready_to_fly,
                self.params.health_timeout_s,
                "vehicle health",
            )
        except LinkError as e:
            raise LinkError(f"{e}; last health: {self.telemetry().health}") from e

    def _notify(self) -> None:
        self._updated.set()
        self._updated = asyncio.Event()

    def _start_subscriptions(self) -> None:
        tel = self._telemetry
        cache = self._cache
        deg = math.radians

        def pose(pv: Any) -> None:
            p, v = pv.position, pv.velocity
            cache.update_pose(
                np.array([p.north_m, p.east_m, p.down_m]),
                np.array([v.north_m_s, v.east_m_s, v.down_m_s]),
                self.now_s(),
            )

        def attitude(a: Any) -> None:
            cache.update_attitude(deg(a.roll_deg), deg(a.pitch_deg), deg(a.yaw_deg), self.now_s())

        def health(h: Any) -> None:
            cache.update_health(
                Health(
                    local_position_ok=h.is_local_position_ok,
                    global_position_ok=h.is_global_position_ok,
                    home_position_ok=h.is_home_position_ok,
                    armable=h.is_armable,
                    sensors_calibrated=h.is_gyrometer_calibration_ok
                    and h.is_accelerometer_calibration_ok,
                    stamp_s=self.now_s(),
                ),
                self.now_s(),
            )

        streams: list[tuple[str, Callable[[], Any], Callable[[Any], None]]] = [
            ("pose", tel.subscribe_position_velocity_ned, pose),
            ("attitude", tel.subscribe_attitude_euler, attitude),
            (
                "flight_mode",
                tel.subscribe_flight_mode,
                lambda m: cache.update_flight_mode(FlightMode.from_name(m.name), self.now_s()),
            ),
            ("armed", tel.subscribe_armed, lambda a: cache.update_armed(a, self.now_s())),
            (
                "landed_state",
                tel.subscribe_landed_state,
                lambda s: cache.update_landed_state(LandedState.from_name(s.name), self.now_s()),
            ),
            (
                "battery",
                tel.subscribe_battery,
                lambda b: cache.update_battery(
                    b.voltage_v, b.remaining_percent / 100.0, self.now_s()
                ),
            ),
            ("health", tel.subscribe_health, health),
            (
                "home",
                tel.subscribe_home,
                lambda h: cache.update_home(
                    h.latitude_deg,
                    h.longitude_deg,
                    h.absolute_altitude_m,
                    np.array([h.local_north_m, h.local_east_m, h.local_down_m]),
                    self.now_s(),
                ),
            ),
            ("status_text", tel.subscribe_status_text, self._vehicle_text),
            # PX4 reports most of it as events, not STATUSTEXT (companion.link.events)
            ("events", self._events.subscribe_events, self._vehicle_event),
            (
                "arming_checks",
                self._events.subscribe_health_and_arming_checks,
                self._arming_check,
            ),
        ]
        for name, subscribe, handle in streams:
            self._spawn(self._subscription(name, subscribe, handle), f"link-sub-{name}")

    def _vehicle_event(self, event: Any) -> None:
        self._event(LinkEventKind.VEHICLE_EVENT, event_detail(event))

    def _arming_check(self, report: Any) -> None:
        detail = arming_report_detail(report)
        if detail != self._arming_report:
            self._arming_report = detail
            self._event(LinkEventKind.ARMING_CHECK, detail)

    def _vehicle_text(self, status: Any) -> None:
        """PX4's STATUSTEXT (mode changes, denials, failsafes) as an event "severity: text"."""
        self._event(LinkEventKind.VEHICLE_TEXT, f"{status.type.name.lower()}: {status.text}")

    async def _subscription(
        self, name: str, subscribe: Callable[[], Any], handle: Callable[[Any], None]
    ) -> None:
        """Feed one MAVSDK stream into the cache; resubscribe after any error."""
        while True:
            try:
                async for item in subscribe():
                    handle(item)
                    self._notify()
            except asyncio.CancelledError:
                raise
            except Exception as e:
                self._error(f"telemetry stream {name}: {e!r}")
                await self.clock.sleep(self.params.reconnect_interval_s)

    async def _request_rates(self) -> None:
        """Ask for pose/attitude at `telemetry_rate_hz` (best effort: PX4 may refuse)."""
        rate_hz = self.params.telemetry_rate_hz
        tel = self._telemetry
        for name, setter in (
            ("position_velocity_ned", tel.set_rate_position_velocity_ned),
            ("attitude_euler", tel.set_rate_attitude_euler),
        ):
            try:
                await setter(rate_hz)
            except Exception as e:
                log.info("rate request %s at %.0f Hz not accepted: %r", name, rate_hz, e)

    # ------------------------------------------------------------------ supervision

    async def _supervise(self) -> None:
        """Detect link loss from the telemetry age; recover softly, then rebuild."""
        keeper = RateKeeper(_SUPERVISE_RATE_HZ, clock=self.now_s, sleep=self.clock.sleep)
        attempts = 0
        while self.state not in (LinkState.CLOSED, LinkState.FAILED):
            try:
                now_s = self.now_s()
                # Silence counts from the (re)connection, not from the last message ever.
                last_s = self.telemetry().last_update_s
                age_s = now_s - max(self._opened_at_s, -math.inf if last_s is None else last_s)
                if self.state is LinkState.CONNECTED and age_s > self.params.link_loss_timeout_s:
                    self._on_link_lost(age_s)
                elif self.state is LinkState.LOST and age_s <= self.params.link_loss_timeout_s:
                    self.state = LinkState.CONNECTED
                    attempts = 0
                    self._event(
                        LinkEventKind.RECONNECTED,
                        f"telemetry back after {now_s - self._lost_since_s:.1f} s",
                    )
                    self._spawn(self._request_rates(), "link-rates")
                elif (
                    self.state is LinkState.LOST
                    and now_s - self._lost_since_s > self.params.reconnect_soft_s
                ):
                    attempts += 1
                    await self._rebuild(attempts)
            except asyncio.CancelledError:
                raise
            except Exception as e:
                self._error(f"supervisor: {e!r}")
            await keeper.wait()

    def _on_link_lost(self, age_s: float) -> None:
        self.state = LinkState.LOST
        self._lost_since_s = self.now_s()
        self._cache.clear()
        self._notify()
        self._event(LinkEventKind.LINK_LOST, f"no telemetry for {age_s:.1f} s")
        if self._offboard_engaged:
            self._disengage("link lost; the vehicle's offboard-loss failsafe takes over")

    async def _rebuild(self, attempt: int) -> None:
        """Tear the MAVSDK instance down and connect again (one attempt)."""
        limit = self.params.reconnect_max_attempts
        log.warning("rebuilding the link, attempt %d", attempt)
        await self._close_connection()
        try:
            await self._open(self.params.reconnect_interval_s)
        except LinkError as e:
            self._event(LinkEventKind.REBUILD_FAILED, f"attempt {attempt}: {e}")
            if limit and attempt >= limit:
                self.state = LinkState.FAILED
            return
        self._cache.clear()
        self._event(LinkEventKind.REBUILT, f"new MAVSDK instance after attempt {attempt}")

    # ------------------------------------------------------------------ commands

    async def _command(self, what: str, call: Callable[[], Awaitable[Any]]) -> Any:
        """Run one MAVSDK command; any MAVSDK failure becomes a `LinkError`."""
        if self._action is None or self.state is not LinkState.CONNECTED:
            raise LinkDownError(f"{what}: link is {self.state.value}")
        try:
            return await self._calls.call(call())
        except Exception as e:
            raise LinkError(f"{what} failed: {e}") from e

    async def arm(self) -> None:
        """Arm, retrying while PX4 denies it (e.g. in the first seconds after boot)."""
        p = self.params
        last_error = ""
        for attempt in range(1, p.arm_attempts + 1):
            if self.telemetry().armed:
                return
            try:
                await self._command("arm", lambda: self._action.arm())
                await self.wait_until(lambda s: bool(s.armed), p.arm_confirm_timeout_s, "armed")
                return
            except LinkDownError:
                raise
            except LinkError as e:
                last_error = str(e)
                self._event(LinkEventKind.ARM_DENIED, f"attempt {attempt}: {e}")
                await self.clock.sleep(p.arm_retry_interval_s)
        raise LinkError(f"arming failed after {p.arm_attempts} attempts: {last_error}")

    async def takeoff(self, altitude_m: float | None = None) -> TelemetrySnapshot:
        """Take off to `altitude_m` (default `takeoff_altitude_m`) and wait for Hold there.

        Waiting for PX4's own end-of-takeoff switch to Hold is what keeps that switch from
        racing a following offboard request.
        """
        p = self.params
        target_m = p.takeoff_altitude_m if altitude_m is None else altitude_m
        try:
            await self._command(
                "set takeoff altitude", lambda: self._action.set_takeoff_altitude(target_m)
            )
        except LinkDownError:
            raise
        except LinkError as e:
            # The autopilot keeps its own MIS_TAKEOFF_ALT: fly to that, and say so.
            target_m = float(
                await self._command(
                    "get takeoff altitude", lambda: self._action.get_takeoff_altitude()
                )
            )
            self._error(f"{e}; taking off to the vehicle's {target_m:.1f} m instead")
        requested_s = self.now_s()
        # PX4 climbs to MIS_TAKEOFF_ALT above home, where it armed; its local origin is not
        # there (the estimate reads -0.5..+0.5 m on the ground), so measure from the ground
        before = self.telemetry()
        ground_m = (
            before.pose.altitude_m
            if before.pose is not None and before.landed_state is LandedState.ON_GROUND
            else 0.0
        )
        await self._command("takeoff", lambda: self._action.takeoff())
        in_hold = _mode_reported_after(FlightMode.HOLD, requested_s)

        def done(s: TelemetrySnapshot) -> bool:
            return (
                s.pose is not None
                and in_hold(s)
                and abs(s.pose.altitude_m - ground_m - target_m) < p.altitude_tolerance_m
            )

        return await self.wait_until(done, p.takeoff_timeout_s, f"Hold at {target_m:.1f} m")

    async def land(self) -> TelemetrySnapshot:
        """Land where it is and wait until disarmed on the ground (PX4 auto-disarms)."""
        await self._leave_offboard()
        await self._command("land", lambda: self._action.land())
        return await self.wait_until(
            lambda s: s.armed is False, self.params.land_timeout_s, "touchdown and disarm"
        )

    async def return_to_launch(self) -> None:
        """Switch to Return (RTL): PX4 flies home and lands."""
        await self._leave_offboard()
        await self._command("return to launch", lambda: self._action.return_to_launch())

    async def hold(self) -> None:
        """Switch to Hold (loiter at the current position)."""
        if self._offboard_engaged:
            await self.stop_offboard()
        else:
            await self._command("hold", lambda: self._action.hold())

    async def read_parameters(self, names: Iterable[str]) -> dict[str, float | int | None]:
        """The autopilot's parameters by name (None: it has no such parameter); for the
        pre-flight failsafe check and the planner's limits (companion.link.preflight,
        companion.link.px4_limits)."""
        if self._system is None or self.state is not LinkState.CONNECTED:
            raise LinkDownError(f"read parameters: link is {self.state.value}")
        return await read_parameters(
            self._system, names, self._calls, self.params.call_drain_timeout_s
        )

    async def _leave_offboard(self) -> None:
        """Before another mode: stop streaming and MAVSDK's re-sending, without waiting."""
        try:
            await self.stop_offboard(confirm_hold=False)
        except LinkError as e:
            self._error(str(e))

    # ------------------------------------------------------------------ offboard

    async def start_offboard(self, initial: Setpoint) -> None:
        """Enter offboard with `initial` as the first setpoint; confirmed by the flight mode.

        Streams setpoints for `offboard_prestream_s` first (PX4 refuses offboard without a
        recent one), requests offboard, then waits up to `offboard_confirm_timeout_s` for a
        heartbeat *after the request* to report OFFBOARD, and `offboard_settle_s` more to see
        it stay (PX4's end-of-takeoff Hold can land just after the switch). `offboard.start()`
        succeeds even when that Hold wins and `offboard.is_active()` is true as soon as a
        setpoint is set, so neither is trusted. Retries `offboard_attempts` times.
        """
        p = self.params
        self.setpoints.publish(initial)
        self._ensure_streaming()
        last_error = ""
        for attempt in range(1, p.offboard_attempts + 1):
            await self.clock.sleep(p.offboard_prestream_s)
            requested_s = self.now_s()
            try:
                await self._command("offboard start", lambda: self._offboard.start())
                await self.wait_until(
                    _mode_reported_after(FlightMode.OFFBOARD, requested_s),
                    p.offboard_confirm_timeout_s,
                    "flight mode OFFBOARD",
                )
                await self.clock.sleep(p.offboard_settle_s)
                snap = self.telemetry()
                if snap.flight_mode is not FlightMode.OFFBOARD:
                    raise LinkError(f"OFFBOARD reverted within {p.offboard_settle_s:.1f} s")
            except LinkDownError:
                await self._stop_streaming()
                raise
            except LinkError as e:
                last_error = f"{e}; mode {self.telemetry().flight_mode.value}"
                self._event(LinkEventKind.OFFBOARD_RETRY, f"attempt {attempt}: {last_error}")
                continue
            self._offboard_engaged = True
            self._engaged_since_s = snap.stamp_s
            self.watchdog.rearm(snap.stamp_s)
            self._event(LinkEventKind.OFFBOARD_STARTED, f"confirmed on attempt {attempt}")
            return
        await self._stop_streaming()
        raise LinkError(f"offboard not entered after {p.offboard_attempts} attempts: {last_error}")

    async def stop_offboard(self, *, confirm_hold: bool = True) -> None:
        """Stop streaming and leave offboard for Hold (which also ends MAVSDK's re-sending).

        With `confirm_hold`, wait until the heartbeat reports HOLD. A no-op when offboard is
        not engaged (never entered, or already left by the watchdog or the vehicle).
        """
        was_engaged = self._offboard_engaged
        self._offboard_engaged = False
        await self._stop_streaming()
        if not was_engaged:
            return
        requested_s = self.now_s()
        await self._command("offboard stop", lambda: self._offboard.stop())
        self._event(LinkEventKind.OFFBOARD_STOPPED, "switched to Hold")
        if confirm_hold:
            await self.wait_until(
                _mode_reported_after(FlightMode.HOLD, requested_s),
                self.params.offboard_confirm_timeout_s,
                "flight mode HOLD",
            )

    def _disengage(self, reason: str) -> None:
        self._offboard_engaged = False
        self._event(LinkEventKind.OFFBOARD_LOST, reason)
        self._streamer = None  # the streamer ends its own loop

    def _ensure_streaming(self) -> None:
        if self._streamer is None or self._streamer.done():
            self._streamer = asyncio.create_task(self._stream(), name="link-streamer")

    async def _stop_streaming(self) -> None:
        """End the streamer after its current tick (a send cut short could land after a stop)."""
        task, self._streamer = self._streamer, None
        if task is None or task is asyncio.current_task():
            return
        try:
            await asyncio.wait_for(asyncio.shield(task), 1.0)
        except TimeoutError:
            task.cancel()
        except Exception as e:
            self._error(f"setpoint streamer ended with {e!r}")

    @property
    def stream_max_lag_s(self) -> float:
        """The largest lag of the setpoint streamer's ticks so far, s."""
        return 0.0 if self._stream_keeper is None else self._stream_keeper.max_lag_s

    async def _stream(self) -> None:
        """Send the latest setpoint at `setpoint_rate_hz`, guarded by the watchdog; a setpoint
        published between ticks is sent at once (the tick grid stays where it is)."""
        keeper = RateKeeper(
            self.params.setpoint_rate_hz, clock=self.now_s, sleep=self._sleep_sending_new
        )
        self._stream_keeper = keeper
        me = asyncio.current_task()
        while self._streamer is me:
            try:
                if not await self._stream_tick():
                    break
            except asyncio.CancelledError:
                raise
            except Exception as e:
                self._error(f"setpoint streamer: {e!r}")
            await keeper.wait()
        if self._streamer is me:
            self._streamer = None

    async def _sleep_sending_new(self, duration_s: float) -> None:
        """Sleep `duration_s`, sending every fresh, valid setpoint published meanwhile at once."""
        deadline_s = self.now_s() + duration_s
        while (remaining_s := deadline_s - self.now_s()) > 0:
            if not await wait_or_timeout(self.clock, self.setpoints.wait_new(), remaining_s):
                return
            setpoint = self.setpoints.latest()
            if (
                self._offboard_engaged
                and self.watchdog.action is WatchdogAction.STREAM
                and setpoint is not None
                and setpoint.valid
                and setpoint.age_s(self.now_s()) <= self.params.setpoint_max_age_s
            ):
                snap = self.telemetry()
                yaw_rad = snap.attitude.yaw_rad if snap.attitude is not None else 0.0
                try:
                    await self._send(setpoint.with_yaw(yaw_rad))
                except Exception as e:
                    self._error(f"setpoint streamer: {e!r}")

    async def _stream_tick(self) -> bool:
        """One streamer tick; False when streaming must end."""
        now_s = self.now_s()
        snap = self.telemetry()
        setpoint = self.setpoints.latest()
        yaw_rad = snap.attitude.yaw_rad if snap.attitude is not None else 0.0
        if not self._offboard_engaged:
            if setpoint is not None:  # pre-stream before the offboard request
                await self._send(setpoint.with_yaw(yaw_rad))
            return True
        if (
            snap.flight_mode_stamp_s is not None
            and snap.flight_mode_stamp_s > self._engaged_since_s
            and snap.flight_mode not in (FlightMode.OFFBOARD, FlightMode.UNKNOWN)
        ):
            self._disengage(f"vehicle left offboard for {snap.flight_mode.value}")
            return False
        speed_mps = snap.pose.speed_mps if snap.pose is not None else math.inf
        stamp_s = None if setpoint is None else setpoint.stamp_s
        valid = setpoint is not None and setpoint.valid
        previous = self.watchdog.action
        action = self.watchdog.update(now_s, stamp_s, speed_mps, valid)
        if action is not previous and self.watchdog.events:
            ev = self.watchdog.events[-1]
            kind = (
                LinkEventKind.WATCHDOG_BRAKE
                if action is WatchdogAction.BRAKE
                else LinkEventKind.WATCHDOG_HOLD
            )
            self._event(kind, ev.reason)
        if action is WatchdogAction.STREAM and setpoint is not None:
            await self._send(setpoint.with_yaw(yaw_rad))
        elif action is WatchdogAction.BRAKE:
            await self._send(Setpoint.brake(yaw_rad, now_s))
        elif action is WatchdogAction.HOLD:
            self._offboard_engaged = False
            await self._leave_offboard_for_hold()
            return False
        return True

    async def _leave_offboard_for_hold(self) -> None:
        """Stop MAVSDK's own setpoint resending and switch to Hold; Hold command as fallback."""
        try:
            await self._command("offboard stop (watchdog)", lambda: self._offboard.stop())
        except LinkError as e:
            self._error(f"{e}; commanding Hold instead")
            try:
                await self._command("hold (watchdog)", lambda: self._action.hold())
            except LinkError as e2:
                self._error(str(e2))

    async def _send(self, setpoint: Setpoint) -> None:
        from mavsdk.asyncio.plugins.offboard import AccelerationNed, PositionNedYaw, VelocityNedYaw

        yaw_deg = math.degrees(setpoint.yaw_rad)
        if setpoint.kind is SetpointKind.POSITION:
            n, e, d = (float(x) for x in setpoint.position_ned_m)
            await self._calls.call(
                self._offboard.set_position_ned(PositionNedYaw(n, e, d, yaw_deg))
            )
        elif setpoint.position_ned_m is not None:  # TRAJECTORY, or a BRAKE along its stop
            n, e, d = (float(x) for x in setpoint.position_ned_m)
            vn, ve, vd = (float(x) for x in setpoint.velocity_ned_mps)
            position = PositionNedYaw(n, e, d, yaw_deg)
            velocity = VelocityNedYaw(vn, ve, vd, yaw_deg)
            if setpoint.acceleration_ned_mps2 is None:
                await self._calls.call(self._offboard.set_position_velocity_ned(position, velocity))
            else:
                an, ae, ad = (float(x) for x in setpoint.acceleration_ned_mps2)
                acceleration = AccelerationNed(an, ae, ad)
                await self._calls.call(
                    self._offboard.set_position_velocity_acceleration_ned(
                        position, velocity, acceleration
                    )
                )
        else:  # VELOCITY and a BRAKE without a position fly the velocity
            n, e, d = (float(x) for x in setpoint.velocity_ned_mps)
            await self._calls.call(
                self._offboard.set_velocity_ned(VelocityNedYaw(n, e, d, yaw_deg))
            )
        self.setpoints_sent += 1

    # ------------------------------------------------------------------ reporting

    def _event(self, kind: LinkEventKind, detail: str) -> None:
        event = LinkEvent(self.now_s(), kind, detail)
        self.events.append(event)
        level = logging.WARNING if kind in _WARN_KINDS else logging.INFO
        log.log(level, "%s: %s", kind.value, detail)

    def _error(self, detail: str) -> None:
        self._event(LinkEventKind.ERROR, detail)

    def events_of(self, kind: LinkEventKind) -> list[LinkEvent]:
        """The events of one kind, oldest first."""
        return [e for e in self.events if e.kind is kind]


def _mode_reported_after(mode: FlightMode, after_s: float) -> Callable[[TelemetrySnapshot], bool]:
    """Predicate: the flight mode is `mode` in a heartbeat that arrived after `after_s`."""

    def reported(s: TelemetrySnapshot) -> bool:
        stamp_s = s.flight_mode_stamp_s
        return s.flight_mode is mode and stamp_s is not None and stamp_s > after_s

    return reported


_WARN_KINDS = frozenset(
    {
        LinkEventKind.LINK_LOST,
        LinkEventKind.REBUILD_FAILED,
        LinkEventKind.ARM_DENIED,
        LinkEventKind.OFFBOARD_RETRY,
        LinkEventKind.OFFBOARD_LOST,
        LinkEventKind.WATCHDOG_BRAKE,
        LinkEventKind.WATCHDOG_HOLD,
        LinkEventKind.ERROR,
    }
)
