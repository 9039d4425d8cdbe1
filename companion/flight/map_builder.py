"""The mapping stage: wire masks and disparity, at the vehicle's pose, into the DROAN map.

Each perception is registered at the camera pose of its exposure: the vehicle pose from
telemetry interpolated at the frame's stamp (`geometry.pose.PoseHistory`, 4.4.6) composed
with the camera mount. A frame whose stamp the pose history does not cover is not fused:
a frame at a wrong pose is worse than none. With `catenary.use_in_collision_check`, wire
masks also feed the catenary mapper (ch. 3), whose confident tubes join the collision check
and whose explained pixels leave DROAN's 4-20 m slab (3.7.2); the refit owed after each
keyframe is handed out (`take_catenary_refit`) to run off the map's worker, and the map uses
the newest finished one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

from companion.flight.perceive import Perception
from geometry.camera import (
    body_from_camera_from_params,
    stereo_rig_from_params,
    world_from_camera,
)
from geometry.pose import Pose, PoseHistory
from mapping.catenary.fit import CatenaryFit
from mapping.catenary.mapper import CatenaryMapper, Keyframes
from mapping.catenary.params import CatenaryParams
from mapping.droan.params import MappingParams
from mapping.droan.pose_graph import DroanMap, InsertResult
from mapping.query import OccupancyMap


@dataclass(frozen=True, slots=True)
class MapUpdate:
    """A frame fused into the map (stamp and sequence of its exposure).

    result: DROAN's insert result, or None when the pose history did not cover the stamp
    (the frame was not fused). nodes: pose-graph size after it; wires: confident catenaries.
    wire_evidence: whether the frame's wire mask was fused (else its stereo alone).
    """

    stamp_s: float
    sequence: int
    world_from_camera: Pose | None
    result: InsertResult | None
    nodes: int
    wires: int
    wire_evidence: bool = True


class MapBuilder:
    """DROAN pose graph (+ the catenary mapper when enabled) fed with registered frames.

    Threads: `add_pose` and `camera_pose_at` on the event loop; `insert` on one worker, the
    same one that runs the planner's queries, so the map never changes under a query.
    """

    def __init__(self, mapping: MappingParams, catenary: CatenaryParams) -> None:
        self.rig = stereo_rig_from_params(mapping.camera)
        self.body_from_camera = body_from_camera_from_params(mapping.camera)
        self.poses = PoseHistory(mapping.pose_max_extrapolation_s, mapping.pose_history_size)
        self.droan = DroanMap(self.rig, mapping)
        self._mapping, self._catenary_params = mapping, catenary
        self.catenary: CatenaryMapper | None = None
        self._refit: Keyframes | None = None
        self.newest_frame_s = -math.inf

    def add_pose(self, stamp_s: float, world_from_body: Pose) -> None:
        """A vehicle pose (body FRD in local NED) sampled at `stamp_s`."""
        self.poses.add(stamp_s, world_from_body)

    def camera_pose_at(self, stamp_s: float) -> Pose | None:
        """`world_from_camera` at `stamp_s`, or None when the pose history does not cover it."""
        world_from_body = self.poses.pose_at(stamp_s)
        return (
            None
            if world_from_body is None
            else world_from_camera(world_from_body, self.body_from_camera)
        )

    def insert(
        self, perception: Perception, pose: Pose | None, wire_evidence: bool = True
    ) -> MapUpdate:
        """Fuse `perception` taken from `pose` (`camera_pose_at` of its stamp); its wire mask
        only with `wire_evidence` (`flight.wires_during_takeoff_and_landing`). Not fused (result
        None) without a pose, or when nothing of the frame is left to fuse."""
        mask = perception.wire_mask if wire_evidence else None
        if pose is None or (mask is None and perception.disparity_px is None):
            return MapUpdate(
                perception.stamp_s, perception.sequence, None, None, len(self.droan), 0,
                wire_evidence,
            )  # fmt: skip
        wires = 0
        if mask is not None and self._catenary_params.use_in_collision_check:
            catenary = self._catenary_mapper(mask.shape[1])
            catenary.add_frame(perception.stamp_s, pose, mask)
            self._refit = catenary.pending_keyframes() or self._refit
            mask = catenary.mask_for_droan(pose, mask)
            wires = len(catenary.obstacles())
        possible = None if mask is None else perception.possible_mask
        result = self.droan.insert(
            perception.stamp_s, pose, perception.disparity_px, mask, possible
        )
        self.newest_frame_s = max(self.newest_frame_s, perception.stamp_s)
        return MapUpdate(
            perception.stamp_s, perception.sequence, pose, result, len(self.droan), wires,
            wire_evidence,
        )  # fmt: skip

    def take_catenary_refit(self) -> Callable[[], list[CatenaryFit]] | None:
        """The catenary refit owed since the last keyframe (once), to run off the map's worker
        (a refit takes up to seconds; meanwhile the last fits stand), or None."""
        keyframes, self._refit = self._refit, None
        if keyframes is None or self.catenary is None:
            return None
        return partial(self.catenary.fit_keyframes, keyframes)

    def use_catenary_fits(self, fits: list[CatenaryFit]) -> None:
        """The finished refit's wires, for the next inserts and planning queries."""
        if self.catenary is not None:
            self.catenary.use_fits(fits)

    def occupancy_map(self) -> OccupancyMap:
        """What the planner queries: DROAN, with the confident catenary tubes when enabled."""
        if self.catenary is None:
            return self.droan
        return self.catenary.collision_map(self.droan)

    def _catenary_mapper(self, mask_width_px: int) -> CatenaryMapper:
        """The catenary mapper in the wire mask's camera (the rig camera scaled to the mask)."""
        if self.catenary is None:
            scale = self.rig.camera.width_px // mask_width_px
            camera = self.rig.camera if scale == 1 else self.rig.camera.scaled(scale)
            self.catenary = CatenaryMapper(camera, self._catenary_params, self._mapping)
        return self.catenary
