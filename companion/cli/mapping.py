"""`wireavoid` commands of the mapping domain: calibrate-sigma, map-sim, bench mapping."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

ConfigOption = Annotated[
    Path | None,
    typer.Option("--config", help="TOML settings file", exists=True, dir_okay=False),
]


def _parse_pattern(pattern: str) -> tuple[int, int]:
    cols, rows = (int(x) for x in pattern.lower().split("x"))
    return cols, rows


def calibrate_sigma(
    samples_dir: Annotated[
        Path | None,
        typer.Argument(
            help="folder of rectified samples NAME_left.png with NAME_disp.npy (float32 px) "
            "or NAME_right.png (SGBM); omit with --simulate",
            exists=True,
            file_okay=False,
        ),
    ] = None,
    pattern: Annotated[str, typer.Option(help="inner corners COLSxROWS")] = "8x5",
    square_m: Annotated[float, typer.Option(help="checkerboard square size, m")] = 0.1,
    simulate: Annotated[
        bool, typer.Option(help="render a board session with the simulated camera instead")
    ] = False,
    noise_px: Annotated[float, typer.Option(help="with --simulate: injected sigma, px")] = 0.23,
    as_json: Annotated[bool, typer.Option("--json", help="print JSON")] = False,
    config: ConfigOption = None,
) -> None:
    """Fit the disparity noise sigma (4.4.2) from checkerboard corners of known depth."""
    import cv2

    from companion.cli.settings import load_sim_settings
    from geometry.camera import stereo_rig_from_params
    from mapping.droan.calibration import (
        corner_depths_m,
        find_corners,
        fit_disparity_sigma,
        sample_disparity,
    )
    from mapping.droan.stereo import disparity_from_pair, sgbm_matcher

    params = load_sim_settings(config).mapping
    rig = stereo_rig_from_params(params.camera)
    inner = _parse_pattern(pattern)
    if simulate:
        shots = _simulated_board_shots(rig, inner, square_m, noise_px)
    elif samples_dir is not None:
        matcher = sgbm_matcher(params.stereo, params.camera.max_disparity_px)
        shots = []
        for left_path in sorted(samples_dir.glob("*_left.png")):
            stem = left_path.name[: -len("_left.png")]
            left = cv2.imread(str(left_path), cv2.IMREAD_GRAYSCALE)
            disp_path = samples_dir / f"{stem}_disp.npy"
            if disp_path.exists():
                disparity = np.load(disp_path).astype(np.float32)
            else:
                right = cv2.imread(str(samples_dir / f"{stem}_right.png"), cv2.IMREAD_GRAYSCALE)
                disparity = disparity_from_pair(matcher, left, right)
            shots.append((left, disparity))
    else:
        raise typer.BadParameter("give SAMPLES_DIR or --simulate")
    measured, expected, used = [], [], 0
    for left, disparity in shots:
        corners = find_corners(left, inner)
        if corners is None:
            continue
        used += 1
        measured.append(sample_disparity(disparity, corners))
        expected.append(rig.disparity_from_depth(corner_depths_m(rig, corners, inner, square_m)))
    if not measured:
        raise typer.Exit(code=1)
    fit = fit_disparity_sigma(np.concatenate(measured), np.concatenate(expected))
    result = {
        "sigma_px": round(fit.sigma_px, 4),
        "bias_px": round(fit.bias_px, 4),
        "samples": fit.samples,
        "rejected": fit.rejected,
        "images_used": used,
        "images": len(shots),
    }
    if as_json:
        typer.echo(json.dumps(result))
    else:
        typer.echo(
            f"sigma = {fit.sigma_px:.3f} px (bias {fit.bias_px:+.3f} px) from {fit.samples} "
            f"corners in {used} images; set mapping.disparity_sigma_px"
        )


def _simulated_board_shots(rig, inner: tuple[int, int], square_m: float, noise_px: float):
    """(left grey, disparity) pairs of a board at 2-4 m rendered by the simulated camera."""
    from geometry.camera import body_from_camera_mount
    from geometry.pose import Pose
    from hil.sensors.cameras import SimulatedStereoCamera
    from hil.sensors.params import CameraSimParams
    from hil.world.model import Checkerboard, World

    cols, rows = inner[0] + 1, inner[1] + 1
    vehicle = Pose.from_yaw_pitch_roll(0.0, 0.0, 0.0, [0.0, 0.0, -5.0])
    shots = []
    for k, distance_m in enumerate(np.arange(2.0, 4.01, 0.5)):
        board = Checkerboard(
            float(distance_m),
            -cols * square_m / 2,
            -5.0 - rows * square_m / 2,
            (cols, rows),
            square_m,
        )
        camera = SimulatedStereoCamera(
            World(boards=[board]),
            rig,
            body_from_camera_mount([0.0, 0.0, 0.0]),
            # the corners are found in the disparity camera's own (full-resolution) image
            CameraSimParams(disparity_noise_px=noise_px),
            colour_downscale=1,
        )
        for shot in range(4):
            frame = camera.render(k + 0.1 * shot, vehicle)
            shots.append((frame.image_bgr.mean(axis=2).astype(np.uint8), frame.disparity_px))
    return shots


def map_sim(
    out: Annotated[Path, typer.Option(help="PLY file of the occupied voxels")] = Path(
        "droan_map.ply"
    ),
    frames: Annotated[int, typer.Option(help="simulated frames (10 Hz, 0.5 m apart)")] = 20,
    resolution_m: Annotated[float, typer.Option(help="voxel size of the export, m")] = 0.5,
    config: ConfigOption = None,
) -> None:
    """Map the simulated power-line crossing with DROAN and export occupied voxels (Fig. 4.5)."""
    from companion.cli.bench_mapping import flight_frames
    from companion.cli.settings import load_sim_settings
    from geometry.camera import stereo_rig_from_params
    from hil.world.model import wire_crossing_world
    from mapping.droan.export import height_colours, occupied_voxels, ply_bytes
    from mapping.droan.pose_graph import DroanMap

    settings = load_sim_settings(config)
    params = settings.mapping
    rig = stereo_rig_from_params(params.camera)
    world = wire_crossing_world(distance_m=14.0)
    droan = DroanMap(rig, params)
    for frame in flight_frames(world, rig, params, settings.camera_sim, frames):
        droan.insert(frame.stamp_s, frame.world_from_camera, frame.disparity_px, frame.wire_mask)
    centre = droan.nodes[-1].world_from_camera.translation_m
    points, _ = occupied_voxels(droan, centre, resolution_m=resolution_m)
    out.write_bytes(ply_bytes(points, height_colours(points)))
    typer.echo(f"{len(points)} occupied voxels from {len(droan)} nodes -> {out}")


def bench_mapping(
    frames: Annotated[int, typer.Option(help="simulated 640x480 frames")] = 20,
    as_json: Annotated[bool, typer.Option("--json", help="print JSON")] = False,
    config: ConfigOption = None,
) -> None:
    """DROAN update / batch query vs an OctoMap on the same simulated frames (issue 4)."""
    from companion.cli.bench_mapping import run_mapping_benchmark
    from companion.cli.settings import load_sim_settings

    result = run_mapping_benchmark(load_sim_settings(config).mapping, frame_count=frames)
    if as_json:
        typer.echo(json.dumps(result, indent=2))
        return
    for key, value in result.items():
        if key != "details":
            typer.echo(f"{key}: {value}")


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add this domain's commands to the root app and its benchmarks to `wireavoid bench`."""
    app.command("calibrate-sigma")(calibrate_sigma)
    app.command("map-sim")(map_sim)
    bench.command("mapping")(bench_mapping)
