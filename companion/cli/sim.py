"""`wireavoid sim` and `wireavoid sweep`: the whole stack flown through simulated wire worlds.

`sim` flies one scenario (or world file) with the real flight process, the real MAVSDK and
the hil vehicle over MAVLink (or PX4 SITL with `--connect`), judges the flight on the world's
true geometry (`hil.judge`), prints the verdict (or one JSON object with `--json`) and writes a
PNG with a top and a side view. `sweep` flies many seeded scenarios in parallel processes and
reports the success rate; past one machine it runs them on a Ray cluster (`--address`).
Exit status 0 when every flight succeeded.
"""

from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Any

import typer

from companion.cli.gcs import MqttUrlOption, VehicleIdOption
from companion.cli.sim_options import (
    FaultOption,
    RecordOption,
    ViewOption,
    ViewPortOption,
    checked_faults,
)
from companion.record.reader import recording_parts


@dataclass(frozen=True)
class FlightSpec:
    """One flight to fly: a built-in scenario and seed, or a world file; the settings file."""

    scenario: str | None
    seed: int
    world_file: str | None
    config: str | None
    realtime: bool = False
    connect_url: str | None = None
    mqtt_url: str | None = None
    vehicle_id: str | None = None
    px4_log: str | None = None
    inference_threads: int | None = None  # the CNN's CPU threads (a sweep shares the cores)
    record: str | None = None  # an MCAP file to record the flight to
    view_port: int | None = None  # a Foxglove WebSocket port for the live view
    faults: tuple[str, ...] = ()  # fault kinds to inject (`hil.faults`)


def fly_and_judge(spec: FlightSpec, png: Path | None = None, progress: bool = False) -> dict:
    """Fly `spec` and return the JSON-ready verdict (the keys of `wireavoid sim --json`)."""
    import asyncio
    import logging

    from companion.cli.settings import load_sim_settings
    from companion.cli.sim_flight import fly_world
    from companion.cli.sim_options import flight_addons
    from companion.ground.options import apply_ground_options
    from hil.judge import FlightJudge, plot_flight
    from hil.px4_truth import ulog_truth
    from hil.world.file import load_world
    from hil.world.scenarios import build_scenario

    logging.getLogger("mavsdk").setLevel(logging.CRITICAL)
    settings = apply_ground_options(
        load_sim_settings(Path(spec.config) if spec.config else None),
        spec.mqtt_url,
        spec.vehicle_id,
    )
    if spec.realtime:
        settings = settings.model_copy(
            update={"sim": settings.sim.model_copy(update={"time": "realtime"})}
        )
    if spec.inference_threads is not None:
        perception = settings.perception.model_copy(
            update={"inference_threads": spec.inference_threads}
        )
        settings = settings.model_copy(update={"perception": perception})
    world = (
        load_world(spec.world_file) if spec.world_file else build_scenario(spec.scenario, spec.seed)
    )
    addons = flight_addons(spec.record, spec.view_port, spec.faults, spec.world_file)
    record = asyncio.run(
        fly_world(settings, world, connect_url=spec.connect_url, progress=progress, addons=addons)
    )
    times, path, on_ground, truth = (
        record.times_s,
        record.path_ned_m,
        record.on_ground,
        record.truth_source,
    )
    if spec.px4_log:
        times, path, on_ground = ulog_truth(spec.px4_log)
        path, truth = path + world.start_ned_m, "PX4 ground truth (its flight log)"
    judge = FlightJudge(world, settings.sim.vehicle_radius_m, settings.sim.goal_radius_m)
    for stamp, position, grounded in zip(times, path, on_ground, strict=True):
        judge.add(float(stamp), position, bool(grounded))
    verdict = judge.verdict()
    timings = record.report.timings
    frame_to_setpoint = timings.get("frame_to_setpoint", {}) if timings else {}
    success = record.completed and not record.failure and verdict.success and verdict.duration_s > 0
    result: dict[str, Any] = {
        "success": bool(success),
        "collisions": verdict.collisions,
        "min_clearance_m": _finite(verdict.min_clearance_m),
        "min_wire_clearance_m": _finite(verdict.min_wire_clearance_m),
        "duration_s": round(verdict.duration_s, 2),
        "path_length_m": round(verdict.path_length_m, 2),
        "frame_to_setpoint_ms_p99": frame_to_setpoint.get("p99_ms"),
        "scenario": spec.scenario if not spec.world_file else world.name,
        "world_file": spec.world_file,
        "seed": spec.seed,
        "goals_reached": list(verdict.goals_reached),
        "goal_times_s": [_finite(t) for t in verdict.goal_times_s],
        "obstacle_collisions": verdict.obstacle_collisions,
        "wire_collisions": verdict.wire_collisions,
        "ground_collisions": verdict.ground_collisions,
        "min_ground_clearance_m": _finite(verdict.min_ground_clearance_m),
        "vehicle_radius_m": settings.sim.vehicle_radius_m,
        "mission_state": record.report.state.value,
        "mission_completed": record.completed,
        "failure": record.failure,
        "time": "realtime" if (spec.realtime or spec.connect_url) else settings.sim.time,
        "truth": truth,
        "cameras_from": record.truth_source,  # the pose the cameras rendered from
        "wire_masks": settings.sim.wire_masks,
        "wall_s": round(record.wall_s, 1),
        "compute_s": _finite(record.compute_s),
        "frames": record.report.frames,
        "fused": record.report.fused,
        "plans": record.report.plans,
        "stages": timings,
        "events": [
            {"t_s": round(e.stamp_s, 2), "state": e.state.value, "text": e.text}
            for e in record.report.events
        ],
    }
    result.update(record.extra)  # the recording, the live view, the faults' rows
    if png is not None:
        title = f"{result['scenario']} seed {spec.seed}: {'PASS' if success else 'FAIL'}"
        result["png"] = str(plot_flight(world, path, png, title=title))
    return result


