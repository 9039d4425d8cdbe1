"""`sim.wire_masks`: the truth-mask diagnostics of a simulated flight's perception stage."""

import asyncio

import cv2
import numpy as np
import pytest

from companion.cli.settings import SimSettings
from companion.cli.sim_camera import SimulatedCameraSource, settings_camera
from companion.cli.sim_masks import NEAR_WIRE_PX, TruthWireDetector
from companion.clock import WallClock
from companion.flight.perceive import WireDetector
from companion.ingest.frames import CameraFrame
from geometry.pose import Pose
from hil.world.scenarios import build_scenario
from perception.segmenter import WireSegmenter

SETTINGS = SimSettings()
WORLD = build_scenario("stacked-wires", 0)


@pytest.fixture(scope="module")
def exposed() -> tuple[SimulatedCameraSource, CameraFrame, WireDetector]:
    """One frame of the stacked wires 6 m ahead, level with the middle one, through the real
    renderer and camera source, and the shipped CNN's detector."""
    wire_north = float(WORLD.wires[1].points_ned_m[:, 0].mean())
    pose = Pose.from_yaw_pitch_roll(
        0.0, 0.0, 0.0, [wire_north - 6.0, 0.0, -WORLD.takeoff_altitude_m]
    )
    source = SimulatedCameraSource(
        settings_camera(SETTINGS, WORLD), lambda: pose, WallClock(), 20.0, 0.0
    )

    async def first_frame() -> CameraFrame:
        await source.open()
        return await source.next_frame()

    frame = asyncio.run(first_frame())
    detector = WireDetector(WireSegmenter.load(params=SETTINGS.perception))
    return source, frame, detector


def on_wire(truth: np.ndarray) -> np.ndarray:
    window = np.ones((2 * NEAR_WIRE_PX + 1,) * 2, np.uint8)
    return cv2.dilate(truth.astype(np.uint8), window) > 0


def test_truth_is_the_renderers_wire_pixels(exposed) -> None:
    source, frame, cnn = exposed
    truth = source.truth_masks[frame.stamp_s]
    assert truth.shape == frame.image_bgr.shape[:2] and truth.sum() > 300  # three wires
    perception = TruthWireDetector(cnn, source, "truth")(frame)
    np.testing.assert_array_equal(perception.wire_mask, truth)
    np.testing.assert_array_equal(perception.possible_mask, truth)
    assert perception.disparity_px is frame.disparity_px


def test_the_cnns_misses_and_its_false_marks_apart(exposed) -> None:
    source, frame, cnn = exposed
    truth = source.truth_masks[frame.stamp_s]
    near = on_wire(truth)
    mask = cnn(frame).wire_mask
    misses = TruthWireDetector(cnn, source, "cnn_misses")(frame).wire_mask
    false_marks = TruthWireDetector(cnn, source, "cnn_false_marks")(frame).wire_mask
    np.testing.assert_array_equal(misses, mask & near)  # the CNN's wire marks, nothing else
    np.testing.assert_array_equal(false_marks, truth | (mask & ~near))
    # each wire pixel the CNN missed is missing from the first and present in the second
    missed = truth & ~near_of(mask)
    assert missed.any() and not (misses & missed).any() and false_marks[missed].all()


def near_of(mask: np.ndarray) -> np.ndarray:
    return cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0


def test_a_frame_without_truth_is_an_error_not_a_guess(exposed) -> None:
    source, frame, cnn = exposed
    stray = CameraFrame(frame.stamp_s + 1.0, frame.sequence + 1, frame.image_bgr, None)
    with pytest.raises(LookupError, match="no true wire mask"):
        TruthWireDetector(cnn, source, "cnn_misses")(stray)
    for mode in ("oracle", "cnn"):  # the product's own mode needs no truth detector
        with pytest.raises(ValueError, match=r"not a truth-mask mode of sim\.wire_masks"):
            TruthWireDetector(cnn, source, mode)
