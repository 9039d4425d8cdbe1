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
from mapping.droan.wire_depth import WireViews

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


FLIGHT_MAP = {
    "camera_width_px": 640, "camera_height_px": 480, "max_nodes": 20,
    "robot_radius_m": 0.5, "wire_position_margin_m": 0.25, "wire_free_weight": 0.25,
}  # fmt: skip


def test_wire_rays_cut_by_the_parallax_of_a_short_climb_keep_the_wires_and_lose_the_wall() -> None:
    """`mapping.wire_parallax_views`: the same 4 m climb; each wire ray's depths are cut to
    those the other views do not rule out before the expansion, and the older nodes are cut
    again as views arrive."""
    altitudes = np.arange(7.0, 11.01, 0.5)
    expanded = fused_map(altitudes, **FLIGHT_MAP)
    cut = fused_map(altitudes, wire_parallax_views=24, **FLIGHT_MAP)
    assert column(cut, WIRE_HEIGHTS_M).all()
    assert not column(cut, [7.5, 10.5]).any()
    assert occupied_fraction(cut) < 0.25 * occupied_fraction(expanded)  # 0.05 against 0.32
    behind = np.concatenate([ray_points(h, [14.0, 18.0]) for h in (6.0, 12.0)])
    before = np.concatenate([ray_points(h, [5.0, 7.0]) for h in (6.0, 12.0)])
    assert expanded.query(np.concatenate([behind, before])).collision.all()
    assert not cut.query(np.concatenate([behind, before])).collision.any()
    # the first view's rays, cut when it was inserted (no view before it) and again since
    first = cut.nodes[0]
    assert first.world_from_camera.translation_m[2] == -7.0
    wire = cut.node_images(0)[1]
    reached = wire.back_px > 0
    near_m, far_m = (
        cut.rig.bf_px_m / np.median(wire.front_px[reached]),
        cut.rig.bf_px_m / np.median(wire.back_px[reached]),
    )
    assert 7.5 < near_m < 10.0 < far_m < 12.0  # 8.5-10.8 m: the wires are 10 m ahead
    alone = fused_map(altitudes[:1], **FLIGHT_MAP).node_images(0)[1]
    assert np.all(wire.front_px <= alone.front_px + 1e-3)  # a cut span lies within the prior


def test_a_wire_approached_level_keeps_its_whole_ray_when_cutting() -> None:
    """No parallax (the wire level with the camera, approached head-on) cuts nothing, and
    views that miss a wire rule out nothing: the depth prior stays whole."""
    params = MappingParams(**FLIGHT_MAP, wire_parallax_views=24)  # type: ignore[arg-type]
    rig = stereo_rig_from_params(params.camera)
    height = 6.0
    ends = [WIRE_NORTH_M, -40, -height], [WIRE_NORTH_M, 40, -height]
    camera = SimulatedStereoCamera(
        World(wires=[catenary_wire(*ends, 0.0, 0.02)]),
        rig, body_from_camera_from_params(params.camera), CameraSimParams(), colour_downscale=2,
    )  # fmt: skip
    droan = DroanMap(rig, params)
    for i in range(8):
        frame = camera.render(0.1 * i, Pose.from_yaw_pitch_roll(0, 0, 0, [0.5 * i, 0, -height]))
        mask = frame.wire_mask if i % 2 == 0 else np.zeros_like(frame.wire_mask)  # every other
        droan.insert(frame.stamp_s, frame.world_from_camera, None, mask)
    last_seen = 6 * 0.5
    along = np.array([[last_seen + d, 0.0, -height] for d in (4.5, 6.0, 12.0, 18.0)])
    prior = fused_map(np.array([height]), **FLIGHT_MAP)  # one view: the prior
    shifted = along - [last_seen, 0, 0]
    assert prior.query(shifted).collision.all()
    assert droan.query(along).collision.all()  # the whole ray, 4.5-18 m ahead of the view
    assert droan.query(np.array([[WIRE_NORTH_M, 0.0, -height]])).collision.all()


def test_the_kept_wire_views_forget_the_one_nearest_another_so_parallax_stays() -> None:
    grid = stereo_rig_from_params(MappingParams().camera).camera.scaled(4)
    views = WireViews(grid, capacity=3, tolerance_cells=1, min_views=2)
    cells = np.zeros(grid.shape, bool)
    for i, (north, height) in enumerate([(0.0, 0.0), (0.0, 5.0), (1.0, 5.0), (1.2, 5.0)]):
        views.add(float(i), Pose.from_yaw_pitch_roll(0, 0, 0, [north, 0, -height]), cells, None)
    kept = [(v.centre_ned_m[0], -v.centre_ned_m[2]) for v in views._views]
    assert kept == [(0.0, 0.0), (0.0, 5.0), (1.2, 5.0)]  # the climb's ends stay
    views.prune(oldest_s=1.0)
    assert len(views) == 2


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
