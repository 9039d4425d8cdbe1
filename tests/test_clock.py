"""`companion.clock`: cancelling tasks that do not stop at the first cancel."""

from __future__ import annotations

import asyncio
import contextlib

from companion.clock import WallClock, cancel_and_wait, wait_or_timeout


async def _swallows_one_cancel(ended: list[str]) -> None:
    """Like a coroutine inside Python 3.11's wait_for when the cancel meets its result."""
    with contextlib.suppress(asyncio.CancelledError):  # the first cancel is lost
        await asyncio.sleep(10.0)
    await asyncio.sleep(10.0)
    ended.append("never")


async def test_a_task_that_swallows_a_cancel_is_cancelled_again_until_it_ends() -> None:
    ended: list[str] = []
    task = asyncio.create_task(_swallows_one_cancel(ended))
    await asyncio.sleep(0)
    await asyncio.wait_for(cancel_and_wait([task]), 2.0)
    assert task.cancelled() and not ended


async def test_a_timeout_ends_even_when_the_loser_swallows_its_cancel() -> None:
    ended: list[str] = []
    finished = await asyncio.wait_for(
        wait_or_timeout(WallClock(), _swallows_one_cancel(ended), 0.05), 2.0
    )
    assert finished is False and not ended
