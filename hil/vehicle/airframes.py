"""Airframes of the hil vehicle, and a real drone's PX4 parameters turned into one.

An airframe is a set of PX4 parameter values (PX4's names) applied over PX4's defaults:
- `sih_quadx` (the default): PX4 SITL's SIH quadrotor X, airframe 10040 `sihsim_quadx`
  (1 kg, SIH_KDV 1.0 drag, default MPC_*/MC_* gains); its flights match PX4 SITL's
  (`../shared/data/px4-sitl-traces`, `tests/test_px4_maneuvers.py`).
- `low_drag_1500g`: PX4's default gains on a 1.5 kg quadrotor with a real drone's light drag
  (0.15 N s/m): it reaches a velocity setpoint in about a second where SIH's strong drag makes
  PX4's integrator take many; the hil vehicle's airframe before it matched SIH.

Making one for a real drone (README "Flying against PX4 SITL"): export its parameters from
QGroundControl (Vehicle Setup > Parameters > Tools > Save to file: a `.params` file) and load them
with `wireavoid vehicle-sim --px4-params FILE`; every MPC_*/MC_*/COM_*/RTL_*/NAV_* value this
simulator models is then the drone's own. What PX4 does not store, the airframe's physics, goes
in SIH_* values in the same file: SIH_MASS (weigh it), SIH_T_MAX (thrust per rotor: SIH_MASS *
9.81 / 4 / hover throttle, the hover throttle from a flight log's `vehicle_thrust_setpoint` in
hover or MPC_THR_HOVER), SIH_KDV (linear drag: from a log, the steady speed v at a steady tilt
theta in level flight gives SIH_KDV = SIH_MASS * 9.81 * tan(theta) / v), SIH_IXX/IYY/IZZ and
SIH_L_ROLL/SIH_L_PITCH (arm lengths) from the frame, SIH_T_TAU (motor lag, ~0.03-0.05 s).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

from hil.vehicle.params import VehicleSimParams, px4_parameter_table

AIRFRAMES: dict[str, dict[str, float | int]] = {
    "sih_quadx": {},
    "low_drag_1500g": {
        "SIH_MASS": 1.5,
        "SIH_KDV": 0.15,
        "SIH_T_MAX": 7.355,  # hovers at 0.5 thrust: 1.5 kg * 9.81 / 4 / 0.5
        "SIH_IXX": 0.03,
        "SIH_IYY": 0.03,
        "SIH_IZZ": 0.05,
        "SIH_L_ROLL": 0.25,
        "SIH_L_PITCH": 0.25,
        "SIH_Q_MAX": 0.15,
        "SIH_T_TAU": 0.03,
    },
}
DEFAULT_AIRFRAME = "sih_quadx"


def params_with_px4_values(
    values: Mapping[str, float | int], base: VehicleSimParams | None = None
) -> tuple[VehicleSimParams, list[str]]:
    """`base` (defaults: PX4's) with the PX4-named `values` applied, and the names it does not
    simulate (ignored). Values are validated against each field's bounds."""
    table = px4_parameter_table()
    update: dict[str, float | int] = {}
    ignored = []
    for name, value in values.items():
        field = table.get(name)
        if field is None:
            ignored.append(name)
        else:
            update[field] = value
    base = base or VehicleSimParams()
    return VehicleSimParams.model_validate({**base.model_dump(), **update}), sorted(ignored)


def airframe_params(name: str, base: VehicleSimParams | None = None) -> VehicleSimParams:
    """The parameters of airframe `name` (see `AIRFRAMES`) over `base`."""
    if name not in AIRFRAMES:
        raise KeyError(f"unknown airframe {name!r}; known: {', '.join(sorted(AIRFRAMES))}")
    params, _ignored = params_with_px4_values(AIRFRAMES[name], base)
    return params


def vehicle_params(
    base: VehicleSimParams,
    *,
    airframe: str | None = None,
    px4_params_file: Path | None = None,
    estimation_error: bool = False,
) -> tuple[VehicleSimParams, list[str]]:
    """`base` with an airframe, then a PX4 parameter file, then PX4 SITL's estimation error
    applied, in that order; and the file's parameters this simulator does not model."""
    from hil.vehicle.estimator import PX4_SITL_ESTIMATION_ERROR

    params = base if airframe is None else airframe_params(airframe, base)
    ignored: list[str] = []
    if px4_params_file is not None:
        params, ignored = params_with_px4_values(read_px4_parameter_file(px4_params_file), params)
    if estimation_error:
        params = VehicleSimParams.model_validate(
            {**params.model_dump(), **PX4_SITL_ESTIMATION_ERROR}
        )
    return params, ignored


def read_px4_parameter_file(path: Path) -> dict[str, float | int]:
    """PX4 parameters from a QGroundControl `.params` file (tab-separated `vehicle component
    NAME value type` lines, `#` comments) or a JSON object {NAME: value}."""
    text = path.read_text()
    if text.lstrip().startswith("{"):
        return {str(k): v for k, v in json.loads(text).items() if v is not None}
    values: dict[str, float | int] = {}
    for line in text.splitlines():
        fields = line.split()
        if not fields or fields[0].startswith("#") or len(fields) < 5:
            continue
        name, value, kind = fields[2], fields[3], fields[4]
        # QGC's MAV_PARAM_TYPE: 9 REAL32, else an integer type
        values[name] = float(value) if kind == "9" else int(float(value))
    return values
