"""Streaming front end of catenary reconstruction: keyframes in, wire fits and obstacles out.

The companion loop feeds every wire-segmentation frame with its camera pose; frames that
pass the keyframe rule of 3.4.2 (`MappingParams.keyframe_translation_m` /
`keyframe_rotation_deg`, shared with DROAN's pose graph) are kept, the newest
`CatenaryParams.max_keyframes` of them. Wires are refitted (3.7.3) only when a keyframe
arrives; between keyframes the last fits stand, stamped with their newest keyframe's time.
Pure and synchronous: no clock, no I/O. The refit can be taken out (`pending_keyframes`,
`fit_keyframes`, `use_fits`) and run on another thread, as the flight process does.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from geometry.camera import PinholeCamera
from geometry.keyframes import is_new_keyframe
from geometry.pose import Pose
from mapping.catenary.fit import CatenaryFit
from mapping.catenary.instances import reconstruct_wires
from mapping.catenary.obstacle import (
    WireObstacle,
    collision_map,
    unexplained_wire_mask,
    wire_obstacle,
)
from mapping.catenary.params import CatenaryParams
from mapping.droan.params import MappingParams
from mapping.query import OccupancyMap

Keyframes = tuple[tuple[float, Pose, np.ndarray], ...]
"""(stamp s, world_from_camera, wire mask) of each keyframe, oldest first."""


class CatenaryMapper:
    """Keyframe buffer plus the wire fits of its keyframes."""

    def __init__(
        self, camera: PinholeCamera, params: CatenaryParams, mapping: MappingParams
    ) -> None:
        self.camera = camera
        self.params = params
        self.mapping = mapping
        self._keyframes: deque[tuple[float, Pose, np.ndarray]] = deque(maxlen=params.max_keyframes)
        self._fits: list[CatenaryFit] = []
        self._dirty = False

    def __len__(self) -> int:
        return len(self._keyframes)

    def add_frame(self, stamp_s: float, world_from_camera: Pose, wire_mask: np.ndarray) -> bool:
        """Offer a frame (`(h, w) bool` binarised segmentation); True if kept as a keyframe."""
        last = self._keyframes[-1][1] if self._keyframes else None
        if not wire_mask.any() or not is_new_keyframe(
            last,
            world_from_camera,
            self.mapping.keyframe_translation_m,
            np.deg2rad(self.mapping.keyframe_rotation_deg),
        ):
            return False
        self._keyframes.append((float(stamp_s), world_from_camera, wire_mask))
        self._dirty = True
        return True

    def fits(self) -> list[CatenaryFit]:
        """One fit per wire seen in >= 2 keyframes; refitted here after a new keyframe."""
        keyframes = self.pending_keyframes()
        if keyframes is not None:
            self.use_fits(self.fit_keyframes(keyframes))
        return self._fits

    def pending_keyframes(self) -> Keyframes | None:
        """The keyframes to refit since a keyframe arrived (once), or None: with
        `fit_keyframes` and `use_fits`, the refit can run elsewhere while the last fits stand."""
        if not self._dirty:
            return None
        self._dirty = False
        return tuple(self._keyframes)

    def fit_keyframes(self, keyframes: Keyframes) -> list[CatenaryFit]:
        """The wires of `keyframes` (3.7.3), each seen in >= 2 of them."""
        stamps, poses, masks = zip(*keyframes, strict=True)
        return reconstruct_wires(
            self.camera,
            poses,
            masks,
            stamps,
            self.params,
            self.mapping.wire_depth_near_m,
            self.mapping.wire_depth_far_m,
        )

    def use_fits(self, fits: list[CatenaryFit]) -> None:
        """Make `fits` the ones `obstacles`, `mask_for_droan` and `collision_map` use."""
        self._fits = fits

    def obstacles(self) -> list[WireObstacle]:
        """Tubes of the confident fits (robot radius + k sigma, 3.7.2), of the last refit."""
        radius_m = self.mapping.robot_radius_m
        return [o for f in self._fits if (o := wire_obstacle(f, radius_m, self.params))]

    def mask_for_droan(self, world_from_camera: Pose, wire_mask: np.ndarray) -> np.ndarray:
        """The wire mask DROAN should turn into its slab: unexplained pixels when switched on."""
        if not self.params.use_in_collision_check:
            return wire_mask
        return unexplained_wire_mask(
            wire_mask, self.camera, world_from_camera, self.obstacles(), self.params
        )

    def collision_map(self, base: OccupancyMap) -> OccupancyMap:
        """`base` (DROAN) with the confident wire tubes when `use_in_collision_check` is on."""
        return collision_map(
            base,
            self._fits,
            self.params,
            self.mapping.robot_radius_m,
            self.mapping.occupancy_threshold,
        )
