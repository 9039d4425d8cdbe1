"""Rigid transforms and stamped pose histories.

Conventions (used by every module of wireavoid):
- World frame: local NED (x north, y east, z down), m.
- Body frame: FRD (x forward, y right, z down), the PX4 convention.
- Camera frame: x right, y down, z forward (optical axis), the OpenCV convention.
- A `Pose` named `a_from_b` maps points expressed in frame b into frame a:
  `p_a = rotation @ p_b + translation_m`. So `world_from_camera.translation_m` is the camera
  centre in the world and its rotation columns are the camera axes expressed in the world.
- Rotations, quaternions and Euler angles: `geometry.rotation`.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from geometry.rotation import (
    quaternion_from_rotation,
    rotation_from_quaternion,
    rotation_from_yaw_pitch_roll,
    slerp_quaternion,
)


@dataclass(frozen=True, slots=True)
class Pose:
    """Rigid transform `a_from_b`: `p_a = rotation @ p_b + translation_m`.

    rotation: `(3, 3) float64` proper rotation matrix.
    translation_m: `(3,) float64` origin of frame b expressed in frame a, m.
    """

    rotation: np.ndarray
    translation_m: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "rotation", np.asarray(self.rotation, dtype=np.float64))
        object.__setattr__(self, "translation_m", np.asarray(self.translation_m, dtype=np.float64))
        if self.rotation.shape != (3, 3) or self.translation_m.shape != (3,):
            raise ValueError("Pose needs a (3, 3) rotation and a (3,) translation")

    @classmethod
    def identity(cls) -> Pose:
        """The identity transform."""
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def from_quaternion(cls, quaternion_wxyz: np.ndarray, translation_m: np.ndarray) -> Pose:
        """Pose from a `(w, x, y, z)` quaternion (normalised here) and a translation, m."""
        return cls(rotation_from_quaternion(quaternion_wxyz), translation_m)

    @classmethod
    def from_yaw_pitch_roll(
        cls, yaw_rad: float, pitch_rad: float, roll_rad: float, translation_m: np.ndarray
    ) -> Pose:
        """Pose from Z-Y-X Euler angles (rad) and a translation (m); see module docstring."""
        return cls(rotation_from_yaw_pitch_roll(yaw_rad, pitch_rad, roll_rad), translation_m)

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> Pose:
        """Pose from a `(4, 4)` homogeneous matrix."""
        matrix = np.asarray(matrix, dtype=np.float64)
        return cls(matrix[:3, :3], matrix[:3, 3])

    def matrix(self) -> np.ndarray:
        """`(4, 4)` homogeneous matrix."""
        out = np.eye(4)
        out[:3, :3] = self.rotation
        out[:3, 3] = self.translation_m
        return out

    def quaternion_wxyz(self) -> np.ndarray:
        """`(4,)` unit quaternion `(w, x, y, z)` of the rotation, w >= 0."""
        return quaternion_from_rotation(self.rotation)

    def yaw_pitch_roll_rad(self) -> tuple[float, float, float]:
        """Z-Y-X Euler angles of the rotation, rad (pitch in [-pi/2, pi/2])."""
        r = self.rotation
        yaw = float(np.arctan2(r[1, 0], r[0, 0]))
        pitch = float(np.arcsin(np.clip(-r[2, 0], -1.0, 1.0)))
        roll = float(np.arctan2(r[2, 1], r[2, 2]))
        return yaw, pitch, roll

    def apply(self, points_m: np.ndarray) -> np.ndarray:
        """Map `(N, 3)` (or `(3,)`) points from frame b to frame a, m."""
        points_m = np.asarray(points_m, dtype=np.float64)
        return points_m @ self.rotation.T + self.translation_m

    def rotate(self, vectors: np.ndarray) -> np.ndarray:
        """Rotate `(N, 3)` (or `(3,)`) free vectors from frame b to frame a (no translation)."""
        return np.asarray(vectors, dtype=np.float64) @ self.rotation.T

    def compose(self, other: Pose) -> Pose:
        """`a_from_c = a_from_b.compose(b_from_c)`."""
        return Pose(
            self.rotation @ other.rotation,
            self.rotation @ other.translation_m + self.translation_m,
        )

    def __matmul__(self, other: Pose) -> Pose:
        """`a_from_b @ b_from_c == a_from_b.compose(b_from_c)`."""
        return self.compose(other)

    def inverse(self) -> Pose:
        """`b_from_a` of this `a_from_b`."""
        rotation_t = self.rotation.T
        return Pose(rotation_t, -rotation_t @ self.translation_m)

    def translation_to(self, other: Pose) -> float:
        """Distance between the two frames' origins (expressed in the same parent), m."""
        return float(np.linalg.norm(other.translation_m - self.translation_m))

    def angle_to(self, other: Pose) -> float:
        """Angle of the relative rotation between the two poses, rad, in [0, pi]."""
        cos_angle = (np.trace(self.rotation.T @ other.rotation) - 1.0) / 2.0
        return float(np.arccos(np.clip(cos_angle, -1.0, 1.0)))


def interpolate_pose(pose0: Pose, pose1: Pose, fraction: float) -> Pose:
    """Pose a `fraction` of the way from `pose0` (0) to `pose1` (1): slerp + linear translation."""
    q = slerp_quaternion(pose0.quaternion_wxyz(), pose1.quaternion_wxyz(), fraction)
    t = (1.0 - fraction) * pose0.translation_m + fraction * pose1.translation_m
    return Pose(rotation_from_quaternion(q), t)


class PoseHistory:
    """Bounded history of stamped poses, interpolated to image timestamps (4.4.6).

    Poses must be added in non-decreasing time order (older ones are ignored). `pose_at`
    interpolates between the two samples around the stamp; it extrapolates by holding the
    nearest sample for at most `max_extrapolation_s`, and returns None further out, so that an
    image is never registered with a pose that was not measured near its exposure time.
    """

    def __init__(self, max_extrapolation_s: float, max_samples: int) -> None:
        """`max_extrapolation_s`: `MappingParams.pose_max_extrapolation_s`; `max_samples`:
        `MappingParams.pose_history_size`."""
        self._stamps_s: deque[float] = deque(maxlen=max_samples)
        self._poses: deque[Pose] = deque(maxlen=max_samples)
        self._max_extrapolation_s = max_extrapolation_s

    def __len__(self) -> int:
        return len(self._stamps_s)

    def add(self, stamp_s: float, pose: Pose) -> None:
        """Append a pose sampled at `stamp_s` (s, the same clock as the images)."""
        if self._stamps_s and stamp_s < self._stamps_s[-1]:
            return
        self._stamps_s.append(float(stamp_s))
        self._poses.append(pose)

    def pose_at(self, stamp_s: float) -> Pose | None:
        """The pose at `stamp_s` (s), interpolated; None when not covered by the history."""
        if not self._stamps_s:
            return None
        stamps = np.fromiter(self._stamps_s, dtype=np.float64, count=len(self._stamps_s))
        if stamp_s <= stamps[0]:
            return self._poses[0] if stamps[0] - stamp_s <= self._max_extrapolation_s else None
        if stamp_s >= stamps[-1]:
            return self._poses[-1] if stamp_s - stamps[-1] <= self._max_extrapolation_s else None
        i = int(np.searchsorted(stamps, stamp_s, side="right"))
        t0, t1 = stamps[i - 1], stamps[i]
        fraction = 0.0 if t1 <= t0 else (stamp_s - t0) / (t1 - t0)
        return interpolate_pose(self._poses[i - 1], self._poses[i], fraction)
