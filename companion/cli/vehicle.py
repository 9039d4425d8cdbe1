"""`wireavoid` commands of the vehicle domain: the standalone SIL vehicle."""

from __future__ import annotations

import signal
import threading
from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add this domain's commands to the root app and its benchmarks to `wireavoid bench`."""
    app.command("vehicle-sim")(vehicle_sim)
    bench.command("vehicle-sim")(bench_vehicle_sim)


def bench_vehicle_sim(
    duration_s: Annotated[float, typer.Option(help="simulated seconds to fly", min=1.0)] = 60.0,
    json_output: Annotated[bool, typer.Option("--json", help="print JSON")] = False,
    config: Annotated[
        Path | None, typer.Option(help="TOML settings file", exists=True, dir_okay=False)
    ] = None,
) -> None:
    """Real-time factor of the SIL vehicle in lockstep: dynamics alone and over MAVLink."""
    import json

    from companion.cli.settings import load_sim_settings
    from hil.vehicle.bench import measure_real_time_factor

    result = measure_real_time_factor(load_sim_settings(config).vehicle_sim, duration_s)
    if json_output:
        typer.echo(json.dumps(result.to_dict()))
    else:
        for key, value in result.to_dict().items():
            typer.echo(f"{key}: {value:.2f}")


def vehicle_sim(
    port: Annotated[
        int, typer.Option(help="UDP port the vehicle sends to (client: udpin://0.0.0.0:PORT)")
    ] = 14540,
    host: Annotated[str, typer.Option(help="host the vehicle sends to")] = "127.0.0.1",
    speed: Annotated[float, typer.Option(help="real-time factor (1 = real time)", min=0.01)] = 1.0,
    seed: Annotated[
        int | None, typer.Option(help="seed (default: config vehicle_sim.seed)")
    ] = None,
    config: Annotated[
        Path | None, typer.Option(help="TOML settings file", exists=True, dir_okay=False)
    ] = None,
    status_period_s: Annotated[
        float, typer.Option(help="wall seconds between status lines", min=0.1)
    ] = 1.0,
    airframe: Annotated[
        str | None,
        typer.Option(
            help="airframe preset over the config's [vehicle_sim]: sih_quadx (PX4 SITL's SIH "
            "quadrotor, the default values) or low_drag_1500g"
        ),
    ] = None,
    px4_params: Annotated[
        Path | None,
        typer.Option(
            help="a drone's PX4 parameters (QGroundControl .params file, or JSON {NAME: value}) "
            "applied last: its MPC_*/MC_*/COM_*/RTL_* values, SIH_* for its physics",
            exists=True,
            dir_okay=False,
        ),
    ] = None,
    estimation_error: Annotated[
        bool,
        typer.Option(
            "--estimation-error",
            help="fly on a drifting estimate like PX4's EKF2 in SITL (seeded; telemetry reports "
            "the estimate, the truth stays for judging)",
        ),
    ] = False,
) -> None:
    """Run the PX4 SIL vehicle over MAVLink until Ctrl-C; MAVSDK, QGC or pymavlink fly it."""
    from companion.cli.settings import load_sim_settings
    from hil.mavlink.server import VehicleServer
    from hil.vehicle.airframes import vehicle_params

    try:
        params, ignored = vehicle_params(
            load_sim_settings(config).vehicle_sim,
            airframe=airframe,
            px4_params_file=px4_params,
            estimation_error=estimation_error,
        )
    except (KeyError, ValueError) as e:
        raise typer.BadParameter(str(e)) from e
    if ignored:
        typer.echo(f"vehicle-sim: {len(ignored)} PX4 parameters not simulated (kept as-is)")
    if seed is not None:
        params = params.model_copy(update={"seed": seed})
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    typer.echo(
        f"vehicle-sim: sending MAVLink 2 to {host}:{port}, speed x{speed}, seed {params.seed}, "
        f"airframe {airframe or 'from config'}"
    )
    with VehicleServer(params, port, speed=speed, host=host) as server:
        while not stop.wait(status_period_s):
            if server.error is not None:
                raise typer.Exit(code=1)
            s = server.truth()
            n, e, d = s.position_ned_m
            vn, ve, vd = s.velocity_ned_mps
            typer.echo(
                f"t={s.time_s:7.1f}s {server.flight_mode.name:8s} "
                f"{'ARMED' if server.armed else 'disarmed':8s} {server.landed_state.name:9s} "
                f"ned=({n:6.1f},{e:6.1f},{d:6.1f})m v=({vn:5.1f},{ve:5.1f},{vd:5.1f})m/s "
                f"lag={server.lag_s:.2f}s"
            )
    typer.echo("vehicle-sim: stopped")
