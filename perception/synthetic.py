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
5. Composited over a background of ``perception.backgrounds``; then lighting, defocus blur,
   motion blur, sensor noise and JPEG artefacts.

The mask is geometric and independent of appearance: a pixel is wire when the wire's centreline,
rasterised 8-connected with sub-pixel precision, passes through it, or when the wire's drawn
footprint covers at least half of it. So every wire, however thin or faint, is a connected
label at least 1 px wide, and a wider wire's label is as wide as its footprint.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch

from perception.backgrounds import (
    Horizon,
    PhotoPool,
    background,
    draw_pole,
    fractal_noise,
)
from perception.inputs import network_input
from perception.params import SyntheticParams

_SHIFT = 4  # fixed-point fractional bits of OpenCV drawing coordinates
_NEAR_M = 0.3  # near clipping depth of the camera, m
_POINTS_PER_SPAN = 240
_R_CAM_FROM_BODY = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
_UP_NED = np.array([0.0, 0.0, -1.0])
MATERIALS = ("dark", "metal", "oxidised", "bright", "rust")


@dataclass(frozen=True)
class Camera:
    """Pinhole camera: intrinsics in px, position in world NED (m), rotation world -> camera."""

    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    width_px: int
    height_px: int
    position_ned_m: np.ndarray
    r_cam_from_world: np.ndarray

    def to_camera(self, points_ned_m: np.ndarray) -> np.ndarray:
        """(N, 3) world NED points -> (N, 3) camera-frame points (x right, y down, z forward)."""
        return (points_ned_m - self.position_ned_m) @ self.r_cam_from_world.T

    def project(self, points_ned_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) pixel coordinates (u, v) and (N,) depths z, m; invalid where z <= 0."""
        p = self.to_camera(points_ned_m)
        z = p[:, 2]
        safe = np.where(z > 1e-6, z, 1e-6)
        uv = np.stack(
            [self.fx_px * p[:, 0] / safe + self.cx_px, self.fy_px * p[:, 1] / safe + self.cy_px], 1
        )
        return uv, z

    def ray_ned(self, u_px: float, v_px: float) -> np.ndarray:
        """Unit world NED direction of the ray through pixel (u, v)."""
        d = np.array([(u_px - self.cx_px) / self.fx_px, (v_px - self.cy_px) / self.fy_px, 1.0])
        r = self.r_cam_from_world.T @ d
        return r / np.linalg.norm(r)


@dataclass(frozen=True)
class WireBundle:
    """Parallel conductors sharing material and diameter: polylines (N, 3) in world NED, m."""

    conductors_ned_m: tuple[np.ndarray, ...]
    diameter_m: float
    width_floor_px: float
    material: str
    poles_ned_m: tuple[tuple[np.ndarray, np.ndarray, float], ...] = ()
    """Unlabelled supports: (top, bottom, diameter_m) of poles and cross-arms."""


def rotation_world_from_body(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """ZYX Euler rotation, body FRD -> world NED."""
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll_rad),
        np.sin(roll_rad),
        np.cos(pitch_rad),
        np.sin(pitch_rad),
        np.cos(yaw_rad),
        np.sin(yaw_rad),
    )
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def sample_camera(rng: np.random.Generator, p: SyntheticParams, h: int, w: int) -> Camera:
    """Random intrinsics (horizontal FOV) and pose (altitude, pitch, roll; yaw 0)."""
    hfov = np.deg2rad(rng.uniform(p.hfov_min_deg, p.hfov_max_deg))
    fx = (w / 2) / np.tan(hfov / 2)
    altitude = np.exp(rng.uniform(np.log(p.camera_altitude_min_m), np.log(p.camera_altitude_max_m)))
    pitch = np.deg2rad(rng.uniform(-p.pitch_max_deg, p.pitch_max_deg * 0.7))
    roll = np.deg2rad(
        np.clip(rng.normal(0, p.roll_std_deg), -3 * p.roll_std_deg, 3 * p.roll_std_deg)
    )
    r_wb = rotation_world_from_body(roll, pitch, 0.0)
    return Camera(
        fx_px=fx,
        fy_px=fx,
        cx_px=w / 2 + rng.normal(0, w * 0.01),
        cy_px=h / 2 + rng.normal(0, h * 0.01),
        width_px=w,
        height_px=h,
        position_ned_m=np.array([0.0, 0.0, -altitude]),
        r_cam_from_world=_R_CAM_FROM_BODY @ r_wb.T,
    )


def horizon_of(camera: Camera) -> Horizon:
    """Image line of the horizon, from two far horizontal directions ahead of the camera."""
    far = np.array([[1e6, -2e5, 0.0], [1e6, 2e5, 0.0]]) + camera.position_ned_m * [1, 1, 0]
    uv, _ = camera.project(far)
    slope = (uv[1, 1] - uv[0, 1]) / (uv[1, 0] - uv[0, 0])
    v_center = uv[0, 1] + slope * (camera.width_px / 2 - uv[0, 0])
    return Horizon(v_center_px=float(v_center), slope=float(slope))


def catenary_height_m(x_m: np.ndarray, a_m: float, x_low_m: float) -> np.ndarray:
    """Height (up) of a catenary y = a cosh((x - x_low) / a), up to a constant (2.3.2)."""
    return a_m * np.cosh((x_m - x_low_m) / a_m)


def _anchor(rng: np.random.Generator, p: SyntheticParams, cam: Camera) -> np.ndarray | None:
    """A world point seen at a random pixel, at a random distance and plausible height."""
    altitude = -cam.position_ned_m[2]
    for _ in range(10):
        ray = cam.ray_ned(rng.uniform(0, cam.width_px), rng.uniform(0, cam.height_px))
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


def sample_bundle(rng: np.random.Generator, p: SyntheticParams, cam: Camera) -> WireBundle | None:
    """A random bundle of parallel conductors passing through a visible anchor point."""
    anchor = _anchor(rng, p, cam)
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
        elevation = np.deg2rad(np.clip(rng.normal(0, 15), -50, 50))
        direction = np.cos(elevation) * along + np.sin(elevation) * _UP_NED
        curve = anchor + (x - at)[:, None] * direction
        step = span * direction
    else:
        sag_ratio = rng.uniform(0.003, max(p.sag_ratio_max, 0.004))
        a = span / (8 * sag_ratio)
        x_low = span / 2 + rng.uniform(-0.6, 0.6) * span
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
        for k in (*spans, spans[-1] + 1):
            top = curve[0] + k * step + _UP_NED * (levels * spacing * 0.5 + 0.3)
            poles.append((top, top * [1, 1, 0], pole_d))
            for lv in range(levels):
                base = curve[0] + k * step + _UP_NED * (lv * spacing - 0.1)
                poles.append((base - arm, base + arm, pole_d * 0.5))
    return WireBundle(
        conductors_ned_m=conductors,
        diameter_m=float(np.exp(rng.uniform(np.log(p.diameter_min_m), np.log(p.diameter_max_m)))),
        width_floor_px=float(rng.uniform(p.width_floor_min_px, p.width_floor_max_px)),
        material=str(rng.choice(MATERIALS, p=[0.35, 0.3, 0.1, 0.15, 0.1])),
        poles_ned_m=tuple(poles),
    )


def wire_segments(
    bundle: WireBundle, cam: Camera, width_max_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Visible segments of a bundle: (M, 2, 2) endpoints (u, v) px, (M,) widths px, (M,) depths m.

    Width is the diameter seen at the segment's depth, ``fx * D / z``, floored and capped.
    """
    ends, widths, depths = [], [], []
    limit = 8.0 * max(cam.width_px, cam.height_px)
    for conductor in bundle.conductors_ned_m:
        uv, z = cam.project(conductor)
        seg = np.stack([uv[:-1], uv[1:]], 1)
        z_seg = 0.5 * (z[:-1] + z[1:])
        keep = (np.minimum(z[:-1], z[1:]) > _NEAR_M) & (np.abs(seg).max(axis=(1, 2)) < limit)
        ends.append(seg[keep])
        depths.append(z_seg[keep])
        widths.append(
            np.clip(
                cam.fx_px * bundle.diameter_m / z_seg[keep], bundle.width_floor_px, width_max_px
            )
        )
    return np.concatenate(ends), np.concatenate(widths), np.concatenate(depths)


