"""The scripted demo flight: take off, a velocity square, a position setpoint, land; measured.

`fly_pattern(link, pattern)` flies the pattern through a connected `VehicleLink`, acting as a
stand-in planner that publishes fresh setpoints at the link's setpoint rate, and measures every
leg from telemetry (and from the simulator's ground truth when one is given). `run_demo` starts
the hil vehicle in-process on a free UDP port (or connects to an external PX4 SITL) and returns
a `FlightSummary` whose `verdict` explains itself. Durations in `DemoPattern` are vehicle
seconds: with a simulator running `speed` times faster than real time, wall time is divided by
`speed` while commanded speeds stay in m/s.
"""

from __future__ import annotations

import contextlib
import json
import math
import socket
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np

from companion.config import Settings
from companion.rate import RateKeeper
from companion.setpoints import Setpoint
from companion.vehicle_link import LinkError, LinkEvent, LinkEventKind, LinkState, VehicleLink


class TruthState(Protocol):
    """What the demo reads from a simulator's ground truth (`hil.multirotor.VehicleState`)."""

    time_s: float
    position_ned_m: np.ndarray
    velocity_ned_mps: np.ndarray


TruthSource = Callable[[], TruthState]


@dataclass(frozen=True)
class DemoPattern:
    """The scripted pattern. NED, relative to where offboard starts; vehicle seconds."""

    square_speed_mps: float = 2.0  # speed of each side of the velocity square
    square_leg_s: float = 3.0  # duration of each side
    settle_fraction: float = 0.5  # velocity is measured over this last fraction of a side
    brake_s: float = 1.0  # zero-velocity pause after the square
    position_offset_ned_m: tuple[float, float, float] = (4.0, -3.0, -1.0)
    position_timeout_s: float = 20.0
    velocity_tolerance_mps: float = 0.25
    position_tolerance_m: float = 0.3
    settled_speed_mps: float = 0.15  # the position leg ends once within tolerance and slower
    landed_altitude_m: float = 0.2


@dataclass(frozen=True)
class LegResult:
    """One leg: what was commanded, what was measured (telemetry, and truth when known)."""

    name: str
    commanded: list[float]  # velocity NED m/s, position NED m or [altitude m]
    achieved: list[float]  # same quantity measured from telemetry
    error: float  # norm of achieved - commanded, in the quantity's unit
    truth_error: float | None  # the same from ground truth; None without a simulator
    tolerance: float
    unit: str
    duration_s: float  # vehicle seconds
    ok: bool
    detail: str = ""


@dataclass
class FlightSummary:
    """The outcome of a demo flight; `ok` is the verdict, `verdict` says why."""

    legs: list[LegResult] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    watchdog_events: int = 0
    setpoints_sent: int = 0
    stream_max_lag_s: float = 0.0
    duration_s: float = 0.0  # wall seconds
    speed: float = 1.0
    connection_url: str = ""
    ok: bool = False
    verdict: str = "not flown"

    def to_json(self) -> str:
        """The summary as a JSON document."""
        return json.dumps(asdict(self), indent=2, default=_json_default)

    def to_text(self) -> str:
        """A readable report: one line per leg, the events, the verdict."""
        lines = [
            f"demo flight on {self.connection_url} (x{self.speed:g} real time), "
            f"{self.duration_s:.1f} s wall",
            f"{'leg':<18}{'commanded':>24}{'achieved':>24}{'error':>9}{'truth':>8}"
            f"{'tol':>7}{'time s':>8}  ok",
            "(error: telemetry vs command; truth: simulator ground truth vs command; "
            "time in vehicle seconds)",
        ]
        for leg in self.legs:
            truth = "-" if leg.truth_error is None else f"{leg.truth_error:.2f}"
            lines.append(
                f"{leg.name:<18}{_vec(leg.commanded):>24}{_vec(leg.achieved):>24}"
                f"{leg.error:>9.2f}{truth:>8}{leg.tolerance:>7.2f}{leg.duration_s:>8.1f}  "
                f"{'yes' if leg.ok else 'NO'} {leg.unit}{'  ' + leg.detail if leg.detail else ''}"
            )
        lines.append(
            f"setpoints sent {self.setpoints_sent}, streamer max lag "
            f"{self.stream_max_lag_s * 1e3:.0f} ms, watchdog events {self.watchdog_events}"
        )
        lines.extend(_event_lines([e for e in self.events if not _routine(e)]))
        lines.append(f"verdict: {'PASS' if self.ok else 'FAIL'} - {self.verdict}")
        return "\n".join(lines)


