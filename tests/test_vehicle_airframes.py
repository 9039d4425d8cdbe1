"""Airframes, a drone's PX4 parameter file, and flying on a drifting estimate."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from hil.vehicle.airframes import (
    AIRFRAMES,
    airframe_params,
    params_with_px4_values,
    read_px4_parameter_file,
    vehicle_params,
)
from hil.vehicle.estimator import PX4_SITL_ESTIMATION_ERROR
from hil.vehicle.multirotor import Multirotor, true_hover_thrust
from hil.vehicle.params import VehicleSimParams, px4_parameter_table
from hil.vehicle.px4_parameters import px4_defaults

QGC_PARAMS = """# Onboard parameters for Vehicle 1
#
# Vehicle-Id Component-Id Name Value Type
1\t1\tMPC_XY_VEL_P_ACC\t2.5\t9
1\t1\tCOM_OBL_RC_ACT\t5\t6
1\t1\tSIH_MASS\t2.0\t9
1\t1\tCAL_ACC0_ID\t1310988\t6
"""


def test_the_default_is_px4_sitls_sih_quadx_with_px4s_values() -> None:
    assert airframe_params("sih_quadx") == VehicleSimParams()
    defaults = px4_defaults()
    assert len(defaults) == 888
    params = VehicleSimParams()
    for name, field in px4_parameter_table().items():
        value, _kind = defaults[name]
        assert getattr(params, field) == pytest.approx(value, rel=1e-5), name
    # SIH: 4 x 5 N carries 1 kg at 0.49 thrust; PX4 assumes 0.5 (its integrator closes the gap)
    assert true_hover_thrust(params) == pytest.approx(0.4903, abs=1e-4)


def test_presets_and_a_drones_parameter_file(tmp_path: Path) -> None:
    light = airframe_params("low_drag_1500g")
    assert light.mass_kg == 1.5 and light.drag_coefficient_nspm == 0.15
    assert true_hover_thrust(light) == pytest.approx(0.5, abs=0.001)
    with pytest.raises(KeyError, match="sih_quadx"):
        airframe_params("x500")
    qgc = tmp_path / "drone.params"
    qgc.write_text(QGC_PARAMS)
    values = read_px4_parameter_file(qgc)
    assert values == {
        "MPC_XY_VEL_P_ACC": 2.5,
        "COM_OBL_RC_ACT": 5,
        "SIH_MASS": 2.0,
        "CAL_ACC0_ID": 1310988,
    }
    params, ignored = vehicle_params(
        VehicleSimParams(), airframe="low_drag_1500g", px4_params_file=qgc
    )
    assert (params.xy_vel_p, params.offboard_loss_action, params.mass_kg) == (2.5, 5, 2.0)
    assert params.drag_coefficient_nspm == 0.15  # the airframe's, the file did not set it
    assert ignored == ["CAL_ACC0_ID"]
    as_json = tmp_path / "drone.json"
    as_json.write_text(json.dumps({"MPC_XY_P": 1.2, "SIH_KL": None}))
    assert read_px4_parameter_file(as_json) == {"MPC_XY_P": 1.2}
    with pytest.raises(ValidationError):
        params_with_px4_values({"MPC_TILTMAX_AIR": 120.0})  # outside the field's bounds
    assert set(AIRFRAMES) == {"sih_quadx", "low_drag_1500g"}


def test_the_controller_flies_the_estimate_and_the_truth_drifts() -> None:
    params, _ = vehicle_params(VehicleSimParams(seed=3), estimation_error=True)
    assert (
        params.ekf_velocity_error_std_mps == PX4_SITL_ESTIMATION_ERROR["ekf_velocity_error_std_mps"]
    )
    vehicle = Multirotor(params)
    target = np.array([0.0, 0.0, -5.0])
    vehicle.reset(target, 0.0)
    vehicle.set_position_setpoint(target, yaw_rad=0.0)
    estimate_errors, truth_errors, heading_errors = [], [], []
    for _ in range(600):  # 30 s
        vehicle.step(0.05)
        estimate_errors.append(np.linalg.norm(vehicle.estimate.position_ned_m - target))
        truth_errors.append(np.linalg.norm(vehicle.state.position_ned_m - target))
        heading_errors.append(abs(vehicle.estimate.yaw_rad - vehicle.state.yaw_rad))
    # PX4 holds its estimate near the setpoint (as in PX4 SITL, within a few decimetres: the
    # estimate moves under it); the truth wanders farther, by the estimate's own error
    assert np.median(estimate_errors[100:]) < 0.5
    assert np.median(estimate_errors[100:]) < np.median(truth_errors[100:]) < 1.5
    assert 0.2 < math.degrees(max(heading_errors)) < 25.0
    # seeded: the same flight again
    again = Multirotor(params)
    again.reset(target, 0.0)
    again.set_position_setpoint(target, yaw_rad=0.0)
    for _ in range(600):
        again.step(0.05)
    assert np.allclose(again.state.position_ned_m, vehicle.state.position_ned_m)
