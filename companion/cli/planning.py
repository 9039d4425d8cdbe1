"""`wireavoid` commands of the planning domain: plan-library, bench planning.

Also the library file format: `save_library` / `load_library` write and read the arrays of
`planning.library.TrajectoryLibrary` as a NumPy `.npz` (the cores do no I/O).
"""

from __future__ import annotations

import json
import time
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer

if TYPE_CHECKING:
    from mapping.query import OccupancyMap
    from planning.library import TrajectoryLibrary
    from planning.params import PlanningParams

ConfigOption = Annotated[
    Path | None,
    typer.Option("--config", help="TOML settings file", exists=True, dir_okay=False),
]


def save_library(library: TrajectoryLibrary, path: Path) -> None:
    """Write `library` to `path` (.npz)."""
    with Path(path).open("wb") as f:
        np.savez(f, **library.as_arrays())


def load_library(path: Path) -> TrajectoryLibrary:
    """The library stored at `path` by `save_library`."""
    from planning.library import TrajectoryLibrary

    with np.load(path, allow_pickle=False) as arrays:
        return TrajectoryLibrary.from_arrays(dict(arrays))


def plot_library(library: TrajectoryLibrary, speed_mps: float, path: Path) -> None:
    """Side and back views of one speed bin, as Fig. 4.8 (x forward, z down drawn up), PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    b = library.bin_for_speed(speed_mps)
    pts = library.positions_m[b]
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    views = (
        ("top", 1, 0, "y right, m", "x forward, m"),
        ("side", 0, 2, "x forward, m", "altitude, m"),
        ("back", 1, 2, "y right, m", "altitude, m"),
    )
    for ax, (title, i, j, xlabel, ylabel) in zip(axes, views, strict=True):
        for k, label in enumerate(library.labels):
            sign = -1.0 if j == 2 else 1.0
            style = "k-" if label == "stop" else "-"
            ax.plot(pts[k, :, i], sign * pts[k, :, j], style, lw=0.8)
            ax.plot(pts[k, :, i], sign * pts[k, :, j], ".", ms=2)
        ax.set_title(f"{title} view")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
    fig.suptitle(
        f"trajectory library: {library.size} manoeuvres x {len(library.times_s)} waypoints, "
        f"initial speed {library.initial_speeds_mps[b]:.2f} m/s (thesis Fig. 4.8)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _droan_map(n_nodes: int, seed: int = 0) -> OccupancyMap:
    """A DROAN map with `n_nodes` keyframes of a wall 8 m ahead with a gap and noise."""
    from companion.config import Settings
    from geometry.camera import (
        body_from_camera_from_params,
        stereo_rig_from_params,
        world_from_camera,
    )
    from geometry.pose import Pose
    from mapping.droan.pose_graph import DroanMap

    mapping = Settings().mapping
    mapping = mapping.model_copy(update={"max_nodes": max(n_nodes, 1)})
    rig = stereo_rig_from_params(mapping.camera)
    droan = DroanMap(rig, mapping)
    rng = np.random.default_rng(seed)
    h, w = rig.camera.shape
    mount = body_from_camera_from_params(mapping.camera)
    for i in range(n_nodes):
        x = -i * 1.1 * mapping.keyframe_translation_m
        depth = np.full((h, w), 8.0 - x)
        depth[:, w // 3 : w // 2] = 30.0
        disparity = rig.disparity_from_depth(depth).astype(np.float32)
        disparity += rng.normal(0.0, 0.1, disparity.shape).astype(np.float32)
        body = Pose.from_yaw_pitch_roll(0.0, 0.0, 0.0, np.array([x, 0.0, -3.0]))
        droan.insert(float(i) * 0.1, world_from_camera(body, mount), disparity)
    return droan


def _synthetic_map(n_nodes: int) -> OccupancyMap:
    """The synthetic map with `n_nodes` views of the same wall (for comparison)."""
    from planning.synthetic_occupancy import SyntheticOccupancyMap, wall

    world = SyntheticOccupancyMap(boxes=[wall(8.0, 1.5, 20.0)], max_views=max(n_nodes, 1))
    for i in range(n_nodes):
        world.add_view(np.array([-0.55 * i, 0.0, -3.0]), 0.0)
    return world


def _median_ms(fn: Any, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times) * 1e3)


def _library_params(base: PlanningParams, size: str) -> PlanningParams:
    """Params with (turn_levels, climb_levels, speed_levels) from "T,C,S"."""
    turn, climb, speed = (int(v) for v in size.split(","))
    return base.model_copy(
        update={"turn_levels": turn, "climb_levels": climb, "speed_levels": speed}
    )


def bench_planning(
    base: PlanningParams,
    shapes: list[str],
    node_counts: list[int],
    repeats: int,
    map_kind: str,
) -> dict[str, Any]:
    """Timings of whole-library evaluation and of one planning cycle (see `bench planning`)."""
    from planning.library import generate_library
    from planning.params import CheckMode
    from planning.planner import LocalPlanner
    from planning.selection import select_trajectory
    from planning.types import VehicleState

    make_map = _droan_map if map_kind == "droan" else _synthetic_map
    maps = {n: make_map(n) for n in sorted({*node_counts, 20})}
    origin, goal = np.array([0.0, 0.0, -3.0]), np.array([30.0, 0.0, -3.0])
    forward = np.array([1.0, 0.0, 0.0])
    rows = []
    for shape in shapes:
        params = _library_params(base, shape)
        gen_ms = _median_ms(partial(generate_library, params), max(1, repeats // 5))
        library = generate_library(params)
        b = library.bin_for_speed(params.max_speed_mps)
        positions, velocities = library.to_world(b, origin, 0.0)
        for n in node_counts:
            row: dict[str, Any] = {
                "library_size": library.size,
                "shape_turn_climb_speed": shape,
                "nodes": n,
                "waypoints": params.waypoints,
                "generate_ms": round(gen_ms, 3),
            }
            for mode in (CheckMode.ALL, CheckMode.CHUNKED):
                select = partial(
                    select_trajectory,
                    positions,
                    velocities,
                    origin,
                    goal,
                    forward,
                    maps[n],
                    params.model_copy(update={"check_mode": mode}),
                    library.stop_index,
                )
                row[f"select_{mode.value}_ms"] = round(_median_ms(select, repeats), 3)
            query_points = positions.reshape(-1, 3)
            row["all_waypoints"] = len(query_points)
            row["query_all_waypoints_ms"] = round(
                _median_ms(partial(maps[n].query, query_points), repeats), 3
            )
            rows.append(row)

    library = generate_library(base)
    planner = LocalPlanner(base, library)
    planner.set_goal(goal, 0.0)
    cruise = np.array([base.max_speed_mps, 0.0, 0.0])
    vehicle = VehicleState(0.0, origin, cruise, 0.0)
    cycle_ms = _median_ms(lambda: planner.step(0.0, vehicle, cruise, maps[20]), repeats)
    return {
        "cycle_ms": round(cycle_ms, 3),
        "cycle_library_size": library.size,
        "cycle_nodes": 20,
        "map": map_kind,
        "check_mode_default": base.check_mode.value,
        "rows": rows,
        "note": "median wall times (shared machine: noisy). select_all_ms: the whole library "
        "costed and checked in one query (check_mode all); select_chunked_ms: cost-ordered "
        "chunks until the first free one; query_all_waypoints_ms: one query of every "
        "waypoint. Map: a wall 8 m ahead with a gap, vehicle at cruise speed.",
    }


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add this domain's commands to the root app and its benchmarks to `wireavoid bench`."""

    @app.command("plan-library")
    def plan_library(
        config: ConfigOption = None,
        out: Annotated[
            Path | None, typer.Option("--out", help="write the library here (.npz)")
        ] = None,
        load: Annotated[
            Path | None,
            typer.Option(
                "--load", help="read this library (.npz) instead of generating", exists=True
            ),
        ] = None,
        plot: Annotated[Path | None, typer.Option("--plot", help="PNG of the library")] = None,
        speed_mps: Annotated[
            float, typer.Option("--speed", help="initial speed of the plotted bin, m/s")
        ] = 2.0,
    ) -> None:
        """Generate (or load) the trajectory library of thesis 4.5 / Fig. 4.8; save, plot."""
        from companion.cli.settings import load_sim_settings
        from planning.library import generate_library

        params = load_sim_settings(config).planning
        library = load_library(load) if load else generate_library(params)
        if out:
            save_library(library, out)
        if plot:
            plot_library(library, speed_mps, plot)
        typer.echo(
            json.dumps(
                {
                    "library_size": library.size,
                    "speed_bins_mps": [round(float(v), 3) for v in library.initial_speeds_mps],
                    "waypoints": len(library.times_s),
                    "horizon_s": float(library.times_s[-1]),
                    "labels": list(library.labels),
                    "out": str(out) if out else None,
                    "plot": str(plot) if plot else None,
                },
                indent=2,
            )
        )

    @bench.command("planning")
    def bench_planning_command(
        config: ConfigOption = None,
        as_json: Annotated[bool, typer.Option("--json", help="print JSON only")] = False,
        shapes: Annotated[
            str,
            typer.Option(
                "--shapes",
                help="library shapes 'turn,climb,speed' separated by ';' (sizes (2T+1)(2C+1)S+1)",
            ),
        ] = "1,1,1;3,2,2;4,3,3;6,4,3",
        nodes: Annotated[str, typer.Option("--nodes", help="graph sizes, comma separated")] = (
            "1,5,10,20"
        ),
        repeats: Annotated[int, typer.Option("--repeats", min=3)] = 20,
        map_kind: Annotated[
            str, typer.Option("--map", help="droan (DROAN pose graph) or synthetic")
        ] = "droan",
    ) -> None:
        """Time to evaluate the whole library vs library size and graph size; `cycle_ms`."""
        from companion.cli.settings import load_sim_settings

        result = bench_planning(
            load_sim_settings(config).planning,
            [s for s in shapes.split(";") if s],
            [int(n) for n in nodes.split(",") if n],
            repeats,
            map_kind,
        )
        if as_json:
            typer.echo(json.dumps(result))
            return
        typer.echo(
            f"cycle_ms={result['cycle_ms']} (library {result['cycle_library_size']}, "
            f"20 nodes, {result['map']} map)"
        )
        for row in result["rows"]:
            typer.echo(json.dumps(row))
