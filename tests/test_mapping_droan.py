"""DROAN geometry with exact expectations (thesis 4.4.3-4.4.6, Table 4.1, eq. 4.3-4.5)."""

import numpy as np
import pytest

from geometry.camera import body_from_camera_mount, stereo_rig_from_params, world_from_camera
from geometry.pose import Pose
from mapping.droan.params import MappingParams
from mapping.droan.pose_graph import DroanMap, InsertResult

PARAMS = MappingParams()
RIG = stereo_rig_from_params(PARAMS.camera)
BF = RIG.bf_px_m
SHAPE = RIG.camera.shape


def camera_at(north_m: float, east_m: float, down_m: float, yaw_rad: float = 0.0) -> Pose:
    """A level camera at the given NED position looking along yaw (0 = north)."""
    body = Pose.from_yaw_pitch_roll(yaw_rad, 0.0, 0.0, [north_m, east_m, down_m])
    return world_from_camera(body, body_from_camera_mount([0.0, 0.0, 0.0]))


def along_axis(depths_m, east_m: float = 0.0, down_m: float = -5.0) -> np.ndarray:
    """World points straight ahead (north) of a camera at (0, 0, -5) looking north."""
    depths = np.asarray(depths_m, dtype=float)
    return np.stack([depths, np.full_like(depths, east_m), np.full_like(depths, down_m)], axis=1)


def test_fronto_parallel_wall_bands() -> None:
    wall_m, r, margin = 5.0, PARAMS.robot_radius_m, PARAMS.disparity_sigma_px
    droan = DroanMap(RIG, PARAMS)
    droan.insert(0.0, camera_at(0, 0, -5), np.full(SHAPE, BF / wall_m, np.float32))
    front_m = BF / (BF / (wall_m - r) + margin)  # eq. 4.3, lambda = 1
    back_m = BF / (BF / (wall_m + r) - margin)
    assert front_m == pytest.approx(4.36, abs=0.01) and back_m == pytest.approx(5.72, abs=0.01)
    eps = 0.02
    answer = droan.query(
        along_axis([1.0, front_m - eps, front_m + eps, wall_m, back_m - eps, back_m + eps, 9.0])
    )
    assert answer.collision.tolist() == [False, False, True, True, True, False, False]
    assert answer.seen.tolist() == [True, True, True, True, True, False, False]  # occluded
    # occupied cost C/(1-C) = (d - sigma)/sigma (Table 4.1, eq. 4.4); free is clamped to 0
    d_wall = BF / wall_m
    assert answer.occupancy[3] == pytest.approx((d_wall - margin) / margin, rel=1e-5)
    assert answer.occupancy[0] == 0.0


def test_free_evidence_is_discounted_and_fuses_over_nodes() -> None:
    droan = DroanMap(RIG, PARAMS)
    droan.insert(0.0, camera_at(0, 0, -5), np.full(SHAPE, BF / 5.0, np.float32))
    odds = (BF / 5.0 - 0.23) / 0.23  # the point is 5 m deep in every node below
    assert droan.query(along_axis([5.0])).occupancy[0] == pytest.approx(odds, rel=1e-5)
    # a node 1 m to the side sees nothing there: safe evidence counts half (Table 4.1)
    droan.insert(1.0, camera_at(0, 1.0, -5), np.zeros(SHAPE, np.float32))
    answer = droan.query(along_axis([5.0]))
    assert answer.occupancy[0] == pytest.approx(0.5 * odds, rel=1e-4)
    assert answer.collision[0]
    droan.insert(2.0, camera_at(0, -1.0, -5), np.zeros(SHAPE, np.float32))
    answer = droan.query(along_axis([5.0]))
    assert answer.occupancy[0] == pytest.approx(0.0, abs=1e-3)  # M clamped at 0 (eq. 4.5)
    assert not answer.collision[0]


def test_wire_row_occupies_the_prior_slab_of_its_rays() -> None:
    droan = DroanMap(RIG, PARAMS)
    mask = np.zeros(SHAPE, bool)
    mask[240, :] = True  # the row through the optical axis (cy = 239.5: rows 239 and 240)
    # stereo sees nothing (sky): its free evidence must not erase the wire
    droan.insert(0.0, camera_at(0, 0, -5), np.zeros(SHAPE, np.float32), mask)
    r = PARAMS.robot_radius_m
    front_m = BF / (BF / (PARAMS.wire_depth_near_m - r) + PARAMS.disparity_sigma_px)
    eps = 0.05
    depths = [2.0, front_m - eps, front_m + eps, 4.0, 12.0, 19.9, 20.1, 24.0]
    answer = droan.query(along_axis(depths, down_m=-5.0 + 0.5 / RIG.camera.fy_px))
    assert answer.collision.tolist() == [False, False, True, True, True, True, False, False]
    assert answer.occupancy[3] == pytest.approx(1.0)  # C(d) with sigma = 0 (4.4.5 note)
    # well above the wire row (outside its area expansion) the rays are free
    high = droan.query(along_axis([4.0, 12.0], down_m=-5.0 - 0.3 * 12.0))
    assert not high.collision.any()


