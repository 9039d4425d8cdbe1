"""Pinhole camera, rectified stereo rig and camera extrinsics on the airframe (thesis 4.4.2).

Frames (see `geometry.pose`): camera x right, y down, z forward (optical axis); body FRD;
world NED. Pixel `(u, v)`: u the column (along camera x), v the row (along camera y), in
pixels, with pixel centres at integer coordinates (the OpenCV convention), so the image spans
`u in [-0.5, width - 0.5)`. A pixel index is `round(u)`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geometry.pose import Pose
from geometry.rotation import rotation_from_yaw_pitch_roll


@dataclass(frozen=True, slots=True)
class StereoCameraParams:
    """The rectified stereo camera and its mount (`MappingParams.camera`, the `mapping.camera_*`
    settings): image size, field of view or calibrated intrinsics, baseline, mount on the body."""

    width_px: int
    height_px: int
    hfov_deg: float
    baseline_m: float
    mount_position_body_m: tuple[float, float, float]
    mount_pitch_deg: float
    max_disparity_px: int
    intrinsics_px: tuple[float, float, float, float] | None = None
    mount_yaw_deg: float = 0.0
    mount_roll_deg: float = 0.0


# body_from_camera rotation of a camera looking straight ahead: camera z -> body x (forward),
# camera x -> body y (right), camera y -> body z (down). Columns are the camera axes in FRD.
BODY_FROM_CAMERA_AXES = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True, slots=True)
class PinholeCamera:
    """Ideal (rectified, undistorted) pinhole camera; focal lengths and centre in px."""

    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    width_px: int
    height_px: int

    @classmethod
    def from_hfov(cls, hfov_rad: float, width_px: int, height_px: int) -> PinholeCamera:
        """Square-pixel camera with the given horizontal field of view, centred principal point."""
        f = (width_px / 2.0) / np.tan(hfov_rad / 2.0)
        return cls(f, f, (width_px - 1) / 2.0, (height_px - 1) / 2.0, width_px, height_px)

    @property
    def shape(self) -> tuple[int, int]:
        """`(height_px, width_px)`, the numpy shape of an image."""
        return self.height_px, self.width_px

    def intrinsic_matrix(self) -> np.ndarray:
        """`(3, 3)` K matrix."""
        return np.array(
            [[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]]
        )

    def project(self, points_cam_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project `(N, 3)` camera-frame points (m) to `(N, 2)` pixels and `(N,)` depths z (m).

        Inverse of eq. 4.2. Points with z <= 0 (behind the camera) get NaN pixels; their depth
        is returned as is so callers can tell them apart.
        """
        p = np.asarray(points_cam_m, dtype=np.float64)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv_z = np.where(z > 0, 1.0 / z, np.nan)
        uv = np.stack(
            [
                self.fx_px * p[..., 0] * inv_z + self.cx_px,
                self.fy_px * p[..., 1] * inv_z + self.cy_px,
            ],
            axis=-1,
        )
        return uv, z

    def rays(self, uv_px: np.ndarray) -> np.ndarray:
        """`(N, 3)` ray directions with z = 1 through `(N, 2)` pixels, camera frame."""
        uv = np.asarray(uv_px, dtype=np.float64)
        return np.stack(
            [
                (uv[..., 0] - self.cx_px) / self.fx_px,
                (uv[..., 1] - self.cy_px) / self.fy_px,
                np.ones(uv.shape[:-1]),
            ],
            axis=-1,
        )

    def back_project(self, uv_px: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
        """`(N, 3)` camera-frame points P = (u z / f, v z / f, z) (eq. 4.2, centred pixels), m."""
        return self.rays(uv_px) * np.asarray(depth_m, dtype=np.float64)[..., None]

    def pixel_rays(self) -> np.ndarray:
        """`(H, W, 3)` z = 1 ray directions through every pixel centre, camera frame."""
        v, u = np.mgrid[0 : self.height_px, 0 : self.width_px].astype(np.float64)
        return self.rays(np.stack([u, v], axis=-1))

    def contains(self, uv_px: np.ndarray) -> np.ndarray:
        """`(N,)` bool: pixel inside the image (NaN pixels are outside)."""
        uv = np.asarray(uv_px, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            return (
                (uv[..., 0] >= -0.5)
                & (uv[..., 0] < self.width_px - 0.5)
                & (uv[..., 1] >= -0.5)
                & (uv[..., 1] < self.height_px - 0.5)
            )

    def scaled(self, factor: int) -> PinholeCamera:
        """The camera of images block-pooled by an integer `factor` (pixel block -> one pixel).

        Block `(i, j)` covers the original pixels `[factor i, factor (i + 1))` etc., so a point
        at original pixel u lands in block `floor((u + 0.5) / factor)`.
        """
        return PinholeCamera(
            self.fx_px / factor,
            self.fy_px / factor,
            (self.cx_px + 0.5) / factor - 0.5,
            (self.cy_px + 0.5) / factor - 0.5,
            -(-self.width_px // factor),
            -(-self.height_px // factor),
        )


@dataclass(frozen=True, slots=True)
class StereoRig:
    """Rectified stereo pair: the left `camera` is the reference; the right one sits
    `baseline_m` along the left camera's +x axis with the same intrinsics.
    """

    camera: PinholeCamera
    baseline_m: float

    @property
    def bf_px_m(self) -> float:
        """b f of eq. 4.1 (baseline times horizontal focal length), px m."""
        return self.baseline_m * self.camera.fx_px

    def depth_from_disparity(self, disparity_px: np.ndarray) -> np.ndarray:
        """z = b f / d (eq. 4.1), m; inf where d == 0, NaN where d is NaN or negative."""
        d = np.asarray(disparity_px, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(d >= 0, self.bf_px_m / d, np.nan)

    def disparity_from_depth(self, depth_m: np.ndarray) -> np.ndarray:
        """d = b f / z (eq. 4.1), px; 0 where z is inf, NaN where z <= 0 or NaN."""
        z = np.asarray(depth_m, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(z > 0, self.bf_px_m / z, np.nan)

    def left_from_right(self) -> Pose:
        """Pose of the right camera in the left camera frame."""
        return Pose(np.eye(3), np.array([self.baseline_m, 0.0, 0.0]))


def body_from_camera_mount(
    position_body_m: np.ndarray,
    yaw_rad: float = 0.0,
    pitch_rad: float = 0.0,
    roll_rad: float = 0.0,
) -> Pose:
    """Camera extrinsics on the airframe: `body_from_camera`.

    position_body_m: `(3,)` camera centre in body FRD, m.
    yaw/pitch/roll: mount angles of the camera relative to body FRD (Z-Y-X, rad); all zero is a
        camera looking along body +x with its image x along body +y; pitch > 0 tilts it up.
    """
    mount = rotation_from_yaw_pitch_roll(yaw_rad, pitch_rad, roll_rad)
    return Pose(mount @ BODY_FROM_CAMERA_AXES, np.asarray(position_body_m, dtype=np.float64))


def world_from_camera(world_from_body: Pose, body_from_camera: Pose) -> Pose:
    """Camera pose in NED from the vehicle pose (FRD in NED) and the camera extrinsics."""
    return world_from_body.compose(body_from_camera)


def stereo_rig_from_params(params: StereoCameraParams) -> StereoRig:
    """The configured stereo rig: the calibrated intrinsics when given, else square pixels and
    a centred principal point from the field of view."""
    if params.intrinsics_px is None:
        hfov_rad = np.deg2rad(params.hfov_deg)
        camera = PinholeCamera.from_hfov(hfov_rad, params.width_px, params.height_px)
    else:
        fx, fy, cx, cy = params.intrinsics_px
        camera = PinholeCamera(fx, fy, cx, cy, params.width_px, params.height_px)
    return StereoRig(camera, params.baseline_m)


def body_from_camera_from_params(params: StereoCameraParams) -> Pose:
    """The configured camera extrinsics `body_from_camera`."""
    return body_from_camera_mount(
        np.asarray(params.mount_position_body_m),
        yaw_rad=np.deg2rad(params.mount_yaw_deg),
        pitch_rad=np.deg2rad(params.mount_pitch_deg),
        roll_rad=np.deg2rad(params.mount_roll_deg),
    )
