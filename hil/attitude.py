"""Quaternion helpers for attitudes. Quaternions are (w, x, y, z), Hamilton, body FRD -> world NED.

`mapping.pose.rotation_from_quaternion(q) @ v_frd` gives the NED vector; Euler angles are the
aerospace Z-Y-X (yaw, pitch, roll) sequence PX4 and MAVLink use.
"""

from __future__ import annotations

import numpy as np


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b of (4,) quaternions (w, x, y, z)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def quaternion_conjugate(q: np.ndarray) -> np.ndarray:
    """Inverse of a unit quaternion (w, x, y, z)."""
    return np.array([q[0], -q[1], -q[2], -q[3]])


def quaternion_from_rotation_vector(rotvec_rad: np.ndarray) -> np.ndarray:
    """Unit quaternion of a rotation by |rotvec| rad about rotvec/|rotvec| (the exponential map)."""
    angle = float(np.linalg.norm(rotvec_rad))
    if angle < 1e-12:
        return np.array([1.0, 0.5 * rotvec_rad[0], 0.5 * rotvec_rad[1], 0.5 * rotvec_rad[2]])
    axis = rotvec_rad / angle
    s = np.sin(0.5 * angle)
    return np.array([np.cos(0.5 * angle), axis[0] * s, axis[1] * s, axis[2] * s])


def quaternion_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Unit quaternion of Z-Y-X Euler angles (yaw, then pitch, then roll), rad."""
    cr, sr = np.cos(0.5 * roll_rad), np.sin(0.5 * roll_rad)
    cp, sp = np.cos(0.5 * pitch_rad), np.sin(0.5 * pitch_rad)
    cy, sy = np.cos(0.5 * yaw_rad), np.sin(0.5 * yaw_rad)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def euler_from_quaternion(q: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in rad, Z-Y-X, of the unit quaternion q."""
    w, x, y, z = q
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return float(roll), float(pitch), float(yaw)


def wrap_pi(angle_rad: float) -> float:
    """Angle wrapped into [-pi, pi), rad."""
    return float((angle_rad + np.pi) % (2.0 * np.pi) - np.pi)
