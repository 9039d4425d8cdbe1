"""Synthetic wire images with pixel-exact masks (thesis 2.3.2), deterministic from (seed, index).

The thesis rendered wires with POV-Ray over flight-video frames. Here, in numpy + OpenCV:

1. A pinhole camera at a random pose: world NED (x north, y east, z down, ground at z = 0),
   body FRD rotated by yaw/pitch/roll, camera frame x right / y down / z forward.
2. Wire bundles in 3D: catenaries ``z_up(x) = a cosh((x - x_low) / a) + c`` (the thesis' "natural
   catenary curve shape", with the lowest point x_low anywhere, hence unequal support heights)
   or straight taut lines between random supports; 1-6 parallel conductors on 1-2 levels with
   random spacing (power-line bundles), over 1-3 consecutive spans with poles and cross-arms
   at the supports (drawn, never labelled).
3. Projection; the wire's image width is its diameter seen at its depth, ``fx * D / z``, with a
   per-bundle floor (sub-pixel to ~1 px) and a cap; rendered anti-aliased by supersampling.
4. Appearance per bundle: dark, metal (shiny, with a specular core and glints), oxidised green,
   bright (against dark) or rust; brightness varying along the wire; atmospheric haze by depth.
5. Composited over a background of ``perception.training.backgrounds``; then lighting, defocus blur,
   motion blur, sensor noise and JPEG artefacts.

The mask is geometric and independent of appearance: a pixel is wire when the wire's centreline,
rasterised 8-connected with sub-pixel precision, passes through it, or when the wire's drawn
footprint covers at least half of it. So every wire, however thin or faint, is a connected
label at least 1 px wide, and a wider wire's label is as wide as its footprint.
"""

from __future__ import annotations

import itertools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import torch

from geometry.camera import PinholeCamera, body_from_camera_mount, world_from_camera
from geometry.pose import Pose
from perception.inputs import network_input
from perception.params import SyntheticParams
from perception.training.aerial import ground_view
from perception.training.backgrounds import (
    TREE_LINE_PROBABILITY,
    Horizon,
    PhotoPool,
    background,
    below_horizon,
    draw_pole,
    fractal_noise,
)
from perception.training.labelled import LabelledFrames
from perception.training.labels import label_mask, rasterise

_NEAR_M = 0.3  # near clipping depth of the camera, m
_POINTS_PER_SPAN = 240
_UP_NED = np.array([0.0, 0.0, -1.0])
_HORIZON_WIRE_MAX_M = 60.0  # farthest level wire on the horizon: beyond it, it is sub-pixel
MATERIALS = ("dark", "metal", "oxidised", "bright", "rust")
_FRAMES_STREAM = 2  # the random stream that picks an item's source and its crop


