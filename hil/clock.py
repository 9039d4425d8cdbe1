"""Pacing of simulated time against the wall clock (the real-time factor of the SIL vehicle).

Simulated time advances in fixed steps; `RealTimePacer` sleeps so that simulated seconds pass at
`speed` times the wall clock, on an accumulating monotonic deadline (no drift). When the
simulation falls behind by more than `max_lag_s` it re-anchors instead of bursting, and counts
the lag it dropped, so a slow machine shows up as a reported lag rather than a time warp.
"""

from __future__ import annotations

import time


class RealTimePacer:
    """Sleeps until the wall time of a simulated instant: wall = anchor + sim / speed."""

    def __init__(self, speed: float, max_lag_s: float = 0.25) -> None:
        if speed <= 0.0:
            raise ValueError("speed must be > 0")
        self.speed = speed
        self.max_lag_s = max_lag_s
        self.dropped_lag_s = 0.0
        self._anchor_wall_s: float | None = None
        self._anchor_sim_s = 0.0

    def lag_s(self, sim_time_s: float) -> float:
        """How far the wall clock is ahead of the simulated instant, wall seconds (> 0: late)."""
        if self._anchor_wall_s is None:
            return 0.0
        deadline = self._anchor_wall_s + (sim_time_s - self._anchor_sim_s) / self.speed
        return time.monotonic() - deadline

    def wait_until(self, sim_time_s: float) -> None:
        """Block until simulated time `sim_time_s` is due on the wall clock."""
        now = time.monotonic()
        if self._anchor_wall_s is None:
            self._anchor_wall_s, self._anchor_sim_s = now, sim_time_s
            return
        deadline = self._anchor_wall_s + (sim_time_s - self._anchor_sim_s) / self.speed
        if deadline > now:
            time.sleep(deadline - now)
        elif now - deadline > self.max_lag_s:
            self.dropped_lag_s += now - deadline
            self._anchor_wall_s, self._anchor_sim_s = now, sim_time_s
