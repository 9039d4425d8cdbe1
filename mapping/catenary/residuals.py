"""Distance-transform residuals of a catenary hypothesis over N keyframes (thesis eq. 3.4, 3.5).

Each keyframe's binarised wire segmentation is turned once into a normalised distance
transform D_i (distance to the nearest wire pixel divided by the image diagonal); a curve
sample projected to pixel p = (u, v) gets the residual D_i(p), looked up bilinearly inside
the image and extrapolated continuously outside it from the nearest boundary pixel p_b:
r = D_i(p_b) + |p - p_b| / sqrt(h^2 + w^2) (eq. 3.4, 3.5). Pixel u is the column (camera
x right), v the row (camera y down); the thesis writes them the other way round.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from geometry.camera import PinholeCamera
from geometry.pose import Pose


def wire_centreline(wire_mask: np.ndarray) -> np.ndarray:
    """`(h, w) bool` morphological skeleton (Lantuejoul) of a wire mask, cv2 only.

    A thick segmentation gives the distance transform a zero band as wide as the wire, in
    which a fit can sit anywhere; its skeleton puts the zero on the centre line instead.
    The union over k of erode^k(mask) minus its opening; the mask itself if that is empty.
    """
    kernel = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    eroded = wire_mask.astype(np.uint8)
    skeleton = np.zeros_like(eroded)
    while eroded.any():
        opened = cv2.morphologyEx(eroded, cv2.MORPH_OPEN, kernel)
        skeleton |= eroded & ~opened & 1
        eroded = cv2.erode(eroded, kernel)
    return skeleton.astype(bool) if skeleton.any() else wire_mask


def normalised_distance_transform(wire_mask: np.ndarray) -> np.ndarray:
    """`(h, w) float32` distance to the nearest wire pixel over the image diagonal (3.3.2).

    `wire_mask` is `(h, w) bool`, True on wire pixels; raises ValueError when it has none.
    OpenCV's Euclidean chamfer distance transform (Borgefors) with a 5x5 mask: the thesis'
    3x3 mask weighs axial steps 0.955, biasing distances (and the gradient) by 4.5%.
    """
    if not wire_mask.any():
        raise ValueError("a keyframe needs at least one wire pixel")
    height_px, width_px = wire_mask.shape
    background = np.where(wire_mask, 0, 255).astype(np.uint8)
    distance_px = cv2.distanceTransform(background, cv2.DIST_L2, cv2.DIST_MASK_5)
    return distance_px / np.float32(np.hypot(height_px, width_px))


@dataclass(frozen=True, slots=True)
class CatenaryViews:
    """N keyframes of one wire with known poses, ready for residual evaluation.

    camera: the shared `geometry.camera.PinholeCamera` (all keyframes come from one camera).
    rotation_cam_from_world: `(N, 3, 3)` R_ext, NED world to camera frame (eq. 3.22).
    translation_cam_from_world_m: `(N, 3)` T_ext, so P_C = R_ext P_W + T_ext, m.
    distance_fields: `(N, h, w)` normalised distance transforms D_i.
    stamps_s: `(N,)` sample times of the keyframes, s.
    wire_width_px: `(N,)` mean width of each view's wire pixels (`wire_width_px`), px.
    """

    camera: PinholeCamera
    rotation_cam_from_world: np.ndarray
    translation_cam_from_world_m: np.ndarray
    distance_fields: np.ndarray
    stamps_s: np.ndarray
    wire_width_px: np.ndarray

    @property
    def n_views(self) -> int:
        """N, the number of keyframes."""
        return self.distance_fields.shape[0]

    @property
    def diagonal_px(self) -> float:
        """sqrt(h^2 + w^2), the normaliser of eq. 3.4, px."""
        return float(np.hypot(*self.distance_fields.shape[1:]))

    def subset(self, indices: np.ndarray | Sequence[int]) -> CatenaryViews:
        """The views at `indices`, in that order."""
        idx = np.asarray(indices, dtype=int)
        return CatenaryViews(
            self.camera,
            self.rotation_cam_from_world[idx],
            self.translation_cam_from_world_m[idx],
            self.distance_fields[idx],
            self.stamps_s[idx],
            self.wire_width_px[idx],
        )


def views_from_keyframes(
    camera: PinholeCamera,
    world_from_camera_poses: Sequence[Pose],
    wire_masks: Sequence[np.ndarray],
    stamps_s: Sequence[float],
    thin: bool = True,
) -> CatenaryViews:
    """Stack keyframes into `CatenaryViews`; D_i is computed here, once per keyframe (3.3.2).

    world_from_camera_poses: `geometry.pose.Pose` per keyframe mapping camera-frame points to
    NED world points (its `rotation` (3, 3) and `translation_m` (3,)).
    wire_masks: `(h, w) bool` binarised segmentations, True on wire.
    thin: measure distances to each mask's centre line (`wire_centreline`), not its body.
    """
    rotations = np.stack([np.asarray(p.rotation, dtype=float) for p in world_from_camera_poses])
    positions = np.stack(
        [np.asarray(p.translation_m, dtype=float) for p in world_from_camera_poses]
    )
    rotation_cw = np.transpose(rotations, (0, 2, 1))
    translation_cw = -np.einsum("nij,nj->ni", rotation_cw, positions)
    fields = np.stack(
        [normalised_distance_transform(wire_centreline(m) if thin else m) for m in wire_masks]
    )
    widths = np.array([1.0 if thin else wire_width_px(m) for m in wire_masks])
    return CatenaryViews(
        camera, rotation_cw, translation_cw, fields, np.asarray(stamps_s, dtype=float), widths
    )


def wire_width_px(wire_mask: np.ndarray) -> float:
    """Wire pixel count over their extent along the principal axis, px (>= the true width).

    The distance transform is zero across the whole width, so a fit can sit anywhere in it;
    the uncertainty (eq. 3.39) uses this as the per-view spread of the curve's position.
    """
    rows, cols = np.nonzero(wire_mask)
    uv = np.stack((cols, rows), axis=1).astype(float)
    centred = uv - uv.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    return float(len(uv) / max(np.ptp(centred @ axes[0]) + 1.0, 1.0))


def points_in_cameras_m(views: CatenaryViews, points_ned_m: np.ndarray) -> np.ndarray:
    """`(N, M, 3)` P_C = R_ext P_W + T_ext for every view (eq. 3.22), camera frame, m."""
    return (
        np.matmul(views.rotation_cam_from_world, points_ned_m.T).transpose(0, 2, 1)
        + views.translation_cam_from_world_m[:, None, :]
    )


def clamped_pixels_px(
    views: CatenaryViews, points_cam_m: np.ndarray, min_depth_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Project `(N, M, 3)` camera points with the depth clamped to `min_depth_m` (eq. 3.18).

    Returns `(N, M, 2)` pixels (u column, v row) and the `(N, M) bool` mask of points whose
    depth was clamped (behind or too close to the camera: projected far off the image,
    so their extrapolated residual is large, with zero derivative in depth).
    """
    clamped = points_cam_m[..., 2] < min_depth_m
    safe = points_cam_m.copy()
    safe[..., 2] = np.maximum(safe[..., 2], min_depth_m)
    uv_px, _ = views.camera.project(safe.reshape(-1, 3))
    return np.asarray(uv_px, dtype=float).reshape((*safe.shape[:2], 2)), clamped


