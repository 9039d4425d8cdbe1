"""Acceptance of the SIL vehicle by the real MAVSDK (4.x, in-process): it cannot tell it from PX4.

The flight link's own tests (tests/test_link_*) fly it in depth; this checks the vehicle side:
discovery as a PX4 autopilot, health_all_ok, arming retried through the after-boot denial,
MIS_TAKEOFF_ALT through the param protocol, takeoff to Hold, offboard, land and auto-disarm.
"""

from __future__ import annotations

import asyncio
import socket

import pytest
from mavsdk.asyncio import Autopilot, ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.offboard import OffboardAsync, VelocityNedYaw
from mavsdk.asyncio.plugins.telemetry import FlightMode, LandedState, TelemetryAsync

from hil.mavlink.server import VehicleServer
from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_modes import Px4Mode as VehicleMode

SPEED = 3.0  # real-time factor: MAVSDK's own timeouts run on the wall clock


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def first(generator, predicate, timeout_s: float):
    async def scan():
        async for item in generator:
            if predicate(item):
                return item

    return await asyncio.wait_for(scan(), timeout_s)


async def test_mavsdk_connects_arms_takes_off_flies_offboard_and_lands() -> None:
    port = free_udp_port()
    params = VehicleSimParams(health_ok_after_boot_s=1.0, arm_denied_after_boot_s=2.5)
    with VehicleServer(params, port, speed=SPEED) as server:
        config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        async with Mavsdk(config) as mavsdk:
            await mavsdk.add_any_connection(f"udpin://0.0.0.0:{port}")
            system = await mavsdk.first_autopilot(timeout_s=10.0)
            assert system is not None
            assert await system.autopilot_type() == Autopilot.PX4
            telemetry, action = TelemetryAsync(system), ActionAsync(system)
            offboard = OffboardAsync(system)

            await first(telemetry.subscribe_health_all_ok(), bool, 10.0)
            health = await telemetry.health()
            assert health.is_armable and health.is_home_position_ok
            assert health.is_local_position_ok and health.is_global_position_ok

            denials = 0
            while True:
                try:
                    await action.arm()
                    break
                except ActionError:
                    denials += 1
                    assert denials < 20
                    await asyncio.sleep(0.2)
            assert denials >= 1  # "arming denied right after boot" reproduced
            assert server.time_s >= params.arm_denied_after_boot_s

            await action.set_takeoff_altitude(3.0)
            assert await action.get_takeoff_altitude() == pytest.approx(3.0)
            await action.takeoff()
            await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.HOLD, 15.0)
            await first(telemetry.subscribe_in_air(), bool, 5.0)
            # PX4 leaves Takeoff within NAV_MC_ALT_RAD (0.8 m); Hold climbs the rest
            for _ in range(100):
                truth = server.truth()
                if (
                    abs(truth.position_ned_m[2] + 3.0) < 0.15
                    and abs(truth.velocity_ned_mps[2]) < 0.05
                ):
                    break
                await asyncio.sleep(0.05)

            await offboard.set_velocity_ned(VelocityNedYaw(1.0, 0.0, 0.0, 0.0))
            await offboard.start()
            start_z_m = server.truth().position_ned_m[2]
            assert start_z_m == pytest.approx(-3.0, abs=0.35)
            await first(telemetry.subscribe_flight_mode(), lambda m: m == FlightMode.OFFBOARD, 5.0)
            await asyncio.sleep(3.0 / SPEED * 2)
            assert server.flight_mode is VehicleMode.OFFBOARD
            # SIH's drag against PX4's slow velocity integrator: 1 m/s approached from below
            assert 0.75 < server.truth().velocity_ned_mps[0] < 1.05
            assert server.truth().position_ned_m[2] == pytest.approx(start_z_m, abs=0.1)  # vz = 0

            await offboard.stop()
            await action.land()
            await first(telemetry.subscribe_armed(), lambda armed: not armed, 30.0)
            assert await telemetry.landed_state() == LandedState.ON_GROUND
            assert server.truth().on_ground
        assert not server.message_errors
