"""The simulation experiments of thesis 3.4.1: synthetic keyframes of a known catenary.

Random camera placement (a look-at point on the wire, an equal-area random viewing direction,
a random distance) and avoidance placement (viewing directions within a small solid angle
around the wire's horizontal normal, as when flying head-on at it), 2, 4 or N cameras,
curved or near-straight wires, plus the degenerate two-camera avoidance case of Fig. 3.10
(baseline parallel to a near-straight wire). Masks are rendered by projecting the true
curve with the shared pinhole camera and drawing it with OpenCV. Deterministic from a seed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from geometry.camera import PinholeCamera
from geometry.pose import Pose
from geometry.shapes import distance_to_polyline_m
from mapping.catenary.fit import CatenaryFit
from mapping.catenary.model import catenary_points_ned_m, sag_height_m, sample_abscissae_m
from mapping.catenary.obstacle import projected_curve_mask
from mapping.catenary.residuals import CatenaryViews, views_from_keyframes
from mapping.catenary.uncertainty import theta_from_inverse_depth

Placement = Literal["random", "avoidance"]
DOWN_NED = np.array([0.0, 0.0, 1.0])
WIRE_THICKNESS_PX = 2


def sim_camera() -> PinholeCamera:
    """A 640 x 480 camera with a ~70 deg horizontal field of view."""
    return PinholeCamera(
        fx_px=460.0, fy_px=460.0, cx_px=319.5, cy_px=239.5, width_px=640, height_px=480
    )


def look_at_pose(position_ned_m: np.ndarray, target_ned_m: np.ndarray) -> Pose:
    """World-from-camera pose at `position` looking at `target`, camera y as close to down."""
    forward = target_ned_m - position_ned_m
    forward = forward / np.linalg.norm(forward)
    right = np.cross(DOWN_NED, forward)
    if np.linalg.norm(right) < 1e-6:
        right = np.array([0.0, 1.0, 0.0])
    right = right / np.linalg.norm(right)
    down = np.cross(forward, right)
    return Pose(rotation=np.stack((right, down, forward), axis=1), translation_m=position_ned_m)


def fraction_in_image(
    camera: PinholeCamera, world_from_camera: Pose, points_ned_m: np.ndarray
) -> float:
    """Fraction of `(K, 3)` NED points in front of the camera and inside its image."""
    points_cam_m = world_from_camera.inverse().apply(points_ned_m)
    in_front = points_cam_m[:, 2] > 0.0
    uv_px, _ = camera.project(np.where(in_front[:, None], points_cam_m, 1.0))
    inside = (
        (uv_px[:, 0] >= 0)
        & (uv_px[:, 0] <= camera.width_px - 1)
        & (uv_px[:, 1] >= 0)
        & (uv_px[:, 1] <= camera.height_px - 1)
    )
    return float(np.mean(in_front & inside))


@dataclass(frozen=True, slots=True)
class SimScenario:
    """Keyframes of one simulated wire: truth, poses, rendered masks and their times."""

    theta_true: np.ndarray
    poses: list[Pose]
    masks: list[np.ndarray]
    stamps_s: np.ndarray

    def views(self, camera: PinholeCamera) -> CatenaryViews:
        """The keyframes as `CatenaryViews`."""
        return views_from_keyframes(camera, self.poses, self.masks, self.stamps_s)


def random_wire(rng: np.random.Generator, straight: bool) -> np.ndarray:
    """True Theta: vertex near the origin 10 m up, random yaw, curved or near-straight sag."""
    a_m = rng.uniform(1000.0, 5000.0) if straight else rng.uniform(10.0, 40.0)
    vertex = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), -10.0 + rng.uniform(-1, 1)])
    return np.array([*vertex, rng.uniform(-np.pi, np.pi), a_m])


def _viewing_direction(rng: np.random.Generator, wire_theta: np.ndarray, placement: Placement):
    """Unit direction from the look-at point towards the camera, NED."""
    if placement == "random":
        # Equal-area cylindrical projection: uniform height and azimuth.
        z = rng.uniform(-1.0, 1.0)
        azimuth = rng.uniform(-np.pi, np.pi)
        r = np.sqrt(1.0 - z**2)
        return np.array([r * np.cos(azimuth), r * np.sin(azimuth), z])
    normal_yaw = wire_theta[3] + np.pi / 2 + rng.uniform(-0.25, 0.25)
    elevation = rng.uniform(-0.15, 0.15)
    return np.array(
        [
            np.cos(elevation) * np.cos(normal_yaw),
            np.cos(elevation) * np.sin(normal_yaw),
            np.sin(elevation),
        ]
    )


def random_scenario(
    rng: np.random.Generator,
    camera: PinholeCamera,
    n_cameras: int,
    placement: Placement,
    straight: bool,
    half_span_m: float,
    wire_half_span_m: float | None = None,
) -> SimScenario:
    """A scenario of 3.4.1 with cameras 1-2.5 spans away from the wire.

    half_span_m: the fitted span (3.3.1). wire_half_span_m: the true wire's half length;
    None: the same, and every camera then sees the whole wire (the thesis' known width).
    A longer wire only has to be in view (>= 100 px), as a real wire rarely ends in view.
    """
    long_wire = wire_half_span_m is not None
    theta = random_wire(rng, straight)
    dense = catenary_points_ned_m(
        theta, sample_abscissae_m(wire_half_span_m if long_wire else half_span_m, 4000)
    )
    window = catenary_points_ned_m(theta, sample_abscissae_m(half_span_m, 200))
    poses, masks = [], []
    while len(poses) < n_cameras:
        look_at_m = catenary_points_ned_m(theta, np.array([rng.uniform(-0.5, 0.5) * half_span_m]))[
            0
        ]
        distance_m = rng.uniform(1.0, 2.5) * 2.0 * half_span_m
        position = look_at_m + distance_m * _viewing_direction(rng, theta, placement)
        pose = look_at_pose(position, look_at_m)
        if long_wire:
            mask = projected_curve_mask(camera, pose, dense, WIRE_THICKNESS_PX)
            if fraction_in_image(camera, pose, window) < 0.5 or mask.sum() < 100:
                continue
        elif fraction_in_image(camera, pose, dense) < 1.0:
            continue
        else:
            mask = projected_curve_mask(camera, pose, dense, WIRE_THICKNESS_PX)
        poses.append(pose)
        masks.append(mask)
    return SimScenario(theta, poses, masks, np.arange(n_cameras, dtype=float))


def degenerate_two_camera_scenario(camera: PinholeCamera, half_span_m: float) -> SimScenario:
    """Fig. 3.10: two head-on views of a near-straight wire, baseline parallel to the wire.

    Every epipolar line then runs along the wire, so its depth is unobservable: the loss
    still goes to zero, but at a wrong depth.
    """
    theta = np.array([0.0, 0.0, -10.0, 0.0, 3000.0])
    dense = catenary_points_ned_m(theta, sample_abscissae_m(half_span_m, 2000))
    along = np.array([np.cos(theta[3]), np.sin(theta[3]), 0.0])
    normal = np.array([-np.sin(theta[3]), np.cos(theta[3]), 0.0])
    poses = []
    for offset_m in (0.0, 1.0):
        position = theta[:3] + 12.0 * normal + offset_m * along + np.array([0.0, 0.0, 1.5])
        poses.append(look_at_pose(position, position - normal + np.array([0.0, 0.0, -0.1])))
    masks = [projected_curve_mask(camera, pose, dense, WIRE_THICKNESS_PX) for pose in poses]
    return SimScenario(theta, poses, masks, np.arange(2, dtype=float))


def frustum_initialisation(
    rng: np.random.Generator, views: CatenaryViews, depth_near_m: float, depth_far_m: float
) -> np.ndarray:
    """A random Theta whose vertex lies inside view 0's frustum within [near, far] m."""
    camera = views.camera
    psi = np.array(
        [
            rng.uniform(0.0, camera.width_px - 1.0),
            rng.uniform(0.0, camera.height_px - 1.0),
            1.0 / rng.uniform(depth_near_m, depth_far_m),
            rng.uniform(-np.pi, np.pi),
            np.exp(rng.uniform(np.log(10.0), np.log(3000.0))),
        ]
    )
    return theta_from_inverse_depth(psi, views)


def curve_error_m(theta_fit: np.ndarray, theta_true: np.ndarray, half_span_m: float) -> float:
    """Symmetric mean closest-point distance between the two sampled curves, m."""
    x_cat = sample_abscissae_m(half_span_m, 200)
    fit = catenary_points_ned_m(theta_fit, x_cat)
    true = catenary_points_ned_m(theta_true, x_cat)
    distances = np.linalg.norm(fit[:, None, :] - true[None, :, :], axis=2)
    return float(0.5 * (distances.min(axis=0).mean() + distances.min(axis=1).mean()))


def sag_error_m(theta_fit: np.ndarray, theta_true: np.ndarray, half_span_m: float) -> float:
    """Error of the sag height at the span end, |a(cosh(h/a) - 1)| fit vs true, m."""
    return float(
        abs(sag_height_m(half_span_m, theta_fit[4]) - sag_height_m(half_span_m, theta_true[4]))
    )


@dataclass(frozen=True, slots=True)
class MultiWireScenario:
    """Keyframes of several wires: `(W, 5)` true Thetas, poses, union masks and times."""

    thetas_true: np.ndarray
    poses: list[Pose]
    masks: list[np.ndarray]
    stamps_s: np.ndarray


def approach_scenario(
    rng: np.random.Generator,
    camera: PinholeCamera,
    thetas: np.ndarray,
    n_cameras: int,
    half_span_m: float,
    start_distance_m: float = 25.0,
    end_distance_m: float = 15.0,
) -> MultiWireScenario:
    """A head-on approach flight towards the wires `(W, 5)` (all with about the same yaw).

    The camera flies along the horizontal normal of the first wire from `start_distance_m`
    to `end_distance_m`, weaving up to 2 m sideways and 1 m up or down (a pure approach
    leaves the depth along the wire nearly unobservable), looking ahead.
    """
    normal = np.array([-np.sin(thetas[0, 3]), np.cos(thetas[0, 3]), 0.0])
    centre = thetas[:, :3].mean(axis=0)
    along = np.array([np.cos(thetas[0, 3]), np.sin(thetas[0, 3]), 0.0])
    poses = []
    for distance_m in np.linspace(start_distance_m, end_distance_m, n_cameras):
        jitter = rng.uniform(-2.0, 2.0) * along + rng.uniform(-1.0, 1.0) * DOWN_NED
        position = centre + distance_m * normal + jitter
        poses.append(look_at_pose(position, position - normal))
    x_cat = sample_abscissae_m(half_span_m, 2000)
    masks = [
        np.any(
            [
                projected_curve_mask(
                    camera, pose, catenary_points_ned_m(theta, x_cat), WIRE_THICKNESS_PX
                )
                for theta in thetas
            ],
            axis=0,
        )
        for pose in poses
    ]
    return MultiWireScenario(thetas, poses, masks, np.arange(n_cameras, dtype=float))


def observed_curve_error_m(
    fit: CatenaryFit, theta_true: np.ndarray, wire_half_span_m: float
) -> float:
    """Mean distance of the fit's observed samples to the true wire (any length), m."""
    dense = catenary_points_ned_m(theta_true, sample_abscissae_m(wire_half_span_m, 4000))
    distance_m, _, _ = distance_to_polyline_m(fit.observed_points_ned_m, dense)
    return float(distance_m.mean()) if distance_m.size else float("inf")


def cnn_like_mask(
    rng: np.random.Generator, mask: np.ndarray, gaps: int = 3, blobs: int = 4
) -> np.ndarray:
    """A rendered wire mask made to look like a CNN segmentation (ch. 2): 4 px thick,
    `gaps` missed stretches of about 8 x 12 px, `blobs` false positives up to 7 x 7 px."""
    noisy = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    rows, cols = np.nonzero(noisy)
    for k in rng.integers(len(rows), size=gaps):
        noisy[max(rows[k] - 6, 0) : rows[k] + 6, max(cols[k] - 4, 0) : cols[k] + 4] = False
    height_px, width_px = mask.shape
    for _ in range(blobs):
        r, c = rng.integers(0, height_px - 8), rng.integers(0, width_px - 8)
        noisy[r : r + rng.integers(2, 8), c : c + rng.integers(2, 8)] = True
    return noisy
