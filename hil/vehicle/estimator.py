"""The estimator's error: what PX4's EKF2 reports, against the simulator's truth.

PX4 flies on its estimate, not on the truth, and the estimate drifts: against SIH's ground truth
(three PX4 SITL flights) the heading was off 3-9 deg on average (up to 24), the velocity by
0.2-0.3 m/s RMS per horizontal axis with a correlation time of 2-3 s, the horizontal position by
about 0.3 m, the altitude by 0.3-0.4 m RMS (up to 0.9). `EstimatorError` draws such errors as
seeded first-order Gauss-Markov processes: a velocity error whose integral is the horizontal
position error (pulled back by GPS with `ekf_gps_correction_time_constant_s`), an altitude
error (baro drift) and a heading error. With every std zero the estimate is the truth.
The controller and the telemetry both read `estimate(truth)`; the truth stays for judging.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from geometry.rotation import quaternion_from_euler, quaternion_multiply
from hil.vehicle.params import VehicleSimParams
from hil.vehicle.state import RigidBodyState, frozen

# What three PX4 SITL flights of airframe 10040 showed (estimate - truth, armed), to reproduce
# with `vehicle-sim --estimation-error`; see ../shared/data/px4-sitl-traces.
PX4_SITL_ESTIMATION_ERROR: dict[str, float] = {
    "ekf_velocity_error_std_mps": 0.22,
    "ekf_velocity_error_time_constant_s": 2.5,
    "ekf_gps_correction_time_constant_s": 2.0,
    "ekf_altitude_error_std_m": 0.3,
    "ekf_altitude_error_time_constant_s": 4.0,
    "ekf_heading_error_std_deg": 5.0,
    "ekf_heading_error_time_constant_s": 10.0,
}


class EstimatorError:
    """Seeded, correlated estimate errors (NED m, m/s, rad), advanced on simulated time."""

    def __init__(self, params: VehicleSimParams, rng: np.random.Generator) -> None:
        self._p = params
        self._rng = rng
        self._velocity_unit = np.zeros(3)  # unit-std Gauss-Markov, scaled by the std when read
        self._position_xy_m = np.zeros(2)
        self._altitude_m = 0.0
        self.heading_rad = 0.0

    @property
    def enabled(self) -> bool:
        """Whether any error is drawn."""
        p = self._p
        return (
            p.ekf_velocity_error_std_mps > 0.0
            or p.ekf_altitude_error_std_m > 0.0
            or p.ekf_heading_error_std_deg > 0.0
        )

    @property
    def velocity_ned_mps(self) -> np.ndarray:
        """(3,) velocity error now, NED m/s (vertical: half the horizontal std)."""
        std = self._p.ekf_velocity_error_std_mps
        return self._velocity_unit * np.array([std, std, 0.5 * std])

    @property
    def position_ned_m(self) -> np.ndarray:
        """(3,) position error now, NED m (z: the altitude error, positive down)."""
        return np.array([*self._position_xy_m, self._altitude_m])

    def _markov(self, value: np.ndarray | float, std: float, tau_s: float, dt_s: float) -> Any:
        decay = math.exp(-dt_s / tau_s)
        size = None if np.isscalar(value) else np.shape(value)
        return value * decay + self._rng.normal(0.0, std * math.sqrt(1.0 - decay * decay), size)

    def step(self, dt_s: float) -> None:
        """Advance the error processes by `dt_s`."""
        if not self.enabled:
            return
        p = self._p
        self._velocity_unit = self._markov(
            self._velocity_unit, 1.0, p.ekf_velocity_error_time_constant_s, dt_s
        )
        drift = self.velocity_ned_mps[:2]
        pull = self._position_xy_m / p.ekf_gps_correction_time_constant_s
        self._position_xy_m = self._position_xy_m + (drift - pull) * dt_s
        self._altitude_m = self._markov(
            self._altitude_m, p.ekf_altitude_error_std_m, p.ekf_altitude_error_time_constant_s, dt_s
        )
        self.heading_rad = self._markov(
            self.heading_rad,
            math.radians(p.ekf_heading_error_std_deg),
            p.ekf_heading_error_time_constant_s,
            dt_s,
        )

    def apply(
        self, position: list[float], velocity: list[float], attitude: tuple[float, ...]
    ) -> tuple[list[float], list[float], tuple[float, ...]]:
        """The estimate of a true (position, velocity, attitude quaternion), as floats."""
        if not self.enabled:
            return position, velocity, attitude
        dp = self.position_ned_m.tolist()
        dv = self.velocity_ned_mps.tolist()
        half = 0.5 * self.heading_rad
        c, s = math.cos(half), math.sin(half)
        w, x, y, z = attitude
        # heading error about world down, applied before the attitude: q_err * q
        q = (c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w)
        return (
            [position[i] + dp[i] for i in range(3)],
            [velocity[i] + dv[i] for i in range(3)],
            q,
        )

    def estimate(self, truth: RigidBodyState) -> RigidBodyState:
        """`truth` as the estimator reports it (the truth itself when disabled)."""
        if not self.enabled:
            return truth
        return dataclasses.replace(
            truth,
            position_ned_m=frozen(truth.position_ned_m + self.position_ned_m),
            velocity_ned_mps=frozen(truth.velocity_ned_mps + self.velocity_ned_mps),
            attitude_wxyz=frozen(
                quaternion_multiply(
                    quaternion_from_euler(0.0, 0.0, self.heading_rad), truth.attitude_wxyz
                )
            ),
        )