def _finite(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else round(float(value), 3)


def verdict_text(result: dict) -> str:
    """The human verdict of one flight."""
    lines = [
        f"scenario {result['scenario']} seed {result['seed']} ({result['time']} time, "
        f"truth from the {result['truth']}, cameras from the {result['cameras_from']}), "
        f"{result['wall_s']} s wall",
        f"mission: {result['mission_state']}"
        + ("" if result["mission_completed"] else " (not completed)"),
        f"goals reached: {sum(result['goals_reached'])}/{len(result['goals_reached'])} "
        f"at {result['goal_times_s']} s",
        f"collisions: {result['collisions']} (solids {result['obstacle_collisions']}, wires "
        f"{result['wire_collisions']}, ground {result['ground_collisions']}) with a "
        f"{result['vehicle_radius_m']} m vehicle",
        f"minimum clearance: {result['min_clearance_m']} m to obstacles, "
        f"{result['min_wire_clearance_m']} m to wires",
        f"time {result['duration_s']} s, path {result['path_length_m']} m, frame to setpoint "
        f"p99 {result['frame_to_setpoint_ms_p99']} ms",
    ]
    for event in result["events"]:
        lines.append(f"  {event['t_s']:7.2f} s  {event['state']:<9} {event['text']}")
    if result.get("png"):
        lines.append(f"plot: {result['png']}")
    if result["failure"]:
        lines.append(f"failure: {result['failure']}")
    lines.append(f"verdict: {'PASS' if result['success'] else 'FAIL'}")
    return "\n".join(lines)


ConfigOption = Annotated[
    Path | None, typer.Option("--config", help="TOML settings file", exists=True, dir_okay=False)
]


def sim(
    scenario: Annotated[
        str,
        typer.Option("--scenario", help="built-in scenario (`wireavoid sim --list` names them)"),
    ] = "ladder-wire",
    world: Annotated[
        Path | None,
        typer.Option("--world", help="a world file (TOML, docs/worlds.md) instead", exists=True),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="varies the scenario")] = 0,
    json_output: Annotated[bool, typer.Option("--json", help="one JSON object on stdout")] = False,
    realtime: Annotated[
        bool, typer.Option("--realtime", help="fly on the wall clock instead of lockstep time")
    ] = False,
    connect: Annotated[
        str | None,
        typer.Option(
            "--connect",
            help="fly an external autopilot (PX4 SITL: udpin://0.0.0.0:14540) in real time; "
            "the cameras render from PX4 SITL's ground truth (sim.px4_ground_truth), else "
            "from its pose estimate",
        ),
    ] = None,
    out: Annotated[
        Path, typer.Option("--out", help="the PNG with the top and side view of the flight")
    ] = Path("sim.png"),
    list_scenarios: Annotated[
        bool, typer.Option("--list", help="list the built-in scenarios and exit")
    ] = False,
    px4_log: Annotated[
        Path | None,
        typer.Option(
            "--px4-log",
            help="with --connect to PX4 SITL: its flight log (.ulg, or the folder of its logs); "
            "the flight is then judged on PX4's ground truth, else on its estimate",
            exists=True,
        ),
    ] = None,
    mqtt: MqttUrlOption = None,
    vehicle_id: VehicleIdOption = None,
    record: RecordOption = None,
    view: ViewOption = False,
    view_port: ViewPortOption = 8765,
    fault: FaultOption = None,
    config: ConfigOption = None,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="log every stage")] = False,
) -> None:
    """Fly the whole stack through a simulated wire world and judge it on the true geometry.

    Camera -> wire CNN -> DROAN -> planner -> setpoints -> MAVSDK -> the simulated PX4-like
    vehicle over MAVLink. Prints the verdict (goal reached, collisions, clearances, time, path
    length) and writes a PNG; exit status 0 on success.
    """
    import logging

    from hil.world.scenarios import SCENARIOS

    if list_scenarios:
        for name, description in SCENARIOS.items():
            typer.echo(f"{name:<22} {description}")
        raise typer.Exit(0)
    if world is None and scenario not in SCENARIOS:
        raise typer.BadParameter(f"unknown scenario {scenario!r}; one of {', '.join(SCENARIOS)}")
    if world is not None:
        from hil.world.file import WorldFileError, load_world

        try:
            load_world(world)
        except WorldFileError as e:
            raise typer.BadParameter(str(e), param_hint="--world") from e
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    spec = FlightSpec(
        scenario, seed, str(world) if world else None, str(config) if config else None,
        realtime, connect, mqtt, vehicle_id, str(px4_log) if px4_log else None,
    )  # fmt: skip
    spec = replace(
        spec,
        record=str(record) if record else None,
        view_port=view_port if view else None,
        faults=tuple(checked_faults(fault or [])),
    )
    result = fly_and_judge(spec, png=out, progress=not json_output)
    typer.echo(json.dumps(result) if json_output else verdict_text(result))
    raise typer.Exit(0 if result["success"] else 1)