_ROUTINE_EVENTS = frozenset({"connected", "offboard_started", "offboard_stopped"})
_ROUTINE_TEXT = ("debug:", "info:", "notice:")


def _routine(event: dict[str, Any]) -> bool:
    """Events the text summary leaves out (they stay in the JSON)."""
    if event["kind"] == LinkEventKind.VEHICLE_TEXT.value:
        return str(event["detail"]).startswith(_ROUTINE_TEXT)
    return event["kind"] in _ROUTINE_EVENTS


def _event_lines(events: list[dict[str, Any]]) -> list[str]:
    """One line per event; a run of events of one kind is folded into its count and last."""
    lines: list[str] = []
    i = 0
    while i < len(events):
        j = i
        while j + 1 < len(events) and events[j + 1]["kind"] == events[i]["kind"]:
            j += 1
        count = f" x{j - i + 1} (last)" if j > i else ""
        lines.append(f"  event {events[j]['kind']}{count}: {events[j]['detail']}")
        i = j + 1
    return lines


def _vec(v: list[float]) -> str:
    return "[" + ", ".join(f"{x:.2f}" for x in v) + "]"


def _json_default(o: object) -> object:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return str(o)


async def fly_pattern(
    link: VehicleLink,
    pattern: DemoPattern,
    *,
    speed: float = 1.0,
    truth: TruthSource | None = None,
    legs: list[LegResult] | None = None,
) -> list[LegResult]:
    """Fly the pattern through a connected link; the measured legs, in order.

    Each leg is appended to `legs` (a new list when None) as soon as it is flown, so the caller
    keeps the legs before a failure. Raises `LinkError` when a step cannot be done at all (no
    arming, no offboard...); legs out of tolerance are reported, not raised.
    """
    p = link.params
    legs = [] if legs is None else legs
    await link.wait_healthy()
    await link.arm()

    t0 = _vehicle_time(link, truth, speed)
    snap = await link.takeoff()
    assert snap.pose is not None
    alt_err = abs(snap.pose.altitude_m - p.takeoff_altitude_m)
    truth_alt_err = (
        None if truth is None else abs(-truth().position_ned_m[2] - p.takeoff_altitude_m)
    )
    legs.append(
        LegResult(
            "takeoff",
            [p.takeoff_altitude_m],
            [snap.pose.altitude_m],
            alt_err,
            truth_alt_err,
            p.altitude_tolerance_m,
            "m altitude",
            _vehicle_time(link, truth, speed) - t0,
            alt_err <= p.altitude_tolerance_m
            and (truth_alt_err is None or truth_alt_err <= p.altitude_tolerance_m),
        )
    )

    yaw_rad = snap.attitude.yaw_rad if snap.attitude is not None else 0.0
    await link.start_offboard(Setpoint.velocity(np.zeros(3), yaw_rad, link.now_s()))
    start_ned_m = link.telemetry().pose.position_ned_m  # type: ignore[union-attr]

    v = pattern.square_speed_mps
    for name, direction in (
        ("velocity north", (1.0, 0.0, 0.0)),
        ("velocity east", (0.0, 1.0, 0.0)),
        ("velocity south", (-1.0, 0.0, 0.0)),
        ("velocity west", (0.0, -1.0, 0.0)),
    ):
        legs.append(
            await _velocity_leg(link, pattern, name, v * np.array(direction), yaw_rad, speed, truth)
        )
    await _stream_for(
        link, lambda now: Setpoint.velocity(np.zeros(3), yaw_rad, now), pattern.brake_s / speed
    )

    legs.append(await _position_leg(link, pattern, start_ned_m, yaw_rad, speed, truth))

    t0 = _vehicle_time(link, truth, speed)
    snap = await link.land()
    alt = snap.pose.altitude_m if snap.pose is not None else math.nan
    truth_alt = None if truth is None else float(-truth().position_ned_m[2])
    legs.append(
        LegResult(
            "land",
            [0.0],
            [alt],
            abs(alt),
            None if truth_alt is None else abs(truth_alt),
            pattern.landed_altitude_m,
            "m altitude",
            _vehicle_time(link, truth, speed) - t0,
            abs(alt) <= pattern.landed_altitude_m and snap.armed is False,
            "disarmed" if snap.armed is False else "still armed",
        )
    )
    return legs


