"""The settings of the commands: the flight process' `Settings` plus the simulator's sections.

`SimSettings` is what every `wireavoid` command but `run` reads (`--config FILE`): the
flight settings and `[vehicle_sim]` / `[camera_sim]` of the hil harness. The flight process
(`wireavoid run`, the drone's `/etc/wireavoid/wireavoid.toml`) reads `Settings` alone, so it
never imports the simulator and a drone's file with simulator sections is rejected.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from companion.config import Settings, load_settings
from hil.sensors.params import CameraSimParams
from hil.vehicle.params import VehicleSimParams

WireMasks = Literal["cnn", "truth", "cnn_misses", "cnn_false_marks"]
"""`sim.wire_masks`: the wire masks a simulated flight's map gets (`companion.cli.sim_masks`)."""


class SimParams(BaseModel):
    """A simulated flight (`wireavoid sim`, `sweep`): time, cameras, the judge's limits."""

    model_config = ConfigDict(extra="forbid")

    time: Literal["lockstep", "realtime"] = Field(
        "lockstep",
        description="lockstep: simulated time that stands still while the simulator works and "
        "charges each computation of the stack its measured duration; realtime: the wall clock",
    )
    max_speed: float = Field(
        2.0,
        gt=0.0,
        le=10.0,
        description="lockstep: simulated time runs at most this many times the wall clock "
        "(MAVSDK's own timers run on the wall clock)",
    )
    compute_scale: float = Field(
        1.0,
        ge=0.0,
        le=20.0,
        description="lockstep: simulated seconds charged per measured second of computation "
        "(2 flies this machine's stack as if it were twice as slow)",
    )
    vehicle_heartbeat_hz: float = Field(
        5.0,
        gt=0.0,
        le=50.0,
        description="lockstep: the vehicle's HEARTBEAT rate in simulated time, high enough that "
        "MAVSDK hears one within its 3 s (wall) timeout while simulated time is slow",
    )
    camera_latency_s: float = Field(
        0.03, ge=0.0, le=1.0, description="exposure to delivery of a frame to the process, s"
    )
    vehicle_radius_m: float = Field(
        0.3,
        gt=0.0,
        le=5.0,
        description="the judge's vehicle radius: closer to true geometry than this is a "
        "collision (the planner expands obstacles by mapping.robot_radius_m), m",
    )
    goal_radius_m: float = Field(
        1.0, gt=0.0, le=20.0, description="the judge counts a goal reached within this, m"
    )
    timeout_s: float = Field(
        120.0, gt=0.0, le=36000.0, description="a flight not done after this fails, simulated s"
    )
    wire_masks: WireMasks = Field(
        "cnn",
        description="the wire masks the flight's map gets, to measure how far perception "
        "limits the loop: cnn, the shipped CNN's (the product); truth, the renderer's true wire "
        "pixels (perfect detection in the image, still no depth; the CNN does not run, so its "
        "compute is not charged); cnn_misses, the CNN's mask without its marks farther than "
        "`sim_masks.NEAR_WIRE_PX` from a true wire (its misses, none of its false marks); "
        "cnn_false_marks, the true wires plus those marks (its false marks, none of its misses)",
    )
    px4_ground_truth: bool = Field(
        True,
        description="with --connect to PX4 SITL: the cameras render from, and the judge samples, "
        "the ground truth its SIH simulator streams (HIL_STATE_QUATERNION to UDP 19410 + "
        "instance) while the stack flies on PX4's estimate; false: both use the estimate",
    )


class SimSettings(Settings):
    """Every tunable of the product and of its software-in-the-loop harness."""

    vehicle_sim: VehicleSimParams = Field(default_factory=VehicleSimParams)
    camera_sim: CameraSimParams = Field(default_factory=CameraSimParams)
    sim: SimParams = Field(default_factory=SimParams)


def load_sim_settings(path: Path | None = None) -> SimSettings:
    """`SimSettings` from the TOML file at `path` with environment overrides (see
    `companion.config.load_settings`)."""
    settings = load_settings(path, SimSettings)
    assert isinstance(settings, SimSettings)
    return settings
