"""A real-time rate keeper: monotonic, accumulating deadlines that skip missed ticks.

Like openpilot's `common/realtime.py`: the deadline advances by whole periods from where it
started (it never drifts the way `sleep(period)` loops do); when a tick overruns by more than a
period, the missed ticks are skipped instead of being run back to back, and the lag is
reported rather than hidden.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class TickPlan:
    """What a loop does at `now_s` (monotonic, s) given its pending deadline."""

    sleep_s: float
    next_deadline_s: float
    skipped_ticks: int
    lag_s: float


def next_tick(deadline_s: float, now_s: float, period_s: float) -> TickPlan:
    """Sleep until `deadline_s` when early; when late, run at once and skip missed ticks.

    Early: sleep `deadline_s - now_s`, the next deadline is `deadline_s + period_s`, lag 0.
    Late by `lag_s`: no sleep, `floor(lag_s / period_s)` grid ticks are skipped and the next
    deadline is the first grid point after `now_s`, so the grid never drifts and the loop
    never bursts to catch up.
    """
    if now_s <= deadline_s:
        return TickPlan(deadline_s - now_s, deadline_s + period_s, 0, 0.0)
    lag_s = now_s - deadline_s
    skipped = math.floor(lag_s / period_s)
    return TickPlan(0.0, deadline_s + (skipped + 1) * period_s, skipped, lag_s)


class RateKeeper:
    """Paces an asyncio loop at `rate_hz` on the monotonic clock and measures its lag.

    Usage: `while True: work(); await keeper.wait()`. `clock` and `sleep` are injectable so
    tests can run it on simulated time.
    """

    def __init__(
        self,
        rate_hz: float,
        *,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
    ) -> None:
        if rate_hz <= 0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        self.period_s = 1.0 / rate_hz
        self._clock = clock
        self._sleep = sleep
        self._deadline_s: float | None = None
        self.ticks = 0
        self.skipped_ticks = 0
        self.last_lag_s = 0.0
        self.max_lag_s = 0.0

    async def wait(self) -> float:
        """Wait for the next tick; return how late it starts (0 when on time), s."""
        now_s = self._clock()
        if self._deadline_s is None:
            self._deadline_s = now_s + self.period_s
        plan = next_tick(self._deadline_s, now_s, self.period_s)
        self._deadline_s = plan.next_deadline_s
        self.ticks += 1
        self.skipped_ticks += plan.skipped_ticks
        self.last_lag_s = plan.lag_s
        self.max_lag_s = max(self.max_lag_s, plan.lag_s)
        await self._sleep(plan.sleep_s)
        return plan.lag_s
