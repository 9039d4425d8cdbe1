"""Wires triangulated by thin-ray votes in a voxel map, C-space expanded afterwards.

Beyond the thesis (4.4.5 note, and its future work on multi-view wire mapping): the wire prior
of 4.4.3 puts a wire seen in one image anywhere on its rays from `wire_depth_near_m` to
`wire_depth_far_m`. DROAN expands each view's rays by r_v before the views vote (Fig. 4.4), so
a point metres before or behind a wire lies inside the expansion of most views of it whenever
they were taken from a short baseline (a takeoff climb seen from 12 m spreads the rays by
0.4 rad), and their fans fuse into a wall. Here the views vote first, on thin rays, and the
expansion comes after:

1. candidates: the voxels (`wire_voxel_m`) that the newest view's wire rays cross within the
   prior's depths, voted on by every view of the pose graph, and the wire voxels kept so far;
2. a view votes on a voxel's centre with the wire costs of the 4.4.5 note left unexpanded:
   +1 where it projects onto the view's wire cells (dilated by `wire_ray_tolerance_cells`)
   within the prior's depths, -`wire_free_weight` where it projects onto cells the CNN ruled
   out, nothing where it is nearer than the prior's near limit (the near prior: views passing
   a wire must not vote it away), out of view or undecided (the possible mask). A keyframe's
   vote stays in the voxel, clamped at `wire_vote_max` as OctoMap clamps log-odds so that the
   map can still change its mind; the live view's counts until the next view replaces it;
3. a voxel whose sum reaches gamma (eq. 4.5) is wire and is kept; the others are forgotten (a
   ray that crosses one again makes it anew, with the votes of the graph's views); a query
   point within r_v + `wire_position_margin_m` + half a voxel diagonal of a wire voxel's centre
   is a wire collision, found through a hash of cells as wide as that radius.

A wire seen in one view keeps its whole ray (the prior, as before); views from elsewhere carve
the ray down to where the rays meet, the wire itself.
"""

from __future__ import annotations

import cv2
import numba
import numpy as np

from geometry.camera import PinholeCamera
from geometry.pose import Pose

WIRE = np.uint8(1)  # a (dilated) wire cell: votes +1 within the prior's depths
POSSIBLE = np.uint8(2)  # a (dilated) cell the CNN did not rule out: abstains
RAY = np.uint8(4)  # an undilated wire cell: its ray makes candidates

_EMPTY = np.int64(-1)
_OFFSET = np.int64(1 << 20)  # voxel indices in [-2^20, 2^20) per axis, packed in 21 bits each


def thin_wire_cells(
    wire_cells: np.ndarray, possible_cells: np.ndarray | None, tolerance_cells: int
) -> np.ndarray:
    """`(Hc, Wc) uint8` flags (`WIRE`, `POSSIBLE`, `RAY`) of one view on the expansion grid,
    from its pooled `(Hc, Wc) bool` wire and possible cells."""
    kernel = np.ones((2 * tolerance_cells + 1, 2 * tolerance_cells + 1), np.uint8)
    rays = wire_cells.astype(np.uint8)
    flags = cv2.dilate(rays, kernel) * WIRE + rays * RAY
    if possible_cells is not None:
        flags |= cv2.dilate(possible_cells.astype(np.uint8), kernel) * POSSIBLE
    return flags


@numba.njit(cache=True, nogil=True)
def _find(table: np.ndarray, keys: np.ndarray, key: np.int64) -> np.int64:
    """Probe position of `key` in the open-addressing `table` (voxel indices into `keys`):
    where it is, or the empty position where it would go."""
    mask = np.int64(len(table) - 1)
    position = (key * np.int64(-7046029254386353131)) >> np.int64(20) & mask
    while table[position] != _EMPTY and keys[table[position]] != key:
        position = (position + 1) & mask
    return position


@numba.njit(cache=True, nogil=True)
def _rehash(table: np.ndarray, keys: np.ndarray, count: int) -> None:
    table[:] = _EMPTY
    for i in range(count):
        table[_find(table, keys, keys[i])] = i