def _fly_quietly(spec: FlightSpec) -> dict:
    """A sweep's flight in a worker process: the verdict, or the error that stopped it; its
    recording (if any) kept only when it failed."""
    try:
        result = fly_and_judge(spec)
    except Exception as e:  # one broken flight must not end the sweep
        result = {"success": False, "scenario": spec.scenario, "seed": spec.seed,
                  "collisions": 0, "failure": f"{type(e).__name__}: {e}"}  # fmt: skip
    return keep_recording_of_failure(spec, result)


def keep_recording_of_failure(spec: FlightSpec, result: dict) -> dict:
    """`result` with the flight's recording: deleted (every part) when the flight succeeded,
    else its path as `recording`. A sweep flight is not deterministic (lockstep charges the
    stack's compute to simulated time), so a failure is replayed from its recording."""
    if spec.record is None or not Path(spec.record).exists():
        return result
    if result["success"]:
        for part in recording_parts(spec.record):
            part.unlink()
        return result
    return {**result, "recording": spec.record}


_FLIGHT_KEYS = ("scenario", "seed", "success", "collisions", "min_clearance_m",
                "min_wire_clearance_m", "duration_s", "wall_s")  # fmt: skip


def _tally(results: list[dict]) -> dict:
    """Flights, successes, collisions and the closest wire pass of `results`."""
    wires = [r.get("min_wire_clearance_m") for r in results]
    wires = [w for w in wires if w is not None]
    return {
        "runs": len(results),
        "successes": sum(bool(r["success"]) for r in results),
        "collisions": sum(int(r.get("collisions") or 0) for r in results),
        "min_wire_clearance_m": min(wires) if wires else None,
    }


def sweep_summary(results: list[dict]) -> dict:
    """The sweep's JSON: `runs`, `success_rate`, `collisions`, `min_clearance_m` and more;
    `by_scenario` and `by_seed` tally the flights of each scenario and of each of its seeds
    (a seed flown `--repeat` times: flights are not repeatable, see README)."""
    clearances = [r["min_clearance_m"] for r in results if r.get("min_clearance_m") is not None]
    latencies = [
        r["frame_to_setpoint_ms_p99"] for r in results if r.get("frame_to_setpoint_ms_p99")
    ]
    total = _tally(results)
    runs, successes = total["runs"], total["successes"]
    return {
        "runs": runs,
        "success_rate": round(successes / runs, 4) if runs else 0.0,
        "successes": successes,
        "collisions": total["collisions"],
        "min_clearance_m": min(clearances) if clearances else None,
        "min_wire_clearance_m": total["min_wire_clearance_m"],
        "frame_to_setpoint_ms_p99_max": max(latencies) if latencies else None,
        "failures": [
            {
                k: r.get(k)
                for k in ("scenario", "seed", "collisions", "mission_state", "failure", "recording")
            }
            for r in results
            if not r["success"]
        ],
        "by_scenario": {
            name: _tally(group) for (name,), group in _grouped(results, "scenario").items()
        },
        "by_seed": [
            {"scenario": name, "seed": seed, **_tally(group)}
            for (name, seed), group in _grouped(results, "scenario", "seed").items()
        ],
        "flights": [{k: r.get(k) for k in _FLIGHT_KEYS} for r in results],
    }


