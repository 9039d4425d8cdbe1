"""PX4's attitude and rate control and the quadrotor mixer, as PX4-Autopilot main runs them.

`AttitudeController` is PX4's `AttitudeControl` (mc_att_control): the thrust vector and yaw
setpoint become an attitude (ControlMath::thrustToAttitude); the error is split into the
reduced (tilt) attitude and a yaw part weighted by MC_YAW_WEIGHT, and the quaternion error
times MC_*_P gives body rates (yaw-rate feed-forward, MC_*RATE_MAX limits). `RateController`
is PX4's `RateControl` (mc_rate_control): PID on the rate error with the D term on the low-passed
angular acceleration (IMU_DGYRO_CUTOFF), the I factor and integrator limits, and the yaw torque
low-pass (MC_YAW_TQ_CUTOFF); its output is a torque normalised to the mixer's range.
`quad_x_motor_commands` is PX4's pseudo-inverse allocation of the SIH quadrotor X (airframe
10040: rotors at (+-1, +-1), roll/pitch normalised to +-1/sqrt(2) per rotor, yaw to +-1) with
the airmode-off desaturation: thrust only reduced, roll/pitch scaled down, yaw mixed last.
Frames: world NED, body FRD; quaternions (w, x, y, z) body -> NED.
"""

from __future__ import annotations

import math

import numpy as np

from hil.vehicle.params import VehicleSimParams

# Rotor order and signs of PX4's quadrotor X (CA_ROTOR0..3 of airframe 10040) as SIH mixes
# them: roll moment (-u0 + u1 + u2 - u3), pitch (u0 - u1 + u2 - u3), yaw (u0 + u1 - u2 - u3).
ROLL_SIGNS = (-1.0, 1.0, 1.0, -1.0)
PITCH_SIGNS = (1.0, -1.0, 1.0, -1.0)
YAW_SIGNS = (1.0, 1.0, -1.0, -1.0)
_RP_MIX = 1.0 / math.sqrt(2.0)  # PX4 normalize_rpy: roll/pitch scale of a symmetric quad X


Quat = tuple[float, float, float, float]
Vec3 = tuple[float, float, float]


def _cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _qmul(a: Quat, b: Quat) -> Quat:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def _qconj(q: Quat) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


def _canonical(q: Quat) -> Quat:
    return q if q[0] >= 0.0 else (-q[0], -q[1], -q[2], -q[3])


def _dcm_z(q: Quat) -> Vec3:
    """Third column of the rotation of q: the body z axis in NED."""
    w, x, y, z = q
    return (2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y))