@dataclass(frozen=True)
class PosedCamera:
    """The pinhole `camera` (`geometry.camera`) at `world_from_camera` (NED): one synthetic view."""

    camera: PinholeCamera
    world_from_camera: Pose
    camera_from_world: Pose = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "camera_from_world", self.world_from_camera.inverse())

    @property
    def position_ned_m(self) -> np.ndarray:
        """The camera centre, world NED, m."""
        return self.world_from_camera.translation_m

    def project(self, points_ned_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) pixel coordinates (u, v) and (N,) depths z, m; NaN pixels where z <= 0."""
        return self.camera.project(self.camera_from_world.apply(points_ned_m))

    def ray_ned(self, u_px: float, v_px: float) -> np.ndarray:
        """Unit world NED direction of the ray through pixel (u, v)."""
        r = self.world_from_camera.rotate(self.camera.rays(np.array([u_px, v_px])))
        return r / np.linalg.norm(r)


def level_view(
    camera: PinholeCamera, position_ned_m: np.ndarray, pitch_rad: float, roll_rad: float
) -> PosedCamera:
    """A forward-looking camera (yaw 0) on a body at `position_ned_m` pitched and rolled."""
    world_from_body = Pose.from_yaw_pitch_roll(0.0, pitch_rad, roll_rad, position_ned_m)
    return PosedCamera(
        camera, world_from_camera(world_from_body, body_from_camera_mount(np.zeros(3)))
    )


@dataclass(frozen=True)
class WireBundle:
    """Parallel conductors sharing material and diameter: polylines (N, 3) in world NED, m."""

    conductors_ned_m: tuple[np.ndarray, ...]
    diameter_m: float
    width_floor_px: float
    material: str
    poles_ned_m: tuple[tuple[np.ndarray, np.ndarray, float], ...] = ()
    """Unlabelled supports: (top, bottom, diameter_m) of poles, cross-arms and tower members."""
    fittings_ned_m: tuple[tuple[np.ndarray, np.ndarray, float], ...] = ()
    """Unlabelled insulator strings and spacers: (end, end, diameter_m), in their own colour."""
    on_horizon: bool = False
    """Hung level at the camera's height (`horizon_anchor`): its contrast floor is
    ``horizon_contrast_min``."""


def sample_camera(rng: np.random.Generator, p: SyntheticParams, h: int, w: int) -> PosedCamera:
    """Random intrinsics (horizontal FOV) and pose (altitude, pitch, roll; yaw 0)."""
    hfov = np.deg2rad(rng.uniform(p.hfov_min_deg, p.hfov_max_deg))
    fx = (w / 2) / np.tan(hfov / 2)
    altitude = np.exp(rng.uniform(np.log(p.camera_altitude_min_m), np.log(p.camera_altitude_max_m)))
    pitch = np.deg2rad(rng.uniform(-p.pitch_max_deg, p.pitch_max_deg * 0.7))
    roll = np.deg2rad(
        np.clip(rng.normal(0, p.roll_std_deg), -3 * p.roll_std_deg, 3 * p.roll_std_deg)
    )
    cx = w / 2 + rng.normal(0, w * 0.01)
    cy = h / 2 + rng.normal(0, h * 0.01)
    camera = PinholeCamera(fx, fx, cx, cy, w, h)
    return level_view(camera, np.array([0.0, 0.0, -altitude]), pitch, roll)


def horizon_of(camera: PosedCamera) -> Horizon:
    """Image line of the horizon, from two far horizontal directions ahead of the camera."""
    far = np.array([[1e6, -2e5, 0.0], [1e6, 2e5, 0.0]]) + camera.position_ned_m * [1, 1, 0]
    uv, _ = camera.project(far)
    slope = (uv[1, 1] - uv[0, 1]) / (uv[1, 0] - uv[0, 0])
    v_center = uv[0, 1] + slope * (camera.camera.width_px / 2 - uv[0, 0])
    if not np.isfinite(v_center) or not np.isfinite(slope):  # looking straight down
        return Horizon(v_center_px=-1e5, slope=0.0)
    v_center = float(np.clip(v_center, -1e5, 1e5))
    return Horizon(v_center_px=v_center, slope=float(slope), focal_px=camera.camera.fy_px)


def catenary_height_m(x_m: np.ndarray, a_m: float, x_low_m: float) -> np.ndarray:
    """Height (up) of a catenary y = a cosh((x - x_low) / a), up to a constant (2.3.2)."""
    return a_m * np.cosh((x_m - x_low_m) / a_m)


def _anchor(rng: np.random.Generator, p: SyntheticParams, cam: PosedCamera) -> np.ndarray | None:
    """A world point seen at a random pixel, at a random distance and plausible height."""
    altitude = -cam.position_ned_m[2]
    for _ in range(10):
        ray = cam.ray_ned(rng.uniform(0, cam.camera.width_px), rng.uniform(0, cam.camera.height_px))
        lo, hi = p.wire_distance_min_m, p.wire_distance_max_m
        if abs(ray[2]) > 1e-6:  # height(s) = altitude - s * ray_z must stay in bounds
            s1 = (altitude - p.wire_height_max_m) / ray[2]
            s2 = (altitude - p.wire_height_min_m) / ray[2]
            lo, hi = max(lo, min(s1, s2)), min(hi, max(s1, s2))
        elif not p.wire_height_min_m <= altitude <= p.wire_height_max_m:
            continue
        if hi > lo:
            s = np.exp(rng.uniform(np.log(lo), np.log(hi)))
            return cam.position_ned_m + s * ray
    return None


def horizon_anchor(
    rng: np.random.Generator, p: SyntheticParams, cam: PosedCamera
) -> np.ndarray | None:
    """A world point at the camera's own height, seen on the horizon at a random column,
    wire_distance_min_m to _HORIZON_WIRE_MAX_M away (log-uniform): a wire there lies along the
    horizon, against the tree line and hills; None when the horizon is out of view."""
    horizon = horizon_of(cam)
    u = rng.uniform(0, cam.camera.width_px)
    v = horizon.v_center_px + horizon.slope * (u - cam.camera.width_px / 2)
    if not 0 <= v < cam.camera.height_px:
        return None
    ray = cam.ray_ned(u, v) * [1.0, 1.0, 0.0]
    lo, hi = (
        p.wire_distance_min_m,
        max(p.wire_distance_min_m, min(p.wire_distance_max_m, _HORIZON_WIRE_MAX_M)),
    )
    s = np.exp(rng.uniform(np.log(lo), np.log(hi)))
    return cam.position_ned_m + s * ray / np.linalg.norm(ray)


def sample_aerial_camera(
    rng: np.random.Generator, p: SyntheticParams, h: int, w: int
) -> PosedCamera:
    """A camera pitched down at the ground (issue 20): pitch -aerial_pitch_min_deg..-89.5 deg,
    altitude log-uniform in the aerial bounds, horizontal FOV as for forward views."""
    hfov = np.deg2rad(rng.uniform(p.hfov_min_deg, p.hfov_max_deg))
    fx = (w / 2) / np.tan(hfov / 2)
    altitude = np.exp(rng.uniform(np.log(p.aerial_altitude_min_m), np.log(p.aerial_altitude_max_m)))
    pitch = -np.deg2rad(rng.uniform(p.aerial_pitch_min_deg, 89.5))
    roll = np.deg2rad(np.clip(rng.normal(0, p.roll_std_deg), -20, 20))
    camera = PinholeCamera(
        fx, fx, w / 2 + rng.normal(0, w * 0.01), h / 2 + rng.normal(0, h * 0.01), w, h
    )
    return level_view(camera, np.array([0.0, 0.0, -altitude]), pitch, roll)


def aerial_wire_params(p: SyntheticParams, altitude_m: float) -> SyntheticParams:
    """Wire ranges of an aerial view: wires between 3 m and 2 m below the camera (at most
    40 m high), as far as 8x the altitude, with the wider aerial width floor."""
    top = float(np.clip(altitude_m - 2.0, 3.5, 40.0))
    return p.model_copy(
        update={
            "wire_height_min_m": 3.0,
            "wire_height_max_m": top,
            "wire_distance_max_m": max(20.0, 8.0 * altitude_m),
            "width_floor_max_px": p.aerial_width_floor_max_px,
        }
    )


def lattice_tower(
    base_ned_m: np.ndarray, height_m: float, across: np.ndarray, along: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Members (end, end, diameter_m) of a lattice tower: four legs tapering from a square base
    (0.18 x height) to a quarter of it at the top, with X-bracing on each face in 4-6 panels."""
    half_base, half_top = 0.09 * height_m, 0.025 * height_m
    corners = [(1, 1), (1, -1), (-1, -1), (-1, 1)]
    levels = np.linspace(0.0, 1.0, 6)

    def corner(i: int, f: float) -> np.ndarray:
        a, b = corners[i % 4]
        half = half_base + (half_top - half_base) * f
        return base_ned_m + half * (a * across + b * along) + _UP_NED * f * height_m

    members = []
    for i in range(4):
        members.append((corner(i, 0.0), corner(i, 1.0), 0.12))
        for f0, f1 in itertools.pairwise(levels):
            members.append((corner(i, f0), corner(i + 1, f1), 0.05))
            members.append((corner(i + 1, f0), corner(i, f1), 0.05))
            members.append((corner(i, f1), corner(i + 1, f1), 0.06))
    return members


