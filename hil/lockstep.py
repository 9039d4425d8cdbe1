"""Simulated time for the whole stack: the flight process and the hil vehicle in lockstep.

`LockstepClock` implements the flight process' clock (`now_s`, `sleep`, `compute`, see
`companion.clock.Clock`) on the vehicle's simulated time, and `run()` drives that time: it
advances the MAVLink vehicle (`hil.mavlink.server.VehicleServer(lockstep=True)`) one physics
step at a time and wakes the sleepers that are due, but only while no computation is running.
A computation (`compute`: the CNN, a map insert, a planner cycle) runs on its worker thread
while time stands still and then costs the process its measured wall duration in simulated
time (times `compute_scale`): the stack is judged as this machine would fly it, and the
simulator's own work (physics, rendering, which happens while time stands still) costs the
drone nothing. Real I/O still runs on the wall clock (MAVSDK's threads, UDP), so time never
runs faster than `max_speed` times the wall clock, which keeps MAVSDK's own heartbeats and
timeouts in step.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

from hil.mavlink.server import VehicleServer

T = TypeVar("T")


class LockstepClock:
    """The flight process' clock on the simulated time of a lockstep `VehicleServer`."""

    def __init__(
        self,
        server: VehicleServer,
        *,
        max_speed: float = 2.0,
        compute_scale: float = 1.0,
        settle_yields: int = 3,
    ) -> None:
        if not server.lockstep:
            raise ValueError("LockstepClock needs a VehicleServer(lockstep=True)")
        if max_speed <= 0 or compute_scale < 0:
            raise ValueError("max_speed must be > 0 and compute_scale >= 0")
        self.server = server
        self.max_speed = max_speed
        self.compute_scale = compute_scale
        self._settle_yields = settle_yields
        self._step_s = 1.0 / server.params.physics_rate_hz
        self._t = server.time_s
        self._timers: list[tuple[float, int, asyncio.Future[None]]] = []
        self._seq = itertools.count()
        self._busy = 0
        self._idle = asyncio.Event()
        self._idle.set()
        self._workers: dict[str, ThreadPoolExecutor] = {}
        self.compute_s = 0.0  # simulated time charged for computation so far

    # ------------------------------------------------------------------ the Clock protocol

    def now_s(self) -> float:
        """Simulated time, s (the vehicle's clock since boot)."""
        return self._t

    async def sleep(self, duration_s: float) -> None:
        """Wait until simulated time has advanced by `duration_s`."""
        if duration_s <= 0:
            await asyncio.sleep(0)
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._timers, (self._t + duration_s, next(self._seq), future))
        await future

    async def compute(self, worker: str, fn: Callable[..., T], *args: object) -> T:
        """`fn(*args)` on `worker`'s thread while time stands still; then its wall duration
        (times `compute_scale`) passes in simulated time before the result is returned."""
        pool = self._workers.get(worker)
        if pool is None:
            pool = self._workers[worker] = ThreadPoolExecutor(1, thread_name_prefix=worker)
        self._busy += 1
        self._idle.clear()
        start = time.perf_counter()
        try:
            result = await asyncio.get_running_loop().run_in_executor(pool, fn, *args)
        finally:
            took_s = time.perf_counter() - start
            self._busy -= 1
            if self._busy == 0:
                self._idle.set()
        charged_s = took_s * self.compute_scale
        self.compute_s += charged_s
        await self.sleep(charged_s)
        return result

    # ------------------------------------------------------------------ for the harness

    async def idle(self) -> None:
        """Wait until no computation runs (the harness renders then, so its work neither
        competes with a measured computation nor lets time pass)."""
        await self._idle.wait()

    async def run(self) -> None:
        """Drive simulated time until cancelled (run it as a task beside the process)."""
        anchor_wall = time.perf_counter()
        anchor_sim = self._t
        while True:
            for _ in range(self._settle_yields):
                await asyncio.sleep(0)
            if self._busy:
                await self._idle.wait()
                continue
            self.server.advance(self._step_s)
            self._t = self.server.time_s
            while self._timers and self._timers[0][0] <= self._t + 1e-12:
                _, _, future = heapq.heappop(self._timers)
                if not future.done():
                    future.set_result(None)
            ahead_s = (self._t - anchor_sim) / self.max_speed - (time.perf_counter() - anchor_wall)
            if ahead_s > 0:
                await asyncio.sleep(ahead_s)
            elif ahead_s < -0.25:  # behind: re-anchor rather than run fast to catch up
                anchor_wall, anchor_sim = time.perf_counter(), self._t

    def close(self) -> None:
        """Let the worker threads end."""
        for pool in self._workers.values():
            pool.shutdown(wait=False, cancel_futures=True)
        self._workers.clear()
