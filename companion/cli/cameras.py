"""`wireavoid bench cameras`: the cost of rendering the simulated cameras, per part.

Flights in simulation are dominated by rendering (the lockstep clock never charges it to the
drone), so this measures one frame of the configured rig along an approach to a scenario's
first obstacle: the colour image (at its down-scaled resolution) and the disparity image (at
the rig's), single-threaded (OpenCV on one thread; numpy is single-threaded). Wall-clock and
process CPU milliseconds, p50 and p99 (and the CPU minimum, the least disturbed frame on a
shared machine); the target is render_ms_p50 <= 60 ms on one core.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

ConfigOption = Annotated[
    Path | None,
    typer.Option("--config", help="TOML settings file", exists=True, dir_okay=False),
]


def _percentiles(name: str, values: list[float]) -> dict[str, float]:
    return {
        f"{name}_p50": round(float(np.percentile(values, 50)), 2),
        f"{name}_p99": round(float(np.percentile(values, 99)), 2),
    }


def run_camera_benchmark(settings: Any, scenario: str, seed: int, frames: int) -> dict[str, Any]:
    """Render `frames` frames of `scenario` (seed) approaching its first goal at 2 m/s and
    10 Hz (plus one warm-up); returns the JSON-ready timings."""
    import cv2

    from companion.cli.sim_camera import settings_camera
    from geometry.pose import Pose
    from hil.world.scenarios import build_scenario

    cv2.setNumThreads(1)
    world = build_scenario(scenario, seed)
    start_build = time.perf_counter()
    camera = settings_camera(settings, world)
    rig = camera.rig
    setup_ms = 1e3 * (time.perf_counter() - start_build)
    start = world.takeoff_point_ned_m
    goal = world.goals_ned_m[0]
    heading = float(np.arctan2(goal[1] - start[1], goal[0] - start[0]))
    step = (goal - start) / max(np.linalg.norm(goal - start), 1e-9) * 0.2  # 2 m/s at 10 Hz
    timings: dict[str, list[float]] = {k: [] for k in ("render", "colour", "disparity")}
    cpu: list[float] = []
    for i in range(frames + 1):
        pose = Pose.from_yaw_pitch_roll(heading, 0.0, 0.0, start + i * step)
        t0, c0 = time.perf_counter(), time.process_time()
        colour = camera.render_colour(0.1 * i, pose)
        t1 = time.perf_counter()
        camera.render_disparity(0.1 * i, pose, colour)
        t2, c2 = time.perf_counter(), time.process_time()
        if i == 0:
            continue  # warm-up: caches
        timings["colour"].append(1e3 * (t1 - t0))
        timings["disparity"].append(1e3 * (t2 - t1))
        timings["render"].append(1e3 * (t2 - t0))
        cpu.append(1e3 * (c2 - c0))
    result: dict[str, Any] = {
        "scenario": scenario,
        "seed": seed,
        "frames": frames,
        "colour_size": list(camera.colour_camera.shape[::-1]),
        "disparity_size": list(rig.camera.shape[::-1]),
        "stereo_mode": settings.camera_sim.stereo_mode,
        "solids": len(world.solids),
        "wires": len(world.wires),
        "setup_ms": round(setup_ms, 1),
    }
    result.update(_percentiles("render_ms", timings["render"]))
    result.update(_percentiles("render_cpu_ms", cpu))
    result["render_cpu_ms_min"] = round(min(cpu), 2)  # the least disturbed frame
    result.update(_percentiles("colour_ms", timings["colour"]))
    result.update(_percentiles("disparity_ms", timings["disparity"]))
    return result


def bench_cameras(
    scenario: Annotated[str, typer.Option(help="built-in scenario to render")] = "ladder-wire",
    seed: Annotated[int, typer.Option(help="scenario seed")] = 0,
    frames: Annotated[int, typer.Option(help="frames to time (after one warm-up)")] = 30,
    as_json: Annotated[bool, typer.Option("--json", help="print JSON")] = False,
    config: ConfigOption = None,
) -> None:
    """Time the simulated cameras: colour + disparity per frame, one thread (issue 17)."""
    from companion.cli.settings import load_sim_settings

    result = run_camera_benchmark(load_sim_settings(config), scenario, seed, frames)
    if as_json:
        typer.echo(json.dumps(result))
        return
    typer.echo(
        f"{scenario}#{seed}: {result['render_ms_p50']:.1f} ms per frame p50 "
        f"({result['render_ms_p99']:.1f} p99; CPU {result['render_cpu_ms_p50']:.1f}): colour "
        f"{'x'.join(map(str, result['colour_size']))} {result['colour_ms_p50']:.1f} ms, "
        f"disparity {'x'.join(map(str, result['disparity_size']))} "
        f"{result['disparity_ms_p50']:.1f} ms"
    )


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add `wireavoid bench cameras`."""
    del app
    bench.command("cameras")(bench_cameras)
