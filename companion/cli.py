"""The `wireavoid` command line: one typer app; each domain registers its own commands.

Heavy imports (torch, MAVSDK) happen inside the commands so that `wireavoid --help` is instant.
"""

from __future__ import annotations

import typer

from companion import (
    cli_catenary,
    cli_config,
    cli_flight,
    cli_mapping,
    cli_perception,
    cli_planning,
    cli_service,
    cli_training,
    cli_vehicle,
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
)
bench_app = typer.Typer(
    help="Benchmarks with JSON output; ratios are measured side by side in one run.",
    no_args_is_help=True,
)
app.add_typer(bench_app, name="bench")

for _module in (
    cli_config,
    cli_service,
    cli_vehicle,
    cli_flight,
    cli_perception,
    cli_training,
    cli_mapping,
    cli_catenary,
    cli_planning,
):
    _module.register(app, bench_app)
