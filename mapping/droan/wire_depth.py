"""Wire depth from the parallax of earlier views: each wire ray's slab cut to the depths that
the other views do not rule out.

Beyond the thesis (4.4.3 and its future work on wire depth): a wire seen in one image lies
anywhere on its rays from `wire_depth_near_m` to `wire_depth_far_m`, and DROAN fuses the
views' C-space expanded slabs by voting (4.4.5). Views a few metres apart, a takeoff climb seen
from 12 m, spread the rays by about 0.4 rad, yet their expanded slabs overlap into one wall
from the ground up: each point before or behind a wire lies inside the expansion of most of
them. Here the depths are cut before the expansion, on thin rays:

1. `WireViews` keeps the wire cells of recent keyframes on the expansion grid, dilated by
   `wire_ray_tolerance_cells` (the mask's and the pose's error), the cells the CNN did not
   rule out counted with them; full, it forgets the view nearest another one, so the views
   that hold parallax (the climb, the far end of a rewind) outlive a head-on approach.
2. Each wire cell of a new view is sampled along its ray at `_DEPTH_SAMPLES` depths of the
   prior (uniform in inverse depth); each sample is projected into every kept view that sees
   it (in front, inside the image).
3. The ray's best depth is where most views saw a wire (the wire is located there when at
   least two views and half of those that looked saw it). Another depth is ruled out where
   `wire_parallax_min_views` views that saw the wire at the best depth looked at it and saw
   none: they place the wire elsewhere on the ray. The ray keeps the span from its nearest to
   its farthest depth not ruled out, one sample wider on either side; a ray without a
   located depth keeps the whole prior.

Without parallax (a head-on approach, a wire level with the camera) every depth projects onto
the wire in every view and the prior stays whole; a view that misses the wire rules out
nothing, since only views that saw it at the best depth vote against the others. The node
images are expanded from the cut spans (`DisparityExpander.expand_wire`), and the views still
vote as in 4.4.5.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numba
import numpy as np

from geometry.camera import PinholeCamera
from geometry.pose import Pose
from mapping.droan.wire_triangulation import POSSIBLE, WIRE, thin_wire_cells

_DEPTH_SAMPLES = 48  # depths of the prior sampled along each wire ray
_LOCATED_MIN_HITS = 2  # views that must see the wire at a depth for it to be located


@numba.njit(cache=True, nogil=True)
def _view_bits(
    centre: np.ndarray,
    rays: np.ndarray,
    depths: np.ndarray,
    projections: np.ndarray,
    offsets: np.ndarray,
    flags: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """`(M, S) uint64` bit masks over the views of the points `centre + depth * ray` (`(3,)`
    world centre, `(M, 3)` world rays scaled to unit camera depth, `(S,)` depths): bit k of
    `hit` where view k (`(K, 3, 3)` projection, `(K, 3)` offset, `(K, Hc, Wc)` flags) sees a
    wire cell at the point, of `looked` where the point is in front of it and inside its
    image. A ray projects to a + depth b (homogeneous), so each sample costs two divisions."""
    m_count, s_count = rays.shape[0], depths.shape[0]
    h, w = flags.shape[1], flags.shape[2]
    hit = np.zeros((m_count, s_count), np.uint64)
    looked = np.zeros((m_count, s_count), np.uint64)
    for k in range(projections.shape[0]):
        p, bit = projections[k], np.uint64(1) << np.uint64(k)
        a = p @ centre + offsets[k]
        for m in range(m_count):
            b = p @ rays[m]
            for s in range(s_count):
                z = a[2] + depths[s] * b[2]
                if z <= 1e-3:
                    continue
                u = np.floor((a[0] + depths[s] * b[0]) / z + 0.5)
                r = np.floor((a[1] + depths[s] * b[1]) / z + 0.5)
                if u < 0 or u >= w or r < 0 or r >= h:
                    continue
                looked[m, s] |= bit
                if flags[k, int(r), int(u)]:
                    hit[m, s] |= bit
    return hit, looked


@numba.njit(cache=True, nogil=True)
def _popcount(bits: np.ndarray) -> np.ndarray:
    """Set bits of each `uint64` (any shape), as int64 (SWAR)."""
    flat = bits.ravel()
    counts = np.empty(flat.size, np.int64)
    m1, m2, m4 = (
        np.uint64(0x5555555555555555),
        np.uint64(0x3333333333333333),
        np.uint64(0x0F0F0F0F0F0F0F0F),
    )
    for i in range(flat.size):
        x = flat[i]
        x = x - ((x >> np.uint64(1)) & m1)
        x = (x & m2) + ((x >> np.uint64(2)) & m2)
        x = (x + (x >> np.uint64(4))) & m4
        counts[i] = np.int64((x * np.uint64(0x0101010101010101)) >> np.uint64(56))
    return counts.reshape(bits.shape)


@dataclass(frozen=True, slots=True)
class WireView:
    """One keyframe's wire evidence: its projection onto the expansion grid and its flags.

    projection, offset: grid K times camera_from_world's rotation and translation.
    flags: `(Hc, Wc) uint8`, `WIRE | POSSIBLE` where the dilated wire or possible cells are.
    """

    stamp_s: float
    centre_ned_m: np.ndarray
    projection: np.ndarray
    offset: np.ndarray
    flags: np.ndarray


class WireViews:
    """Recent keyframes' wire cells; `depth_limits` cuts a new view's wire rays with them."""

    def __init__(
        self,
        grid_camera: PinholeCamera,
        capacity: int,
        tolerance_cells: int,
        min_views: int,
    ) -> None:
        self.grid_camera = grid_camera
        self.capacity = capacity
        self.tolerance_cells = tolerance_cells
        self.min_views = min_views
        self._views: deque[WireView] = deque()
        # compile (or load) the kernels now, not at the first wire in flight
        none = np.zeros((0, 3))
        _view_bits(
            np.zeros(3), none, np.ones(1), np.zeros((0, 3, 3)), none, np.zeros((0, 1, 1), np.uint8)
        )
        _popcount(np.zeros((1, 1), np.uint64))

    def __len__(self) -> int:
        return len(self._views)

    def clear(self) -> None:
        self._views.clear()

    def memory_bytes(self) -> int:
        """Bytes held by the kept views' flags."""
        return sum(v.flags.nbytes for v in self._views)

    def prune(self, oldest_s: float) -> None:
        """Forget the views taken before `oldest_s`."""
        self._views = deque(v for v in self._views if v.stamp_s >= oldest_s)

    def add(
        self,
        stamp_s: float,
        world_from_camera: Pose,
        wire_cells: np.ndarray,
        possible_cells: np.ndarray | None,
    ) -> None:
        """Keep a keyframe's pooled `(Hc, Wc) bool` wire (and possible) cells; full, forget the
        view whose camera is nearest another's (the older of the two)."""
        flags = thin_wire_cells(wire_cells, possible_cells, self.tolerance_cells)
        camera_from_world = world_from_camera.inverse()
        k = self.grid_camera.intrinsic_matrix()
        self._views.append(
            WireView(
                float(stamp_s),
                np.asarray(world_from_camera.translation_m, float),
                k @ camera_from_world.rotation,
                k @ camera_from_world.translation_m,
                flags & (WIRE | POSSIBLE),
            )
        )
        if len(self._views) > self.capacity:
            centres = np.array([v.centre_ned_m for v in self._views])
            gaps = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
            gaps[np.diag_indices(len(centres))] = np.inf
            i, j = np.unravel_index(np.argmin(gaps), gaps.shape)
            del self._views[min(i, j)]

    def depth_limits(
        self,
        world_from_camera: Pose,
        wire_cells: np.ndarray,
        near_m: float,
        far_m: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """`(Hc, Wc) float32` near and far depth (m) of each wire cell's span along its ray,
        within the prior [`near_m`, `far_m`] (NaN off the wire cells); see the module doc."""
        near = np.full(wire_cells.shape, np.nan, np.float32)
        far = near.copy()
        v, u = np.nonzero(wire_cells)
        near[v, u], far[v, u] = near_m, far_m
        if len(v) == 0 or not self._views:
            return near, far
        depths = 1.0 / np.linspace(1.0 / far_m, 1.0 / near_m, _DEPTH_SAMPLES)  # far first
        rays = world_from_camera.rotate(self.grid_camera.rays(np.stack([u, v], axis=1)))
        views = list(self._views)
        hit, looked = _view_bits(
            np.asarray(world_from_camera.translation_m, np.float64),
            np.ascontiguousarray(rays, np.float64),
            depths,
            np.array([view.projection for view in views], np.float64),
            np.array([view.offset for view in views], np.float64),
            np.array([view.flags for view in views]),
        )  # (M, S) uint64: bit k set where view k saw a wire / looked at the depth
        hits, looks = _popcount(hit), _popcount(looked)
        located = (hits >= _LOCATED_MIN_HITS) & (2 * hits >= looks)
        # the best depth of each ray: most views saw the wire there (the highest share on ties)
        score = np.where(located, hits + hits / np.maximum(looks, 1), -1.0)
        best = hit[np.arange(len(v)), np.argmax(score, axis=1)]  # (M,) the views that saw it
        against = _popcount(best[:, None] & looked & ~hit)  # ...and not at this depth
        kept = (against < self.min_views) | ~located.any(axis=1)[:, None]
        # the span from the nearest to the farthest kept depth, one sample wider each way
        index = np.arange(_DEPTH_SAMPLES)
        first = np.where(kept, index, _DEPTH_SAMPLES).min(axis=1)  # farthest kept
        last = np.where(kept, index, -1).max(axis=1)  # nearest kept
        far[v, u] = depths[np.maximum(first - 1, 0)]
        near[v, u] = depths[np.minimum(last + 1, _DEPTH_SAMPLES - 1)]
        return near, far
