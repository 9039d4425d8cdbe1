"""The `wireavoid` command line: one typer app; each domain registers its own commands.

Heavy imports (torch, MAVSDK) happen inside the commands so that `wireavoid --help` is instant.
"""

from __future__ import annotations

import typer

from companion.cli import (
    cameras,
    catenary,
    config,
    faults,
    flight,
    gcs,
    mapping,
    perception,
    planning,
    record,
    service,
    sil_perception,
    sim,
    training,
    vehicle,
)

app = typer.Typer(
    name="wireavoid",
    help=(
        "Wire-aware obstacle avoidance for small drones: wire segmentation, DROAN mapping,\n"
        "catenary reconstruction and trajectory-library planning, flying PX4 through MAVSDK."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
    rich_markup_mode=None,  # help texts name extras as [view]: plain text, not rich markup
)
bench_app = typer.Typer(
    help="Benchmarks with JSON output; ratios are measured side by side in one run.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(bench_app, name="bench")

for _module in (
    config,
    service,
    vehicle,
    flight,
    sim,
    gcs,
    perception,
    sil_perception,
    training,
    mapping,
    catenary,
    planning,
    cameras,
    record,
    faults,
):
    _module.register(app, bench_app)
