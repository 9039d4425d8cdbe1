"""Jumps of the autopilot's local frame (an estimator reset), seen from consecutive positions.

When PX4's estimator resets, its local position jumps while the vehicle does not move: every
pose after it is in a shifted frame, so the map built before it (registered at the old poses)
no longer lines up with the vehicle. The flight process and its replay both ask
`pose_jump_m` of each new local position; above `flight.pose_jump_m` the map is rebuilt.
"""

from __future__ import annotations

import numpy as np

from companion.link.telemetry import LocalPosition


def pose_jump_m(previous: LocalPosition | None, current: LocalPosition, max_gap_s: float) -> float:
    """How far `current` lies from where `previous` predicts it at constant velocity, m.

    0 without a previous position, or when the two are more than `max_gap_s` apart (too long
    for the prediction: after a link loss the vehicle may have flown anywhere).
    """
    if previous is None:
        return 0.0
    dt_s = current.stamp_s - previous.stamp_s
    if not 0.0 <= dt_s <= max_gap_s:
        return 0.0
    predicted = previous.position_ned_m + dt_s * previous.velocity_ned_mps
    return float(np.linalg.norm(current.position_ned_m - predicted))
