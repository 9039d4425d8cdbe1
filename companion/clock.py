"""The flight process' clock: the time it reads, the way it waits, and where it computes.

Every part of the process takes a `Clock` instead of calling `time.monotonic` or
`asyncio.sleep` itself (STYLE.md practice 8: pass the clock in). On the drone it is the
`WallClock`: monotonic time, asyncio sleeps, and blocking stage work (the CNN, the map, the
planner) on one worker thread per stage, off the event loop. A simulator may pass any other
implementation of the same three methods: the hil harness' lockstep clock runs the same
process on simulated time and charges each computation its measured duration, so a flight
is judged as this machine would fly it, but the simulator's own cost is never charged.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Protocol, TypeVar

T = TypeVar("T")
_RECANCEL_S = 0.1  # a cancelled task still running after this is cancelled again


class Clock(Protocol):
    """Time, waiting and off-loop computation for the flight process."""

    def now_s(self) -> float:
        """The current time, s (monotonic; the stamp of every message in the process)."""
        ...

    async def sleep(self, duration_s: float) -> None:
        """Wait `duration_s` seconds of this clock's time (no wait when <= 0)."""
        ...

    async def compute(self, worker: str, fn: Callable[..., T], *args: object) -> T:
        """`fn(*args)` on the worker thread named `worker` (one per stage, so one stage's work
        runs in order and never in two threads at once), awaited without blocking the loop."""
        ...


class WallClock:
    """The real clock: `time.monotonic`, `asyncio.sleep`, one daemon thread per worker."""

    def __init__(self) -> None:
        self._workers: dict[str, ThreadPoolExecutor] = {}

    def now_s(self) -> float:
        """Monotonic wall time, s."""
        return time.monotonic()

    async def sleep(self, duration_s: float) -> None:
        """`asyncio.sleep` (0 for negative durations)."""
        await asyncio.sleep(max(duration_s, 0.0))

    async def compute(self, worker: str, fn: Callable[..., T], *args: object) -> T:
        """`fn(*args)` on the thread of `worker`."""
        pool = self._workers.get(worker)
        if pool is None:
            pool = self._workers[worker] = ThreadPoolExecutor(1, thread_name_prefix=worker)
        return await asyncio.get_running_loop().run_in_executor(pool, fn, *args)

    def close(self) -> None:
        """Let the worker threads end once their current work is done."""
        for pool in self._workers.values():
            pool.shutdown(wait=False, cancel_futures=True)
        self._workers.clear()


async def wait_or_timeout(clock: Clock, awaitable: Awaitable[object], timeout_s: float) -> bool:
    """Await `awaitable` for at most `timeout_s` of `clock`'s time: True when it finished.

    On timeout the awaitable is cancelled. Its exception, if any, propagates; so does a
    cancellation of the caller, even one that arrives while the loser is being cancelled.
    """
    return await finished_first(awaitable, clock.sleep(timeout_s))


async def finished_first(awaitable: Awaitable[object], other: Awaitable[object]) -> bool:
    """Await `awaitable` until `other` completes: True when `awaitable` finished first.

    The loser is cancelled and awaited. The awaitable's exception, if any, propagates; so
    does a cancellation of the caller, even one that arrives while the loser is cancelled.
    """
    work = asyncio.ensure_future(awaitable)
    race = asyncio.ensure_future(other)
    try:
        await asyncio.wait((work, race), return_when=asyncio.FIRST_COMPLETED)
    finally:
        await cancel_and_wait((work, race))
    if work.cancelled():
        return False
    work.result()
    return True


async def cancel_and_wait(tasks: Iterable[asyncio.Future[Any]]) -> None:
    """Cancel the unfinished `tasks` and wait until they have ended, without taking their
    CancelledError for the caller's. One that goes on is cancelled again: Python 3.11's
    `asyncio.wait_for` (aiomqtt's publish and connect use it) can swallow a cancellation that
    meets its inner future finishing, and a task that ran on would keep its waiter forever."""
    pending = {task for task in tasks if not task.done()}
    while pending:
        for task in pending:
            task.cancel()
        _, pending = await asyncio.wait(pending, timeout=_RECANCEL_S)
