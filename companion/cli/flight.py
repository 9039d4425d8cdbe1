"""`wireavoid` commands of the flight domain: the scripted demo flight through the MAVSDK link."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def fly_pattern(
    connect: Annotated[
        str | None,
        typer.Option(
            "--connect",
            help="fly an external autopilot at this MAVSDK URL instead of the built-in "
            "simulator, e.g. udpin://0.0.0.0:14540 for PX4 SITL",
        ),
    ] = None,
    speed: Annotated[
        float,
        typer.Option(
            "--speed",
            min=0.1,
            max=4.0,
            help="real-time factor of the built-in simulator (MAVSDK's own timers stay in wall "
            "time: its 1 Hz companion heartbeat must stay inside COM_OBC_LOSS_T, so at most 4)",
        ),
    ] = 2.0,
    json_output: Annotated[bool, typer.Option("--json", help="print the summary as JSON")] = False,
    config: Annotated[
        Path | None,
        typer.Option("--config", help="TOML settings file", exists=True, dir_okay=False),
    ] = None,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="log the link's events")] = False,
    failsafe_check: Annotated[
        str | None,
        typer.Option(
            "--failsafe-check",
            help="before offboard, check PX4's failsafes (COM_OBL_RC_ACT, COM_OF_LOSS_T, "
            "RTL_RETURN_ALT, NAV_RCL_ACT): off, warn or refuse (default: config "
            "link.failsafe_check)",
        ),
    ] = None,
) -> None:
    """Take off, fly a velocity square and a position setpoint, land; print what was measured.

    Without --connect, a simulated PX4-like vehicle is flown over real MAVLink (free UDP port).

    Exit status 0 when every leg is within tolerance.
    """
    import asyncio
    import logging

    from companion.cli.demo_flight import run_demo
    from companion.cli.settings import load_sim_settings

    logging.basicConfig(
        level=logging.INFO if verbose else logging.ERROR,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    logging.getLogger("mavsdk").setLevel(logging.WARNING if verbose else logging.CRITICAL)
    settings = load_sim_settings(config)
    if failsafe_check is not None:
        if failsafe_check not in ("off", "warn", "refuse"):
            raise typer.BadParameter("--failsafe-check must be off, warn or refuse")
        link = settings.link.model_copy(update={"failsafe_check": failsafe_check})
        settings = settings.model_copy(update={"link": link})
    summary = asyncio.run(run_demo(settings, connect_url=connect, speed=speed))
    typer.echo(summary.to_json() if json_output else summary.to_text())
    raise typer.Exit(0 if summary.ok else 1)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add this domain's commands to the root app and its benchmarks to `wireavoid bench`."""
    app.command("fly-pattern")(fly_pattern)
