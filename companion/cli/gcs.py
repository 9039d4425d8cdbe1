"""`wireavoid gcs`: command a vehicle and watch it over MQTT, for operators without a GCS app.

Also home of the `--mqtt URL` / `--vehicle-id ID` options that `wireavoid fly` and
`wireavoid sim` take (`MqttUrlOption`, `VehicleIdOption`; apply them with
`companion.ground.options.apply_ground_options`).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

if TYPE_CHECKING:
    from companion.ground.params import GroundParams
    from companion.ground.protocol import Ack, Event, Status

MqttUrlOption = Annotated[
    str | None,
    typer.Option(
        "--mqtt",
        help="MQTT broker of the ground link, mqtt://HOST[:PORT] or mqtts://HOST[:PORT] "
        "(overrides ground.broker_url)",
    ),
]
VehicleIdOption = Annotated[
    str | None,
    typer.Option(
        "--vehicle-id",
        help="the vehicle's id in the topics wireavoid/<id>/... (overrides ground.vehicle_id)",
    ),
]

EXIT_REJECTED, EXIT_INVALID, EXIT_NO_ANSWER = 1, 2, 3

gcs_app = typer.Typer(
    help=(
        "Send commands to a vehicle and print its acks, status and events (MQTT).\n\n"
        "Connection options come before the command: wireavoid gcs --mqtt mqtts://HOST:8883 "
        "--vehicle-id drone1 --username gcs --password-file FILE --ca-file CA goto --north 10 "
        "--east 0 --down -3. They default to the ground settings (--config FILE, "
        "WIREAVOID_GROUND__*). Exit status: 0 accepted, 1 rejected, 2 invalid command, "
        "3 no broker or no answer in time."
    ),
    no_args_is_help=True,
    rich_markup_mode=None,
)


@dataclass(frozen=True)
class _Session:
    params: GroundParams
    timeout_s: float
    json_output: bool


@gcs_app.callback()
def connection(
    ctx: typer.Context,
    mqtt: MqttUrlOption = None,
    vehicle_id: VehicleIdOption = None,
    username: Annotated[
        str | None, typer.Option("--username", help="the ground station's MQTT username")
    ] = None,
    password_file: Annotated[
        Path | None,
        typer.Option("--password-file", help="file holding its password", dir_okay=False),
    ] = None,
    ca_file: Annotated[
        Path | None, typer.Option("--ca-file", help="CA certificate of the broker (mqtts://)")
    ] = None,
    cert_file: Annotated[
        Path | None, typer.Option("--cert-file", help="client certificate (mqtts://)")
    ] = None,
    key_file: Annotated[Path | None, typer.Option("--key-file", help="its private key")] = None,
    config: Annotated[
        Path | None,
        typer.Option(
            "--config", help="TOML settings file (its ground section)", exists=True, dir_okay=False
        ),
    ] = None,
    timeout: Annotated[
        float, typer.Option("--timeout", help="wait this long for an ack or a status, s", min=0.1)
    ] = 5.0,
    json_output: Annotated[
        bool, typer.Option("--json", help="print the raw JSON messages, one per line")
    ] = False,
) -> None:
    """Where the broker is and who this ground station is (checked when a command runs)."""
    options = {
        "broker_url": mqtt,
        "vehicle_id": vehicle_id,
        "username": username,
        "password_file": password_file,
        "tls_ca_file": ca_file,
        "tls_cert_file": cert_file,
        "tls_key_file": key_file,
    }
    ctx.obj = (
        config,
        {k: str(v) for k, v in options.items() if v is not None},
        timeout,
        json_output,
    )


def _session(ctx: typer.Context) -> _Session:
    """The connection the options and settings describe; exit 2 when they are invalid."""
    from pydantic import ValidationError

    from companion.cli.settings import load_sim_settings
    from companion.ground.params import GroundParams

    config, overrides, timeout_s, json_output = ctx.obj
    ground = load_sim_settings(config).ground
    try:
        params = GroundParams.model_validate({**ground.model_dump(), **overrides})
    except ValidationError as e:
        typer.echo(f"invalid connection options: {e}", err=True)
        raise typer.Exit(EXIT_INVALID) from None
    if not params.enabled:
        typer.echo("no broker: pass --mqtt URL or set ground.broker_url", err=True)
        raise typer.Exit(EXIT_INVALID)
    return _Session(params, timeout_s, json_output)


# ---------------------------------------------------------------------------- commands


@gcs_app.command("takeoff")
def takeoff(
    ctx: typer.Context,
    altitude: Annotated[float, typer.Option("--altitude", help="above home, m")],
) -> None:
    """Arm, take off to ALTITUDE above home and hold."""
    _send(ctx, {"type": "takeoff", "altitude_m": altitude})


@gcs_app.command("goto")
def goto(
    ctx: typer.Context,
    north: Annotated[float | None, typer.Option("--north", help="local NED north, m")] = None,
    east: Annotated[float | None, typer.Option("--east", help="local NED east, m")] = None,
    down: Annotated[
        float | None, typer.Option("--down", help="local NED down, m (-3: 3 m above)")
    ] = None,
    lat: Annotated[float | None, typer.Option("--lat", help="latitude, deg (WGS84)")] = None,
    lon: Annotated[float | None, typer.Option("--lon", help="longitude, deg (WGS84)")] = None,
    altitude: Annotated[
        float | None, typer.Option("--altitude", help="with --lat/--lon: above home, m")
    ] = None,
    speed: Annotated[float | None, typer.Option("--speed", help="cruise speed, m/s")] = None,
    yaw: Annotated[
        str | None, typer.Option("--yaw", help="yaw policy: motion, goal or fixed")
    ] = None,
    yaw_deg: Annotated[
        float | None, typer.Option("--yaw-deg", help="with --yaw fixed: heading from north, deg")
    ] = None,
) -> None:
    """Fly to a goal: --north/--east/--down (local NED) or --lat/--lon/--altitude."""
    local = {"north_m": north, "east_m": east, "down_m": down}
    geo = {"lat_deg": lat, "lon_deg": lon, "altitude_m": altitude}
    given_geo = any(v is not None for v in geo.values())
    if given_geo and any(v is not None for v in local.values()):
        typer.echo(
            "not sent: give --north/--east/--down or --lat/--lon/--altitude, not both", err=True
        )
        raise typer.Exit(EXIT_INVALID)
    target = geo if given_geo else local
    waypoint: dict[str, Any] = {"target": {k: v for k, v in target.items() if v is not None}}
    for key, value in (
        ("speed_mps", speed),
        ("yaw", yaw),
        ("yaw_rad", None if yaw_deg is None else math.radians(yaw_deg)),
    ):
        if value is not None:
            waypoint[key] = value
    _send(ctx, {"type": "goto", **waypoint})


@gcs_app.command("mission")
def mission(
    ctx: typer.Context,
    waypoints: Annotated[
        Path,
        typer.Argument(
            help='JSON file: a list of waypoints, or {"waypoints": [...]}; each '
            '{"target": {"north_m", "east_m", "down_m"} or {"lat_deg", "lon_deg", '
            '"altitude_m"}, "speed_mps"?, "yaw"?, "yaw_rad"?}',
            exists=True,
            dir_okay=False,
        ),
    ],
) -> None:
    """Fly a list of waypoints in order (replacing the goal queue)."""
    try:
        loaded = json.loads(waypoints.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        typer.echo(f"{waypoints}: not JSON: {e}", err=True)
        raise typer.Exit(EXIT_INVALID) from None
    listed = loaded.get("waypoints") if isinstance(loaded, dict) else loaded
    _send(ctx, {"type": "mission", "waypoints": listed})


@gcs_app.command("hold")
def hold(ctx: typer.Context) -> None:
    """Brake and hold where the vehicle is."""
    _send(ctx, {"type": "hold"})


@gcs_app.command("resume")
def resume(ctx: typer.Context) -> None:
    """Continue to the active goal after a hold."""
    _send(ctx, {"type": "resume"})


@gcs_app.command("land")
def land(ctx: typer.Context) -> None:
    """Land where the vehicle is."""
    _send(ctx, {"type": "land"})


@gcs_app.command("rtl")
def rtl(ctx: typer.Context) -> None:
    """Return to launch and land."""
    _send(ctx, {"type": "rtl"})


@gcs_app.command("abort")
def abort(ctx: typer.Context) -> None:
    """Brake and hold at once, dropping the remaining goals."""
    _send(ctx, {"type": "abort"})


@gcs_app.command("set-speed")
def set_speed(
    ctx: typer.Context, speed: Annotated[float, typer.Argument(help="cruise speed, m/s")]
) -> None:
    """Change the cruise speed (the `set_speed` command)."""
    _send(ctx, {"type": "set_speed", "speed_mps": speed})


@gcs_app.command("send")
def send(
    ctx: typer.Context,
    payload: Annotated[str, typer.Argument(help="JSON file to send as it is, or - for stdin")],
) -> None:
    """Send a raw payload unchecked (testing the vehicle's validation) and print the ack."""
    data = sys.stdin.buffer.read() if payload == "-" else Path(payload).read_bytes()
    session = _session(ctx)
    ack = _run(session, lambda station: station.send_raw(data, session.timeout_s))
    raise typer.Exit(_print_ack(session, ack))


@gcs_app.command("status")
def status(
    ctx: typer.Context,
    follow: Annotated[
        bool, typer.Option("--follow", "-f", help="keep printing status and events (Ctrl-C)")
    ] = False,
) -> None:
    """Print the vehicle's status (the retained one, or the next); --follow streams them."""
    session = _session(ctx)
    if follow:
        _run(session, lambda station: _follow(session, station))
        return
    latest = _run(session, lambda station: station.next_status(session.timeout_s))
    if latest is None:
        typer.echo(f"no status from {session.params.vehicle_id} in {session.timeout_s} s", err=True)
        raise typer.Exit(EXIT_NO_ANSWER)
    typer.echo(latest.model_dump_json() if session.json_output else status_text(latest))


# ---------------------------------------------------------------------------- helpers


def _send(ctx: typer.Context, fields: dict[str, Any]) -> None:
    """Validate the command here (the vehicle's own rules), send it, print its ack."""
    from companion.ground.protocol import PROTOCOL_VERSION, Rejection, parse_command
    from companion.ground.station import new_command_id

    session = _session(ctx)
    payload = {"v": PROTOCOL_VERSION, "id": new_command_id(), **fields}
    command = parse_command(json.dumps(payload).encode())
    if isinstance(command, Rejection):
        typer.echo(f"not sent: {command.reason}", err=True)
        raise typer.Exit(EXIT_INVALID)
    ack = _run(session, lambda station: station.send(command, session.timeout_s))
    raise typer.Exit(_print_ack(session, ack))


def _run(session: _Session, work: Any) -> Any:
    """`await work(station)` on a connected `GroundStation`; exit 3 if the broker is out of
    reach."""
    import asyncio

    import aiomqtt

    from companion.ground.station import GroundStation

    async def main() -> Any:
        async with GroundStation(session.params) as station:
            return await work(station)

    try:
        return asyncio.run(main())
    except (aiomqtt.MqttError, OSError) as e:
        typer.echo(f"cannot reach {session.params.broker_url}: {e}", err=True)
        raise typer.Exit(EXIT_NO_ANSWER) from None
    except KeyboardInterrupt:
        raise typer.Exit(0) from None


def _print_ack(session: _Session, ack: Ack | None) -> int:
    """Print the ack; the exit status it means."""
    if ack is None:
        typer.echo(f"no ack from {session.params.vehicle_id} in {session.timeout_s} s", err=True)
        return EXIT_NO_ANSWER
    if session.json_output:
        typer.echo(ack.model_dump_json())
    else:
        verdict = "accepted" if ack.accepted else "rejected"
        reason = f": {ack.reason}" if ack.reason else ""
        typer.echo(f"{verdict} {ack.command or '?'} {ack.id or '(no id)'}{reason}")
    return 0 if ack.accepted else EXIT_REJECTED


async def _follow(session: _Session, station: Any) -> None:
    """Print every status and event as it arrives, until interrupted."""
    shown_events = 0
    shown_statuses = 0
    while True:

        def news(statuses: int = shown_statuses, events: int = shown_events) -> bool:
            return station.status_count > statuses or len(station.events) > events

        await station.wait_for(news, 3600.0)
        for event in station.events[shown_events:]:
            typer.echo(event.model_dump_json() if session.json_output else event_text(event))
        shown_events = len(station.events)
        if station.status_count > shown_statuses and station.status is not None:
            latest = station.status
            typer.echo(latest.model_dump_json() if session.json_output else status_text(latest))
            shown_statuses = station.status_count


def _vector(values: tuple[float, ...] | None, digits: int = 2) -> str:
    return "?" if values is None else ", ".join(f"{v:.{digits}f}" for v in values)


def _known(value: object) -> str:
    if value is None:
        return "?"
    if isinstance(value, bool):
        return "yes" if value else "no"
    return str(value)


def status_text(s: Status) -> str:
    """A vehicle status for a person to read (a few lines)."""
    if not s.online:
        return f"{s.vehicle_id or '?'}: offline"
    lines = [
        f"{s.vehicle_id}: online  mode {_known(s.mode)}"
        + (f" (failsafe: {s.failsafe})" if s.failsafe else "")
        + f"  PX4 {_known(s.flight_mode)}  armed {_known(s.armed)}  in air {_known(s.in_air)}",
        f"  position NED m {_vector(s.position_ned_m)}  velocity m/s "
        f"{_vector(s.velocity_ned_mps)}  yaw "
        + ("?" if s.yaw_rad is None else f"{math.degrees(s.yaw_rad):.0f} deg"),
    ]
    goal = s.active_goal
    if goal is not None:
        lines.append(
            f"  goal {goal.index + 1}/{goal.count} NED m {_vector(goal.target_ned_m, 1)}"
            + (f" ({goal.command_id})" if goal.command_id else "")
        )
    lines.append(
        f"  planner {_known(s.planner_state)}  speed "
        + ("?" if s.speed_mps is None else f"{s.speed_mps:.1f} m/s")
        + "  battery "
        + _battery_text(s)
    )
    for name, stage in s.stages.items():
        parts = [name, "ok" if stage.ok else "NOT OK"]
        if stage.rate_hz is not None:
            parts.append(f"{stage.rate_hz:.1f} Hz")
        if stage.latency_ms is not None:
            parts.append(f"{stage.latency_ms:.0f} ms")
        if stage.age_s is not None:
            parts.append(f"age {stage.age_s:.2f} s")
        if stage.detail:
            parts.append(stage.detail)
        lines.append("  stage " + " ".join(parts))
    return "\n".join(lines)


def _battery_text(s: Status) -> str:
    b = s.battery
    if b is None:
        return "?"
    volts = "?" if b.voltage_v is None else f"{b.voltage_v:.2f} V"
    percent = "?" if b.remaining_frac is None else f"{100 * b.remaining_frac:.0f} %"
    return f"{volts} {percent}"


def event_text(e: Event) -> str:
    """An event on one line."""
    state = f" [{e.state}]" if e.state else ""
    return f"{e.severity.upper():7s} {e.kind}{state}: {e.text}"


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add `wireavoid gcs ...`."""
    app.add_typer(gcs_app, name="gcs")
