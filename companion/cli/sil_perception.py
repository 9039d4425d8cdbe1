"""`wireavoid evaluate-sim` and `sil-frames`: the closed loop's wire mask on simulator frames.

`evaluate` scores probability maps on labelled photographs; this scores what the flight
process makes of what its cameras see in SIL: the shipped CNN's thresholded mask
(`WireSegmenter.mask_of`, with the settings' `perception`) and that mask continued as the
flight process continues it (`WireDetector.continued`: with
`perception.wire_continuation_stops_at_surfaces`, up to the surfaces the same frame's
stereo sees), on frames the simulated cameras
render of built-in scenarios, against the renderer's true wire pixels. Poses are drawn
(seeded) over the first 60% of the way to the first goal, within 2.5 m of the take-off
altitude, 0.4 rad of the goal's bearing, pitched 0.15 rad down to 0.05 up.

`sil-frames` writes such frames with their true wire pixels as a labelled folder, from poses
drawn wider, of worlds seeded apart from those flights and evaluations use, for `wireavoid
train --frames`: the CNN then learns what the simulated cameras show, the ground and sky the
closed loop flies over.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from companion.cli.perception import ModelOption, load_segmenter, resolve_checkpoint

_SCENARIOS = ["ladder-wire", "stacked-wires", "power-line-corridor", "random"]
_TRAINING_FIRST_SEED = 1000  # training worlds start here; flights and evaluations from 0


@dataclass(frozen=True)
class PoseSpread:
    """Where `scenario_frames` draws camera poses: along the first `way` of the straight line
    from the take-off point to the first goal, within `altitude_m` of the take-off altitude,
    `yaw_rad` of the goal's bearing, pitched `pitch_rad` (low, high), rolled with a normal
    spread of `roll_std_rad` (0: level)."""

    way: float
    altitude_m: float
    yaw_rad: float
    pitch_rad: tuple[float, float]
    roll_std_rad: float


EVALUATION_POSES = PoseSpread(0.6, 2.5, 0.4, (-0.15, 0.05), 0.0)
"""`evaluate-sim`'s poses: where the vehicle looks on its way to the first wires."""
TRAINING_POSES = PoseSpread(0.9, 3.0, 0.6, (-0.3, 0.1), 0.08)
"""`sil-frames`' poses: wider, to cover the views of climbs, descents and turns."""
_LOWEST_M = 0.3  # drawn poses stay this far above the ground, m


def scenario_frames(
    settings: Any, scenario: str, seed: int, count: int, spread: PoseSpread = EVALUATION_POSES
) -> list[tuple[Any, Any, Any]]:
    """`count` (image_bgr, disparity_px, true wire mask of the colour image) frames of
    `scenario` (seed) from poses drawn (seeded) within `spread`."""
    from companion.cli.sim_camera import settings_camera
    from geometry.pose import Pose
    from hil.world.scenarios import build_scenario

    world = build_scenario(scenario, seed)
    camera = settings_camera(settings, world)
    rng = np.random.default_rng([seed, count])
    start, goal = world.takeoff_point_ned_m, np.asarray(world.goals_ned_m[0], float)
    frames = []
    for k in range(count):
        position = start + rng.uniform(0.0, spread.way) * (goal - start)
        climb_m = rng.uniform(-spread.altitude_m, spread.altitude_m)
        position[2] = min(position[2] + climb_m, -_LOWEST_M)
        bearing = np.arctan2(goal[1] - position[1], goal[0] - position[0])
        yaw = bearing + rng.uniform(-spread.yaw_rad, spread.yaw_rad)
        pitch = rng.uniform(*spread.pitch_rad)
        # level views draw no roll, so evaluate-sim's frames stay what they were
        roll = rng.normal(0.0, spread.roll_std_rad) if spread.roll_std_rad > 0 else 0.0
        frame = camera.render(float(k), Pose.from_yaw_pitch_roll(yaw, pitch, roll, position))
        frames.append((frame.image_bgr, frame.disparity_px, frame.image_wire_mask))
    return frames


