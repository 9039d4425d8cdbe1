"""Fig. 4.5: fusing wire observations from several heights localises stacked wires."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from geometry.camera import body_from_camera_from_params, stereo_rig_from_params
from geometry.pose import Pose
from hil.sensors.cameras import SimulatedStereoCamera
from hil.sensors.params import CameraSimParams
from hil.world.model import World, catenary_wire
from mapping.droan.params import MappingParams
from mapping.droan.pose_graph import DroanMap

WIRE_HEIGHTS_M = (6.0, 9.0, 12.0)
WIRE_NORTH_M = 10.0


def fused_map(
    altitudes_m: np.ndarray, wire_free_weight: float = 0.5, **mapping: float | int | bool
) -> DroanMap:
    params = MappingParams(
        **{
            "robot_radius_m": 0.3,
            "max_nodes": 40,
            "camera_width_px": 320,
            "camera_height_px": 240,
            "wire_free_weight": wire_free_weight,
            "wire_position_margin_m": 0.0,  # the expansion of eq. 4.3 alone, as in Fig. 4.5
            **mapping,
        }
    )
    rig = stereo_rig_from_params(params.camera)
    world = World(
        wires=[
            catenary_wire([WIRE_NORTH_M, -40, -h], [WIRE_NORTH_M, 40, -h], 0.0, 0.02)
            for h in WIRE_HEIGHTS_M
        ]
    )
    camera = SimulatedStereoCamera(
        world, rig, body_from_camera_from_params(params.camera), CameraSimParams(),
        colour_downscale=2,
    )  # fmt: skip
    droan = DroanMap(rig, params)
    for i, altitude in enumerate(altitudes_m):
        frame = camera.render(0.1 * i, Pose.from_yaw_pitch_roll(0, 0, 0, [0, 0, -altitude]))
        # wires only, as Robot-1 flew in 4.6.2 (the ground is tested elsewhere)
        droan.insert(frame.stamp_s, frame.world_from_camera, None, frame.wire_mask)
    return droan


def column(droan: DroanMap, heights_m) -> np.ndarray:
    heights = np.asarray(heights_m, dtype=float)
    points = np.stack([np.full_like(heights, WIRE_NORTH_M), np.zeros_like(heights), -heights], 1)
    return droan.query(points).collision


def ray_points(wire_height_m: float, norths_m) -> np.ndarray:
    """Points on the ray from the single view (altitude 9 m) through a wire, NED, m."""
    north = np.asarray(norths_m, dtype=float)
    heights = 9.0 + (wire_height_m - 9.0) * north / WIRE_NORTH_M
    return np.stack([north, np.zeros_like(north), -heights], 1)


def occupied_fraction(droan: DroanMap) -> float:
    """Fraction of the vertical plane through the flight line (0-24 m ahead, 0-18 m up)."""
    north, height = np.meshgrid(np.arange(0.0, 24.1, 0.5), np.arange(0.0, 18.1, 0.25))
    points = np.stack([north.ravel(), np.zeros(north.size), -height.ravel()], 1)
    return float(droan.query(points).collision.mean())


def test_single_observation_is_a_slab_and_fusion_localises_three_wires() -> None:
    single = fused_map(np.array([9.0]))
    assert len(single) == 1
    # one view: every wire is a 4-20 m slab of rays; the gaps between them are resolved in
    # angle, but along the rays nothing is: in front of and behind each wire is occupied
    assert column(single, WIRE_HEIGHTS_M).all()
    assert not column(single, [7.5, 10.5, 3.0, 15.0]).any()
    behind = np.concatenate([ray_points(h, [14.0, 18.0]) for h in (6.0, 12.0)])
    assert single.query(behind).collision.all()
    assert single.query(ray_points(9.0, [3.0, 21.0])).collision.sum() == 0  # outside 4-20 m

    altitudes = np.arange(1.0, 17.01, 0.5)
    carving = fused_map(altitudes, wire_free_weight=2.0)
    assert column(carving, WIRE_HEIGHTS_M).all()  # every wire is still occupied
    assert not column(carving, [7.5, 10.5, 3.0, 15.0]).any()  # the space between clears
    assert not carving.query(behind).collision.any()  # and the slabs behind the wires
    assert occupied_fraction(carving) < 0.75 * occupied_fraction(single)

    # The thesis' 0.5 weight: with the expansion true to each depth of the slab (eq. 4.3 at
    # z, not at the near limit throughout), views a metre apart in height vote the slabs
    # behind the wires free; at the near limit's width everywhere they kept any point that a
    # third of the views placed on a wire ray, and fusing heights did not shrink the slabs.
    thesis = fused_map(altitudes)
    assert column(thesis, WIRE_HEIGHTS_M).all()
    assert not column(thesis, [7.5, 10.5]).any()
    assert not thesis.query(behind).collision.any()
    assert occupied_fraction(thesis) < 0.95 * occupied_fraction(single)


def passing_map(
    views: int, possible: bool, triangulation: bool = False
) -> tuple[DroanMap, np.ndarray]:
    """`views` views flown level with a wire 10 m ahead, 0.5 m apart (a wire no view can
    triangulate): the first two detect it, with a false wire about 1.1 m higher at its
    distance; the views after them miss both, their CNN (`possible`) still scoring the true
    wire undecided. Returns the map and the points (on the wire, on the false wire)."""
    params = MappingParams(
        robot_radius_m=0.3,
        camera_width_px=320,
        camera_height_px=240,
        wire_free_weight=0.5,  # the thesis' weight
        wire_triangulation=triangulation,
    )
    rig = stereo_rig_from_params(params.camera)
    height = 6.0
    ends = [WIRE_NORTH_M, -40, -height], [WIRE_NORTH_M, 40, -height]
    camera = SimulatedStereoCamera(
        World(wires=[catenary_wire(*ends, 0.0, 0.02)]), rig,
        body_from_camera_from_params(params.camera), CameraSimParams(), colour_downscale=2,
    )  # fmt: skip
    droan = DroanMap(rig, params)
    for i in range(views):
        frame = camera.render(0.1 * i, Pose.from_yaw_pitch_roll(0, 0, 0, [0.5 * i, 0, -height]))
        if i < 2:  # 12 rows up at 110 px focal length: 0.11 rad
            mask = frame.wire_mask | np.roll(frame.wire_mask, -12, axis=0)
            droan.insert(frame.stamp_s, frame.world_from_camera, None, mask)
        else:
            missed = np.zeros_like(frame.wire_mask)
            undecided = frame.wire_mask if possible else None
            droan.insert(frame.stamp_s, frame.world_from_camera, None, missed, undecided)
    return droan, np.array([[WIRE_NORTH_M, 0, -height], [WIRE_NORTH_M, 0, -height - 1.1]])


@pytest.mark.parametrize("triangulation", [False, True])
def test_a_wire_the_cnn_still_doubts_is_not_voted_away(triangulation: bool) -> None:
    seen, points = passing_map(2, possible=False, triangulation=triangulation)
    assert seen.query(points).collision.tolist() == [True, True]
    # the thesis' two-way mask: eight views that miss it erase a wire seen twice
    thesis, _ = passing_map(10, possible=False, triangulation=triangulation)
    assert thesis.query(points).collision.tolist() == [False, False]
    # views whose CNN scores the wire undecided abstain there, and still carve the false wire
    doubting, _ = passing_map(10, possible=True, triangulation=triangulation)
    assert doubting.query(points).collision.tolist() == [True, False]


def test_triangulated_wires_keep_the_wires_and_carve_the_fans_of_a_short_climb() -> None:
    """`mapping.wire_triangulation`: a 4 m climb 10 m before three stacked wires, seen as the
    flight camera sees them (640 x 480) and with the flight's expansion radius. Expanded
    before the vote (Fig. 4.4), the fans of views a few decimetres apart overlap into one
    wall; voted on thin rays and expanded after, they meet at the wires."""
    flight = {
        "camera_width_px": 640, "camera_height_px": 480, "max_nodes": 20,
        "robot_radius_m": 0.5, "wire_position_margin_m": 0.25,
    }  # fmt: skip
    altitudes = np.arange(7.0, 11.01, 0.5)
    expanded = fused_map(altitudes, wire_free_weight=0.25, **flight)
    voted = fused_map(altitudes, wire_free_weight=0.25, wire_triangulation=True, **flight)
    for droan in (expanded, voted):
        assert column(droan, WIRE_HEIGHTS_M).all()
        assert not column(droan, [7.5, 10.5]).any()
    assert occupied_fraction(voted) < 0.5 * occupied_fraction(expanded)  # 0.12 against 0.32
    behind = np.concatenate([ray_points(h, [14.0, 18.0]) for h in (6.0, 12.0)])
    assert expanded.query(behind).collision.all()
    assert voted.query(behind).collision.sum() <= 2
    # one view alone is the prior: its rays through the wires, 4-20 m, expanded
    single = fused_map(np.array([9.0]), wire_free_weight=0.25, wire_triangulation=True, **flight)
    assert single.query(behind).collision.all()
    assert not single.query(ray_points(6.0, [3.0, 21.5])).collision.any()


def test_the_wire_voxels_answer_exactly_within_their_radius() -> None:
    """The cell hash finds a wire voxel within the radius exactly where a k-d tree does."""
    droan = fused_map(np.arange(7.0, 11.01, 0.5), wire_free_weight=0.25, wire_triangulation=True)
    voxels = droan.wire_voxels
    assert voxels is not None and len(voxels.wire_centres_m) > 1000
    points = np.random.default_rng(1).uniform([0, -20, -15], [25, 20, 0], (100_000, 3))
    distance, _ = cKDTree(voxels.wire_centres_m).query(points)
    within = distance <= voxels.radius_m
    assert 1000 < within.sum() < len(points) / 2
    np.testing.assert_array_equal(voxels.occupancy(points) >= 1.0, within)
