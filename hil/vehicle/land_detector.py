"""PX4's multicopter land detector (land_detector/MulticopterLandDetector), on the estimate.

Three stages, each with PX4's hysteresis: ground contact (no vertical movement while a descent
is commanded, or low thrust; 0.35 s), maybe landed (ground contact at minimal thrust, not
rotating; 0.25 s), landed (maybe landed for 0.3 s). Leaving `landed` needs the vehicle to be
clearly flying (thrust above the low-thrust level, or moving), as in PX4. Thresholds:
LNDMC_Z_VEL_MAX, LNDMC_XY_VEL_MAX, LNDMC_ROT_MAX; low thrust is 30% and minimal thrust 10% of
the way from MPC_THR_MIN to MPC_THR_HOVER. PX4 takes seconds to see a touchdown in Land's crawl
(the velocity integrator must wind the thrust down to the low-thrust level first), and so does
this one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.vehicle.params import VehicleSimParams

# PX4 LandDetector.h / MulticopterLandDetector.h hysteresis times
GROUND_CONTACT_TRIGGER_S = 0.35
MAYBE_LANDED_TRIGGER_S = 0.25
LANDED_TRIGGER_S = 0.3


class _Hysteresis:
    """True once the input has been true for `rise_s` (falls at once), like PX4's hysteresis."""

    def __init__(self, rise_s: float, state: bool) -> None:
        self.rise_s = rise_s
        self.state = state
        self._since_s: float | None = None

    def update(self, value: bool, now_s: float) -> bool:
        if not value:
            self._since_s = None
            self.state = False
        else:
            if self._since_s is None:
                self._since_s = now_s
            if now_s - self._since_s >= self.rise_s:
                self.state = True
        return self.state


@dataclass(frozen=True)
class LandDetectorInput:
    """What the detector reads each step (the estimate and the controllers' outputs)."""

    now_s: float
    velocity_ned_mps: np.ndarray  # (3,) estimated
    angular_velocity_frd_radps: np.ndarray  # (3,)
    collective_thrust: float  # normalised 0..1
    velocity_setpoint_z_mps: float  # NaN when vertical velocity is not controlled
    armed: bool


class LandDetector:
    """PX4's ground contact / maybe landed / landed states."""

    def __init__(self, params: VehicleSimParams) -> None:
        self._p = params
        self._ground_contact = _Hysteresis(GROUND_CONTACT_TRIGGER_S, True)
        self._maybe_landed = _Hysteresis(MAYBE_LANDED_TRIGGER_S, True)
        self._landed = _Hysteresis(LANDED_TRIGGER_S, True)

    @property
    def landed(self) -> bool:
        """vehicle_land_detected.landed."""
        return self._landed.state

    @property
    def ground_contact(self) -> bool:
        """vehicle_land_detected.ground_contact."""
        return self._ground_contact.state

    def update(self, x: LandDetectorInput) -> bool:
        """Run one step; the landed state."""
        p = self._p
        if not x.armed:
            # disarmed on the ground is landed at once
            for stage in (self._ground_contact, self._maybe_landed, self._landed):
                stage.state = True
                stage._since_s = None
            return True
        span = p.hover_thrust - p.thr_min
        low_thrust = x.collective_thrust <= p.thr_min + 0.3 * span
        minimal_thrust = x.collective_thrust <= p.thr_min + 0.1 * span
        land_speed_threshold = 0.9 * max(p.land_speed_mps, 0.1)
        max_climb_mps = min(0.5 * land_speed_threshold, p.land_detect_z_vel_max_mps)
        vertical_movement = abs(float(x.velocity_ned_mps[2])) > max_climb_mps
        horizontal_movement = (
            float(np.hypot(*x.velocity_ned_mps[:2])) > p.land_detect_xy_vel_max_mps
        )
        in_descend = math.isfinite(x.velocity_setpoint_z_mps) and (
            x.velocity_setpoint_z_mps >= land_speed_threshold
        )
        hit_ground = in_descend and not vertical_movement
        contact = (low_thrust or hit_ground) and not horizontal_movement and not vertical_movement
        rotating = float(np.linalg.norm(x.angular_velocity_frd_radps)) > math.radians(
            p.land_detect_rot_max_deg_s
        )
        self._ground_contact.update(contact, x.now_s)
        self._maybe_landed.update(
            self._ground_contact.state and minimal_thrust and not rotating, x.now_s
        )
        self._landed.update(self._maybe_landed.state, x.now_s)
        return self._landed.state
