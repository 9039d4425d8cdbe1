"""Rigid transforms, camera model and pose interpolation (geometry.pose, geometry.camera)."""

import numpy as np
import pytest

from geometry.camera import (
    PinholeCamera,
    StereoRig,
    body_from_camera_from_params,
    body_from_camera_mount,
    stereo_rig_from_params,
    world_from_camera,
)
from geometry.pose import Pose, PoseHistory
from geometry.rotation import quaternion_from_rotation, rotation_from_quaternion
from mapping.droan.params import MappingParams


def test_compose_inverse_and_apply_round_trip() -> None:
    a = Pose.from_yaw_pitch_roll(0.3, -0.2, 0.1, [1.0, 2.0, -3.0])
    b = Pose.from_yaw_pitch_roll(-1.0, 0.4, 0.7, [0.5, -0.5, 0.2])
    points = np.random.default_rng(0).normal(size=(10, 3))
    np.testing.assert_allclose((a @ b).apply(points), a.apply(b.apply(points)), atol=1e-12)
    np.testing.assert_allclose(a.inverse().apply(a.apply(points)), points, atol=1e-12)
    assert a.yaw_pitch_roll_rad() == pytest.approx((0.3, -0.2, 0.1))


def test_quaternion_round_trip_and_ned_yaw() -> None:
    east_facing = Pose.from_quaternion([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)], [0, 0, 0])
    np.testing.assert_allclose(east_facing.apply([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-12)
    r = Pose.from_yaw_pitch_roll(2.5, 0.3, -0.6, [0, 0, 0]).rotation
    np.testing.assert_allclose(rotation_from_quaternion(quaternion_from_rotation(r)), r, atol=1e-12)


def test_camera_extrinsics_follow_frd_and_camera_conventions() -> None:
    body_from_camera = body_from_camera_mount([0.1, 0.0, 0.0])
    vehicle = Pose.from_yaw_pitch_roll(np.pi / 2, 0.0, 0.0, [0.0, 0.0, -5.0])  # facing east
    camera = world_from_camera(vehicle, body_from_camera)
    # optical axis (camera z) points east, image x (right) points south, image y down
    np.testing.assert_allclose(camera.rotate([0, 0, 1.0]), [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(camera.rotate([1.0, 0, 0]), [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(camera.rotate([0, 1.0, 0]), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(camera.translation_m, [0.0, 0.1, -5.0], atol=1e-12)


def test_projection_back_projection_and_disparity() -> None:
    camera = PinholeCamera(400.0, 410.0, 320.0, 240.0, 640, 480)
    rig = StereoRig(camera, 0.1)
    uv = np.array([[10.0, 20.0], [320.0, 240.0], [600.5, 470.25]])
    depth = np.array([2.0, 5.0, 11.0])
    uv2, z = camera.project(camera.back_project(uv, depth))
    np.testing.assert_allclose(uv2, uv)
    np.testing.assert_allclose(z, depth)
    np.testing.assert_allclose(rig.disparity_from_depth(depth), 40.0 / depth)  # eq. 4.1
    np.testing.assert_allclose(rig.depth_from_disparity(40.0 / depth), depth)
    assert np.isnan(camera.project(np.array([[0.0, 0.0, -1.0]]))[0]).all()
    # a 4x pooled grid maps the pixel block [4i, 4i + 4) onto cell i
    grid = camera.scaled(4)
    cell, _ = grid.project(camera.back_project(np.array([[7.4, 8.0]]), np.array([3.0])))
    assert np.floor(cell[0] + 0.5).tolist() == [1.0, 2.0]


def test_pose_history_interpolates_and_refuses_to_extrapolate() -> None:
    history = PoseHistory(max_extrapolation_s=0.05, max_samples=10)
    history.add(1.0, Pose.from_yaw_pitch_roll(0.0, 0.0, 0.0, [0.0, 0.0, 0.0]))
    history.add(2.0, Pose.from_yaw_pitch_roll(np.pi / 2, 0.0, 0.0, [2.0, 4.0, -2.0]))
    mid = history.pose_at(1.25)
    assert mid is not None
    assert mid.yaw_pitch_roll_rad()[0] == pytest.approx(np.pi / 8)
    np.testing.assert_allclose(mid.translation_m, [0.5, 1.0, -0.5])
    assert history.pose_at(2.04) is not None
    assert history.pose_at(2.2) is None
    assert history.pose_at(0.5) is None


def test_calibrated_intrinsics_and_mount_angles_come_from_the_settings() -> None:
    default = stereo_rig_from_params(MappingParams().camera).camera
    assert default.fx_px == default.fy_px and default.cx_px == (640 - 1) / 2.0
    calibrated = MappingParams(camera_intrinsics_px=(451.2, 452.8, 322.4, 236.9))
    camera = stereo_rig_from_params(calibrated.camera).camera
    assert (camera.fx_px, camera.fy_px, camera.cx_px, camera.cy_px) == (451.2, 452.8, 322.4, 236.9)
    with pytest.raises(ValueError, match="fx > 0"):
        MappingParams(camera_intrinsics_px=(0.0, 450.0, 320.0, 240.0))

    mount = body_from_camera_from_params(
        MappingParams(camera_mount_yaw_deg=90.0, camera_mount_roll_deg=90.0).camera
    )
    # the optical axis (camera z) looks along body +y (right); camera x (image right) then
    # points down after a 90 deg roll about that axis
    np.testing.assert_allclose(mount.rotation @ [0, 0, 1], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(mount.rotation @ [1, 0, 0], [0, 0, 1], atol=1e-12)
