"""The options of `wireavoid sim` that add to a flight: --record, --view, --fault.

Light on purpose (the commands import it: `wireavoid --help` stays instant); `flight_addons`
builds the `companion.cli.sim_addons` they stand for.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from companion.cli.sim_addons import FlightAddon, RecordAddon, ViewAddon

RecordOption = Annotated[
    Path | None,
    typer.Option(
        "--record",
        help="record the flight to this MCAP file (Foxglove opens it; `wireavoid replay` "
        "re-runs it); split and capped as [record] says",
        dir_okay=False,
    ),
]
ViewOption = Annotated[
    bool,
    typer.Option(
        "--view",
        help="show it live in Foxglove (ws://localhost:PORT; pip install 'wireavoid[view]')",
    ),
]
ViewPortOption = Annotated[int, typer.Option("--view-port", help="the live view's WebSocket port")]
FaultOption = Annotated[
    list[str] | None,
    typer.Option(
        "--fault",
        help="inject a fault (repeatable; `wireavoid faults --list` names them); the first "
        "starts 3 s after offboard engages, the next ones 10 s apart",
    ),
]
FAULT_SPACING_S = 10.0  # between the faults of one `sim --fault A --fault B` flight


def checked_faults(names: list[str]) -> list[str]:
    """`names`, each a known fault kind (else a usage error naming them)."""
    from hil.faults import FAULT_KINDS

    unknown = [n for n in names if n not in FAULT_KINDS]
    if unknown:
        raise typer.BadParameter(f"unknown faults {unknown}; one of {', '.join(FAULT_KINDS)}")
    return names


def flight_addons(
    record: str | None, view_port: int | None, faults: tuple[str, ...], world_file: str | None
) -> list[FlightAddon]:
    """The addons of `wireavoid sim`: a recorder, a live view, the faults named and those of
    the world file's `[[fault]]` tables."""
    addons: list[FlightAddon] = []
    if record:
        addons.append(RecordAddon(Path(record)))
    if view_port is not None:
        addons.append(ViewAddon(view_port))
    from hil.faults import FaultSpec
    from hil.world.file import load_faults

    specs = [FaultSpec(kind=k, start_s=3.0 + FAULT_SPACING_S * i) for i, k in enumerate(faults)]
    if world_file:
        specs += load_faults(world_file)
    if specs:
        from companion.cli.sim_faults import FaultAddon

        addons.append(FaultAddon(specs, judge_s=None))
    return addons
