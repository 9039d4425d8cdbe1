"""A live simulated flight recorded through the recorder hook and replayed: the flight process
on lockstep time is reproduced by the replay to the last bit (no divergence)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from companion.cli.settings import load_sim_settings
from companion.cli.sim_addons import FlightAddon
from companion.cli.sim_flight import fly_world
from companion.record.reader import iter_recorded, summary
from companion.record.replay import replay
from companion.record.writer import start_recording
from hil.world.file import load_world

DATA = Path(__file__).parent / "data" / "replay"


class _Hook(FlightAddon):
    """What `wireavoid run --record` does: the service's hook on the built process."""

    def attach(self, process: Any, clock: Any, stop: asyncio.Event) -> None:
        self.recorder = start_recording(process)

    def close(self, record: Any) -> dict[str, Any]:
        return {"recording": self.recorder.close().to_dict()}


def test_a_recorded_flight_replays_exactly(tmp_path: Path) -> None:
    settings = load_sim_settings(DATA / "hop-settings.toml")
    settings = settings.model_copy(
        update={
            "record": settings.record.model_copy(update={"path": str(tmp_path / "f-%Y.mcap")}),
            "sim": settings.sim.model_copy(update={"timeout_s": 15.0}),
            "flight": settings.flight.model_copy(
                update={"wires_during_takeoff_and_landing": False}
            ),
        }
    )
    record = asyncio.run(fly_world(settings, load_world(DATA / "hop.toml"), addons=[_Hook()]))
    assert not record.failure.startswith("link"), record.failure
    recording = record.extra["recording"]
    assert recording["dropped"] == 0 and recording["errors"] == 0
    (path,) = (Path(p) for p in recording["parts"])
    assert path.parent == tmp_path and path.name.startswith("f-20")  # strftime filled in
    info = summary(path)
    assert info["frames"] == record.report.frames and info["frames"] > 40
    assert info["channels"]["/plan"]["messages"] == record.report.plans
    # the frames on the ground and in the takeoff climb gave the map their stereo alone
    wires = [m.payload["wire_evidence"] for m in iter_recorded([path], {"/map"})]
    airborne = wires.index(True)
    assert airborne > 20 and not any(wires[:airborne]) and sum(wires[airborne:]) > 20, wires
    result, _ = replay([path])
    assert result.messages_replayed == record.report.perceptions + record.report.fused + (
        record.report.unregistered + record.report.plans
    )
    assert result.divergences == 0, result.to_dict()
