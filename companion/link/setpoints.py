"""The mailbox between the tracker and the link's setpoint streamer (STYLE.md practice 2, 6).

The tracker publishes `planning.types.Setpoint`s, each stamped with the time it was produced;
the link's streamer reads the latest one at the setpoint rate and the watchdog judges it by
its age and its validity.
"""

from __future__ import annotations

import asyncio

from planning.types import Setpoint


class SetpointSource:
    """The latest setpoint from the planner (a one-slot mailbox; newer replaces older).

    One consumer (the streamer) may `await wait_new()` to send a new setpoint at once instead
    of at its next tick.
    """

    def __init__(self) -> None:
        self._latest: Setpoint | None = None
        self._new = asyncio.Event()
        self.published = 0

    def publish(self, setpoint: Setpoint) -> None:
        """Replace the latest setpoint and wake the consumer."""
        self._latest = setpoint
        self.published += 1
        self._new.set()

    async def wait_new(self) -> None:
        """Wait until a setpoint is published after the previous wait returned."""
        await self._new.wait()
        self._new.clear()

    def latest(self) -> Setpoint | None:
        """The most recent setpoint, or None before the first."""
        return self._latest
