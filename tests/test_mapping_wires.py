"""Fig. 4.5: fusing wire observations from several heights localises stacked wires."""

import numpy as np

from hil.camera_params import CameraSimParams
from hil.cameras import SimulatedStereoCamera
from hil.world import World, catenary_wire
from mapping.camera import body_from_camera_from_params, stereo_rig_from_params
from mapping.droan import DroanMap
from mapping.params import MappingParams
from mapping.pose import Pose

WIRE_HEIGHTS_M = (6.0, 9.0, 12.0)
WIRE_NORTH_M = 10.0


def fused_map(altitudes_m: np.ndarray) -> DroanMap:
    params = MappingParams(
        robot_radius_m=0.3,
        max_nodes=40,
        camera_width_px=320,
        camera_height_px=240,
    )
    rig = stereo_rig_from_params(params.camera)
    world = World(
        wires=[
            catenary_wire([WIRE_NORTH_M, -40, -h], [WIRE_NORTH_M, 40, -h], 0.0, 0.02)
            for h in WIRE_HEIGHTS_M
        ]
    )
    camera = SimulatedStereoCamera(
        world, rig, body_from_camera_from_params(params.camera), CameraSimParams()
    )
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


def test_single_observation_is_a_slab_and_fusion_localises_three_wires() -> None:
    single = fused_map(np.array([9.0]))
    assert len(single) == 1
    # one view: every wire is a 4-20 m slab, the gaps between them cannot be resolved
    # along the view direction, but points at the wires' own depth are all occupied
    assert column(single, WIRE_HEIGHTS_M).all()

    fused = fused_map(np.arange(1.0, 17.01, 0.5))
    assert column(fused, WIRE_HEIGHTS_M).all()
    midpoints = [7.5, 10.5]
    assert not column(fused, midpoints).any()  # the space between the wires clears
    assert not column(fused, [3.0, 15.0]).any()  # and the space above / below them
