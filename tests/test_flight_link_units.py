"""Unit tests of the flight link's pure parts: rate keeper, watchdog, telemetry cache, setpoints,
MAVSDK calls in flight."""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading

import numpy as np
import pytest

from companion.link.calls import MavsdkCalls, returned_within
from companion.link.params import LinkParams
from companion.link.setpoints import SetpointSource
from companion.link.telemetry import FlightMode, Health, LandedState, TelemetryCache
from companion.link.watchdog import SetpointWatchdog, WatchdogAction
from companion.rate import RateKeeper, next_tick
from planning.types import Setpoint, SetpointKind


class SimClock:
    """Simulated monotonic clock; `sleep` advances it."""

    def __init__(self) -> None:
        self.t = 100.0
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.t

    async def sleep(self, dt: float) -> None:
        self.sleeps.append(dt)
        self.t += dt


# ---------------------------------------------------------------- rate keeper


def test_next_tick_early_sleeps_to_deadline_and_keeps_grid():
    plan = next_tick(deadline_s=10.0, now_s=9.98, period_s=0.05)
    assert plan.sleep_s == pytest.approx(0.02)
    assert plan.next_deadline_s == pytest.approx(10.05)
    assert (plan.skipped_ticks, plan.lag_s) == (0, 0.0)


def test_next_tick_late_skips_missed_ticks_without_bursting():
    plan = next_tick(deadline_s=10.0, now_s=10.17, period_s=0.05)
    assert plan.sleep_s == 0.0
    assert plan.skipped_ticks == 3  # 10.05, 10.10, 10.15 passed
    assert plan.next_deadline_s == pytest.approx(10.20)  # back on the grid, after now
    assert plan.lag_s == pytest.approx(0.17)


async def test_rate_keeper_does_not_drift_with_work_time():
    clock = SimClock()
    keeper = RateKeeper(20.0, clock=clock, sleep=clock.sleep)
    start = clock.t
    for _ in range(100):
        clock.t += 0.013  # work of each tick
        await keeper.wait()
    # The grid starts at the first wait (after 13 ms of work); 100 ticks later it is exactly
    # 100 periods on: no drift despite the 13 ms of work per tick.
    assert clock.t - start == pytest.approx(0.013 + 100 * 0.05, abs=1e-9)
    assert keeper.skipped_ticks == 0
    assert keeper.max_lag_s == 0.0


async def test_rate_keeper_reports_overrun_and_skips():
    clock = SimClock()
    keeper = RateKeeper(10.0, clock=clock, sleep=clock.sleep)
    await keeper.wait()  # first deadline at t0 + 0.1
    clock.t += 0.35  # one tick overran by 0.25 s past its deadline
    lag = await keeper.wait()
    assert lag == pytest.approx(0.25)
    assert keeper.skipped_ticks == 2
    assert keeper.max_lag_s == pytest.approx(0.25)


def test_rate_keeper_rejects_nonpositive_rate():
    with pytest.raises(ValueError):
        RateKeeper(0.0)


# ---------------------------------------------------------------- watchdog


def _watchdog() -> SetpointWatchdog:
    return SetpointWatchdog(max_age_s=0.3, brake_timeout_s=2.0, brake_speed_mps=0.2)


def test_watchdog_streams_fresh_setpoints():
    wd = _watchdog()
    for k in range(20):
        assert wd.update(10.0 + 0.05 * k, 10.0 + 0.05 * k - 0.1, 3.0) is WatchdogAction.STREAM
    assert wd.events == []


def test_watchdog_brakes_on_stale_plan_then_holds_once_slow():
    wd = _watchdog()
    assert wd.update(10.0, 9.75, 3.0) is WatchdogAction.STREAM  # 0.25 s: fresh
    assert wd.update(10.1, 9.75, 3.0) is WatchdogAction.BRAKE  # 0.35 s: stale
    assert wd.update(10.5, 9.75, 1.0) is WatchdogAction.BRAKE  # still fast
    assert wd.update(10.9, 9.75, 0.1) is WatchdogAction.HOLD  # slowed down
    assert wd.update(11.0, 9.75, 0.0) is WatchdogAction.TRIPPED
    assert [e.action for e in wd.events] == [WatchdogAction.BRAKE, WatchdogAction.HOLD]
    assert wd.events[0].setpoint_age_s == pytest.approx(0.35)
    assert wd.events[0].stamp_s == 10.1


def test_watchdog_holds_after_brake_timeout_even_if_never_slow():
    wd = _watchdog()
    wd.update(10.0, 5.0, 3.0)
    assert wd.update(11.9, 5.0, math.inf) is WatchdogAction.BRAKE
    assert wd.update(12.0, 5.0, math.nan) is WatchdogAction.HOLD


def test_watchdog_stays_tripped_until_rearmed_even_if_plan_recovers():
    wd = _watchdog()
    wd.update(10.0, 5.0, 0.0)
    wd.update(10.05, 5.0, 0.0)
    assert wd.update(10.1, 10.1, 0.0) is WatchdogAction.TRIPPED  # fresh again: still tripped
    wd.rearm(10.15)
    assert wd.update(10.2, 10.15, 0.0) is WatchdogAction.STREAM


def test_watchdog_gives_the_planner_the_age_limit_after_rearm():
    wd = _watchdog()
    wd.rearm(20.0)  # offboard entered with a setpoint from t = 17 s (entry takes seconds)
    assert wd.update(20.25, 17.0, 0.0) is WatchdogAction.STREAM
    assert wd.update(20.35, 17.0, 0.0) is WatchdogAction.BRAKE
    assert wd.events[0].setpoint_age_s == pytest.approx(0.35)