@numba.vectorize(["int64(int64, int64, int64)"], cache=True)
def voxel_key(ix: int, iy: int, iz: int) -> int:
    """One int64 key of integer voxel indices in [-2^20, 2^20) (a ufunc: any shapes)."""
    return ((ix + _OFFSET) << np.int64(42)) | ((iy + _OFFSET) << np.int64(21)) | (iz + _OFFSET)


@numba.njit(cache=True, nogil=True)
def _key(x: float, y: float, z: float, inv_voxel: float) -> np.int64:
    """`voxel_key` of the voxel of edge 1 / `inv_voxel` holding point (x, y, z)."""
    return voxel_key(
        np.int64(np.floor(x * inv_voxel)),
        np.int64(np.floor(y * inv_voxel)),
        np.int64(np.floor(z * inv_voxel)),
    )


@numba.njit(cache=True, nogil=True)
def _centre(key: np.int64, voxel: float) -> tuple[float, float, float]:
    bits = np.int64((1 << 21) - 1)
    ix = ((key >> np.int64(42)) & bits) - _OFFSET
    iy = ((key >> np.int64(21)) & bits) - _OFFSET
    iz = (key & bits) - _OFFSET
    return (ix + 0.5) * voxel, (iy + 0.5) * voxel, (iz + 0.5) * voxel


