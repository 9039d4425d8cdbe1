"""The planner's limits from a vehicle's PX4 parameters (companion.link.px4_limits)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.link.px4_limits import (
    DEFAULT_DRAG_PER_S,
    PX4_LIMIT_PARAMETERS,
    vehicle_limits,
)
from hil.vehicle.airframes import AIRFRAMES, airframe_params
from hil.vehicle.multirotor import Multirotor
from planning.params import PlanningParams
from planning.selection import braking_distance_m


def _hil_braking_m(airframe: str, speed_mps: float) -> tuple[float, float]:
    """(steady speed, distance in 5 s after a zero setpoint) of the PX4 controllers in lockstep."""
    vehicle = Multirotor(airframe_params(airframe))
    vehicle.reset(np.array([0.0, 0.0, -10.0]), 0.0)
    vehicle.set_velocity_setpoint(np.array([speed_mps, 0.0, 0.0]), yaw_rad=0.0)
    vehicle.step(60.0)  # steady: the integrator holds the drag
    start = vehicle.state
    vehicle.set_velocity_setpoint(np.zeros(3), yaw_rad=0.0)
    vehicle.step(5.0)
    return float(start.velocity_ned_mps[0]), float(
        vehicle.state.position_ned_m[0] - start.position_ned_m[0]
    )


def _sih_values(airframe: str) -> dict[str, float]:
    values = AIRFRAMES[airframe]
    return {"SIH_KDV": values.get("SIH_KDV", 1.0), "SIH_MASS": values.get("SIH_MASS", 1.0)}


@pytest.mark.parametrize("airframe", ["sih_quadx", "low_drag_1500g"])
@pytest.mark.parametrize("speed_mps", [1.0, 2.0])
def test_braking_distance_is_what_the_px4_controller_flies(airframe: str, speed_mps: float):
    steady_mps, flown_m = _hil_braking_m(airframe, speed_mps)
    limits = vehicle_limits(_sih_values(airframe))
    assert float(limits.braking_distance_m(steady_mps)) == pytest.approx(flown_m, rel=0.15)


def test_defaults_are_px4s_and_sih_drag_lengthens_the_stop():
    assert set(PX4_LIMIT_PARAMETERS) >= {"MPC_ACC_HOR", "MPC_JERK_AUTO", "MPC_XY_VEL_MAX"}
    real = vehicle_limits({}, cruise_speed_mps=2.0)  # no SIH_*: a real drone's light drag
    assert real.drag_per_s == DEFAULT_DRAG_PER_S
    assert real.max_speed_mps == 2.0 and real.max_jerk_mps3 == 4.0
    assert real.max_accel_mps2 == 3.0  # MPC_ACC_HOR
    assert real.max_yaw_rate_radps == pytest.approx(math.radians(60.0))
    assert real.max_vertical_speed_mps == 1.5
    sih = vehicle_limits({"SIH_KDV": 1.0, "SIH_MASS": 1.0}, cruise_speed_mps=2.0)
    # SIH's strong drag: the integrator holds more, and keeps pushing while it unwinds
    assert sih.braking_distance_m(2.0) > 2.0 * real.braking_distance_m(2.0)
    assert vehicle_limits({"MPC_XY_VEL_MAX": 1.5}, cruise_speed_mps=2.0).max_speed_mps == 1.5
    # a 10 deg tilt limit caps the acceleration at g tan(10 deg)
    tilted = vehicle_limits({"MPC_TILTMAX_AIR": 10.0, "MPC_ACC_HOR": 5.0})
    assert tilted.max_accel_mps2 == pytest.approx(9.80665 * math.tan(math.radians(10.0)))


def test_planning_overrides_make_the_planners_braking_formula_match():
    for px4 in ({"SIH_KDV": 1.0, "SIH_MASS": 1.0}, {}):
        limits = vehicle_limits(px4, cruise_speed_mps=2.0)
        params = PlanningParams().model_copy(update=limits.planning_overrides())
        PlanningParams.model_validate(params.model_dump())  # within the planner's bounds
        planned = float(braking_distance_m(2.0, params))
        # the formula reaches the vehicle's distance, or its minimum (accel = sqrt(j v)) below
        assert planned >= float(limits.braking_distance_m(2.0)) - 0.05
        assert params.max_accel_mps2 <= limits.max_accel_mps2


def test_the_vehicle_check_flies_the_planner_under_the_geofence_ceiling() -> None:
    from companion.config import Settings
    from companion.flight.vehicle_check import vehicle_check
    from companion.ground.params import GeofenceParams
    from hil.vehicle.params import VehicleSimParams, px4_parameter_table

    vehicle = VehicleSimParams()
    px4 = {name: getattr(vehicle, field) for name, field in px4_parameter_table().items()}
    fenced = Settings(geofence=GeofenceParams(max_altitude_m=30.0))
    assert vehicle_check(fenced, px4).settings.planning.max_altitude_m == 30.0
    low = fenced.model_copy(update={"planning": PlanningParams(max_altitude_m=12.0)})
    assert vehicle_check(low, px4).settings.planning.max_altitude_m == 12.0
