"""Simulated stereo + colour camera of the SIL harness: vectorised ray casting of `hil.world`.

Frames: world NED, body FRD, camera x right / y down / z forward (`mapping.pose`). Rays are
cast per pixel with analytic ray-plane and ray-box (slab) intersections; a box is only tested
for the pixels inside its projected bounding rectangle. Wires are thin tubes: each short
polyline segment is projected and drawn (anti-aliased, painter's order far to near) with its
apparent width, so sub-pixel wires appear as faint partial-coverage lines as in real images.

Outputs per frame (`CameraFrame`): the disparity image (eq. 4.1, NaN never, 0 = no return or
beyond `max_range_m`, plus N(0, sigma^2) noise; wires only where at least
`stereo_min_wire_width_px` wide, since stereo misses thin wires), the colour image, the
ground-truth wire mask and depth. Deterministic: the noise is drawn from (seed, stamp).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from hil.camera_params import CameraSimParams
from hil.multirotor import VehicleState
from hil.world import World
from mapping.camera import PinholeCamera, StereoRig, world_from_camera
from mapping.pose import Pose

_NEAR_M = 0.05
_SUBPIXEL_BITS = 4


@dataclass(frozen=True, slots=True)
class CameraFrame:
    """One simulated exposure; images are `(H, W)` in the rectified left camera.

    disparity_px: float32, px (0 = no return). image_bgr: uint8 (H, W, 3). wire_mask: bool.
    depth_m: float32 ground-truth camera-z depth of the scene without wires, inf = no return.
    """

    stamp_s: float
    world_from_body: Pose
    world_from_camera: Pose
    disparity_px: np.ndarray
    image_bgr: np.ndarray
    wire_mask: np.ndarray
    depth_m: np.ndarray


@dataclass(frozen=True, slots=True)
class SceneRender:
    """Ray-cast scene without wires: depth (inf = sky), grey shade in [0, 1], surface class
    (0 sky, 1 ground, 2 box) per pixel."""

    depth_m: np.ndarray
    shade: np.ndarray
    surface: np.ndarray


def _box_pixel_rect(
    camera: PinholeCamera, camera_from_world: Pose, lo: np.ndarray, hi: np.ndarray
) -> tuple[int, int, int, int] | None:
    """Pixel rectangle (u0, u1, v0, v1) that bounds a box's projection; None if off-screen."""
    corners = np.array(np.meshgrid(*zip(lo, hi, strict=True), indexing="ij")).reshape(3, -1).T
    pc = camera_from_world.apply(corners)
    if np.all(pc[:, 2] <= _NEAR_M):
        return None
    if np.any(pc[:, 2] <= _NEAR_M):
        return 0, camera.width_px, 0, camera.height_px
    uv, _ = camera.project(pc)
    u0, v0 = np.floor(uv.min(axis=0)).astype(int) - 1
    u1, v1 = np.ceil(uv.max(axis=0)).astype(int) + 2
    u0, u1 = max(u0, 0), min(u1, camera.width_px)
    v0, v1 = max(v0, 0), min(v1, camera.height_px)
    if u0 >= u1 or v0 >= v1:
        return None
    return u0, u1, v0, v1


