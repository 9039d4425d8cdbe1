"""How much faster than real time the SIL vehicle runs (lockstep, no wall-clock pacing).

Flies a fixed pattern (arm, takeoff, offboard velocity legs) on `Px4Vehicle` alone (physics,
controller, commander) and through `VehicleServer` in lockstep (plus MAVLink telemetry encoding
and UDP sends), and reports simulated seconds per wall second for each.
"""

from __future__ import annotations

import socket
import time
from dataclasses import asdict, dataclass

import numpy as np

from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_controller import TrajectorySetpoint
from hil.vehicle.px4_modes import Px4Mode, Px4Vehicle

_LEG_VELOCITIES_NED_MPS = ((2.0, 0.0, 0.0), (0.0, 2.0, 0.0), (-2.0, 0.0, -0.5), (0.0, -2.0, 0.5))


@dataclass(frozen=True)
class VehicleBenchResult:
    """Real-time factors (simulated s / wall s) and what was simulated."""

    sim_duration_s: float
    physics_rate_hz: float
    dynamics_real_time_factor: float
    mavlink_lockstep_real_time_factor: float

    def to_dict(self) -> dict[str, float]:
        """JSON-ready dict."""
        return asdict(self)


def _fly_pattern(vehicle: Px4Vehicle, advance, duration_s: float) -> None:
    vehicle.arm(force=True)
    vehicle.takeoff()
    advance(5.0)
    leg = 0
    vehicle.offboard_setpoint(TrajectorySetpoint(velocity_ned_mps=np.zeros(3)))
    vehicle.request_mode(Px4Mode.OFFBOARD)
    while vehicle.time_s < duration_s:
        velocity = np.array(_LEG_VELOCITIES_NED_MPS[leg % len(_LEG_VELOCITIES_NED_MPS)])
        vehicle.offboard_setpoint(TrajectorySetpoint(velocity_ned_mps=velocity, yaw_rad=0.0))
        advance(0.05)
        leg = int(vehicle.time_s // 4.0)


def measure_real_time_factor(
    params: VehicleSimParams, duration_s: float = 60.0
) -> VehicleBenchResult:
    """Fly the pattern for `duration_s` simulated seconds, both ways, and time it."""
    from hil.mavlink.server import VehicleServer

    vehicle = Px4Vehicle(params)
    start = time.perf_counter()
    _fly_pattern(vehicle, vehicle.step, duration_s)
    dynamics_wall_s = time.perf_counter() - start

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:
        sink.bind(("127.0.0.1", 0))
        sink.setblocking(False)
        port = sink.getsockname()[1]
        server = VehicleServer(params, port, lockstep=True).start()
        try:
            served = server.with_vehicle(lambda v: v)

            def advance(dt_s: float) -> None:
                server.advance(dt_s)
                try:
                    while sink.recv(65536):
                        pass
                except BlockingIOError:
                    pass

            start = time.perf_counter()
            _fly_pattern(served, advance, duration_s)
            server_wall_s = time.perf_counter() - start
        finally:
            server.stop()
    return VehicleBenchResult(
        sim_duration_s=duration_s,
        physics_rate_hz=params.physics_rate_hz,
        dynamics_real_time_factor=duration_s / dynamics_wall_s,
        mavlink_lockstep_real_time_factor=duration_s / server_wall_s,
    )
