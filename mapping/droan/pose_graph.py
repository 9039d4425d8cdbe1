"""DROAN: a pose graph of expanded disparity images answering batched collision queries
(thesis 4.4.6 with 4.4.3-4.4.5). Implements `mapping.query.OccupancyMap`.

Each node holds the camera pose `world_from_camera` (NED from camera frame, see
`geometry.pose`), the image timestamp, and eight expanded images on the expansion grid (stereo
front/back and own-return front/back, wire front/back, possible-wire front/back; see
`mapping.droan.expansion`). Node images live in one preallocated `(max_nodes, Hc, Wc, 8)
float32` array, so a query projects all points into each node and costs it in one compiled
pass (`mapping.droan.occupancy.summed_costs`); a large batch is split across `query_threads`
threads (the kernel releases the GIL), each point's answer unchanged.

Keyframes (4.4.6, 3.4.2): a frame becomes a new node when the camera moved at least
`keyframe_translation_m` or turned at least `keyframe_rotation_deg` since the newest keyframe;
otherwise it replaces the newest node if that one is a non-keyframe "live" node (or becomes
that live node), so the latest observation is always fused exactly once
(`replace_latest_non_keyframe`; when False it is dropped). The oldest node is evicted when the
graph is full; nodes older than `max_node_age_s` are evicted on `insert` / `prune`.
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from enum import Enum

import numpy as np

from geometry.camera import StereoRig
from geometry.keyframes import is_new_keyframe
from geometry.pose import Pose
from mapping.droan.expansion import DisparityExpander, ExpandedImage
from mapping.droan.occupancy import summed_costs
from mapping.droan.params import MappingParams
from mapping.droan.wire_depth import WireViews
from mapping.droan.wire_triangulation import WireVoxels, thin_wire_cells
from mapping.query import OccupancyQuery

_MIN_DEPTH_M = 1e-3


class InsertResult(Enum):
    """What `DroanMap.insert` did with a frame."""

    KEYFRAME = "keyframe"
    LIVE = "live"
    DROPPED = "dropped"


@dataclass(frozen=True, slots=True)
class DroanNode:
    """Metadata of one pose-graph node (its images live in the map's node array)."""

    stamp_s: float
    world_from_camera: Pose
    keyframe: bool
    has_stereo: bool
    has_wire: bool


class DroanMap:
    """Pose graph of expanded disparity images (4.4.6); `query` is the planner's hot path."""

    def __init__(self, rig: StereoRig, params: MappingParams) -> None:
        self.params = params
        self.rig = rig
        self.expander = DisparityExpander(rig, params)
        self.grid_camera = self.expander.grid_camera
        h, w = self.grid_camera.shape
        n = params.max_nodes
        # 8 channels: a pixel's 32-byte row never straddles a cache line
        self._images = np.full((n * h * w, 8), -1.0, dtype=np.float32)
        self._projection = np.zeros((n, 3, 3), dtype=np.float32)  # K_grid @ R_cw
        self._offset = np.zeros((n, 3), dtype=np.float32)  # K_grid @ t_cw
        self._slots: list[DroanNode | None] = [None] * n
        self._order: list[int] = []  # occupied slots, oldest first
        self._active = np.zeros(0, dtype=np.intp)
        self.wire_voxels = (
            WireVoxels(
                self.grid_camera,
                n,
                params.wire_voxel_m,
                params.robot_radius_m + params.wire_position_margin_m,
                params.occupancy_threshold,
                params.wire_free_weight,
                params.wire_vote_max,
                (params.wire_depth_near_m, params.wire_depth_far_m),
                params.max_range_m,
            )
            if params.wire_triangulation
            else None
        )
        self.wire_views = (
            WireViews(
                self.grid_camera,
                params.wire_parallax_views,
                params.wire_ray_tolerance_cells,
                params.wire_parallax_min_views,
            )
            if params.wire_parallax_views > 0
            else None
        )
        self._wire_prior_m = (params.wire_depth_near_m, params.wire_depth_far_m)
        self._wire_cells: list[np.ndarray | None] = [None] * n  # pooled, when cutting rays
        self._cut_s = np.zeros(n)  # when each node's wire rays were last cut
        self._occupancy(np.zeros((0, 3)))  # compile (or load) the query kernel now, not in flight

    # --- graph ---------------------------------------------------------------------------

    @property
    def nodes(self) -> list[DroanNode]:
        """The nodes, oldest first."""
        return [self._slots[i] for i in self._order]  # type: ignore[misc]

    def __len__(self) -> int:
        return len(self._order)

    def clear(self) -> None:
        """Forget every node."""
        self._slots = [None] * len(self._slots)
        self._order = []
        self._active = np.zeros(0, dtype=np.intp)
        self._wire_cells = [None] * len(self._slots)
        if self.wire_voxels is not None:
            self.wire_voxels.clear()
        if self.wire_views is not None:
            self.wire_views.clear()

    def memory_bytes(self) -> int:
        """Bytes held by node images and poses (preallocated for `max_nodes`), and by the
        wire voxels when triangulating or the kept wire views when cutting wire rays."""
        voxels = 0 if self.wire_voxels is None else self.wire_voxels.memory_bytes()
        views = 0 if self.wire_views is None else self.wire_views.memory_bytes()
        cells = sum(c.nbytes for c in self._wire_cells if c is not None)
        nodes = self._images.nbytes + self._projection.nbytes + self._offset.nbytes
        return nodes + voxels + views + cells

    def prune(self, now_s: float) -> None:
        """Evict nodes older than `max_node_age_s` (when that limit is set)."""
        if self.params.max_node_age_s <= 0:
            return
        oldest_s = now_s - self.params.max_node_age_s
        self._order = [i for i in self._order if self._slots[i].stamp_s >= oldest_s]  # type: ignore[union-attr]
        self._active = np.array(self._order, dtype=np.intp)
        if self.wire_views is not None:
            self.wire_views.prune(oldest_s)

    def _is_keyframe(self, world_from_camera: Pose) -> bool:
        keyframes = [self._slots[i] for i in self._order if self._slots[i].keyframe]  # type: ignore[union-attr]
        last = keyframes[-1].world_from_camera if keyframes else None  # type: ignore[union-attr]
        return is_new_keyframe(
            last,
            world_from_camera,
            self.params.keyframe_translation_m,
            np.deg2rad(self.params.keyframe_rotation_deg),
        )

    def insert(
        self,
        stamp_s: float,
        world_from_camera: Pose,
        disparity_px: np.ndarray | None = None,
        wire_mask: np.ndarray | None = None,
        possible_mask: np.ndarray | None = None,
    ) -> InsertResult:
        """Fuse one frame taken at `stamp_s` (s) from `world_from_camera` (NED from camera).

        disparity_px: `(H, W) float32` px (NaN invalid, 0 no return; `mapping.droan.expansion`), or
            None when only a wire mask is available.
        wire_mask: `(H, W) bool` wire pixels registered to the disparity camera, or None when
            no wire detection ran for this frame (no wire evidence, not "no wire").
        possible_mask: `(H, W) bool` like `wire_mask`, the pixels the detector does not rule
            out as wire (a superset of it): where only its C-space expansion reaches, the node
            votes neither for a wire nor against one. None: every pixel outside the wire
            mask's expansion is no-wire evidence (4.4.5).
        """
        if disparity_px is None and wire_mask is None:
            raise ValueError("a frame needs a disparity image, a wire mask or both")
        self.prune(stamp_s)
        keyframe = self._is_keyframe(world_from_camera)
        newest = self._slots[self._order[-1]] if self._order else None
        live_newest = newest is not None and not newest.keyframe
        if not keyframe and not self.params.replace_latest_non_keyframe:
            return InsertResult.DROPPED
        if live_newest:
            slot = self._order.pop()
        elif len(self._order) < len(self._slots):
            slot = min(set(range(len(self._slots))) - set(self._order))
        else:
            slot = self._order.pop(0)
        self._slots[slot] = DroanNode(
            float(stamp_s),
            world_from_camera,
            keyframe,
            disparity_px is not None,
            wire_mask is not None,
        )
        if wire_mask is not None and self.wire_voxels is not None:
            self._vote_wires(slot, keyframe, world_from_camera, wire_mask, possible_mask)
            wire_mask = possible_mask = None  # the voxels hold its wire evidence
        spans = None
        self._wire_cells[slot] = None
        if wire_mask is not None and self.wire_views is not None:
            spans = self._cut_wire_rays(
                slot, stamp_s, keyframe, world_from_camera, wire_mask, possible_mask
            )
        self._write(slot, world_from_camera, disparity_px, wire_mask, possible_mask, spans)
        self._order.append(slot)
        self._active = np.array(self._order, dtype=np.intp)
        if self.wire_views is not None:
            self._recut_stalest(stamp_s)
        return InsertResult.KEYFRAME if keyframe else InsertResult.LIVE

    def _write(
        self,
        slot: int,
        world_from_camera: Pose,
        disparity_px: np.ndarray | None,
        wire_mask: np.ndarray | None,
        possible_mask: np.ndarray | None,
        spans: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        images = self._node_view(slot)
        images.fill(-1.0)
        if disparity_px is not None:
            stereo = self.expander.expand_stereo(disparity_px)
            images[..., 0], images[..., 1] = stereo.front_px, stereo.back_px
            images[..., 2], images[..., 3] = stereo.own_front_px, stereo.own_back_px
        if wire_mask is not None:
            wire = self.expander.expand_wire(wire_mask, spans)
            images[..., 4], images[..., 5] = wire.front_px, wire.back_px
            if possible_mask is not None and (possible_mask & ~wire_mask).any():
                possible = self.expander.expand_wire(possible_mask | wire_mask)
                images[..., 6], images[..., 7] = possible.front_px, possible.back_px
        camera_from_world = world_from_camera.inverse()
        k = self.grid_camera.intrinsic_matrix()
        self._projection[slot] = k @ camera_from_world.rotation
        self._offset[slot] = k @ camera_from_world.translation_m

    def _cut_wire_rays(
        self,
        slot: int,
        stamp_s: float,
        keyframe: bool,
        world_from_camera: Pose,
        wire_mask: np.ndarray,
        possible_mask: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The depth spans of a frame's wire rays cut by the kept views (`wire_depth`); a
        keyframe's cells are kept for the next frames, and the node's for `_recut_stalest`."""
        views = self.wire_views
        assert views is not None
        pooled = self.expander.pooled_wire_mask
        cells = pooled(wire_mask)
        self._wire_cells[slot], self._cut_s[slot] = cells, stamp_s
        spans = views.depth_limits(world_from_camera, cells, *self._wire_prior_m)
        if keyframe:
            possible = None if possible_mask is None else pooled(possible_mask | wire_mask)
            views.add(stamp_s, world_from_camera, cells, possible)
        return spans

    def _recut_stalest(self, now_s: float) -> None:
        """Cut again the wire rays of the older node whose cut is the oldest, with the views
        kept now: a node inserted early in a climb was cut by the few views before it, and
        the views after it hold the parallax (one node per insert, each in turn)."""
        views = self.wire_views
        older = [i for i in self._order[:-1] if self._wire_cells[i] is not None]
        if views is None or not older:
            return
        slot = min(older, key=lambda i: self._cut_s[i])
        cells, node = self._wire_cells[slot], self._slots[slot]
        assert cells is not None and node is not None
        spans = views.depth_limits(node.world_from_camera, cells, *self._wire_prior_m)
        wire = self.expander.expand_wire(cells, spans)
        images = self._node_view(slot)
        images[..., 4], images[..., 5] = wire.front_px, wire.back_px
        self._cut_s[slot] = now_s

    def _vote_wires(
        self,
        slot: int,
        keyframe: bool,
        world_from_camera: Pose,
        wire_mask: np.ndarray,
        possible_mask: np.ndarray | None,
    ) -> None:
        """A frame's thin-ray votes into the wire voxels (`wire_triangulation`)."""
        pooled = self.expander.pooled_wire_mask
        flags = thin_wire_cells(
            pooled(wire_mask),
            None if possible_mask is None else pooled(possible_mask | wire_mask),
            self.params.wire_ray_tolerance_cells,
        )
        voters = [i for i in self._order if i != slot and self._slots[i].has_wire]  # type: ignore[union-attr]
        self.wire_voxels.insert(  # type: ignore[union-attr]
            slot, keyframe, world_from_camera, flags, np.array(voters, np.intp)
        )

    def _node_view(self, slot: int) -> np.ndarray:
        h, w = self.grid_camera.shape
        return self._images[slot * h * w : (slot + 1) * h * w].reshape(h, w, 8)

    def node_images(self, index: int) -> tuple[ExpandedImage, ExpandedImage]:
        """(stereo, wire) expanded images of the `index`-th node, oldest first."""
        images = self._node_view(self._order[index])
        return (
            ExpandedImage(images[..., 0], images[..., 1], images[..., 2], images[..., 3]),
            ExpandedImage(images[..., 4], images[..., 5]),
        )

    # --- queries ---------------------------------------------------------------------------

    def query(self, points_ned_m: np.ndarray) -> OccupancyQuery:
        """Batched collision check of `(N, 3)` NED world points (m) against all nodes (4.4.5).

        occupancy: max(M_stereo, M_wire), each M = max(sum over nodes of occ, 0) (eq. 4.5)
            with the stereo costs of Table 4.1 and the wire costs of the 4.4.5 note, summed
            separately (stereo cannot see wires, so its free evidence must not erase them);
        collision: occupancy >= gamma; solid: M_stereo >= gamma (the wire prior left out);
        seen: some node observed the point directly: inside its image, in front of the camera,
            within `max_range_m`, on a valid pixel and not occluded (behind its back limit);
            only stereo observations make points seen (a wire mask alone says nothing of free
            space).
        """
        points = np.asarray(points_ned_m, dtype=np.float32).reshape(-1, 3)
        n = len(points)
        if n == 0 or not self._order:
            none = np.zeros(n, bool)
            return OccupancyQuery(none, np.zeros(n, dtype=np.float32), none, none)
        threads = self.params.query_threads
        if threads == 1 or n < self.params.query_split_min_points:
            stereo, wire, seen = self._occupancy(points)
        else:
            parts = list(_pool(threads).map(self._occupancy, np.array_split(points, threads)))
            stereo, wire, seen = (np.concatenate(part) for part in zip(*parts, strict=True))
        gamma = self.params.occupancy_threshold
        if self.wire_voxels is not None:
            wire = np.maximum(wire, self.wire_voxels.occupancy(points))
        occupancy = np.maximum(stereo, wire)
        return OccupancyQuery(occupancy >= gamma, occupancy, seen, stereo >= gamma)

    def _occupancy(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M_stereo, M_wire `(N,) float32`, seen `(N,) bool`) of `(N, 3) float32` points
        over all nodes."""
        h, w = self.grid_camera.shape
        f32 = np.float32
        return summed_costs(
            np.ascontiguousarray(points, dtype=f32),
            self._projection,
            self._offset,
            self._active,
            self._images,
            h,
            w,
            f32(self.rig.bf_px_m),
            f32(_MIN_DEPTH_M),
            f32(self.params.max_range_m),
            f32(self.params.disparity_sigma_px),
            f32(self.params.free_discount),
            f32(self.params.occluded_discount),
            f32(self.params.wire_free_weight),
            f32(self.expander.wire_front_px),
        )


@functools.cache
def _pool(threads: int) -> ThreadPoolExecutor:
    """The process-wide worker pool of `threads` threads shared by all maps' queries."""
    return ThreadPoolExecutor(max_workers=threads, thread_name_prefix="droan-query")