def test_watchdog_without_any_setpoint_is_stale():
    assert _watchdog().update(1.0, None, 0.0) is WatchdogAction.BRAKE


# ---------------------------------------------------------------- telemetry cache


def test_telemetry_cache_unknown_until_received_and_stamped():
    cache = TelemetryCache()
    snap = cache.snapshot(5.0)
    assert snap.pose is None and snap.armed is None
    assert snap.flight_mode is FlightMode.UNKNOWN
    assert snap.age_s() == math.inf

    cache.update_pose(np.array([1.0, 2.0, -3.0]), np.array([0.3, 0.4, 0.0]), 6.0)
    cache.update_flight_mode(FlightMode.from_name("OFFBOARD"), 6.5)
    cache.update_landed_state(LandedState.from_name("IN_AIR"), 6.6)
    snap = cache.snapshot(7.0)
    assert snap.pose is not None
    assert snap.pose.altitude_m == pytest.approx(3.0)
    assert snap.pose.speed_mps == pytest.approx(0.5)
    assert snap.pose.stamp_s == 6.0
    assert snap.flight_mode is FlightMode.OFFBOARD and snap.flight_mode_stamp_s == 6.5
    assert snap.landed_state is LandedState.IN_AIR
    assert snap.age_s() == pytest.approx(0.4)

    cache.clear()
    assert cache.snapshot(8.0).pose is None


def test_telemetry_cache_snapshot_is_isolated_from_caller_arrays():
    cache = TelemetryCache()
    p = np.array([1.0, 2.0, 3.0])
    cache.update_pose(p, np.zeros(3), 1.0)
    p[0] = 99.0
    assert cache.snapshot(1.0).pose.position_ned_m[0] == 1.0


def test_unknown_mode_names_map_to_unknown():
    assert FlightMode.from_name("PRECISION_LAND") is FlightMode.UNKNOWN
    assert LandedState.from_name("FLYING_SIDEWAYS") is LandedState.UNKNOWN


def test_health_ready_to_fly_needs_position_home_and_armable():
    ok = Health(True, True, True, True, True, 0.0)
    assert ok.ready_to_fly
    assert not Health(True, True, False, True, True, 0.0).ready_to_fly
    assert not Health(True, True, True, False, True, 0.0).ready_to_fly


# ---------------------------------------------------------------- setpoints and params


def test_setpoint_yaw_fill_and_age():
    sp = Setpoint.velocity([1.0, 0.0, 0.0], math.nan, stamp_s=3.0)
    assert sp.kind is SetpointKind.VELOCITY
    assert sp.with_yaw(0.5).yaw_rad == 0.5
    assert Setpoint.position([0, 0, -3], 1.0, 3.0).with_yaw(0.5).yaw_rad == 1.0
    assert sp.age_s(3.4) == pytest.approx(0.4)
    assert np.array_equal(Setpoint.brake(0.2, 1.0).velocity_ned_mps, np.zeros(3))


def test_setpoint_rejects_nonfinite_vector():
    with pytest.raises(ValueError):
        Setpoint.position([0.0, math.nan, -3.0], 0.0, 0.0)


def test_setpoint_source_keeps_latest():
    src = SetpointSource()
    assert src.latest() is None
    a = Setpoint.brake(0.0, 1.0)
    b = Setpoint.brake(0.0, 2.0)
    src.publish(a)
    src.publish(b)
    assert src.latest() is b and src.published == 2


def test_link_params_enforce_setpoint_rate_floor():
    with pytest.raises(ValueError):
        LinkParams(setpoint_rate_hz=10.0)
    assert LinkParams().setpoint_max_age_s == 0.3


async def test_a_cancelled_mavsdk_call_is_waited_for_until_its_thread_returns():
    """MAVSDK runs each call in a worker thread; cancelling the caller leaves the thread in C,
    so `drained` counts it until it returns, and only then may the plugin be destroyed."""
    calls = MavsdkCalls()
    release = threading.Event()
    loop = asyncio.get_running_loop()

    async def blocking_call() -> str:  # MAVSDK's asyncio plugins: run_in_executor(None, ...)
        return await loop.run_in_executor(None, lambda: release.wait(10.0) and "acked")

    caller = asyncio.create_task(calls.call(blocking_call()))
    await asyncio.sleep(0.05)
    caller.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await caller
    assert caller.cancelled()
    assert calls.running == 1
    assert await calls.drained(0.1) == 1  # still in its thread
    release.set()
    assert await calls.drained(2.0) == 0
    assert calls.running == 0


async def test_a_mavsdk_call_raises_to_its_caller():
    calls = MavsdkCalls()

    async def refused() -> None:
        raise RuntimeError("COMMAND_DENIED")

    with pytest.raises(RuntimeError, match="COMMAND_DENIED"):
        await calls.call(refused())
    assert calls.running == 0


async def test_a_mavsdk_destroy_that_never_returns_leaves_the_loop_running():
    """MAVSDK's destroy blocks in C; one that hangs must not freeze the flight process."""
    stuck = threading.Event()
    ticks = 0

    async def loop_ticks() -> None:
        nonlocal ticks
        while True:
            await asyncio.sleep(0.01)
            ticks += 1

    ticker = asyncio.create_task(loop_ticks())
    try:
        assert not await returned_within(lambda: stuck.wait(5.0), 0.3, "stuck-destroy")
        assert ticks >= 10  # the loop went on while the destroy hung
        assert await returned_within(lambda: None, 1.0, "quick-destroy")
    finally:
        ticker.cancel()
        stuck.set()