def render_scene(
    world: World, camera: PinholeCamera, world_from_cam: Pose, texture_cell_m: float
) -> SceneRender:
    """Ray-cast ground and boxes (no wires) for every pixel of `camera` at `world_from_cam`."""
    origin = world_from_cam.translation_m
    # unnormalised rays with camera-z component 1: the ray parameter t is the camera depth
    directions = world_from_cam.rotate(camera.pixel_rays().reshape(-1, 3)).reshape(
        camera.height_px, camera.width_px, 3
    )
    h, w = camera.shape
    depth = np.full((h, w), np.inf)
    normal_axis = np.full((h, w), -1, dtype=np.int8)
    albedo = np.zeros((h, w))
    surface = np.zeros((h, w), np.uint8)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = (world.ground_down_m - origin[2]) / directions[..., 2]
    ground = (directions[..., 2] > 1e-9) & (t_ground > 0)
    depth[ground] = t_ground[ground]
    normal_axis[ground] = 2
    albedo[ground] = 0.55
    surface[ground] = 1
    camera_from_world = world_from_cam.inverse()
    for box in world.boxes:
        rect = _box_pixel_rect(camera, camera_from_world, box.min_ned_m, box.max_ned_m)
        if rect is None:
            continue
        u0, u1, v0, v1 = rect
        d = directions[v0:v1, u0:u1]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
            t1 = (box.min_ned_m - origin) * inv
            t2 = (box.max_ned_m - origin) * inv
        near = np.nan_to_num(np.minimum(t1, t2), nan=-np.inf)
        far = np.nan_to_num(np.maximum(t1, t2), nan=np.inf)
        t_in, t_out = near.max(axis=-1), far.min(axis=-1)
        sub_depth = depth[v0:v1, u0:u1]
        hit = (t_in <= t_out) & (t_in > 0) & (t_in < sub_depth)
        sub_depth[hit] = t_in[hit]
        normal_axis[v0:v1, u0:u1][hit] = np.argmax(near, axis=-1)[hit]
        albedo[v0:v1, u0:u1][hit] = box.albedo
        surface[v0:v1, u0:u1][hit] = 2
    board_shade = np.full((h, w), np.nan)
    for board in world.boards:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (board.north_m - origin[0]) / directions[..., 0]
        east = origin[1] + t * directions[..., 1]
        down = origin[2] + t * directions[..., 2]
        cols, rows = board.squares
        i = np.floor((east - board.east_m) / board.square_m)
        j = np.floor((down - board.down_m) / board.square_m)
        hit = (t > 0) & (t < depth) & (i >= -1) & (i <= cols) & (j >= -1) & (j <= rows)
        hit &= directions[..., 0] > 0
        margin = (i < 0) | (i >= cols) | (j < 0) | (j >= rows)
        black = ((i + j) % 2 == 0) & ~margin
        depth[hit] = t[hit]
        normal_axis[hit] = 0
        surface[hit] = 2
        board_shade[hit] = np.where(black, 0.08, 0.92)[hit]
    points = origin + directions * np.where(np.isfinite(depth), depth, 0.0)[..., None]
    table = world.texture_table()
    cells = np.floor(points / texture_cell_m).astype(np.int64) & 255
    # texture coordinates: the two axes tangent to the surface
    axis_a = np.where(normal_axis == 0, 1, 0)
    axis_b = np.where(normal_axis == 2, 1, 2)
    ca = np.take_along_axis(cells, axis_a[..., None].astype(np.int64), axis=-1)[..., 0]
    cb = np.take_along_axis(cells, axis_b[..., None].astype(np.int64), axis=-1)[..., 0]
    texture = table[ca, cb]
    facing = np.array([0.85, 0.7, 1.0])[np.clip(normal_axis, 0, 2)]
    shade = albedo * facing * (0.45 + 0.55 * texture)
    on_board = np.isfinite(board_shade)
    shade[on_board] = board_shade[on_board]
    elevation = -directions[..., 2] / np.linalg.norm(directions, axis=-1)
    sky = ~np.isfinite(depth)
    shade[sky] = (0.75 + 0.2 * np.clip(elevation, 0, 1))[sky]
    return SceneRender(depth.astype(np.float32), shade.astype(np.float32), surface)


@dataclass(frozen=True, slots=True)
class WireRender:
    """Wires drawn over a scene: coverage in [0, 1], their depth (inf where none), and the
    depth of only the wires wide enough for stereo (inf elsewhere); all `(H, W) float32`."""

    coverage: np.ndarray
    depth_m: np.ndarray
    stereo_depth_m: np.ndarray


def render_wires(
    world: World, camera: PinholeCamera, world_from_cam: Pose, stereo_min_width_px: float
) -> WireRender:
    """Project and draw every wire segment (painter's order, far to near), see module doc."""
    h, w = camera.shape
    coverage = np.zeros((h, w), np.uint8)
    depth = np.full((h, w), np.inf, np.float32)
    stereo_depth = np.full((h, w), np.inf, np.float32)
    camera_from_world = world_from_cam.inverse()
    segments = []
    for wire in world.wires:
        pc = camera_from_world.apply(wire.sample(0.25))
        a, b = pc[:-1], pc[1:]
        keep = (a[:, 2] > _NEAR_M) | (b[:, 2] > _NEAR_M)
        a, b = a[keep], b[keep]
        # clip segments to the near plane
        for p, q in ((a, b), (b, a)):
            behind = p[:, 2] <= _NEAR_M
            s = (_NEAR_M - p[behind, 2]) / (q[behind, 2] - p[behind, 2])
            p[behind] = p[behind] + s[:, None] * (q[behind] - p[behind])
        z_mid = 0.5 * (a[:, 2] + b[:, 2])
        width_px = 2.0 * wire.radius_m * camera.fx_px / z_mid
        segments.append((a, b, z_mid, width_px))
    if not segments:
        return WireRender(coverage.astype(np.float32), depth, stereo_depth)
    a = np.concatenate([s[0] for s in segments])
    b = np.concatenate([s[1] for s in segments])
    z_mid = np.concatenate([s[2] for s in segments])
    width_px = np.concatenate([s[3] for s in segments])
    uv_a, _ = camera.project(a)
    uv_b, _ = camera.project(b)
    scale = 1 << _SUBPIXEL_BITS
    limit = 8 * max(h, w) * scale
    pa = np.clip(np.round(uv_a * scale), -limit, limit).astype(np.int64)
    pb = np.clip(np.round(uv_b * scale), -limit, limit).astype(np.int64)
    for i in np.argsort(-z_mid):
        thickness = max(round(float(width_px[i])), 1)
        intensity = round(255 * min(float(width_px[i]), 1.0))
        p0, p1 = tuple(int(x) for x in pa[i]), tuple(int(x) for x in pb[i])
        cv2.line(coverage, p0, p1, intensity, thickness, cv2.LINE_AA, _SUBPIXEL_BITS)
        cv2.line(depth, p0, p1, float(z_mid[i]), thickness, cv2.LINE_8, _SUBPIXEL_BITS)
        if width_px[i] >= stereo_min_width_px:
            cv2.line(stereo_depth, p0, p1, float(z_mid[i]), thickness, cv2.LINE_8, _SUBPIXEL_BITS)
    depth[coverage == 0] = np.inf
    return WireRender(coverage.astype(np.float32) / 255.0, depth, stereo_depth)