def test_views_nearer_than_the_wire_prior_do_not_vote_a_wire_away() -> None:
    """A wire 8 m ahead stays mapped while the vehicle closes in on it: views from within
    the near prior (4 m) see it on their wire rays but nearer than their slab; before, each
    voted -wire_free_weight and two of them erased the wire the vehicle was about to pass."""
    droan = DroanMap(RIG, PARAMS.model_copy(update={"keyframe_translation_m": 0.1}))
    mask = np.zeros(SHAPE, bool)
    mask[239:241, :] = True  # a horizontal wire through the optical axis
    sky = np.zeros(SHAPE, np.float32)
    droan.insert(0.0, camera_at(0, 0, -5), sky, mask)
    wire = along_axis([8.0])
    assert droan.query(wire).collision[0]
    for step, north_m in enumerate([5.0, 5.5, 6.0, 6.5]):  # 3 to 1.5 m from the wire
        droan.insert(1.0 + step, camera_at(north_m, 0, -5), sky, mask)
    assert droan.query(wire).occupancy[0] == pytest.approx(1.0)  # the far view's vote alone
    # a near view that sees no wire there still says nothing about it
    droan.insert(9.0, camera_at(7.0, 0, -5), sky, np.zeros(SHAPE, bool))
    assert droan.query(wire).collision[0]


def test_unseen_space_is_unknown() -> None:
    droan = DroanMap(RIG, PARAMS)
    assert not droan.query(along_axis([3.0])).seen.any()  # empty graph
    droan.insert(0.0, camera_at(0, 0, -5), np.zeros(SHAPE, np.float32))
    behind = np.array([[-3.0, 0.0, -5.0]])
    beside = np.array([[1.0, 10.0, -5.0]])  # 84 deg off axis, outside the 72 deg FOV
    too_far = along_axis([PARAMS.max_range_m + 1.0])
    answer = droan.query(np.concatenate([behind, beside, too_far, along_axis([10.0])]))
    assert answer.seen.tolist() == [False, False, False, True]
    assert not answer.collision.any()
    invalid = DroanMap(RIG, PARAMS)
    invalid.insert(0.0, camera_at(0, 0, -5), np.full(SHAPE, np.nan, np.float32))
    assert not invalid.query(along_axis([3.0])).seen[0]


def test_keyframes_live_node_and_eviction() -> None:
    params = PARAMS.model_copy(update={"max_nodes": 3})
    droan = DroanMap(RIG, params)
    free = np.zeros(SHAPE, np.float32)
    results = [droan.insert(0.1 * i, camera_at(0.2 * i, 0, -5), free) for i in range(6)]
    # 0 m key, 0.2/0.4 m live (replacing each other), 0.6 m key, 0.8/1.0 m live
    assert results == [
        InsertResult.KEYFRAME,
        InsertResult.LIVE,
        InsertResult.LIVE,
        InsertResult.KEYFRAME,
        InsertResult.LIVE,
        InsertResult.LIVE,
    ]
    assert [n.stamp_s for n in droan.nodes] == pytest.approx([0.0, 0.3, 0.5])
    assert droan.insert(1.0, camera_at(0.6, 0, -5, yaw_rad=np.deg2rad(20)), free) == (
        InsertResult.KEYFRAME
    )
    more = [droan.insert(2.0 + i, camera_at(5.0 * (i + 1), 0, -5), free) for i in range(3)]
    assert more == [InsertResult.KEYFRAME] * 3
    assert len(droan) == 3
    assert [n.stamp_s for n in droan.nodes] == [2.0, 3.0, 4.0]  # oldest evicted first


def test_dropping_non_keyframes_and_age_limit() -> None:
    params = PARAMS.model_copy(update={"replace_latest_non_keyframe": False, "max_node_age_s": 1.5})
    droan = DroanMap(RIG, params)
    free = np.zeros(SHAPE, np.float32)
    assert droan.insert(0.0, camera_at(0, 0, -5), free) is InsertResult.KEYFRAME
    assert droan.insert(0.5, camera_at(0.1, 0, -5), free) is InsertResult.DROPPED
    assert droan.insert(1.0, camera_at(1.0, 0, -5), free) is InsertResult.KEYFRAME
    assert droan.insert(2.0, camera_at(2.0, 0, -5), free) is InsertResult.KEYFRAME
    assert [n.stamp_s for n in droan.nodes] == [1.0, 2.0]
    droan.prune(now_s=3.2)
    assert [n.stamp_s for n in droan.nodes] == [2.0]


