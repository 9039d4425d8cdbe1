"""What a simulated flight can carry besides the stack: a recorder, a live view, fault injection.

`companion.cli.sim_flight.fly_world` takes a list of `FlightAddon`s and calls each at the same
points of the composition: `settings` (what the process flies with: an addon may add what its
part needs, e.g. a broker of its own for the ground link), `vehicle_port` (the UDP port the
simulated vehicle sends to: a relay may sit in between), `camera` (wrap the camera source),
`attach` (the process is built: hang on its bus, wrap its stage callables), `run` (a task
beside the flight), `close` (the flight is over: finish files, release what was opened,
report). None of them changes the flight process' code: they use its bus
and its parts, as a drone's recorder or a test harness would.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import asyncio

    from companion.cli.settings import SimSettings
    from companion.clock import Clock
    from companion.flight.process import FlightProcess
    from companion.ingest.frames import CameraSource


class FlightAddon:
    """A part of a simulated flight beside the stack; every hook does nothing by default."""

    def settings(self, settings: SimSettings) -> SimSettings:
        """The settings the flight process is built with (first of the hooks)."""
        return settings

    def vehicle_port(self, port: int) -> int:
        """The port the simulated vehicle should send MAVLink to (the link listens on `port`)."""
        return port

    def camera(self, source: CameraSource, clock: Clock) -> CameraSource:
        """The camera source the process reads (wrap `source` to change what it delivers)."""
        return source

    def attach(self, process: FlightProcess, clock: Clock, stop: asyncio.Event) -> None:
        """The process is built and about to run; setting `stop` ends the flight."""

    async def run(self) -> None:
        """Runs beside the flight until it ends (then it is cancelled)."""

    def close(self, record: Any) -> dict[str, Any]:
        """The flight ended (`record`, its `FlightRecord`): release what was opened; what to
        add to its JSON."""
        return {}


class RecordAddon(FlightAddon):
    """`sim --record FILE`: the flight's bus to MCAP (`companion.record.writer`)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._recorder: Any = None

    def attach(self, process: FlightProcess, clock: Clock, stop: asyncio.Event) -> None:
        from companion.record.writer import record_process

        self._recorder = record_process(process, self.path, source="sim")

    def close(self, record: Any) -> dict[str, Any]:
        if self._recorder is None:
            return {}
        return {"recording": self._recorder.close().to_dict()}


class ViewAddon(FlightAddon):
    """`sim --view`: the flight live in Foxglove (`companion.view`)."""

    def __init__(self, port: int) -> None:
        self.port = port
        self._view: Any = None

    def attach(self, process: FlightProcess, clock: Clock, stop: asyncio.Event) -> None:
        from companion.view.live import LiveView

        self._view = LiveView.start(process.settings, self.port)
        process.bus.subscribe(self._view.on_message)

    def close(self, record: Any) -> dict[str, Any]:
        if self._view is None:
            return {}
        return {"view": self._view.close()}