def _quaternion_from_axes(bx: Vec3, by: Vec3, bz: Vec3) -> Quat:
    """Unit quaternion (w >= 0) of the rotation with columns bx, by, bz (Shepperd)."""
    r00, r11, r22 = bx[0], by[1], bz[2]
    trace = r00 + r11 + r22
    if trace >= max(r00, r11, r22):
        s = 2.0 * math.sqrt(1.0 + trace)
        q = (0.25 * s, (by[2] - bz[1]) / s, (bz[0] - bx[2]) / s, (bx[1] - by[0]) / s)
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        q = ((by[2] - bz[1]) / s, 0.25 * s, (by[0] + bx[1]) / s, (bz[0] + bx[2]) / s)
    elif r11 >= r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        q = ((bz[0] - bx[2]) / s, (by[0] + bx[1]) / s, 0.25 * s, (bz[1] + by[2]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
        q = ((bx[1] - by[0]) / s, (bz[0] + bx[2]) / s, (bz[1] + by[2]) / s, 0.25 * s)
    n = math.sqrt(sum(c * c for c in q))
    return _canonical((q[0] / n, q[1] / n, q[2] / n, q[3] / n))


def attitude_from_body_z(body_z: np.ndarray, yaw_rad: float) -> np.ndarray:
    """Quaternion (w, x, y, z) whose body z axis is `body_z` (NED) with heading `yaw_rad`.

    PX4 ControlMath::bodyzToAttitude: x_b = y_C x z_b with y_C the yaw direction turned 90 deg.
    """
    return np.array(_attitude_from_body_z(tuple(body_z.tolist()), yaw_rad))


def _attitude_from_body_z(bz: Vec3, yaw_rad: float) -> Quat:
    y_c = (-math.sin(yaw_rad), math.cos(yaw_rad), 0.0)
    bx = _cross(y_c, bz)
    if bz[2] < 0.0:
        bx = (-bx[0], -bx[1], -bx[2])
    if abs(bz[2]) < 1e-6:
        bx = (0.0, 0.0, 1.0)
    n = math.sqrt(bx[0] ** 2 + bx[1] ** 2 + bx[2] ** 2)
    bx = (bx[0] / n, bx[1] / n, bx[2] / n)
    return _quaternion_from_axes(bx, _cross(bz, bx), bz)


def _quaternion_between(a: Vec3, b: Vec3) -> Quat:
    """The shortest rotation taking unit vector a onto unit vector b (PX4 Quatf(a, b))."""
    cr = _cross(a, b)
    dt = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    if cr[0] ** 2 + cr[1] ** 2 + cr[2] ** 2 < 1e-12 and dt < 0.0:
        # opposite vectors: 180 deg about any perpendicular axis
        axis = _cross(a, (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0))
        n = math.sqrt(sum(c * c for c in axis))
        return (0.0, axis[0] / n, axis[1] / n, axis[2] / n)
    q = (dt + 1.0, *cr)
    n = math.sqrt(sum(c * c for c in q))
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


class AttitudeController:
    """PX4 AttitudeControl: attitude setpoint -> body-rate setpoint, FRD rad/s."""

    def __init__(self, params: VehicleSimParams) -> None:
        self._p = params

    def rate_setpoint(
        self, attitude_wxyz: np.ndarray, setpoint_wxyz: np.ndarray, yaw_rate_ff_radps: float
    ) -> np.ndarray:
        """(3,) body rates towards `setpoint_wxyz`, yaw priority MC_YAW_WEIGHT."""
        q = tuple(attitude_wxyz.tolist())
        qd = tuple(setpoint_wxyz.tolist())
        return np.array(self.rates(q, qd, yaw_rate_ff_radps))

    def rates(self, q: Quat, qd: Quat, yaw_rate_ff_radps: float) -> Vec3:
        """`rate_setpoint` on tuples (the hot path of the simulation)."""
        p = self._p
        yaw_w = min(max(p.yaw_weight, 0.0), 1.0)
        # reduced desired attitude: only the tilt, keeping the current yaw
        q_red = _quaternion_between(_dcm_z(q), _dcm_z(qd))
        if abs(q_red[1]) > 1.0 - 1e-5 or abs(q_red[2]) > 1.0 - 1e-5:
            q_red = qd
        else:
            q_red = _qmul(q_red, q)
        q_mix = _canonical(_qmul(_qconj(q_red), qd))
        w0 = min(max(q_mix[0], -1.0), 1.0)
        w3 = min(max(q_mix[3], -1.0), 1.0)
        q_d = _qmul(
            q_red, (math.cos(yaw_w * math.acos(w0)), 0.0, 0.0, math.sin(yaw_w * math.asin(w3)))
        )
        q_e = _canonical(_qmul(_qconj(q), q_d))
        yaw_gain = p.yaw_p / yaw_w if yaw_w > 1e-4 else p.yaw_p
        rates = [2.0 * q_e[1] * p.roll_p, 2.0 * q_e[2] * p.pitch_p, 2.0 * q_e[3] * yaw_gain]
        if math.isfinite(yaw_rate_ff_radps) and yaw_rate_ff_radps != 0.0:
            # world down in body axes: the third row of R(q)
            w, x, y, z = q
            down = (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))
            rates = [rates[i] + down[i] * yaw_rate_ff_radps for i in range(3)]
        limits = (
            math.radians(p.roll_rate_max_deg_s),
            math.radians(p.pitch_rate_max_deg_s),
            math.radians(p.yaw_rate_max_deg_s),
        )
        return (
            min(max(rates[0], -limits[0]), limits[0]),
            min(max(rates[1], -limits[1]), limits[1]),
            min(max(rates[2], -limits[2]), limits[2]),
        )


def _low_pass_alpha(dt_s: float, cutoff_hz: float) -> float:
    if cutoff_hz <= 0.0:
        return 1.0
    return dt_s / (dt_s + 1.0 / (2.0 * math.pi * cutoff_hz))


class RateController:
    """PX4 RateControl: body-rate PID -> torque normalised to the mixer, roll/pitch/yaw."""

    def __init__(self, params: VehicleSimParams) -> None:
        self._p = params
        self.reset()

    def reset(self) -> None:
        """Zero the integrators and filters."""
        self.saturation: Vec3 = (0.0, 0.0, 0.0)  # the mixer's last cut per axis: +1, -1, 0
        self._rate_int = [0.0, 0.0, 0.0]
        self._last_rate: Vec3 | None = None
        self._ang_acc = [0.0, 0.0, 0.0]
        self._yaw_torque = 0.0

    def update(self, dt_s: float, rate: Vec3, rate_sp: Vec3, landed: bool) -> Vec3:
        """Torque setpoint in [-1, 1] for one step (FRD rates in rad/s)."""
        p = self._p
        gain_p = (
            p.roll_rate_k * p.roll_rate_p,
            p.pitch_rate_k * p.pitch_rate_p,
            p.yaw_rate_k * p.yaw_rate_p,
        )
        gain_i = (
            p.roll_rate_k * p.roll_rate_i,
            p.pitch_rate_k * p.pitch_rate_i,
            p.yaw_rate_k * p.yaw_rate_i,
        )
        gain_d = (
            p.roll_rate_k * p.roll_rate_d,
            p.pitch_rate_k * p.pitch_rate_d,
            p.yaw_rate_k * p.yaw_rate_d,
        )
        limits = (p.roll_rate_int_lim, p.pitch_rate_int_lim, p.yaw_rate_int_lim)
        if self._last_rate is not None:
            alpha = _low_pass_alpha(dt_s, p.dgyro_cutoff_hz)
            last = self._last_rate
            self._ang_acc = [
                a + alpha * ((rate[i] - last[i]) / dt_s - a) for i, a in enumerate(self._ang_acc)
            ]
        self._last_rate = rate
        torque = [0.0, 0.0, 0.0]
        for i in range(3):
            error = rate_sp[i] - rate[i]
            torque[i] = gain_p[i] * error + self._rate_int[i] - gain_d[i] * self._ang_acc[i]
            if not landed:
                # no integration further into the mixer's saturation (PX4 updateIntegral)
                if self.saturation[i] > 0.0:
                    error = min(error, 0.0)
                elif self.saturation[i] < 0.0:
                    error = max(error, 0.0)
                i_factor = max(0.0, 1.0 - (error / math.radians(400.0)) ** 2)
                integral = self._rate_int[i] + i_factor * gain_i[i] * error * dt_s
                self._rate_int[i] = min(max(integral, -limits[i]), limits[i])
        self._yaw_torque += _low_pass_alpha(dt_s, p.yaw_torque_cutoff_hz) * (
            torque[2] - self._yaw_torque
        )
        return (
            min(max(torque[0], -1.0), 1.0),
            min(max(torque[1], -1.0), 1.0),
            min(max(self._yaw_torque, -1.0), 1.0),
        )


def quad_x_motor_commands(collective: float, torque: Vec3) -> tuple[list[float], Vec3]:
    """Motor commands (4) in [0, 1] for a collective thrust (0..1) and normalised torque,
    and the saturation per axis: +1 / -1 where the torque was cut in that direction.

    PX4 ControlAllocationSequentialDesaturation with airmode off: roll/pitch first (thrust only
    ever reduced to make room, then roll/pitch scaled down), yaw added last and scaled to fit.
    """
    rp = [_RP_MIX * (ROLL_SIGNS[i] * torque[0] + PITCH_SIGNS[i] * torque[1]) for i in range(4)]
    base = [collective] * 4
    top = max(collective + d for d in rp)
    if top > 1.0:
        base = [b - (top - 1.0) for b in base]
    scale = 1.0
    for b, d in zip(base, rp, strict=True):
        if b + d < 0.0 and d < 0.0:
            scale = min(scale, max(b, 0.0) / -d)
    sat_r = sat_p = sat_y = 0.0
    if scale < 1.0:
        sat_r, sat_p = math.copysign(1.0, torque[0]), math.copysign(1.0, torque[1])
    u = [b + d * scale for b, d in zip(base, rp, strict=True)]
    yaw = [YAW_SIGNS[i] * torque[2] for i in range(4)]
    scale = 1.0
    for b, d in zip(u, yaw, strict=True):
        if d > 0.0 and b + d > 1.0:
            scale = min(scale, max(1.0 - b, 0.0) / d)
        elif d < 0.0 and b + d < 0.0:
            scale = min(scale, max(b, 0.0) / -d)
    if scale < 1.0:
        sat_y = math.copysign(1.0, torque[2])
    return [min(max(b + d * scale, 0.0), 1.0) for b, d in zip(u, yaw, strict=True)], (
        sat_r,
        sat_p,
        sat_y,
    )
