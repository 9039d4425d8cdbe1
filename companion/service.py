"""The companion service: the process systemd starts at boot on the drone's Jetson.

It runs the whole flight process (`companion.flight.process.FlightProcess`: camera ingest,
wire CNN, DROAN, planner, tracker, the mission manager and, when `ground.broker_url` is set,
the ground link). It loads the wire CNN first, then opens the MAVSDK link (`VehicleLink`) and
keeps trying until an autopilot is heard, since PX4 may boot after us; while it waits it asks
systemd for more start-up time (EXTEND_TIMEOUT_USEC). Once connected it sends READY=1 and
starts the flight process. A supervision loop paced by a `RateKeeper` runs at `tick_rate_hz`.
Each tick builds a one-line status from the telemetry snapshot (link state, flight mode,
armed, landed state, NED position, battery, health, mission state) and sends it to systemd as
STATUS. The line is logged every `status_period_s`, and at once when the link state, mode,
armed, landed state, readiness or mission state changes; the stage timings are logged by the
process itself. The link logs its own `LinkEvent`s when they happen (logger
`companion.link.vehicle_link`), so they reach the journal in order with these lines. A
warning says when the vehicle is still not ready to fly after `link.health_timeout_s`.
WATCHDOG=1 is sent only on a tick that starts on time (lateness up to `watchdog_max_lag_s`)
while the flight process' mission loop is ticking too; it is never sent from a timer of its
own, so a stalled or starved process is restarted by systemd (WatchdogSec). A link that gave
up (`LinkState.FAILED`) ends the process with status 1 (Restart=on-failure). SIGTERM/SIGINT
send STOPPING=1, stop the flight process, close the link and exit 0.

The vehicle is commanded only by the mission: from the ground station's commands, or on its
own with `mission.auto_start` and configured goals; with neither it never arms.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import signal
from collections.abc import Awaitable, Callable, Iterator
from typing import TYPE_CHECKING

from companion.clock import finished_first
from companion.flight.process import FlightProcess
from companion.flight.vehicle_check import check_vehicle
from companion.ingest.frames import CameraSource
from companion.ingest.sources import camera_source
from companion.link.telemetry import Health, TelemetrySnapshot
from companion.link.vehicle_link import LinkError, LinkState, VehicleLink
from companion.mission import MissionState
from companion.rate import RateKeeper
from companion.record.writer import start_recording
from companion.service_params import ServiceParams
from companion.systemd_notify import SystemdNotifier, watchdog_interval_s

if TYPE_CHECKING:
    from companion.config import Settings

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------------- status (pure)


def status_line(
    state: LinkState, snap: TelemetrySnapshot, mission: MissionState | None = None
) -> str:
    """One line describing the link, the vehicle and the mission; `?` marks what was never
    received.

    Example: `link=connected mode=HOLD armed=no landed=ON_GROUND ned_m=0.00,0.00,-0.01
    battery=12.40V/87% health=ready age_s=0.03 mission=idle`. Position NED from the
    autopilot's local origin, m; `age_s` is the time since the last telemetry of any kind.
    """
    pose = snap.pose
    ned = "?" if pose is None else ",".join(f"{x:.2f}" for x in pose.position_ned_m)
    age_s = snap.age_s()
    return " ".join(
        (
            f"link={state.value}",
            f"mode={snap.flight_mode.value}",
            f"armed={_yes_no(snap.armed)}",
            f"landed={snap.landed_state.value}",
            f"ned_m={ned}",
            f"battery={_battery_text(snap)}",
            f"health={_health_text(snap.health)}",
            f"age_s={'?' if math.isinf(age_s) else f'{age_s:.2f}'}",
            *(() if mission is None else (f"mission={mission.value}",)),
        )
    )


def status_key(state: LinkState, snap: TelemetrySnapshot) -> tuple[object, ...]:
    """What makes a status line worth logging at once when it changes."""
    ready = None if snap.health is None else snap.health.ready_to_fly
    return state, snap.flight_mode, snap.armed, snap.landed_state, ready


class ReadinessWatch:
    """Says once per episode when the vehicle has not been ready to fly for over `timeout_s`.

    Pure: the caller passes `now_s` (monotonic, s). An episode starts at construction or when
    readiness is lost, and ends when the vehicle is ready again.
    """

    def __init__(self, timeout_s: float, now_s: float) -> None:
        self.timeout_s = timeout_s
        self._not_ready_since_s: float | None = now_s
        self._reported = False

    def overdue(self, ready: bool, now_s: float) -> bool:
        """True on the first call of an episode that is older than `timeout_s`."""
        if ready:
            self._not_ready_since_s, self._reported = None, False
            return False
        if self._not_ready_since_s is None:
            self._not_ready_since_s = now_s
        if self._reported or now_s - self._not_ready_since_s <= self.timeout_s:
            return False
        self._reported = True
        return True


def _yes_no(value: bool | None) -> str:
    return "?" if value is None else ("yes" if value else "no")


def _battery_text(snap: TelemetrySnapshot) -> str:
    b = snap.battery
    if b is None:
        return "?"
    volts = "?V" if math.isnan(b.voltage_v) else f"{b.voltage_v:.2f}V"
    percent = "?%" if math.isnan(b.remaining_frac) else f"{100.0 * b.remaining_frac:.0f}%"
    return f"{volts}/{percent}"


def _health_text(h: Health | None) -> str:
    """`ready`, or `not-ready(<failed checks>)`; `?` before the first report."""
    if h is None:
        return "?"
    if h.ready_to_fly:
        return "ready"
    failed = [
        name
        for name, ok in (
            ("local_position", h.local_position_ok),
            ("home", h.home_position_ok),
            ("armable", h.armable),
        )
        if not ok
    ]
    return f"not-ready({','.join(failed)})"


# ---------------------------------------------------------------------------- the process


async def run_service(
    settings: Settings,
    params: ServiceParams | None = None,
    *,
    notify: SystemdNotifier | None = None,
    stop: asyncio.Event | None = None,
    handle_signals: bool = True,
    camera: CameraSource | None = None,
) -> int:
    """Run the service until `stop` is set or SIGTERM/SIGINT arrives; the exit status.

    0 after a requested stop, 1 when the link gave up reconnecting or the flight process
    failed. `notify` defaults to `$NOTIFY_SOCKET` (a no-op outside systemd); `camera`, to
    `camera.source` of the settings. Cancelling the task also stops the flight process, closes
    the link and sends STOPPING=1 before `CancelledError` propagates.
    """
    p = ServiceParams() if params is None else params
    notifier = SystemdNotifier.from_environment() if notify is None else notify
    stop_event = asyncio.Event() if stop is None else stop
    link = VehicleLink(settings.link)
    _warn_if_watchdog_too_tight(p)
    notifier.extend_timeout(p.startup_grace_s * 6, "loading the wire CNN")
    process = FlightProcess(settings, link, camera or camera_source(settings), link.clock)
    recorder = None
    flight: asyncio.Task | None = None
    with _stop_on_signals(stop_event, enabled=handle_signals):
        try:
            if not await _connect_with_retry(link, p, notifier, stop_event):
                return 0
            notifier.ready(status_line(link.state, link.telemetry(), process.mission.state))
            log.info("link up on %s; flying", settings.link.connection_url)
            process.adopt(await check_vehicle(process.settings, link))
            # after the vehicle check: a recording carries the adopted limits (record.path,
            # `run --record`; None: not recording)
            recorder = start_recording(process)
            flight = asyncio.create_task(process.run(stop_event), name="flight")
            return await _supervise(link, process, p, notifier, stop_event, flight)
        finally:
            notifier.stopping("stopping: the flight process and the link")
            stop_event.set()
            if flight is not None:
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(asyncio.shield(flight), p.stop_timeout_s)
                if not flight.done():
                    flight.cancel()
                    with contextlib.suppress(asyncio.CancelledError, Exception):
                        await flight
            if recorder is not None:
                recorder.close()
            await link.close()
            log.info("stopped")
            notifier.close()


async def _connect_with_retry(
    link: VehicleLink, p: ServiceParams, notifier: SystemdNotifier, stop: asyncio.Event
) -> bool:
    """Try `link.connect()` until an autopilot is heard (True) or `stop` is set (False)."""
    url = link.params.connection_url
    per_attempt_s = link.params.connect_timeout_s + p.connect_retry_interval_s + p.startup_grace_s
    attempt = 0
    while not stop.is_set():
        attempt += 1
        notifier.extend_timeout(
            per_attempt_s, f"waiting for an autopilot on {url} (attempt {attempt})"
        )
        try:
            return await _unless_stopped(link.connect, stop)
        except LinkError as e:
            log.warning(
                "attempt %d: %s; retrying in %.1f s", attempt, e, p.connect_retry_interval_s
            )
        await _unless_stopped(lambda: asyncio.sleep(p.connect_retry_interval_s), stop)
    return False


async def _supervise(
    link: VehicleLink,
    process: FlightProcess,
    p: ServiceParams,
    notifier: SystemdNotifier,
    stop: asyncio.Event,
    flight: asyncio.Task,
) -> int:
    """The supervision loop; returns the exit status once `stop` is set, the link failed or
    the flight process ended with an error (status 1)."""
    pacer = _StoppablePacer(p.tick_rate_hz, link.now_s, stop)
    readiness = ReadinessWatch(link.params.health_timeout_s, link.now_s())
    last_key: tuple[object, ...] | None = None
    next_log_s = -math.inf
    lag_s = 0.0
    mission_period_s = 1.0 / process.settings.flight.mission_rate_hz
    while not stop.is_set():
        if flight.done() and not stop.is_set():
            error = flight.exception()
            log.error("the flight process ended: %r; exiting for systemd to restart us", error)
            return 1
        snap = link.telemetry()
        mission = process.mission.state
        line = status_line(link.state, snap, mission)
        key = (*status_key(link.state, snap), mission)
        if key != last_key or snap.stamp_s >= next_log_s:
            log.info("%s", line)
            last_key, next_log_s = key, snap.stamp_s + p.status_period_s
        if readiness.overdue(snap.health is not None and snap.health.ready_to_fly, snap.stamp_s):
            log.warning(
                "vehicle not ready to fly for over %.0f s (link.health_timeout_s): %s",
                readiness.timeout_s,
                line,
            )
        if link.state is LinkState.FAILED:
            log.error("the link gave up reconnecting; exiting for systemd to restart us")
            return 1
        mission_lag_s = link.now_s() - process.mission_tick_s - mission_period_s
        if lag_s <= p.watchdog_max_lag_s and mission_lag_s <= p.watchdog_max_lag_s:
            notifier.watchdog(line)
        else:
            late = max(lag_s, mission_lag_s)
            log.warning("a loop ran %.2f s late: systemd watchdog not fed", late)
            notifier.status(line)
        lag_s = await pacer.next_tick()
    return 0


class _StoppablePacer:
    """A `RateKeeper` whose sleep ends early when `stop` is set, measuring each tick's lateness.

    A tick is late when the previous one overran its period (the keeper's lag) or when the
    event loop woke us late (oversleep, e.g. a blocked loop): both count.
    """

    def __init__(self, rate_hz: float, clock: Callable[[], float], stop: asyncio.Event) -> None:
        self._clock = clock
        self._stop = stop
        self._keeper = RateKeeper(rate_hz, clock=clock, sleep=self._sleep)
        self._oversleep_s = 0.0

    async def _sleep(self, duration_s: float) -> None:
        wake_s = self._clock() + duration_s
        await _unless_stopped(lambda: asyncio.sleep(duration_s), self._stop)
        self._oversleep_s = max(0.0, self._clock() - wake_s)

    async def next_tick(self) -> float:
        """Wait for the next tick; how late it starts, s."""
        await self._keeper.wait()
        return self._keeper.last_lag_s + self._oversleep_s


async def _unless_stopped(start: Callable[[], Awaitable[object]], stop: asyncio.Event) -> bool:
    """Await `start()` unless `stop` is set first: True when it completed, False when stopped.

    The work's exception propagates; stopping cancels it.
    """
    if stop.is_set():
        return False
    return await finished_first(start(), stop.wait())


@contextlib.contextmanager
def _stop_on_signals(stop: asyncio.Event, *, enabled: bool) -> Iterator[None]:
    """Set `stop` on SIGTERM (systemctl stop) and SIGINT (Ctrl-C) while inside."""
    loop = asyncio.get_running_loop()
    installed: list[signal.Signals] = []
    if enabled:
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, _on_signal, sig, stop)
            installed.append(sig)
    try:
        yield
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)


def _on_signal(sig: signal.Signals, stop: asyncio.Event) -> None:
    log.info("%s received: stopping", sig.name)
    stop.set()


def _warn_if_watchdog_too_tight(p: ServiceParams) -> None:
    """Warn when the ticks cannot feed systemd's watchdog often enough (`$WATCHDOG_USEC`)."""
    interval_s = watchdog_interval_s()
    if interval_s is not None and 1.0 / p.tick_rate_hz + p.watchdog_max_lag_s > interval_s / 2:
        log.warning(
            "tick period %.2f s + max lag %.2f s exceeds half of WatchdogSec (%.1f s)",
            1.0 / p.tick_rate_hz,
            p.watchdog_max_lag_s,
            interval_s,
        )
