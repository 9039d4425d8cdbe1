"""The 3D trajectory library of thesis 4.5 (Fig. 4.8): generation, array form, world transform.

Every trajectory is a manoeuvre of a point-mass multirotor with a heading: straight, left and
right turns of several curvatures, climbs and descents, their combinations (every turn with
every climb at every target speed) and a stop. Each is integrated forward from a given
initial speed under the vehicle limits (speed, acceleration, jerk, yaw rate; the lateral
jerk v * d(yaw rate)/dt is bounded too), then sampled into m waypoints with times.

Library frame: origin at the vehicle, x forward along the initial horizontal velocity (or the
nose when hovering), y right, z down; `to_world` turns it into local NED by the heading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planning.params import PlanningParams

_MIN_TURN_SPEED_MPS = 0.1  # floor of v in the lateral limits a_max / v and j_max / v


@dataclass(frozen=True, slots=True)
class TrajectoryLibrary:
    """Trajectories for S initial speeds x K manoeuvres x M waypoints.

    initial_speeds_mps: (S,) speeds each bin is built at, ascending, m/s.
    times_s: (M,) waypoint times t_1..t_m after the start (t_0 = 0 is the start itself), s.
    positions_m: (S, K, M, 3) waypoints, library frame (x fwd, y right, z down), m.
    velocities_mps: (S, K, M, 3) velocities at the waypoints, library frame, m/s.
    yaw_rates_radps: (K,) commanded turn rate, + turns right, rad/s.
    vertical_speeds_mps: (K,) commanded vertical speed, + descends (NED), m/s.
    target_speeds_mps: (K,) commanded horizontal speed, m/s.
    labels: (K,) names like "straight", "right-2 climb-1 v1.0", "stop".
    stop_index: index of the stop manoeuvre in K.
    """

    initial_speeds_mps: np.ndarray
    times_s: np.ndarray
    positions_m: np.ndarray
    velocities_mps: np.ndarray
    yaw_rates_radps: np.ndarray
    vertical_speeds_mps: np.ndarray
    target_speeds_mps: np.ndarray
    labels: tuple[str, ...]
    stop_index: int

    @property
    def size(self) -> int:
        """K, manoeuvres per speed bin."""
        return len(self.labels)

    def bin_for_speed(self, speed_mps: float) -> int:
        """Index of the speed bin nearest `speed_mps`."""
        return int(np.argmin(np.abs(self.initial_speeds_mps - speed_mps)))

    def to_world(
        self, bin_index: int, origin_ned_m: np.ndarray, heading_rad: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Positions (K, M, 3) and velocities (K, M, 3) of one bin in local NED, m and m/s.

        The library frame is rotated about down by `heading_rad` (0 = north) and moved to
        `origin_ned_m` (3,).
        """
        c, s = np.cos(heading_rad), np.sin(heading_rad)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        positions = self.positions_m[bin_index] @ rot.T + np.asarray(origin_ned_m, float)
        velocities = self.velocities_mps[bin_index] @ rot.T
        return positions, velocities

    def as_arrays(self) -> dict[str, np.ndarray]:
        """Plain arrays (for `np.savez`); `from_arrays` inverts it."""
        return {
            "initial_speeds_mps": self.initial_speeds_mps,
            "times_s": self.times_s,
            "positions_m": self.positions_m,
            "velocities_mps": self.velocities_mps,
            "yaw_rates_radps": self.yaw_rates_radps,
            "vertical_speeds_mps": self.vertical_speeds_mps,
            "target_speeds_mps": self.target_speeds_mps,
            "labels": np.array(self.labels, dtype=np.str_),
            "stop_index": np.array(self.stop_index),
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> TrajectoryLibrary:
        """The library stored by `as_arrays`, with its shapes checked."""
        positions = np.asarray(arrays["positions_m"], float)
        velocities = np.asarray(arrays["velocities_mps"], float)
        speeds = np.asarray(arrays["initial_speeds_mps"], float)
        times = np.asarray(arrays["times_s"], float)
        labels = tuple(str(label) for label in arrays["labels"])
        shape = (len(speeds), len(labels), len(times), 3)
        if positions.shape != shape or velocities.shape != shape:
            raise ValueError(f"library arrays have shape {positions.shape}, expected {shape}")
        return cls(
            initial_speeds_mps=speeds,
            times_s=times,
            positions_m=positions,
            velocities_mps=velocities,
            yaw_rates_radps=np.asarray(arrays["yaw_rates_radps"], float),
            vertical_speeds_mps=np.asarray(arrays["vertical_speeds_mps"], float),
            target_speeds_mps=np.asarray(arrays["target_speeds_mps"], float),
            labels=labels,
            stop_index=int(arrays["stop_index"]),
        )


def _manoeuvres(params: PlanningParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Commanded (yaw rate, vertical speed, target speed) and label of each of the K."""
    yaw_rates, vertical, speeds, labels = [], [], [], []
    turn_rate_step = params.max_heading_change_rad / params.horizon_s / max(params.turn_levels, 1)
    climb_step = params.max_vertical_speed_mps / max(params.climb_levels, 1)
    for speed_level in range(params.speed_levels, 0, -1):
        speed = params.max_speed_mps * speed_level / params.speed_levels
        for turn in range(-params.turn_levels, params.turn_levels + 1):
            for climb in range(-params.climb_levels, params.climb_levels + 1):
                parts = []
                if turn:
                    parts.append(f"{'right' if turn > 0 else 'left'}-{abs(turn)}")
                if climb:
                    parts.append(f"{'climb' if climb > 0 else 'descend'}-{abs(climb)}")
                label = " ".join(parts) or "straight"
                if speed_level != params.speed_levels:
                    label += f" v{speed:.1f}"
                yaw_rates.append(turn * turn_rate_step)
                vertical.append(-climb * climb_step)  # NED: climbing is negative down speed
                speeds.append(speed)
                labels.append(label)
    yaw_rates.append(0.0)
    vertical.append(0.0)
    speeds.append(0.0)
    labels.append("stop")
    return np.array(yaw_rates), np.array(vertical), np.array(speeds), labels


def _jerk_limited_accel(
    error: np.ndarray, accel: np.ndarray, accel_max: float, jerk_max: np.ndarray, dt_s: float
) -> np.ndarray:
    """Next acceleration driving `error` (target - value) to 0 without overshoot.

    The desired acceleration a = sign(e) * min(a_max, sqrt((j dt)^2 + 2 j |e|) - j dt) is the
    fastest that, held for this step (a dt) and then ramped down to zero at jerk j = j_max
    (a^2 / 2j), still closes the error without crossing it; the acceleration moves towards it
    by at most j_max * dt per step. dt_s = inf: no ramp, the desired acceleration of dt -> 0.
    """
    lag = jerk_max * dt_s if np.isfinite(dt_s) else np.zeros_like(jerk_max)
    reach = np.sqrt(lag * lag + 2.0 * jerk_max * np.abs(error)) - lag
    desired = np.sign(error) * np.minimum(accel_max, reach)
    return accel + np.clip(desired - accel, -jerk_max * dt_s, jerk_max * dt_s)


def generate_library(params: PlanningParams) -> TrajectoryLibrary:
    """The library of Fig. 4.8 for `params.speed_bins` initial speeds in [0, max_speed_mps].

    All S x K trajectories are integrated together (vectorised over bins and manoeuvres):
    horizontal speed and vertical speed follow jerk-limited profiles towards their targets,
    starting at the acceleration that profile asks for (the receding horizon replans every
    cycle, so a ramp from zero acceleration would be restarted forever);
    the yaw rate is bounded by `max_yaw_rate_radps` and by the lateral acceleration
    a_max / v, and changes no faster than j_max / v (lateral jerk).
    """
    yaw_rates, vertical, target_speeds, labels = _manoeuvres(params)
    speeds0 = np.linspace(0.0, params.max_speed_mps, params.speed_bins)
    n_bins, n_traj, m = len(speeds0), len(labels), params.waypoints
    dt = params.horizon_s / (m * params.integration_substeps)
    a_max, j_max = params.max_accel_mps2, params.max_jerk_mps3

    speed = np.repeat(speeds0[:, None], n_traj, axis=1)
    climb = np.zeros_like(speed)
    jerk = np.full_like(speed, j_max)
    # the receding horizon restarts the library every cycle: start each manoeuvre already
    # accelerating towards its targets, or the jerk ramp would never let the vehicle speed up
    speed_accel = _jerk_limited_accel(
        target_speeds - speed, np.zeros_like(speed), a_max, jerk, np.inf
    )
    climb_accel = _jerk_limited_accel(vertical - climb, np.zeros_like(speed), a_max, jerk, np.inf)
    heading = np.zeros_like(speed)
    yaw_rate = np.zeros_like(speed)
    position = np.zeros((n_bins, n_traj, 3))
    positions = np.empty((n_bins, n_traj, m, 3))
    velocities = np.empty((n_bins, n_traj, m, 3))
    for step in range(1, m * params.integration_substeps + 1):
        speed_accel = _jerk_limited_accel(target_speeds - speed, speed_accel, a_max, jerk, dt)
        climb_accel = _jerk_limited_accel(vertical - climb, climb_accel, a_max, jerk, dt)
        speed = np.maximum(speed + speed_accel * dt, 0.0)
        climb = climb + climb_accel * dt
        lateral_speed = np.maximum(speed, _MIN_TURN_SPEED_MPS)
        rate_limit = np.minimum(params.max_yaw_rate_radps, a_max / lateral_speed)
        rate_target = np.clip(yaw_rates, -rate_limit, rate_limit)
        yaw_accel = j_max / lateral_speed
        yaw_rate += np.clip(rate_target - yaw_rate, -yaw_accel * dt, yaw_accel * dt)
        heading += yaw_rate * dt
        velocity = np.stack([speed * np.cos(heading), speed * np.sin(heading), climb], axis=-1)
        position += velocity * dt
        if step % params.integration_substeps == 0:
            k = step // params.integration_substeps - 1
            positions[:, :, k] = position
            velocities[:, :, k] = velocity
    return TrajectoryLibrary(
        initial_speeds_mps=speeds0,
        times_s=np.arange(1, m + 1) * params.horizon_s / m,
        positions_m=positions,
        velocities_mps=velocities,
        yaw_rates_radps=yaw_rates,
        vertical_speeds_mps=vertical,
        target_speeds_mps=target_speeds,
        labels=tuple(labels),
        stop_index=len(labels) - 1,
    )