@numba.njit(cache=True, nogil=True)
def _centres(keys: np.ndarray, voxel: float) -> np.ndarray:
    """`(M, 3)` centres of the voxels `keys`."""
    out = np.empty((keys.shape[0], 3))
    for i in range(keys.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = _centre(keys[i], voxel)
    return out


@numba.njit(cache=True, nogil=True)
def _add_candidates(
    table: np.ndarray,
    keys: np.ndarray,
    votes: np.ndarray,
    count: int,
    samples: np.ndarray,
    voxel: float,
) -> int:
    """Add the voxels of `(S, 3)` world points not yet in the map (votes 0); the new count."""
    inv_voxel = 1.0 / voxel
    for j in range(samples.shape[0]):
        key = _key(samples[j, 0], samples[j, 1], samples[j, 2], inv_voxel)
        position = _find(table, keys, key)
        if table[position] == _EMPTY:
            keys[count] = key
            votes[count] = 0.0
            table[position] = count
            count += 1
    return count


@numba.njit(cache=True, nogil=True)
def _vote(
    keys: np.ndarray,
    votes: np.ndarray,
    first: int,
    count: int,
    voxel: float,
    projection: np.ndarray,
    offset: np.ndarray,
    slots: np.ndarray,
    flags: np.ndarray,
    near_m: float,
    far_m: float,
    max_range_m: float,
    free_weight: float,
    vote_max: float,
) -> None:
    """The votes (step 2 of the module doc) of the views `slots` added to `votes` of the
    voxels `first..count`, clamped at `vote_max` after each view. View s projects world
    points with `projection[s]` (K R_cw) and `offset[s]` (K t_cw) onto its `(Hc, Wc)`
    `flags[s]`."""
    height, width = flags.shape[1], flags.shape[2]
    for slot in slots:
        k, t = projection[slot], offset[slot]
        for i in range(first, count):
            x, y, z_w = _centre(keys[i], voxel)
            z = k[2, 0] * x + k[2, 1] * y + k[2, 2] * z_w + t[2]
            if z < near_m or z > max_range_m:
                continue  # nearer than the prior (the near prior) or out of range: abstain
            u = (k[0, 0] * x + k[0, 1] * y + k[0, 2] * z_w + t[0]) / z + 0.5
            v = (k[1, 0] * x + k[1, 1] * y + k[1, 2] * z_w + t[1]) / z + 0.5
            if u < 0.0 or u >= width or v < 0.0 or v >= height:
                continue
            cell = flags[slot, np.int64(v), np.int64(u)]
            if cell & 1 and z <= far_m:
                votes[i] = min(votes[i] + 1.0, vote_max)
            elif not cell & 2:
                votes[i] -= free_weight


@numba.njit(cache=True, nogil=True)
def _keep(keys: np.ndarray, votes: np.ndarray, keep: np.ndarray, count: int) -> int:
    """Compact the voxels flagged in `keep` to the front (order kept); the new count."""
    kept = 0
    for i in range(count):
        if keep[i]:
            keys[kept] = keys[i]
            votes[kept] = votes[i]
            kept += 1
    return kept


@numba.njit(cache=True, nogil=True)
def _cell_lists(
    centres: np.ndarray, cell_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(table, cell keys, first voxel of each cell, next voxel in its cell) of `(M, 3)`
    centres bucketed into cubic cells of `cell_m`: a hash of linked lists."""
    m = centres.shape[0]
    size = 16
    while size < 2 * m:
        size *= 2
    table = np.full(size, _EMPTY, np.int64)
    keys = np.empty(max(m, 1), np.int64)
    heads = np.full(max(m, 1), -1, np.int64)
    following = np.full(max(m, 1), -1, np.int64)
    cells = 0
    inv_cell = 1.0 / cell_m
    for i in range(m):
        key = _key(centres[i, 0], centres[i, 1], centres[i, 2], inv_cell)
        position = _find(table, keys, key)
        if table[position] == _EMPTY:
            keys[cells] = key
            table[position] = cells
            cells += 1
        cell = table[position]
        following[i] = heads[cell]
        heads[cell] = i
    return table, keys, heads, following


@numba.njit(cache=True, nogil=True)
def _votes_within(
    points: np.ndarray,
    centres: np.ndarray,
    votes: np.ndarray,
    table: np.ndarray,
    keys: np.ndarray,
    heads: np.ndarray,
    following: np.ndarray,
    cell_m: float,
    radius_m: float,
) -> np.ndarray:
    """`(N,) float32`: the votes of a wire voxel within `radius_m` (<= `cell_m`) of each
    point (the first found), else 0."""
    out = np.zeros(points.shape[0], np.float32)
    r2 = radius_m * radius_m
    inv_cell = 1.0 / cell_m
    for n in range(points.shape[0]):
        x, y, z = points[n, 0], points[n, 1], points[n, 2]
        found = False
        for dx in (-cell_m, 0.0, cell_m):
            for dy in (-cell_m, 0.0, cell_m):
                for dz in (-cell_m, 0.0, cell_m):
                    position = _find(table, keys, _key(x + dx, y + dy, z + dz, inv_cell))
                    i = table[position]
                    j = heads[i] if i != _EMPTY else -1
                    while j >= 0 and not found:
                        ex, ey, ez = centres[j, 0] - x, centres[j, 1] - y, centres[j, 2] - z
                        if ex * ex + ey * ey + ez * ez <= r2:
                            out[n] = votes[j]
                            found = True
                        j = following[j]
                    if found:
                        break
                if found:
                    break
            if found:
                break
    return out


class WireVoxels:
    """The thin-ray wire votes in voxels (module doc) and their wire voxels' C-space check.

    Views live in the slots of the pose graph that feeds it (`DroanMap`), which says whether
    each one is a keyframe.
    """

    def __init__(
        self,
        camera: PinholeCamera,
        slots: int,
        voxel_m: float,
        radius_m: float,
        gamma: float,
        free_weight: float,
        vote_max: float,
        depth_range_m: tuple[float, float],
        max_range_m: float,
    ) -> None:
        self.camera = camera
        self.voxel_m = voxel_m
        self.radius_m = radius_m + 0.5 * np.sqrt(3.0) * voxel_m  # from a voxel's centre
        self.gamma = gamma
        self._vote_args = (
            depth_range_m[0], depth_range_m[1], max_range_m, free_weight, vote_max
        )  # fmt: skip
        self._depths = np.arange(depth_range_m[0], depth_range_m[1] + voxel_m / 2, voxel_m)
        self._flags = np.zeros((slots, *camera.shape), np.uint8)
        self._projection = np.zeros((slots, 3, 3))  # K R_cw
        self._offset = np.zeros((slots, 3))  # K t_cw
        self.clear()
        self._compile()

    def _compile(self) -> None:
        """Compile (or load) the kernels now, not at the first wire seen in flight."""
        _add_candidates(self._table, self._keys, self._votes, 0, np.zeros((0, 3)), self.voxel_m)
        self._vote(self._votes, 0, 0, np.zeros(0, np.intp))
        _keep(self._keys, self._votes, np.zeros(0, bool), 0)
        _rehash(self._table, self._keys, 0)
        _centres(self._keys[:0], self.voxel_m)
        point = np.zeros((1, 3))
        _votes_within(point, point, np.ones(1, np.float32), *_cell_lists(point, 1.0), 1.0, 1.0)

    def clear(self) -> None:
        """Forget every vote."""
        self._keys = np.zeros(1 << 16, np.int64)
        self._votes = np.zeros(1 << 16, np.float32)  # the keyframes' summed votes
        self._table = np.full(1 << 17, _EMPTY, np.int64)
        self._count = 0
        self._use(np.zeros((0, 3)), np.zeros(0, np.float32))

    def __len__(self) -> int:
        return self._count

    def memory_bytes(self) -> int:
        """Bytes held by the views' cells and the voxels (their hash and the wire cells')."""
        held = (self._flags, self._keys, self._votes, self._table, self._centres, *self._cells)
        return sum(a.nbytes for a in held)

    @property
    def wire_centres_m(self) -> np.ndarray:
        """`(M, 3)` centres of the voxels held to be wire (votes >= gamma), world NED, m."""
        return self._centres

    def insert(
        self,
        slot: int,
        keyframe: bool,
        world_from_camera: Pose,
        flags: np.ndarray,
        voters: np.ndarray,
    ) -> None:
        """One view's `thin_wire_cells` on the grid of `camera`, taken from
        `world_from_camera`, into pose-graph `slot`; `voters`: the other slots holding wire
        views."""
        camera_from_world = world_from_camera.inverse()
        k = self.camera.intrinsic_matrix()
        self._flags[slot] = flags
        self._projection[slot] = k @ camera_from_world.rotation
        self._offset[slot] = k @ camera_from_world.translation_m
        old = self._count
        v, u = np.nonzero(flags & RAY)
        rays = self.camera.rays(np.stack([u, v], axis=-1).astype(np.float64))
        samples = world_from_camera.apply(
            (rays[:, None, :] * self._depths[None, :, None]).reshape(-1, 3)
        )
        self._reserve(old + len(samples))
        self._count = _add_candidates(
            self._table, self._keys, self._votes, old, samples, self.voxel_m
        )
        self._vote(self._votes, old, self._count, voters)
        this = np.array([slot], np.intp)
        if keyframe:
            self._vote(self._votes, 0, self._count, this)
            votes = self._votes[: self._count]
        else:
            votes = self._votes[: self._count].copy()
            self._vote(votes, 0, self._count, this)
        wire = votes >= self.gamma
        keep = wire | (self._votes[: self._count] >= self.gamma)
        centres = _centres(self._keys[: self._count][wire], self.voxel_m)
        wire_votes = votes[wire]
        if not keep.all():
            self._count = _keep(self._keys, self._votes, keep, self._count)
            _rehash(self._table, self._keys, self._count)
        self._use(centres, wire_votes)

    def _use(self, centres: np.ndarray, votes: np.ndarray) -> None:
        """Answer queries from these wire voxels."""
        self._centres, self._wire_votes = centres, votes
        self._cells = _cell_lists(centres, self.radius_m)

    def _vote(self, votes: np.ndarray, first: int, count: int, slots: np.ndarray) -> None:
        _vote(
            self._keys, votes, first, count, self.voxel_m, self._projection, self._offset,
            np.asarray(slots, np.intp), self._flags, *self._vote_args,
        )  # fmt: skip

    def _reserve(self, count: int) -> None:
        """Room for `count` voxels, the hash table at most half full."""
        if count <= len(self._keys):
            return
        size = 1 << int(np.ceil(np.log2(count)))
        self._keys = np.resize(self._keys, size)
        self._votes = np.resize(self._votes, size)
        self._table = np.full(2 * size, _EMPTY, np.int64)
        _rehash(self._table, self._keys, self._count)

    def occupancy(self, points_ned_m: np.ndarray) -> np.ndarray:
        """`(N,) float32`: the votes of a wire voxel within reach of each point, else 0."""
        points = np.asarray(points_ned_m, np.float64).reshape(-1, 3)
        if not len(self._centres) or not len(points):
            return np.zeros(len(points), np.float32)
        return _votes_within(
            points, self._centres, self._wire_votes, *self._cells, self.radius_m, self.radius_m
        )