def bundle_fittings(
    rng: np.random.Generator, conductors: tuple[np.ndarray, ...], per_level: int, spacing_m: float
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Insulator strings (0.5-2.5 m, hanging each conductor at both ends of its span) and, for
    conductors closer than 1 m, spacers every 30-80 points along them."""
    length, diameter = rng.uniform(0.5, 2.5), rng.uniform(0.12, 0.3)
    out = []
    for polyline in conductors:
        for end in (polyline[0], polyline[-1]):
            out.append((end + _UP_NED * length, end, diameter))
    if spacing_m < 1.0 and per_level > 1:
        step = int(rng.integers(30, 80))
        for a, b in itertools.combinations(conductors, 2):
            if np.linalg.norm(a[0] - b[0]) < 1.5 * spacing_m:
                out += [(a[j], b[j], 0.04) for j in range(step // 2, len(a), step)]
    return out


def sample_bundle(
    rng: np.random.Generator,
    p: SyntheticParams,
    cam: PosedCamera,
    material_weights: tuple[float, ...] = (0.35, 0.3, 0.1, 0.15, 0.1),
    on_horizon: bool = False,
) -> WireBundle | None:
    """A random bundle of parallel conductors passing through a visible anchor point.

    material_weights: probabilities of ``MATERIALS``.
    on_horizon: anchored by `horizon_anchor`, level (straight) or with the anchor near the
    catenary's lowest point, so that the wire runs along the horizon.
    """
    anchor = horizon_anchor(rng, p, cam) if on_horizon else _anchor(rng, p, cam)
    if anchor is None:
        return None
    yaw = rng.uniform(0, np.pi)
    along = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    across = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    span = np.exp(rng.uniform(np.log(p.span_min_m), np.log(p.span_max_m)))
    x = np.linspace(0.0, span, _POINTS_PER_SPAN)
    at = rng.uniform(0.05, 0.95) * span
    straight = rng.random() < p.straight_probability
    if straight:
        elevation = 0.0 if on_horizon else np.deg2rad(np.clip(rng.normal(0, 15), -50, 50))
        direction = np.cos(elevation) * along + np.sin(elevation) * _UP_NED
        curve = anchor + (x - at)[:, None] * direction
        step = span * direction
    else:
        sag_ratio = rng.uniform(0.003, max(p.sag_ratio_max, 0.004))
        a = span / (8 * sag_ratio)
        x_low = (
            at + rng.uniform(-0.1, 0.1) * span
            if on_horizon
            else span / 2 + rng.uniform(-0.6, 0.6) * span
        )
        height = catenary_height_m(x, a, x_low) - catenary_height_m(np.array(at), a, x_low)
        curve = anchor + (x - at)[:, None] * along + height[:, None] * _UP_NED
        step = span * along + (height[-1] - height[0]) * _UP_NED
    n = int(rng.integers(1, p.conductors_max + 1)) if rng.random() < 0.7 else 1
    levels = 2 if n >= 4 and rng.random() < 0.5 else 1
    per_level = int(np.ceil(n / levels))
    spacing = rng.uniform(p.conductor_spacing_min_m, p.conductor_spacing_max_m)
    offsets = [
        across * (j - (per_level - 1) / 2) * spacing
        + _UP_NED * lv * spacing * rng.uniform(0.6, 1.5)
        for lv in range(levels)
        for j in range(per_level)
    ][:n]
    spans = range(-int(rng.integers(0, 2)), int(rng.integers(1, 3)))
    conductors = tuple(curve + off + k * step for off in offsets for k in spans)
    poles: list[tuple[np.ndarray, np.ndarray, float]] = []
    if not straight and rng.random() < 0.6:
        pole_d = rng.uniform(0.15, 0.6)
        arm = across * ((per_level - 1) / 2 * spacing + 0.3)
        towers = p.tower_probability > 0 and rng.random() < p.tower_probability
        for k in (*spans, spans[-1] + 1):
            top = curve[0] + k * step + _UP_NED * (levels * spacing * 0.5 + 0.3)
            if towers:
                height = max(3.0, -float(top[2]))
                poles += lattice_tower(top * [1, 1, 0], height, across, along)
            else:
                poles.append((top, top * [1, 1, 0], pole_d))
            for lv in range(levels):
                base = curve[0] + k * step + _UP_NED * (lv * spacing - 0.1)
                poles.append((base - arm, base + arm, pole_d * 0.5))
    fittings: list[tuple[np.ndarray, np.ndarray, float]] = []
    if p.fittings_probability > 0 and rng.random() < p.fittings_probability:
        fittings = bundle_fittings(rng, conductors, per_level, spacing)
    return WireBundle(
        conductors_ned_m=conductors,
        diameter_m=float(np.exp(rng.uniform(np.log(p.diameter_min_m), np.log(p.diameter_max_m)))),
        width_floor_px=float(rng.uniform(p.width_floor_min_px, p.width_floor_max_px)),
        material=str(rng.choice(MATERIALS, p=list(material_weights))),
        poles_ned_m=tuple(poles),
        fittings_ned_m=tuple(fittings),
        on_horizon=on_horizon,
    )


def wire_segments(
    bundle: WireBundle, cam: PosedCamera, width_max_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Visible segments of a bundle: (M, 2, 2) endpoints (u, v) px, (M,) widths px, (M,) depths m.

    Width is the diameter seen at the segment's depth, ``fx * D / z``, floored and capped.
    """
    ends, widths, depths = [], [], []
    limit = 8.0 * max(cam.camera.width_px, cam.camera.height_px)
    for conductor in bundle.conductors_ned_m:
        uv, z = cam.project(conductor)
        seg = np.stack([uv[:-1], uv[1:]], 1)
        z_seg = 0.5 * (z[:-1] + z[1:])
        keep = (np.minimum(z[:-1], z[1:]) > _NEAR_M) & (np.abs(seg).max(axis=(1, 2)) < limit)
        ends.append(seg[keep])
        depths.append(z_seg[keep])
        widths.append(
            np.clip(
                cam.camera.fx_px * bundle.diameter_m / z_seg[keep],
                bundle.width_floor_px,
                width_max_px,
            )
        )
    return np.concatenate(ends), np.concatenate(widths), np.concatenate(depths)


def _material_rgb(rng: np.random.Generator, material: str) -> tuple[np.ndarray, float]:
    """Base colour (3,) in [0, 1] and specular strength of a wire material."""
    tint = rng.normal(0, 0.02, 3)
    base, spec = {
        "dark": (np.full(3, rng.uniform(0.02, 0.22)), rng.uniform(0.0, 0.2)),
        "metal": (rng.uniform(0.35, 0.7) + np.array([0, 0.01, 0.03]), rng.uniform(0.3, 0.8)),
        "oxidised": (np.array([0.33, 0.55, 0.45]) + rng.normal(0, 0.06, 3), rng.uniform(0, 0.3)),
        "bright": (np.full(3, rng.uniform(0.75, 1.0)), rng.uniform(0.2, 0.6)),
        "rust": (np.array([0.45, 0.28, 0.18]) + rng.normal(0, 0.05, 3), rng.uniform(0, 0.2)),
    }[material]
    return np.clip(base + tint, 0, 1), float(spec)


def composite_wires(
    rng: np.random.Generator,
    image: np.ndarray,
    bundles: list[WireBundle],
    cam: PosedCamera,
    p: SyntheticParams,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Draw supports and wires over a float (H, W, 3) image; returns (image, mask uint8 {0, 1},
    coverage float32 (H, W) in [0, 1]: the wires' anti-aliased footprint, before degradation)."""
    h, w = image.shape[:2]
    img = image.copy()
    mask = np.zeros((h, w), np.uint8)
    footprint = np.zeros((h, w), np.float32)
    haze_rgb = img[: max(1, h // 3)].reshape(-1, 3).mean(axis=0)
    visibility_m = rng.uniform(300, 3000)
    for bundle in bundles:
        pole_rgb = np.clip(rng.uniform(0.1, 0.6) + rng.normal(0, 0.05, 3), 0, 1)
        draw_members(img, bundle.poles_ned_m, cam, pole_rgb)
        if bundle.fittings_ned_m:
            ceramic = rng.choice([0.85, 0.55, 0.35]) * np.ones(3) + rng.normal(0, 0.05, 3)
            draw_members(img, bundle.fittings_ned_m, cam, np.clip(ceramic, 0, 1))
    for bundle in bundles:
        segments, widths, depths = wire_segments(bundle, cam, p.width_max_px)
        if len(segments) == 0:
            continue
        coverage = rasterise(segments, widths, h, w, p.supersampling)
        mask |= label_mask(segments, coverage)
        np.maximum(footprint, coverage, out=footprint)
        base, spec = _material_rgb(rng, bundle.material)
        along = 1 + rng.uniform(0, 0.6) * (fractal_noise(rng, h, w, 3)[..., None] - 0.5)
        glint = np.clip((fractal_noise(rng, h, w, 6) - 0.75) / 0.1, 0, 1)[..., None] * spec
        colour = np.clip(base * along + glint, 0, 1)
        haze = min(0.6, 1 - np.exp(-float(np.median(depths)) / visibility_m))
        colour = colour * (1 - haze) + haze_rgb * haze
        floor = p.horizon_contrast_min if bundle.on_horizon else p.contrast_min
        colour = with_local_contrast(colour, img, rng.uniform(floor, p.contrast_max))
        alpha = (coverage * rng.uniform(0.75, 1.0))[..., None]
        img = img * (1 - alpha) + colour * alpha
        thick = widths >= 2.0
        if spec > 0.25 and thick.any():
            core = rasterise(segments[thick], widths[thick] * 0.3, h, w, p.supersampling)
            img = img + (1 - img) * (core * spec * (1 - haze))[..., None]
    return img.astype(np.float32), mask, footprint


def draw_members(
    img: np.ndarray,
    members: tuple[tuple[np.ndarray, np.ndarray, float], ...] | list,
    cam: PosedCamera,
    rgb: np.ndarray,
) -> None:
    """Draw (end, end, diameter_m) members (poles, arms, towers, insulators) in place, each as
    wide as its diameter seen at its mean depth; members behind the camera are skipped."""
    h, w = img.shape[:2]
    for top, bottom, diameter_m in members:
        uv, z = cam.project(np.stack([top, bottom]))
        if z.min() > _NEAR_M and np.abs(uv).max() < 8 * max(h, w):
            draw_pole(img, uv[0], uv[1], cam.camera.fx_px * diameter_m / z.mean(), rgb)


def shadow_points(points_ned_m: np.ndarray, sun_ned: np.ndarray) -> np.ndarray:
    """(N, 3) points where sunlight travelling along `sun_ned` (unit, down > 0) past (N, 3)
    points above the ground (z < 0, NED) meets the ground z = 0."""
    t = -points_ned_m[:, 2] / sun_ned[2]
    return points_ned_m + t[:, None] * sun_ned


def sunlight(rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """(unit NED direction sunlight travels, sun 25-70 deg high, any azimuth; shadow strength
    0.3-0.7, the share of light a full shadow takes away)."""
    elevation, azimuth = np.deg2rad(rng.uniform(25, 70)), rng.uniform(0, 2 * np.pi)
    sun = np.array(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            np.sin(elevation),
        ]
    )
    return sun, float(rng.uniform(0.3, 0.7))


def unseen_poles(rng: np.random.Generator, cam: PosedCamera) -> WireBundle:
    """One to three poles (3-15 m high) standing on the ground beside the view of a forward
    camera, as a bundle without conductors: only their long shadows reach into the image,
    thin dark lines on the ground that are not wires."""
    n = int(rng.integers(1, 4))
    half_fov = np.arctan(cam.camera.width_px / 2 / cam.camera.fx_px)
    bearing = rng.uniform(half_fov + 0.05, 1.4, n) * rng.choice([-1.0, 1.0], n)
    distance = rng.uniform(3.0, 40.0, n)
    ahead = cam.ray_ned(cam.camera.cx_px, cam.camera.cy_px)
    yaw = np.arctan2(ahead[1], ahead[0])
    base = cam.position_ned_m[:2] + distance[:, None] * np.stack(
        [np.cos(yaw + bearing), np.sin(yaw + bearing)], 1
    )
    height = rng.uniform(3.0, 15.0, n)
    poles = tuple(
        (np.array([b[0], b[1], -h]), np.array([b[0], b[1], 0.0]), float(d))
        for b, h, d in zip(base, height, rng.uniform(0.08, 0.4, n), strict=True)
    )
    return WireBundle((), 0.0, 0.0, "dark", poles_ned_m=poles)


def draw_shadows(
    img: np.ndarray,
    ground: np.ndarray,
    bundles: list[WireBundle],
    cam: PosedCamera,
    sun: np.ndarray,
    strength: float,
    supersampling: int,
) -> None:
    """Shadows of wires, poles and towers on the (H, W) bool `ground` (never labelled), in place.

    A wire of diameter D at height z casts a penumbra D + 0.0093 z wide (the sun's 0.53 deg
    disc), darkened by `strength` x D / (D + 0.0093 z), with a floor of a quarter so that thin
    shadows still show, as they do on bright concrete.
    """
    h, w = img.shape[:2]
    darkening = np.zeros((h, w), np.float32)
    for bundle in bundles:
        for conductor in bundle.conductors_ned_m:
            above = conductor[conductor[:, 2] < -0.2]
            if len(above) < 2:
                continue
            uv, z = cam.project(shadow_points(above, sun))
            seg = np.stack([uv[:-1], uv[1:]], 1)
            zs = 0.5 * (z[:-1] + z[1:])
            keep = (np.minimum(z[:-1], z[1:]) > _NEAR_M) & (
                np.abs(seg).max(axis=(1, 2)) < 8 * max(h, w)
            )
            if not keep.any():
                continue
            penumbra = 0.0093 * float(-above[:, 2].mean())
            width = cam.camera.fx_px * (bundle.diameter_m + penumbra) / zs[keep]
            dark = max(0.25, bundle.diameter_m / (bundle.diameter_m + penumbra)) * strength
            cover = rasterise(seg[keep], np.clip(width, 0.4, 20.0), h, w, supersampling)
            np.maximum(darkening, cover * dark, out=darkening)
        for top, bottom, diameter_m in bundle.poles_ned_m:
            ends = np.stack([top, bottom])
            if (ends[:, 2] >= -0.2).all():
                ends[:, 2] = np.minimum(ends[:, 2], -0.01)
            uv, z = cam.project(shadow_points(ends, sun))
            if z.min() > _NEAR_M and np.abs(uv).max() < 8 * max(h, w):
                canvas = np.zeros((h, w), np.float32)
                draw_pole(
                    canvas[..., None],
                    uv[0],
                    uv[1],
                    cam.camera.fx_px * diameter_m / z.mean(),
                    np.ones(1),
                )
                np.maximum(darkening, canvas * strength, out=darkening)
    img *= 1 - (darkening * ground)[..., None]


def with_local_contrast(colour: np.ndarray, image: np.ndarray, contrast: float) -> np.ndarray:
    """Wire colour field (H, W, 3) shifted where its luminance is within `contrast` of the
    local background's (5x5 box mean), so that a labelled wire is never invisible by
    construction; the shift keeps the sign of the existing difference (brighter or darker)."""
    weights = np.array([0.299, 0.587, 0.114], np.float32)
    background = cv2.blur(image, (5, 5)) @ weights
    delta = colour @ weights - background
    room_up, room_down = 1 - background, background
    sign = np.where(delta == 0, np.where(room_up > room_down, 1.0, -1.0), np.sign(delta))
    sign = np.where((sign > 0) & (room_up < contrast), -1.0, sign)
    sign = np.where((sign < 0) & (room_down < contrast), 1.0, sign)
    shift = np.where(np.abs(delta) < contrast, sign * contrast - delta, 0.0)
    return np.clip(colour + shift[..., None], 0, 1).astype(np.float32)


def degrade(rng: np.random.Generator, image: np.ndarray) -> np.ndarray:
    """Camera effects on a float (H, W, 3) image: lighting, defocus, motion blur, noise, JPEG.

    Returns RGB uint8 (H, W, 3).
    """
    img = np.clip(image, 0, 1) ** rng.uniform(0.75, 1.35)
    img = img * rng.uniform(0.6, 1.3) * rng.uniform(0.92, 1.08, 3)
    if rng.random() < 0.5:
        sigma = rng.uniform(0.3, 1.3)
        img = cv2.GaussianBlur(img, (0, 0), sigma)
    if rng.random() < 0.25:
        length = int(rng.integers(3, 10))
        kernel = np.zeros((length, length), np.float32)
        angle = rng.uniform(0, np.pi)
        c = (length - 1) / 2
        d = np.array([np.cos(angle), np.sin(angle)]) * c
        cv2.line(
            kernel,
            tuple(np.round([c - d[0], c - d[1]]).astype(int)),
            tuple(np.round([c + d[0], c + d[1]]).astype(int)),
            1.0,
            1,
        )
        img = cv2.filter2D(img, -1, kernel / kernel.sum())
    noise_sigma = rng.uniform(0, 0.03)
    img = img + rng.normal(0, 1, img.shape).astype(np.float32) * noise_sigma * np.sqrt(
        np.clip(img, 0.02, 1)
    )
    out = np.clip(img * 255 + 0.5, 0, 255).astype(np.uint8)
    return jpeg(rng, out)


def jpeg(rng: np.random.Generator, out: np.ndarray) -> np.ndarray:
    """JPEG artefacts (quality 35-95) on 60% of RGB uint8 images."""
    if rng.random() < 0.6:
        quality = int(rng.integers(35, 96))
        ok, buf = cv2.imencode(".jpg", out[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])
        if ok:
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
    return np.ascontiguousarray(out)


def sensor_effects(rng: np.random.Generator, image: np.ndarray) -> np.ndarray:
    """Vignetting (corner falloff 10-45%), over-exposure (gain 1-1.6, clipped highlights) and
    resampling blur (down to 50-90% and back) on a float (H, W, 3) image, each half the time."""
    h, w = image.shape[:2]
    img = image
    if rng.random() < 0.5:
        v, u = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((u - w / 2) ** 2 + (v - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
        img = img * (1 - rng.uniform(0.1, 0.45) * r2)[..., None]
    if rng.random() < 0.5:
        img = img * rng.uniform(1.0, 1.6)
    if rng.random() < 0.5:
        f = rng.uniform(0.5, 0.9)
        small = cv2.resize(
            img, (max(8, round(w * f)), max(8, round(h * f))), interpolation=cv2.INTER_AREA
        )
        img = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    return np.clip(img, 0, 1).astype(np.float32)


AERIAL_MATERIALS = (0.25, 0.35, 0.05, 0.3, 0.05)
"""Material probabilities in aerial views: sunlit aluminium (metal, bright) seen from above."""


def synthetic_sample(
    seed: int,
    index: int,
    height_px: int,
    width_px: int,
    params: SyntheticParams | None = None,
    pool: PhotoPool | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """RGB uint8 image (H, W, 3) and wire mask uint8 (H, W) {0, 1}; deterministic in seed, index."""
    image, mask, _ = rendered_sample(seed, index, height_px, width_px, params, pool)
    return image, mask


def rendered_sample(
    seed: int,
    index: int,
    height_px: int,
    width_px: int,
    params: SyntheticParams | None = None,
    pool: PhotoPool | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`synthetic_sample` plus the wires' anti-aliased coverage (H, W) float32 in [0, 1]."""
    p = params or SyntheticParams()
    rng = np.random.default_rng([seed, index])
    aerial = p.aerial_probability > 0 and rng.random() < p.aerial_probability
    if aerial:
        cam = sample_aerial_camera(rng, p, height_px, width_px)
        q, materials = aerial_wire_params(p, -cam.position_ned_m[2]), AERIAL_MATERIALS
    else:
        cam = sample_camera(rng, p, height_px, width_px)
        q, materials = p, (0.35, 0.3, 0.1, 0.15, 0.1)
    level = not aerial and p.horizon_wire_probability > 0
    level = level and rng.random() < p.horizon_wire_probability
    bundles: list[WireBundle] = []
    if rng.random() >= p.no_wire_probability:
        for k in range(int(rng.integers(1, p.bundles_max + 1))):
            bundle = sample_bundle(rng, q, cam, materials, on_horizon=level and k == 0)
            if bundle is not None:
                bundles.append(bundle)
    # a level wire's hard case is the tree line behind it: a landscape, always with trees
    photos, trees = (0.0, 1.0) if level else (p.photo_probability, TREE_LINE_PROBABILITY)
    horizon = horizon_of(cam)
    clouds = p.perspective_cloud_probability
    bg, photo = background(rng, height_px, width_px, horizon, pool, photos, trees, clouds)
    if aerial:
        bg, ground = ground_view(rng, bg, cam.camera, cam.world_from_camera, pool)
        if rng.random() < p.wire_shadow_probability:
            draw_shadows(bg, ground, bundles, cam, *sunlight(rng), p.supersampling)
    elif (
        not photo and p.ground_shadow_probability > 0 and rng.random() < p.ground_shadow_probability
    ):
        ground = below_horizon(height_px, width_px, horizon)
        casters = [*bundles, unseen_poles(rng, cam)]
        draw_shadows(bg, ground, casters, cam, *sunlight(rng), p.supersampling)
    image, mask, coverage = composite_wires(rng, bg, bundles, cam, q)
    if p.sensor_effects_probability > 0 and rng.random() < p.sensor_effects_probability:
        image = sensor_effects(rng, image)
    return degrade(rng, image), mask, coverage


class SyntheticWireDataset(torch.utils.data.Dataset):
    """On-the-fly training data: item i = (network input (C, H, W) float32, mask (H, W) int64).

    With `frame_folders` (labelled image folders, `labelled`), a share `frames_share` of the
    items, drawn from (seed, index), is a crop of one of their frames instead of a synthetic
    image: frames the simulated cameras render (`wireavoid sil-frames`), never evaluation
    photographs.
    """

    def __init__(
        self,
        seed: int,
        length: int,
        height_px: int,
        width_px: int,
        input_mode: str = "rgb",
        params: SyntheticParams | None = None,
        photo_sources: tuple[str, ...] = (),
        frame_folders: tuple[str, ...] = (),
        frames_share: float = 0.0,
    ) -> None:
        self.seed, self.length = seed, length
        self.height_px, self.width_px = height_px, width_px
        self.input_mode = input_mode
        self.params = params or SyntheticParams()
        self.photo_sources = photo_sources
        self.frame_folders, self.frames_share = frame_folders, frames_share
        self._pool: PhotoPool | None = None
        self._frames: LabelledFrames | None = None

    def __len__(self) -> int:
        return self.length

    @property
    def pool(self) -> PhotoPool:
        """Photographs, loaded on first use (once per DataLoader worker)."""
        if self._pool is None:
            self._pool = PhotoPool.load(list(self.photo_sources))
        return self._pool

    @property
    def frames(self) -> LabelledFrames:
        """The labelled frames, loaded on first use (once per DataLoader worker)."""
        if self._frames is None:
            self._frames = LabelledFrames(self.frame_folders)
        return self._frames

    def sample(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Item `index` as an RGB uint8 image and its uint8 {0, 1} mask."""
        rng = np.random.default_rng([self.seed, index, _FRAMES_STREAM])
        if self.frame_folders and rng.random() < self.frames_share:
            return self.frames.crop(rng, self.height_px, self.width_px)
        return synthetic_sample(
            self.seed, index, self.height_px, self.width_px, self.params, self.pool
        )

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        image, mask = self.sample(index)
        x = network_input(image, self.input_mode)  # type: ignore[arg-type]
        return torch.from_numpy(x), torch.from_numpy(mask.astype(np.int64))


def write_dataset(
    out_dir: str | os.PathLike,
    count: int,
    seed: int,
    height_px: int,
    width_px: int,
    params: SyntheticParams | None = None,
    photo_sources: tuple[str, ...] = (),
) -> Path:
    """Write ``images/NNNNNN.png`` (RGB) and ``masks/NNNNNN.png`` (0/255) plus ``synth.json``."""
    out = Path(out_dir)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "masks").mkdir(parents=True, exist_ok=True)
    p = params or SyntheticParams()
    pool = PhotoPool.load(list(photo_sources))
    for i in range(count):
        image, mask = synthetic_sample(seed, i, height_px, width_px, p, pool)
        cv2.imwrite(str(out / "images" / f"{i:06d}.png"), image[..., ::-1])
        cv2.imwrite(str(out / "masks" / f"{i:06d}.png"), mask * 255)
    record = {
        "seed": seed,
        "count": count,
        "height_px": height_px,
        "width_px": width_px,
        "params": p.model_dump(),
        "photos": pool.names,
    }
    (out / "synth.json").write_text(json.dumps(record, indent=2) + "\n")
    return out
