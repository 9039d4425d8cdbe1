"""Keyframe selection from a flight (thesis 3.4.2).

A frame becomes a keyframe when the camera has moved at least `min_translation_m` or turned
at least `min_rotation_rad` (quaternion geodesic distance) since the previous keyframe.
The thresholds are `MappingParams.keyframe_translation_m` / `keyframe_rotation_deg`, shared
with DROAN's pose graph (4.4.6), so they are defined once.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from geometry.pose import Pose


def is_new_keyframe(
    last_keyframe: Pose | None, pose: Pose, min_translation_m: float, min_rotation_rad: float
) -> bool:
    """True if `pose` (world_from_camera) is far enough from the last keyframe (3.4.2)."""
    if last_keyframe is None:
        return True
    return (
        last_keyframe.translation_to(pose) >= min_translation_m
        or last_keyframe.angle_to(pose) >= min_rotation_rad
    )


def select_keyframes(
    poses: Sequence[Pose], min_translation_m: float, min_rotation_rad: float
) -> np.ndarray:
    """`(K,) int` indices of the chronological keyframes of a flight's camera poses (3.4.2)."""
    selected: list[int] = []
    for index, pose in enumerate(poses):
        last = poses[selected[-1]] if selected else None
        if is_new_keyframe(last, pose, min_translation_m, min_rotation_rad):
            selected.append(index)
    return np.array(selected, dtype=int)