def _vehicle_time(link: VehicleLink, truth: TruthSource | None, speed: float) -> float:
    """Vehicle seconds: the simulator's clock when known, else scaled monotonic time."""
    return truth().time_s if truth is not None else link.now_s() * speed


async def _stream_for(
    link: VehicleLink,
    make: Callable[[float], Setpoint],
    wall_s: float,
    on_tick: Callable[[], None] | None = None,
) -> None:
    """Publish `make(now_s)` at the setpoint rate for `wall_s` seconds (a stand-in planner)."""
    keeper = RateKeeper(link.params.setpoint_rate_hz, clock=link.now_s)
    end_s = link.now_s() + wall_s
    while link.now_s() < end_s:
        if not link.offboard_engaged:
            raise LinkError(f"offboard lost mid-leg: {_last_event(link)}")
        link.setpoints.publish(make(link.now_s()))
        if on_tick is not None:
            on_tick()
        await keeper.wait()


def _last_event(link: VehicleLink) -> str:
    return f"{link.events[-1].kind.value}: {link.events[-1].detail}" if link.events else "-"


async def _velocity_leg(
    link: VehicleLink,
    pattern: DemoPattern,
    name: str,
    velocity_ned_mps: np.ndarray,
    yaw_rad: float,
    speed: float,
    truth: TruthSource | None,
) -> LegResult:
    """Command a constant velocity for `square_leg_s`; measure it over the settled part."""
    tel_samples: list[np.ndarray] = []
    truth_samples: list[np.ndarray] = []
    leg_wall_s = pattern.square_leg_s / speed
    settle_after_s = link.now_s() + leg_wall_s * (1.0 - pattern.settle_fraction)
    t0 = _vehicle_time(link, truth, speed)

    def sample() -> None:
        if link.now_s() < settle_after_s:
            return
        pose = link.telemetry().pose
        if pose is not None:
            tel_samples.append(pose.velocity_ned_mps)
        if truth is not None:
            truth_samples.append(np.asarray(truth().velocity_ned_mps))

    await _stream_for(
        link, lambda now: Setpoint.velocity(velocity_ned_mps, yaw_rad, now), leg_wall_s, sample
    )
    achieved = np.mean(tel_samples, axis=0) if tel_samples else np.full(3, np.nan)
    error = float(np.linalg.norm(achieved - velocity_ned_mps))
    truth_error = (
        float(np.linalg.norm(np.mean(truth_samples, axis=0) - velocity_ned_mps))
        if truth_samples
        else None
    )
    tol = pattern.velocity_tolerance_mps
    return LegResult(
        name,
        velocity_ned_mps.tolist(),
        achieved.tolist(),
        error,
        truth_error,
        tol,
        "m/s",
        _vehicle_time(link, truth, speed) - t0,
        error <= tol and (truth_error is None or truth_error <= tol),
        f"{len(tel_samples)} samples",
    )


async def _position_leg(
    link: VehicleLink,
    pattern: DemoPattern,
    start_ned_m: np.ndarray,
    yaw_rad: float,
    speed: float,
    truth: TruthSource | None,
) -> LegResult:
    """Command a position; wait until it is reached and settled (or the timeout)."""
    target = start_ned_m + np.array(pattern.position_offset_ned_m)
    tol = pattern.position_tolerance_m
    t0 = _vehicle_time(link, truth, speed)
    deadline_s = link.now_s() + pattern.position_timeout_s / speed
    keeper = RateKeeper(link.params.setpoint_rate_hz, clock=link.now_s)
    settled = False
    while link.now_s() < deadline_s and not settled:
        if not link.offboard_engaged:
            raise LinkError(f"offboard lost mid-leg: {_last_event(link)}")
        link.setpoints.publish(Setpoint.position(target, yaw_rad, link.now_s()))
        pose = link.telemetry().pose
        settled = (
            pose is not None
            and float(np.linalg.norm(pose.position_ned_m - target)) < 0.5 * tol
            and pose.speed_mps < pattern.settled_speed_mps
        )
        await keeper.wait()
    pose = link.telemetry().pose
    achieved = pose.position_ned_m if pose is not None else np.full(3, np.nan)
    error = float(np.linalg.norm(achieved - target))
    truth_error = None if truth is None else float(np.linalg.norm(truth().position_ned_m - target))
    return LegResult(
        "position",
        target.tolist(),
        achieved.tolist(),
        error,
        truth_error,
        tol,
        "m",
        _vehicle_time(link, truth, speed) - t0,
        settled and error <= tol and (truth_error is None or truth_error <= tol),
        "settled" if settled else "timed out before settling",
    )