def _grouped(results: list[dict], *keys: str) -> dict[tuple, list[dict]]:
    """`results` by their values of `keys`, in the order first flown."""
    groups: dict[tuple, list[dict]] = {}
    for r in results:
        groups.setdefault(tuple(r[k] for k in keys), []).append(r)
    return groups


def sweep_specs(
    names: list[str],
    seeds: range,
    config: Path | None,
    threads: int | None,
    record_dir: Path | None = None,
    repeats: int = 1,
) -> list[FlightSpec]:
    """`repeats` flights of each scenario in `names` with each seed, scenario by scenario,
    each recorded to `record_dir`/SCENARIO-SEED.mcap (SCENARIO-SEED-R.mcap, R from 1, when
    repeated) when given."""
    settings = str(config) if config else None

    def record(name: str, seed: int, repeat: int) -> str | None:
        if record_dir is None:
            return None
        stem = f"{name}-{seed}" if repeats == 1 else f"{name}-{seed}-{repeat}"
        return str(record_dir / f"{stem}.mcap")

    return [
        FlightSpec(
            name, seed, None, settings, inference_threads=threads, record=record(name, seed, r)
        )
        for name in names
        for seed in seeds
        for r in range(1, repeats + 1)
    ]


def sweep(
    scenarios: Annotated[
        str, typer.Option("--scenarios", help="comma-separated built-in scenarios")
    ] = "ladder-wire,ladder-wire-left,ladder-wire-right,stacked-wires,power-line-corridor,random",
    seeds: Annotated[
        int, typer.Option("--seeds", min=1, help="how many seeds of each: F..F+N-1")
    ] = 5,
    first_seed: Annotated[
        int,
        typer.Option(
            "--first-seed", min=0, help="the first seed F (extend an earlier sweep of 0..F-1)"
        ),
    ] = 0,
    repeat: Annotated[
        int,
        typer.Option(
            "--repeat",
            min=1,
            help="fly each scenario and seed this many times (flights are not repeatable: "
            "`by_seed` tells a seed that always fails from one that sometimes does)",
        ),
    ] = 1,
    jobs: Annotated[int, typer.Option("--jobs", min=1, help="flights in parallel")] = 2,
    address: Annotated[
        str | None,
        typer.Option(
            "--address",
            help="run on a Ray cluster at this address (`pip install wireavoid[ray]`); "
            "'local' starts one on this machine",
        ),
    ] = None,
    json_output: Annotated[bool, typer.Option("--json", help="one JSON object on stdout")] = False,
    config: ConfigOption = None,
    record_failures: Annotated[
        Path | None,
        typer.Option(
            "--record-failures",
            file_okay=False,
            help="record every flight to DIR/SCENARIO-SEED.mcap and keep the recordings of "
            "the failed ones (`recording` in the JSON's failures), for `wireavoid replay`",
        ),
    ] = None,
) -> None:
    """Fly many seeded scenarios and report the success rate (exit 0 when all succeeded)."""
    from hil.world.scenarios import SCENARIOS

    names = [s.strip() for s in scenarios.split(",") if s.strip()]
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        raise typer.BadParameter(f"unknown scenarios {unknown}; one of {', '.join(SCENARIOS)}")
    # the flights share this machine's cores: each CNN gets its share of them, not all
    threads = None if address else max(1, (os.cpu_count() or 1) // jobs)
    if record_failures is not None:
        record_failures.mkdir(parents=True, exist_ok=True)
    seed_range = range(first_seed, first_seed + seeds)
    specs = sweep_specs(names, seed_range, config, threads, record_failures, repeat)
    results = _run_on_ray(specs, address) if address else _run_locally(specs, jobs)
    summary = sweep_summary(results)
    if json_output:
        typer.echo(json.dumps(summary))
    else:
        for flight in summary["flights"]:
            typer.echo(
                f"{flight['scenario']:<22} seed {flight['seed']:>3}: "
                f"{'PASS' if flight['success'] else 'FAIL'}  collisions {flight['collisions']}  "
                f"clearance {flight['min_clearance_m']} m, "
                f"wires {flight['min_wire_clearance_m']} m"
            )
        tallies = [(f"{s['scenario']} seed {s['seed']}", s) for s in summary["by_seed"]]
        tallies = (tallies if repeat > 1 else []) + list(summary["by_scenario"].items())
        for name, tally in tallies:
            typer.echo(
                f"{name:<30} {tally['successes']}/{tally['runs']} succeeded, "
                f"{tally['collisions']} collisions, wires {tally['min_wire_clearance_m']} m"
            )
        typer.echo(
            f"{summary['successes']}/{summary['runs']} succeeded ({summary['success_rate']:.1%}), "
            f"{summary['collisions']} collisions, minimum clearance {summary['min_clearance_m']} m"
        )
    raise typer.Exit(0 if summary["successes"] == summary["runs"] else 1)


def _run_locally(specs: list[FlightSpec], jobs: int) -> list[dict]:
    """Each flight in a fresh process (spawned: MAVSDK and torch do not survive a fork)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(jobs, mp_context=context, max_tasks_per_child=1) as pool:
        return list(pool.map(_fly_quietly, specs))


def _run_on_ray(specs: list[FlightSpec], address: str) -> list[dict]:
    """Each flight as a Ray task in a fresh worker process, one CPU core each."""
    try:
        import ray
    except ImportError as e:
        raise typer.BadParameter(
            "--address needs Ray: pip install 'wireavoid[ray]' on every machine of the cluster"
        ) from e
    ray.init(address=None if address == "local" else address, ignore_reinit_error=True)
    remote = ray.remote(num_cpus=1, max_calls=1)(_fly_quietly)
    return ray.get([remote.remote(spec) for spec in specs])


def bench_flight(
    scenario: Annotated[
        str, typer.Option("--scenario", help="the world patrolled")
    ] = "ladder-wire",
    seed: Annotated[int, typer.Option("--seed")] = 0,
    duration_s: Annotated[
        float, typer.Option("--duration", min=10.0, help="simulated seconds of flight")
    ] = 600.0,
    json_output: Annotated[bool, typer.Option("--json", help="print JSON")] = False,
    config: ConfigOption = None,
) -> None:
    """A long patrol through a scenario (its goals, then back to the start, over and over):
    frame-to-setpoint latency and planning overruns of the whole stack on this machine."""
    import asyncio
    import logging
    from dataclasses import replace

    import numpy as np

    from companion.cli.settings import load_sim_settings
    from companion.cli.sim_flight import fly_world
    from hil.world.scenarios import build_scenario

    logging.getLogger("mavsdk").setLevel(logging.CRITICAL)
    settings = load_sim_settings(config)
    world = build_scenario(scenario, seed)
    home = world.takeoff_point_ned_m + np.array([0.0, 0.0, -world.takeoff_altitude_m])
    lap = [*np.asarray(world.goals_ned_m), home]
    laps = int(duration_s // 20.0) + 1  # more laps than the time allows: it never runs out
    patrol = replace(world, goals_ned_m=np.array(lap * laps))
    sim = settings.sim.model_copy(update={"timeout_s": duration_s})
    mission = settings.mission.model_copy(update={"end_action": "hold"})
    settings = settings.model_copy(update={"sim": sim, "mission": mission})
    record = asyncio.run(fly_world(settings, patrol))
    stages = record.report.timings
    flown_s = float(record.times_s[-1] - record.times_s[0]) if len(record.times_s) else 0.0
    result = {
        "frame_to_setpoint_ms_p99": stages["frame_to_setpoint"]["p99_ms"],
        "frame_to_setpoint_ms_p50": stages["frame_to_setpoint"]["p50_ms"],
        "plan_overruns": stages["plan_overruns"],
        "plan_cycle_ms_p99": stages["plan"]["p99_ms"],
        "plan_rate_hz": round(record.report.plans / max(flown_s, 1e-9), 2),
        "dropped_frames": stages["dropped_frames"],
        "duration_s": round(flown_s, 1),
        "wall_s": round(record.wall_s, 1),
        "stages": stages,
        "scenario": scenario,
        "seed": seed,
        "failure": record.failure if record.completed else "",
        "note": "lockstep: each computation costs its measured wall time on this machine "
        "(sim.compute_scale); the simulator's rendering costs nothing",
    }
    if json_output:
        typer.echo(json.dumps(result))
    else:
        for key, value in result.items():
            if key != "stages":
                typer.echo(f"{key}: {value}")


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add `wireavoid sim`, `wireavoid sweep` and `wireavoid bench flight`."""
    app.command("sim")(sim)
    app.command("sweep")(sweep)
    bench.command("flight")(bench_flight)
