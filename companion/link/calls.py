"""MAVSDK calls that outlive their caller, tracked so that the instance is not destroyed under them.

MAVSDK's asyncio plugins run each call (a command, a setpoint, a parameter read) as a blocking C
call in a worker thread (`loop.run_in_executor`). Cancelling the task that awaits it does not
stop that thread: the C call goes on, on the plugin's handle, until MAVSDK answers or times out.
Destroying the plugin or the `Mavsdk` instance meanwhile frees what the running call uses. So
every call goes through `MavsdkCalls.call`, and the link waits for `MavsdkCalls.drained` before
it destroys anything. The destroy itself blocks in C (MAVSDK joins its threads):
`returned_within` runs it in a daemon thread, so that a MAVSDK that never lets go leaves the
flight process responsive, its timeouts and watchdogs working, instead of freezing its loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections.abc import Awaitable, Callable
from typing import TypeVar

T = TypeVar("T")

log = logging.getLogger(__name__)


class MavsdkCalls:
    """The MAVSDK calls still running, whether or not anyone still awaits them."""

    def __init__(self) -> None:
        self._running: set[asyncio.Future[object]] = set()

    @property
    def running(self) -> int:
        """How many calls have not returned yet."""
        return len(self._running)

    async def call(self, awaitable: Awaitable[T]) -> T:
        """Await one MAVSDK call. Cancelled, the caller leaves at once; the call runs to its
        end and is counted until then."""
        task = asyncio.ensure_future(awaitable)
        self._running.add(task)
        task.add_done_callback(self._finished)
        return await asyncio.shield(task)

    def _finished(self, task: asyncio.Future[object]) -> None:
        self._running.discard(task)
        if not task.cancelled():
            task.exception()  # its caller may be gone: retrieved here, raised to the caller

    async def drained(self, timeout_s: float) -> int:
        """Wait up to `timeout_s` for the running calls to return; how many still run."""
        if not self._running:
            return 0
        _, pending = await asyncio.wait(set(self._running), timeout=timeout_s)
        return len(pending)


async def returned_within(blocking: Callable[[], None], timeout_s: float, name: str) -> bool:
    """Run `blocking` in a daemon thread named `name`; whether it returned within `timeout_s`.
    One that did not is left to its thread (an exception it raises is logged)."""
    loop = asyncio.get_running_loop()
    returned: asyncio.Future[None] = loop.create_future()

    def run() -> None:
        try:
            blocking()
        except Exception:
            log.exception("%s raised", name)
        with contextlib.suppress(RuntimeError):  # the loop may be closed by now
            loop.call_soon_threadsafe(_set_if_pending, returned)

    threading.Thread(target=run, name=name, daemon=True).start()
    try:
        await asyncio.wait_for(asyncio.shield(returned), timeout_s)
    except TimeoutError:
        return False
    return True


def _set_if_pending(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)
