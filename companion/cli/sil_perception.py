"""`wireavoid evaluate-sim`: the wire mask the closed loop flies on, scored on simulator frames.

`evaluate` scores probability maps on labelled photographs; this scores what the flight
process makes of what its cameras see in SIL: the shipped CNN's thresholded mask
(`WireSegmenter.mask_of`, with the settings' `perception`) and that mask continued as the
flight process continues it (`WireDetector.continued`: with
`perception.wire_continuation_stops_at_surfaces`, up to the surfaces the same frame's
stereo sees), on frames the simulated cameras
render of built-in scenarios, against the renderer's true wire pixels. Poses are drawn
(seeded) over the first 60% of the way to the first goal, within 2.5 m of the take-off
altitude, 0.4 rad of the goal's bearing, pitched 0.15 rad down to 0.05 up.
"""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Annotated, Any

import numpy as np
import typer

from companion.cli.perception import ModelOption, load_segmenter, resolve_checkpoint

_SCENARIOS = ["ladder-wire", "stacked-wires", "power-line-corridor", "random"]


def scenario_frames(
    settings: Any, scenario: str, seed: int, count: int
) -> list[tuple[Any, Any, Any]]:
    """`count` (image_bgr, disparity_px, true wire mask of the colour image) frames of
    `scenario` (seed) from drawn poses."""
    from companion.cli.sim_camera import settings_camera
    from geometry.pose import Pose
    from hil.world.scenarios import build_scenario

    world = build_scenario(scenario, seed)
    camera = settings_camera(settings, world)
    rng = np.random.default_rng([seed, count])
    start, goal = world.takeoff_point_ned_m, np.asarray(world.goals_ned_m[0], float)
    frames = []
    for k in range(count):
        position = start + rng.uniform(0.0, 0.6) * (goal - start)
        position[2] += rng.uniform(-2.5, 2.5)
        bearing = np.arctan2(goal[1] - position[1], goal[0] - position[0])
        yaw, pitch, roll = bearing + rng.uniform(-0.4, 0.4), rng.uniform(-0.15, 0.05), 0.0
        pose = Pose.from_yaw_pitch_roll(yaw, pitch, roll, position)
        frame = camera.render(float(k), pose)
        frames.append((frame.image_bgr, frame.disparity_px, frame.image_wire_mask))
    return frames


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
    than 50 such pixels; each for the mask and the continued mask (`*_continued`).
    """
    from companion.cli.settings import load_sim_settings
    from companion.flight.perceive import WireDetector
    from hil.world.scenarios import SCENARIOS
    from perception.metrics import MaskScore

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
                plain += MaskScore.of(mask, truth)
                continued += MaskScore.of(detector.continued(mask, disparity), truth)
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
