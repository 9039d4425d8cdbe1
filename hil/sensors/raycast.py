"""Vectorised ray casting of a `World`'s ground, solids and calibration boards (no wires).

Frames: world NED, camera x right / y down / z forward. Each pixel's ray has camera-z
component 1, so the ray parameter t is the pixel's camera depth. The ground is a ray-plane
intersection, solids the slab test restricted to the pixels of their projected bounding
rectangle, boards a plane with a pattern.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geometry.camera import PinholeCamera
from geometry.pose import Pose
from hil.world.model import World

NEAR_M = 0.05
SKY = -1
GROUND = 0


@dataclass(frozen=True, slots=True)
class SceneHits:
    """What each pixel's ray hits first (wires excluded); all `(H, W)`.

    depth_m: float32 camera-z depth, inf = nothing (sky).
    surface: int32, SKY (-1), GROUND (0), 1 + k for solid k, 1 + len(solids) + j for board j.
    axis: int8 the NED axis of the hit face's normal (0 north, 1 east, 2 down).
    sign: int8 the normal's sign along `axis` (it faces the camera).
    board_black: bool, on a board's black square.
    direction_planes: `(3, H, W) float32` world ray directions (camera-z component 1).
    origin_ned_m: `(3,)` the camera centre.
    """

    depth_m: np.ndarray
    surface: np.ndarray
    axis: np.ndarray
    sign: np.ndarray
    board_black: np.ndarray
    direction_planes: np.ndarray
    origin_ned_m: np.ndarray

    def directions(self, which: np.ndarray) -> np.ndarray:
        """`(K, 3) float32` ray directions of the pixels selected by `(H, W) bool` `which`."""
        return self.direction_planes[:, which].T


def box_pixel_rects(
    camera: PinholeCamera, camera_from_world: Pose, lo: np.ndarray, hi: np.ndarray
) -> np.ndarray:
    """`(S, 4) int` pixel rectangles (u0, u1, v0, v1) bounding the projections of `(S, 3)`
    boxes `lo`..`hi`; empty rectangles (u0 >= u1) for boxes out of view."""
    picks = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
    corners = np.where(picks[None] == 0, lo[:, None, :], hi[:, None, :])  # (S, 8, 3)
    pc = camera_from_world.apply(corners.reshape(-1, 3)).reshape(-1, 8, 3)
    z = pc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = camera.fx_px * pc[..., 0] / z + camera.cx_px
        v = camera.fy_px * pc[..., 1] / z + camera.cy_px
    w, h = camera.width_px, camera.height_px
    rects = np.stack(
        [
            np.floor(u.min(axis=1)) - 1,
            np.ceil(u.max(axis=1)) + 2,
            np.floor(v.min(axis=1)) - 1,
            np.ceil(v.max(axis=1)) + 2,
        ],
        axis=1,
    )
    straddles = (z <= NEAR_M).any(axis=1)
    rects[straddles] = [0, w, 0, h]
    rects[(z <= NEAR_M).all(axis=1)] = [0, 0, 0, 0]
    rects = np.nan_to_num(rects, nan=0.0, posinf=1e6, neginf=-1e6)
    rects[:, 0:2] = np.clip(rects[:, 0:2], 0, w)
    rects[:, 2:4] = np.clip(rects[:, 2:4], 0, h)
    return rects.astype(np.int64)


def _cast_faces(
    world: World,
    camera: PinholeCamera,
    world_from_cam: Pose,
    planes: np.ndarray,
    inverse: np.ndarray,
    depth: np.ndarray,
    surface: np.ndarray,
    axis: np.ndarray,
    sign: np.ndarray,
) -> None:
    """Intersect every solid's faces that face the camera (at most three per box: a ray
    from outside enters a box through one of them) inside the face's projected rectangle,
    keeping the nearest hit per pixel; updates the `(H, W)` arrays in place."""
    origin = world_from_cam.translation_m
    lo = np.array([s.box.min_ned_m for s in world.solids]) - origin
    hi = np.array([s.box.max_ned_m for s in world.solids]) - origin
    faces = []  # (solid, axis, plane offset from the camera, outward normal sign)
    for a in range(3):
        for k in np.flatnonzero(lo[:, a] > 0):
            faces.append((k, a, lo[k, a], -1))
        for k in np.flatnonzero(hi[:, a] < 0):
            faces.append((k, a, hi[k, a], 1))
    if not faces:
        return
    solid_of = np.array([f[0] for f in faces])
    axis_of = np.array([f[1] for f in faces])
    plane_of = np.array([f[2] for f in faces])
    face_lo, face_hi = lo[solid_of].copy(), hi[solid_of].copy()
    rows = np.arange(len(faces))
    face_lo[rows, axis_of] = plane_of
    face_hi[rows, axis_of] = plane_of
    rects = box_pixel_rects(camera, world_from_cam.inverse(), face_lo + origin, face_hi + origin)
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)
    for f in np.flatnonzero((rects[:, 0] < rects[:, 1]) & (rects[:, 2] < rects[:, 3])):
        k, a, plane, normal = faces[f]
        u0, u1, v0, v1 = rects[f]
        window = (slice(v0, v1), slice(u0, u1))
        b, c = (a + 1) % 3, (a + 2) % 3
        with np.errstate(invalid="ignore"):
            t = np.float32(plane) * inverse[a][window]
            pb = t * planes[b][window]
            pc = t * planes[c][window]
            sub_depth = depth[window]
            hit = (t > 0) & (t < sub_depth)
            hit &= (pb >= lo32[k, b]) & (pb <= hi32[k, b]) & (pc >= lo32[k, c]) & (pc <= hi32[k, c])
        if not hit.any():
            continue
        np.copyto(sub_depth, t, where=hit)
        surface[window][hit] = 1 + k
        axis[window][hit] = a
        sign[window][hit] = normal


def cast(
    world: World, camera: PinholeCamera, world_from_cam: Pose, pixel_planes: np.ndarray
) -> SceneHits:
    """Ray-cast `world` for every pixel of `camera` at `world_from_cam`; `pixel_planes` is
    the camera's `(2, H, W) float32` ray slopes ((u - cx) / fx, (v - cy) / fy)."""
    origin = world_from_cam.translation_m
    r = world_from_cam.rotation.astype(np.float32)
    x, y = pixel_planes
    planes = np.stack([r[i, 0] * x + r[i, 1] * y + r[i, 2] for i in range(3)])
    h, w = camera.shape
    depth = np.full((h, w), np.inf, np.float32)
    surface = np.full((h, w), SKY, np.int32)
    axis = np.full((h, w), 2, np.int8)
    sign = np.full((h, w), -1, np.int8)
    dz = planes[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = np.float32(world.ground_down_m - origin[2]) / dz
        inverse = 1.0 / planes
    ground = (dz > 1e-9) & (t_ground > 0)
    depth[ground] = t_ground[ground]
    surface[ground] = GROUND
    if world.solids:
        _cast_faces(world, camera, world_from_cam, planes, inverse, depth, surface, axis, sign)
    board_black = np.zeros((h, w), bool)
    first_board = 1 + len(world.solids)
    for j, board in enumerate(world.boards):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (board.north_m - origin[0]) * inverse[0]
        east = origin[1] + t * planes[1]
        down = origin[2] + t * planes[2]
        cols, rows = board.squares
        i = np.floor((east - board.east_m) / board.square_m)
        jj = np.floor((down - board.down_m) / board.square_m)
        hit = (t > 0) & (t < depth) & (i >= -1) & (i <= cols) & (jj >= -1) & (jj <= rows)
        hit &= planes[0] > 0
        margin = (i < 0) | (i >= cols) | (jj < 0) | (jj >= rows)
        black = ((i + jj) % 2 == 0) & ~margin
        depth[hit] = t[hit]
        surface[hit] = first_board + j
        axis[hit] = 0
        sign[hit] = -1
        board_black[hit] = black[hit]
    return SceneHits(depth, surface, axis, sign, board_black, planes, origin)