def test_export_returns_the_occupied_band_as_voxels() -> None:
    from mapping.droan.export import occupied_voxels, ply_bytes

    droan = DroanMap(RIG, PARAMS)
    droan.insert(0.0, camera_at(0, 0, -5), np.full(SHAPE, BF / 5.0, np.float32))
    centres, occupancy = occupied_voxels(droan, np.array([5.0, 0.0, -5.0]), (4.0, 2.0, 2.0), 0.25)
    assert len(centres) > 0 and (occupancy >= PARAMS.occupancy_threshold).all()
    # exactly the voxels whose centre lies in the expanded band [4.36 m, 5.72 m]
    assert centres[:, 0].min() == pytest.approx(4.375) and centres[:, 0].max() == pytest.approx(
        5.625
    )
    assert len(centres) == 6 * 8 * 8
    assert ply_bytes(centres).count(b"\n") == len(centres) + 7


def test_far_surface_stays_visible_past_the_fringe_of_a_near_obstacle() -> None:
    disparity = np.full(SHAPE, BF / 15.0, np.float32)  # wall at 15 m
    disparity[200:280, 300:340] = BF / 3.0  # pole at 3 m
    droan = DroanMap(RIG, PARAMS)
    droan.insert(0.0, camera_at(0, 0, -5), disparity)
    # the ray through pixel column 350 (right of the pole, inside its expansion window)
    ray = RIG.camera.rays(np.array([[350.0, 239.5]]))[0]
    depths = np.array([3.0, 9.0, 15.0, 18.0])
    camera_points = ray[None, :] * depths[:, None]
    answer = droan.query(camera_at(0, 0, -5).apply(camera_points))
    # pole fringe occupied, free between, the wall itself occupied, behind the wall occluded
    assert answer.collision.tolist() == [True, False, True, False]
    assert answer.seen.tolist() == [True, True, True, False]


def test_thesis_discount_of_occluded_space_is_configurable() -> None:
    def wall_occupancy(params: MappingParams) -> float:
        droan = DroanMap(RIG, params)
        droan.insert(0.0, camera_at(0, 0, -5), np.full(SHAPE, BF / 5.0, np.float32))
        # a second view from 3 m further back sees a nearer wall at north 1 m: the first
        # wall (north 5 m) is occluded there
        droan.insert(1.0, camera_at(-3.0, 0, -5), np.full(SHAPE, BF / 4.0, np.float32))
        answer = droan.query(along_axis([5.0]))
        assert answer.seen[0]
        return float(answer.occupancy[0])

    odds_first = (BF / 5.0 - 0.23) / 0.23
    odds_second = (BF / 8.0 - 0.23) / 0.23
    assert wall_occupancy(PARAMS) == pytest.approx(odds_first, rel=1e-5)
    thesis = PARAMS.model_copy(update={"occluded_discount": 0.5})  # Table 4.1 as printed
    assert wall_occupancy(thesis) == pytest.approx(odds_first - 0.5 * odds_second, rel=1e-4)


def test_a_point_on_one_cameras_plane_keeps_the_other_nodes_evidence() -> None:
    # Node 1 looks east at a wall 5 m away; node 2, at the same spot, looks north, so the wall
    # point lies exactly on its image plane (depth 0): it must add nothing, not poison M.
    droan = DroanMap(RIG, PARAMS)
    droan.insert(0.0, camera_at(0, 0, -5, yaw_rad=np.pi / 2), np.full(SHAPE, BF / 5.0, np.float32))
    wall_point = np.array([[0.0, 5.0, -5.0]])
    assert droan.query(wall_point).collision[0]
    droan.insert(1.0, camera_at(0, 0, -5), np.zeros(SHAPE, np.float32))
    answer = droan.query(wall_point)
    assert np.isfinite(answer.occupancy).all()
    assert answer.collision[0]


def test_threaded_and_serial_queries_agree() -> None:
    droan = DroanMap(RIG, PARAMS)
    serial = DroanMap(RIG, PARAMS.model_copy(update={"query_threads": 1}))
    rng = np.random.default_rng(3)
    for i, yaw in enumerate(np.linspace(-0.6, 0.6, 5)):
        disparity = rng.uniform(0.0, BF / 3.0, SHAPE).astype(np.float32)
        mask = np.zeros(SHAPE, bool)
        mask[100 + 10 * i, :] = True
        for world in (droan, serial):
            world.insert(float(i), camera_at(0, 0.5 * i, -5, yaw), disparity, mask)
    points = rng.uniform([-2, -8, -9], [25, 8, -1], size=(10_000, 3))
    threaded, single = droan.query(points), serial.query(points)
    assert 0 < threaded.collision.sum() < len(points)
    np.testing.assert_array_equal(threaded.collision, single.collision)
    np.testing.assert_array_equal(threaded.seen, single.seen)
    np.testing.assert_array_equal(threaded.occupancy, single.occupancy)
