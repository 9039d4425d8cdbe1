"""`wireavoid faults`: the fault matrix, every fault injected into a simulated flight.

Each fault flies the fault field (`hil/world/examples/fault-field.toml`: a straight flight
between rows of poles and wires) with the whole stack on lockstep time; the fault starts
`--start-s` after offboard engages, lasts `--duration-s`, and the flight is judged until
`--judge-s` after it cleared (`companion.cli.sim_faults` says what each column measures).
One flight per fault (in `--jobs` processes), or all faults in turn in one flight with
`--sequential`. Exit status 0 when every fault's row is ok: no collision, recovered, and
(for stale perception or a stalled stage) braking to a hold within 0.5 s of detectable.
mqtt_restart restarts a broker the flight runs itself (mosquitto on a free loopback port), so
it is skipped when `--mqtt` gives the flights another broker.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

if TYPE_CHECKING:
    from companion.ground.params import GeofenceParams
    from hil.world.model import World

FAULT_WORLD = "fault-field.toml"  # in hil/world/examples
FENCE_MARGIN_M = 20.0  # beyond the farthest goal, when the matrix widens a cylinder geofence
OFFBOARD_LOSS_HOLD = 5  # COM_OBL_RC_ACT: Hold (stops where it is)
_OWN_BROKER = {"mqtt_restart"}  # restart a broker the flight runs itself: not with --mqtt


@dataclass(frozen=True)
class FaultFlight:
    """One flight of the matrix: the faults it carries, the world, the settings file, the
    ground link's broker (None: as configured, or the fault's own for mqtt_restart)."""

    faults: tuple[dict[str, Any], ...]
    world_file: str
    config: str | None
    judge_s: float
    mqtt_url: str | None = None


def fly_faults(flight: FaultFlight) -> list[dict[str, Any]]:
    """Fly one flight of the matrix; its fault rows (a failed flight gives failed rows)."""
    import asyncio
    import logging

    from companion.cli.settings import load_sim_settings
    from companion.cli.sim_faults import FaultAddon
    from companion.cli.sim_flight import fly_world
    from companion.ground.options import apply_ground_options
    from hil.faults import FaultSpec
    from hil.world.file import load_world

    logging.getLogger("mavsdk").setLevel(logging.CRITICAL)
    specs = [FaultSpec.model_validate(f) for f in flight.faults]
    addon = FaultAddon(specs, judge_s=flight.judge_s)
    try:
        settings = load_sim_settings(Path(flight.config) if flight.config else None)
        settings = apply_ground_options(settings, flight.mqtt_url, None)
        last_end_s = max(s.start_s + s.duration_s for s in specs)
        timeout_s = max(settings.sim.timeout_s, 40.0 + last_end_s + flight.judge_s)
        settings = settings.model_copy(
            update={"sim": settings.sim.model_copy(update={"timeout_s": timeout_s})}
        )
        # the matrix judges recovery: once the vehicle link is back it flies on to the goal
        mission = settings.mission.model_copy(update={"vehicle_link_back_action": "resume"})
        # and it flies the autopilot the pre-flight check asks for: on offboard loss PX4 holds
        # where it is (COM_OBL_RC_ACT 5), not its default Return, which climbs to 30 m blind
        # (that failsafe is the pre-flight check's and test_flight_link_sil's to judge)
        vehicle = settings.vehicle_sim.model_copy(
            update={"offboard_loss_action": OFFBOARD_LOSS_HOLD}
        )
        settings = settings.model_copy(update={"mission": mission, "vehicle_sim": vehicle})
        world = load_world(flight.world_file)
        # the matrix judges the faults, not the fence: the fault field's goal lies 220 m out,
        # past the default 100 m cylinder that a long --sequential flight reaches
        settings = settings.model_copy(update={"geofence": fence_around(settings.geofence, world)})
        record = asyncio.run(fly_world(settings, world, addons=[addon]))
        rows = record.extra.get("faults", [])
        for row in rows:
            row["flight_failure"] = record.failure or None
            row["wall_s"] = round(record.wall_s, 1)
        return rows
    except Exception as e:  # one broken flight must not end the matrix
        return [
            {"name": s.kind, "injected": False, "ok": False, "collisions": 0,
             "recovered": False, "detected_after_s": None, "stopped_after_s": None,
             "note": f"{type(e).__name__}: {e}"}
            for s in specs
        ]  # fmt: skip
    finally:
        addon.release()  # the hog, the relay, the broker, whatever became of the flight


def fence_around(fence: GeofenceParams, world: World) -> GeofenceParams:
    """`fence`, a cylinder widened to take in the world's goals (local NED from its start)
    with `FENCE_MARGIN_M` to spare; a polygon or a cylinder that holds them, unchanged."""
    import numpy as np

    from companion.ground.params import FenceShape

    if fence.shape is not FenceShape.CYLINDER:
        return fence
    goals_ne_m = np.asarray(world.goals_ned_m, dtype=np.float64).reshape(-1, 3)[:, :2]
    offsets = goals_ne_m - np.asarray(world.start_ned_m)[:2] - np.asarray(fence.center_ned_m)
    reach_m = float(np.linalg.norm(offsets, axis=1).max(initial=0.0)) + FENCE_MARGIN_M
    return fence if reach_m <= fence.radius_m else fence.model_copy(update={"radius_m": reach_m})


def matrix_summary(rows: list[dict[str, Any]], wall_s: float, skipped: list[str]) -> dict:
    """The JSON of `wireavoid faults --json`."""
    return {
        "faults": rows,
        "all_ok": bool(rows) and all(r.get("ok") for r in rows),
        "collisions": sum(int(r.get("collisions") or 0) for r in rows),
        "stop_within_s": 0.5,
        "skipped": skipped,
        "wall_s": round(wall_s, 1),
    }


def faults(
    json_output: Annotated[bool, typer.Option("--json", help="one JSON object on stdout")] = False,
    list_faults: Annotated[bool, typer.Option("--list", help="list the faults and exit")] = False,
    only: Annotated[
        str | None, typer.Option("--only", help="comma-separated faults (default: all)")
    ] = None,
    sequential: Annotated[
        bool, typer.Option("--sequential", help="all faults in turn in one flight")
    ] = False,
    spacing_s: Annotated[
        float, typer.Option("--spacing-s", help="--sequential: from one fault's start to the next")
    ] = 10.0,
    start_s: Annotated[float, typer.Option("--start-s", help="after offboard engages, s")] = 3.0,
    duration_s: Annotated[float, typer.Option("--duration-s", help="each fault lasts, s")] = 2.0,
    judge_s: Annotated[
        float, typer.Option("--judge-s", help="the flight goes on this long after the last fault")
    ] = 6.0,
    jobs: Annotated[int, typer.Option("--jobs", min=1, help="flights in parallel")] = 1,
    world: Annotated[
        Path | None, typer.Option("--world", help="another world file to fly", exists=True)
    ] = None,
    mqtt: Annotated[
        str | None,
        typer.Option(
            "--mqtt",
            help="fly with the ground link on this broker (mqtt_restart, which restarts a "
            "broker of its own, is then skipped)",
        ),
    ] = None,
    config: Annotated[
        Path | None, typer.Option("--config", help="TOML settings file", exists=True)
    ] = None,
) -> None:
    """Inject every fault (camera freeze, drop, delay, reorder, pose jump, MAVLink link loss,
    stalled CNN, stalled planner, CPU hog, MQTT broker restart) into simulated flights and
    report, per fault, when it was detected, how soon the vehicle braked to a hold, collisions
    and recovery (for the broker restart: how soon the ground link reconnected and its status
    flowed again). Exit status 0 when every fault is handled."""
    from hil.faults import FAULT_DESCRIPTIONS, FAULT_KINDS

    if list_faults:
        for name in FAULT_KINDS:
            typer.echo(f"{name:<16} {FAULT_DESCRIPTIONS[name]}")
        raise typer.Exit(0)
    names = [n.strip() for n in only.split(",")] if only else list(FAULT_KINDS)
    unknown = [n for n in names if n not in FAULT_KINDS]
    if unknown:
        raise typer.BadParameter(f"unknown faults {unknown}; one of {', '.join(FAULT_KINDS)}")
    skipped = [n for n in names if n in _OWN_BROKER and mqtt]
    names = [n for n in names if n not in skipped]
    import hil.world

    world_file = str(world or Path(hil.world.__file__).parent / "examples" / FAULT_WORLD)
    cfg = str(config) if config else None

    def spec(name: str, start: float) -> dict[str, Any]:
        return {"kind": name, "start_s": start, "duration_s": duration_s}

    if sequential:
        flights = [
            FaultFlight(
                tuple(spec(n, start_s + i * spacing_s) for i, n in enumerate(names)),
                world_file, cfg, judge_s, mqtt,
            )
        ]  # fmt: skip
    else:
        flights = [FaultFlight((spec(n, start_s),), world_file, cfg, judge_s, mqtt) for n in names]
    started = time.monotonic()
    rows = [row for flight_rows in _run(flights, jobs) for row in flight_rows]
    summary = matrix_summary(rows, time.monotonic() - started, skipped)
    if json_output:
        typer.echo(json.dumps(summary))
    else:
        typer.echo(
            f"{'fault':<16} {'detectable':>10} {'detected':>9} {'stopped':>8} {'halted':>7} "
            f"{'collisions':>10} {'recovered':>9}  ok"
        )
        for r in rows:
            typer.echo(
                f"{r['name']:<16} {_cell(r.get('detectable_after_s')):>10} "
                f"{_cell(r.get('detected_after_s')):>9} {_cell(r.get('stopped_after_s')):>8} "
                f"{_cell(r.get('halted_after_s')):>7} {r.get('collisions'):>10} "
                f"{'yes' if r.get('recovered') else 'no':>9}  {'ok' if r.get('ok') else 'FAIL'}"
            )
        if skipped:
            typer.echo(
                f"skipped (they restart a broker of their own, not --mqtt's): {', '.join(skipped)}"
            )
    raise typer.Exit(0 if summary["all_ok"] else 1)


def _cell(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _run(flights: list[FaultFlight], jobs: int) -> list[list[dict[str, Any]]]:
    """Each flight in a fresh process (spawned: MAVSDK and torch do not survive a fork)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(jobs, mp_context=context, max_tasks_per_child=1) as pool:
        return list(pool.map(fly_faults, flights))


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add `wireavoid faults`."""
    app.command("faults")(faults)