def distance_lookup(
    distance_fields: np.ndarray, uv_px: np.ndarray, exit_gate_px: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Residuals and their pixel gradients for `(N, M, 2)` pixels in N fields (eq. 3.4, 3.17).

    Inside the image: the bilinear interpolant of D_i and its exact derivative. Outside:
    D_i(p_b) + phi |p - p_b| / diag with p_b the pixel clamped to the image (eq. 3.5); the
    derivative includes D_i's slope along the boundary. Returns `(N, M)` and `(N, M, 2)`.

    exit_gate_px None: phi = 1, the thesis' extrapolation. Otherwise phi =
    min(1, D_i(p_b) diag / exit_gate_px): leaving the image where the observed wire leaves it
    costs nothing, so a wire longer than the image is not pulled into it (3.7.1); leaving it
    elsewhere is penalised as in eq. 3.4. Continuous, and differentiable almost everywhere.
    """
    n_views, height_px, width_px = distance_fields.shape
    diagonal_px = np.hypot(height_px, width_px)
    u_b = np.clip(uv_px[..., 0], 0.0, width_px - 1.0)
    v_b = np.clip(uv_px[..., 1], 0.0, height_px - 1.0)
    u0 = np.minimum(u_b.astype(np.intp), width_px - 2)
    v0 = np.minimum(v_b.astype(np.intp), height_px - 2)
    fu = u_b - u0
    fv = v_b - v0
    base = v0 * width_px + u0
    base += (np.arange(n_views) * (height_px * width_px))[:, None]
    flat = distance_fields.reshape(-1)
    d00 = flat[base]
    d01 = flat[base + 1]
    d10 = flat[base + width_px]
    d11 = flat[base + (width_px + 1)]
    slope_u_top = d01 - d00
    slope_u_bottom = d11 - d10
    top = d00 + fu * slope_u_top
    bottom = d10 + fu * slope_u_bottom
    boundary = top + fv * (bottom - top)
    du = uv_px[..., 0] - u_b
    dv = uv_px[..., 1] - v_b
    outside_px = np.hypot(du, dv)
    # Clamped coordinates do not move with p: their bilinear slope drops out (eq. 3.17).
    grad = np.empty(uv_px.shape)
    grad[..., 0] = np.where(du == 0.0, slope_u_top + fv * (slope_u_bottom - slope_u_top), 0.0)
    grad[..., 1] = np.where(dv == 0.0, bottom - top, 0.0)
    if exit_gate_px is None:
        phi = np.ones_like(boundary)
    else:
        ramp = boundary * (diagonal_px / exit_gate_px)
        phi = np.minimum(ramp, 1.0)
        grad *= (1.0 + outside_px / exit_gate_px * (ramp < 1.0))[..., None]
    value = boundary + phi * outside_px / diagonal_px
    scale = np.where(outside_px > 0.0, phi / np.maximum(outside_px, 1e-300) / diagonal_px, 0.0)
    grad[..., 0] += du * scale
    grad[..., 1] += dv * scale
    return value, grad
