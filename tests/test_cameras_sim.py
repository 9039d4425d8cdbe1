"""The simulated cameras of the SIL harness (hil.world, hil.cameras)."""

import numpy as np
import pytest

from hil.camera_params import CameraSimParams
from hil.cameras import SimulatedStereoCamera
from hil.world import Box, World, catenary_wire
from mapping.camera import body_from_camera_mount, stereo_rig_from_params
from mapping.params import MappingParams
from mapping.pose import Pose

PARAMS = MappingParams(camera_width_px=320, camera_height_px=240)
RIG = stereo_rig_from_params(PARAMS.camera)
MOUNT = body_from_camera_mount([0.0, 0.0, 0.0])
LEVEL = Pose.from_yaw_pitch_roll(0.0, 0.0, 0.0, [0.0, 0.0, -5.0])


def camera(world: World, **overrides) -> SimulatedStereoCamera:
    return SimulatedStereoCamera(world, RIG, MOUNT, CameraSimParams(**overrides))


def wall(north_m: float) -> Box:
    return Box([north_m, -50.0, -50.0], [north_m + 1.0, 50.0, 10.0])


def test_wall_depth_disparity_noise_and_determinism() -> None:
    sim = camera(World(boxes=[wall(8.0)]), disparity_noise_px=0.3, seed=7)
    frame = sim.render(1.0, LEVEL)
    np.testing.assert_allclose(frame.depth_m, 8.0, rtol=1e-5)  # camera z, not ray length
    errors = frame.disparity_px - RIG.bf_px_m / 8.0
    assert errors.mean() == pytest.approx(0.0, abs=0.01)
    assert errors.std() == pytest.approx(0.3, rel=0.03)
    again = sim.render(1.0, LEVEL)
    np.testing.assert_array_equal(again.disparity_px, frame.disparity_px)
    assert not np.array_equal(sim.render(1.1, LEVEL).disparity_px, frame.disparity_px)
    assert frame.stamp_s == 1.0


def test_sky_and_out_of_range_give_no_return() -> None:
    frame = camera(World(boxes=[wall(60.0)], ground_down_m=1000.0), max_range_m=40.0).render(
        0.0, LEVEL
    )
    assert np.all(frame.disparity_px == 0.0)
    assert np.isfinite(frame.depth_m).all()  # the wall is there, just beyond range
    sky = camera(World(ground_down_m=1000.0)).render(0.0, LEVEL)
    assert np.all(sky.disparity_px == 0.0)
    assert np.isinf(sky.depth_m[:120]).all()  # above the horizon: sky


def test_thin_wires_are_in_the_mask_but_not_in_the_disparity() -> None:
    wire = catenary_wire([10.0, -30.0, -5.0], [10.0, 30.0, -5.0], sag_m=0.0, radius_m=0.01)
    frame = camera(World(boxes=[wall(30.0)], wires=[wire]), disparity_noise_px=0.0).render(
        0.0, LEVEL
    )
    rows = np.flatnonzero(frame.wire_mask.any(axis=1))
    assert set(rows) <= {119, 120}  # the optical axis row (cy = 119.5)
    assert frame.wire_mask.any(axis=0).mean() > 0.95  # continuous across the image
    # stereo sees the wall behind the wire, not the wire
    np.testing.assert_allclose(frame.disparity_px[frame.wire_mask], RIG.bf_px_m / 30.0)
    assert frame.image_bgr[frame.wire_mask].mean() < frame.image_bgr[~frame.wire_mask].mean()


def test_wide_wires_appear_in_stereo_and_boxes_occlude_wires() -> None:
    thick = catenary_wire([3.0, -5.0, -5.0], [3.0, 5.0, -5.0], sag_m=0.0, radius_m=0.05)
    frame = camera(World(wires=[thick], ground_down_m=1000.0), disparity_noise_px=0.0).render(
        0.0, LEVEL
    )
    on_wire = frame.disparity_px[118:122, 100:220]
    np.testing.assert_allclose(on_wire, RIG.bf_px_m / 3.0, rtol=0.02)
    hidden = catenary_wire([20.0, -30.0, -5.0], [20.0, 30.0, -5.0], sag_m=0.0, radius_m=0.05)
    occluded = camera(World(boxes=[wall(8.0)], wires=[hidden])).render(0.0, LEVEL)
    assert not occluded.wire_mask.any()


def test_camera_pose_follows_the_vehicle() -> None:
    east_box = Box([-1.0, 10.0, -6.0], [1.0, 12.0, -4.0])
    sim = camera(World(boxes=[east_box], ground_down_m=1000.0))
    facing_north = sim.render(0.0, LEVEL)
    assert np.isinf(facing_north.depth_m[:120]).all()
    facing_east = Pose.from_yaw_pitch_roll(np.pi / 2, 0.0, 0.0, [0.0, 0.0, -5.0])
    frame = sim.render(0.0, facing_east)
    assert frame.depth_m[120, 160] == pytest.approx(10.0, abs=1e-4)
    np.testing.assert_allclose(frame.world_from_camera.matrix(), (facing_east @ MOUNT).matrix())


def test_render_state_uses_the_vehicle_ground_truth() -> None:
    from types import SimpleNamespace

    yaw = np.pi / 2
    state = SimpleNamespace(
        time_s=2.5,
        position_ned_m=np.array([0.0, 0.0, -5.0]),
        attitude_wxyz=np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]),
    )
    sim = camera(World(boxes=[Box([-1.0, 10.0, -6.0], [1.0, 12.0, -4.0])], ground_down_m=1000.0))
    frame = sim.render_state(state)
    assert frame.stamp_s == 2.5
    assert frame.depth_m[120, 160] == pytest.approx(10.0, abs=1e-4)