def rasterise(
    segments_px: np.ndarray, widths_px: np.ndarray, h: int, w: int, supersampling: int
) -> np.ndarray:
    """Anti-aliased coverage (H, W) float32 in [0, 1] of segments of given widths (supersampled)."""
    s = supersampling
    canvas = np.zeros((h * s, w * s), np.uint8)
    pts = np.round((segments_px * s + (s - 1) / 2) * (1 << _SHIFT)).astype(np.int32)
    levels = np.maximum(1, np.round(widths_px * s)).astype(np.int32)
    for level in np.unique(levels):
        cv2.polylines(
            canvas, list(pts[levels == level]), False, 255, int(level), cv2.LINE_8, _SHIFT
        )
    return cv2.resize(canvas, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0


def label_mask(segments_px: np.ndarray, coverage: np.ndarray) -> np.ndarray:
    """Geometric wire mask (H, W) uint8 {0, 1} of segments whose anti-aliased `coverage`
    (`rasterise`) is given: the centreline, 8-connected and 1 px wide, plus every pixel the wire
    covers at least half. A sub-pixel wire is a connected 1-px line; a wider one is as wide as
    it is drawn (a 1-px wire straddling two pixels marks both)."""
    mask = (coverage >= 0.5).astype(np.uint8)
    pts = np.round(segments_px * (1 << _SHIFT)).astype(np.int32)
    cv2.polylines(mask, list(pts), False, 1, 1, cv2.LINE_8, _SHIFT)
    return mask


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
    cam: Camera,
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
        for top, bottom, diameter_m in bundle.poles_ned_m:
            uv, z = cam.project(np.stack([top, bottom]))
            if z.min() > _NEAR_M and np.abs(uv).max() < 8 * max(h, w):
                draw_pole(img, uv[0], uv[1], cam.fx_px * diameter_m / z.mean(), pole_rgb)
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
        colour = with_local_contrast(colour, img, rng.uniform(p.contrast_min, p.contrast_max))
        alpha = (coverage * rng.uniform(0.75, 1.0))[..., None]
        img = img * (1 - alpha) + colour * alpha
        thick = widths >= 2.0
        if spec > 0.25 and thick.any():
            core = rasterise(segments[thick], widths[thick] * 0.3, h, w, p.supersampling)
            img = img + (1 - img) * (core * spec * (1 - haze))[..., None]
    return img.astype(np.float32), mask, footprint


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
    if rng.random() < 0.6:
        quality = int(rng.integers(35, 96))
        ok, buf = cv2.imencode(".jpg", out[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])
        if ok:
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
    return np.ascontiguousarray(out)


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
    cam = sample_camera(rng, p, height_px, width_px)
    bundles: list[WireBundle] = []
    if rng.random() >= p.no_wire_probability:
        for _ in range(int(rng.integers(1, p.bundles_max + 1))):
            bundle = sample_bundle(rng, p, cam)
            if bundle is not None:
                bundles.append(bundle)
    bg = background(rng, height_px, width_px, horizon_of(cam), pool, p.photo_probability)
    image, mask, coverage = composite_wires(rng, bg, bundles, cam, p)
    return degrade(rng, image), mask, coverage


class SyntheticWireDataset(torch.utils.data.Dataset):
    """On-the-fly training data: item i = (network input (C, H, W) float32, mask (H, W) int64)."""

    def __init__(
        self,
        seed: int,
        length: int,
        height_px: int,
        width_px: int,
        input_mode: str = "rgb",
        params: SyntheticParams | None = None,
        photo_sources: tuple[str, ...] = (),
    ) -> None:
        self.seed, self.length = seed, length
        self.height_px, self.width_px = height_px, width_px
        self.input_mode = input_mode
        self.params = params or SyntheticParams()
        self.photo_sources = photo_sources
        self._pool: PhotoPool | None = None

    def __len__(self) -> int:
        return self.length

    @property
    def pool(self) -> PhotoPool:
        """Photographs, loaded on first use (once per DataLoader worker)."""
        if self._pool is None:
            self._pool = PhotoPool.load(list(self.photo_sources))
        return self._pool

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        image, mask = synthetic_sample(
            self.seed, index, self.height_px, self.width_px, self.params, self.pool
        )
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