class SimulatedStereoCamera:
    """Renders `CameraFrame`s of a `World` for vehicle poses (a camera source for SIL)."""

    def __init__(
        self, world: World, rig: StereoRig, body_from_camera: Pose, params: CameraSimParams
    ) -> None:
        self.world = world
        self.rig = rig
        self.body_from_camera = body_from_camera
        self.params = params

    def render(self, stamp_s: float, world_from_body: Pose) -> CameraFrame:
        """The frame exposed at `stamp_s` (s) with the vehicle at `world_from_body`."""
        camera = self.rig.camera
        pose = world_from_camera(world_from_body, self.body_from_camera)
        scene = render_scene(self.world, camera, pose, self.params.texture_cell_m)
        wires = render_wires(self.world, camera, pose, self.params.stereo_min_wire_width_px)
        visible = wires.depth_m < scene.depth_m
        wire_mask = visible & (wires.coverage >= self.params.wire_mask_min_coverage)
        stereo_depth = np.minimum(scene.depth_m, wires.stereo_depth_m)
        rng = np.random.default_rng([self.params.seed, round(stamp_s * 1e6)])
        noise = rng.normal(0.0, self.params.disparity_noise_px, stereo_depth.shape)
        in_range = stereo_depth <= self.params.max_range_m
        disparity = np.where(
            in_range, self.rig.bf_px_m / np.where(in_range, stereo_depth, 1.0) + noise, 0.0
        )
        disparity = np.maximum(disparity, 0.0).astype(np.float32)
        image = self._colour(scene, np.where(visible, wires.coverage, 0.0))
        return CameraFrame(
            float(stamp_s), world_from_body, pose, disparity, image, wire_mask, scene.depth_m
        )

    def render_state(self, state: VehicleState) -> CameraFrame:
        """The frame exposed at the simulated vehicle's ground-truth state (`hil.multirotor`)."""
        world_from_body = Pose.from_quaternion(state.attitude_wxyz, state.position_ned_m)
        return self.render(state.time_s, world_from_body)

    def render_pair(self, world_from_body: Pose) -> tuple[np.ndarray, np.ndarray]:
        """Rectified `(H, W) uint8` grey left and right images (for SGBM and calibration)."""
        left_pose = world_from_camera(world_from_body, self.body_from_camera)
        right_pose = left_pose.compose(self.rig.left_from_right())
        images = []
        for pose in (left_pose, right_pose):
            scene = render_scene(self.world, self.rig.camera, pose, self.params.texture_cell_m)
            wires = render_wires(self.world, self.rig.camera, pose, np.inf)
            cover = np.where(wires.depth_m < scene.depth_m, wires.coverage, 0.0)
            grey = scene.shade * (1.0 - cover) + 0.08 * cover
            images.append(np.clip(grey * 255.0, 0, 255).astype(np.uint8))
        return images[0], images[1]

    @staticmethod
    def _colour(scene: SceneRender, wire_cover: np.ndarray) -> np.ndarray:
        """BGR uint8: blue sky, green-brown ground, grey boxes, dark wires."""
        tint = np.array([[0.95, 0.8, 0.65], [0.55, 0.75, 0.7], [0.9, 0.9, 0.9]], np.float32)
        bgr = scene.shade[..., None] * tint[scene.surface]
        bgr = bgr * (1.0 - wire_cover[..., None]) + 0.08 * wire_cover[..., None]
        return np.clip(bgr * 255.0, 0, 255).astype(np.uint8)