def sil_frames(
    out: Annotated[Path, typer.Option("--out", help="dataset folder (created)")],
    scenarios: Annotated[
        list[str] | None,
        typer.Option("--scenario", help="built-in scenario; repeat for more (default: random)"),
    ] = None,
    first_seed: Annotated[
        int, typer.Option("--first-seed", min=0, help="worlds' first seed")
    ] = _TRAINING_FIRST_SEED,
    seeds: Annotated[int, typer.Option("--seeds", min=1, help="worlds per scenario")] = 300,
    frames: Annotated[int, typer.Option("--frames", min=1, help="frames per world")] = 8,
) -> None:
    """Write labelled frames the simulated cameras render, for `wireavoid train --frames`.

    Each world (scenario and seed) is rendered from `frames` poses drawn wider than
    `evaluate-sim`'s; DIR/images/NNNNNN.png holds the colour image, DIR/masks/NNNNNN.png its
    true wire pixels (255), DIR/sil_frames.json what was rendered. Flights, sweeps and
    `evaluate-sim` use seeds from 0: keep training worlds apart from them (the default starts
    at 1000).
    """
    import cv2

    from companion.cli.settings import load_sim_settings
    from hil.world.scenarios import SCENARIOS

    names = scenarios or ["random"]
    if unknown := [n for n in names if n not in SCENARIOS]:
        raise typer.BadParameter(f"unknown scenario {unknown[0]!r}; one of {', '.join(SCENARIOS)}")
    settings = load_sim_settings()
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "masks").mkdir(parents=True, exist_ok=True)
    index, wire_pixels = 0, 0
    for scenario in names:
        for seed in range(first_seed, first_seed + seeds):
            rendered = scenario_frames(settings, scenario, seed, frames, TRAINING_POSES)
            for image, _, truth in rendered:
                cv2.imwrite(str(out / "images" / f"{index:06d}.png"), image)
                cv2.imwrite(str(out / "masks" / f"{index:06d}.png"), truth.astype(np.uint8) * 255)
                index, wire_pixels = index + 1, wire_pixels + int(truth.sum())
    record = {
        "scenarios": names,
        "first_seed": first_seed,
        "seeds": seeds,
        "frames_per_world": frames,
        "frames": index,
        "wire_pixel_share": wire_pixels / max(index * truth.size, 1),
        "poses": asdict(TRAINING_POSES),
        "camera_sim": settings.camera_sim.model_dump(include={"wire_specular", "wire_gloss"}),
    }
    (out / "sil_frames.json").write_text(json.dumps(record, indent=2) + "\n")
    typer.echo(json.dumps(record))


def evaluate_sim(
    scenarios: Annotated[
        list[str] | None, typer.Option("--scenario", help="built-in scenario; repeat for more")
    ] = None,
    seeds: Annotated[int, typer.Option("--seeds", min=1, help="seeds 0..N-1 of each")] = 3,
    frames: Annotated[int, typer.Option("--frames", min=1, help="frames per world")] = 8,
    model: ModelOption = None,
    as_json: Annotated[bool, typer.Option("--json", help="print JSON only")] = False,
) -> None:
    """Wire recall and false marks of the closed loop's wire mask on simulator frames.

    `wire_recall`: share of true wire pixels within 2 px of the mask; `false_share`: share of
    mask pixels farther than 4 px from any wire; `frames_with_false_marks`: frames with more
    than 50 such pixels; `wire_recall_against_surfaces` / `_against_sky`: the recall of the
    wire pixels seen against what stereo sees as a surface (ground, trees, buildings) and of
    the rest; each for the mask and the continued mask (`*_continued`).
    """
    from companion.cli.settings import load_sim_settings
    from companion.flight.perceive import WireDetector
    from hil.world.scenarios import SCENARIOS
    from perception.metrics import MaskScore
    from perception.postprocess import stereo_surface

    names = scenarios or _SCENARIOS
    if unknown := [n for n in names if n not in SCENARIOS]:
        raise typer.BadParameter(f"unknown scenario {unknown[0]!r}; one of {', '.join(SCENARIOS)}")
    settings = load_sim_settings()
    segmenter = replace(
        load_segmenter(str(resolve_checkpoint(model)), "auto"), params=settings.perception
    )
    detector = WireDetector(segmenter)
    plain, continued = MaskScore(), MaskScore()
    for scenario in names:
        for seed in range(seeds):
            for image, disparity, truth in scenario_frames(settings, scenario, seed, frames):
                mask = segmenter.mask_of(segmenter.probability(image, "bgr"))
                surface = stereo_surface(disparity, mask.shape)
                plain += MaskScore.of(mask, truth, surface)
                continued += MaskScore.of(detector.continued(mask, disparity), truth, surface)
    result = {"scenarios": names, "seeds": seeds, "frames": plain.frames}
    result.update(plain.summary())
    result.update({f"{k}_continued": v for k, v in continued.summary().items()})
    if as_json:
        typer.echo(json.dumps(result))
        return
    for key, value in result.items():
        typer.echo(f"{key:36s} {value}")


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add this command to the root app."""
    del bench
    app.command("evaluate-sim")(evaluate_sim)
    app.command("sil-frames")(sil_frames)