def verdict(legs: list[LegResult], events: list[LinkEvent]) -> tuple[bool, str]:
    """Whether the flight passed, and why (the first failure named)."""
    expected = {"takeoff", "position", "land"}
    missing = expected - {leg.name for leg in legs}
    if missing:
        return False, f"legs not flown: {', '.join(sorted(missing))}"
    bad = [leg for leg in legs if not leg.ok]
    if bad:
        leg = bad[0]
        return False, (
            f"leg '{leg.name}' off by {leg.error:.2f} {leg.unit} (tolerance {leg.tolerance})"
        )
    faults = [
        e
        for e in events
        if e.kind
        in (LinkEventKind.WATCHDOG_BRAKE, LinkEventKind.LINK_LOST, LinkEventKind.OFFBOARD_LOST)
    ]
    if faults:
        return False, f"{faults[0].kind.value}: {faults[0].detail}"
    return True, f"all {len(legs)} legs within tolerance"


def free_udp_port() -> int:
    """A UDP port free on this machine right now (bound to port 0 and released)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("0.0.0.0", 0))
        return int(s.getsockname()[1])


async def run_demo(
    settings: Settings,
    *,
    connect_url: str | None = None,
    speed: float = 1.0,
    pattern: DemoPattern | None = None,
) -> FlightSummary:
    """Fly the demo pattern and summarise it; never raises for a flight failure.

    Without `connect_url` the hil vehicle is started in-process on a free UDP port at `speed`
    times real time; with it, an external autopilot (PX4 SITL: `udpin://0.0.0.0:14540`) flies,
    at real time.
    """
    pattern = pattern or DemoPattern()
    started = time.monotonic()
    server = None
    truth: TruthSource | None = None
    if connect_url is None:
        from hil.vehicle_server import VehicleServer

        port = free_udp_port()
        server = VehicleServer(settings.vehicle_sim, port, speed=speed)
        server.start()
        truth = server.truth
        connect_url = f"udpin://0.0.0.0:{port}"
    else:
        speed = 1.0
    link_params = settings.link.model_copy(update={"connection_url": connect_url})
    summary = FlightSummary(speed=speed, connection_url=link_params.connection_url)
    link = VehicleLink(link_params)
    legs: list[LegResult] = []
    failure = ""
    try:
        await link.connect()
        await fly_pattern(link, pattern, speed=speed, truth=truth, legs=legs)
    except LinkError as e:
        failure = str(e)
        await _bring_down(link)
    except Exception as e:  # the command reports every failure as a verdict, never a traceback
        failure = f"{type(e).__name__}: {e}"
        await _bring_down(link)
    finally:
        await link.close()
        if server is not None:
            server.stop()
            if server.error is not None:
                failure = f"the simulated vehicle crashed: {server.error!r}"
    summary.legs = legs
    summary.events = [
        {"stamp_s": e.stamp_s, "kind": e.kind.value, "detail": e.detail} for e in link.events
    ]
    summary.watchdog_events = len(link.watchdog.events)
    summary.setpoints_sent = link.setpoints_sent
    summary.stream_max_lag_s = link.stream_max_lag_s
    summary.duration_s = time.monotonic() - started
    if failure:
        summary.ok, summary.verdict = False, failure
    else:
        summary.ok, summary.verdict = verdict(legs, link.events)
    return summary


async def _bring_down(link: VehicleLink) -> None:
    """After a failure mid-flight: try to land, without raising."""
    if link.state is not LinkState.CONNECTED or not link.telemetry().armed:
        return
    with contextlib.suppress(LinkError):
        await link.land()
