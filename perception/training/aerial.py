"""Ground seen from above and obliquely, where drones fly (issue 20; beyond thesis 2.3.2).

The thesis superimposed wires on forward-looking flight-video frames, mostly against sky. A drone
inspecting or crossing power lines looks down at them over cluttered ground instead: asphalt
with lane markings and kerbs, parking stalls, roofs, crop rows, forest canopy, water, snow.
Those are full of long, thin, straight, bright or dark lines that are not wires, and the wires'
own shadows lie among them.

Here a ground texture is built at metric scale (``ground_texture``: one of several scene kinds,
each a base material plus drawn features, or a real photograph as the ground), and warped into
the posed camera by the exact ground-plane homography (``ground_homography``; camera frame x
right / y down / z forward, world NED with the ground at z = 0). Pixels whose rays miss the
ground within ``_FAR_M`` keep the caller's sky/landscape background, hazed at the seam.
"""

from __future__ import annotations

import cv2
import numpy as np

from geometry.camera import PinholeCamera
from geometry.pose import Pose
from perception.training.backgrounds import PhotoPool, fractal_noise, photo_crop, vegetation

GROUND_KINDS = ("urban", "parking", "suburb", "rural", "forest", "water", "snow", "photo")
_GROUND_WEIGHTS = (0.2, 0.1, 0.15, 0.15, 0.12, 0.06, 0.07, 0.15)
_TEXTURE_PX = 512  # largest side of the ground texture, px (at most twice the image side)
_FAR_M = 600.0  # ground farther than this along the ray is left to the background, m
_MIN_RES_M = 0.015  # finest ground texture resolution, m per px


def ground_homography(
    camera_from_world_r: np.ndarray,
    position_ned_m: np.ndarray,
    intrinsics: np.ndarray,
    origin_ne_m: np.ndarray,
    metres_per_px: float,
) -> np.ndarray:
    """(3, 3) homography from ground-texture pixels (tu, tv) to image pixels (u, v).

    Texture pixel (tu, tv) is the ground point north = n0 + tv * res, east = e0 + tu * res,
    down = 0 (NED). With G = M [tu, tv, 1]^T, the camera point is R (G - C), so the image
    point is K (R M + (-R C) e3^T) [tu, tv, 1]^T: exact for every texture pixel, including
    ones behind the camera (their homogeneous w is negative; callers mask them).
    """
    res = float(metres_per_px)
    m = np.array([[0.0, res, origin_ne_m[0]], [res, 0.0, origin_ne_m[1]], [0.0, 0.0, 0.0]])
    n = camera_from_world_r @ m
    n[:, 2] -= camera_from_world_r @ np.asarray(position_ned_m, np.float64)
    return intrinsics @ n


def ground_hits(
    rays_world: np.ndarray, position_ned_m: np.ndarray, far_m: float = _FAR_M
) -> tuple[np.ndarray, np.ndarray]:
    """Where (H, W, 3) world NED rays from the camera meet the ground z = 0.

    Returns (H, W, 2) north/east hit points, m (NaN where missed) and (H, W) ray length, m (inf
    where the ray points at or above the horizon or hits beyond `far_m`).
    """
    altitude = -float(position_ned_m[2])
    down = rays_world[..., 2]
    norm = np.linalg.norm(rays_world, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(down > 1e-6, altitude / down, np.inf)
    length = t * norm
    length = np.where(length <= far_m, length, np.inf)
    hit = position_ned_m[:2] + t[..., None] * rays_world[..., :2]
    hit[~np.isfinite(length)] = np.nan
    return hit, length


def _line(img: np.ndarray, a, b, rgb, width_px: float) -> None:
    """Anti-aliased line of any width in place. A sub-pixel width is drawn 1 px wide in the
    colour mixed with the image at the line's middle by alpha = width, as a camera integrates
    it (exact over a uniform background)."""
    h, w = img.shape[:2]
    colour = np.asarray(rgb, np.float64)
    if width_px < 1.0:
        mid = np.clip(np.round((np.asarray(a) + np.asarray(b)) / 2), 0, [w - 1, h - 1]).astype(int)
        colour = colour * width_px + img[mid[1], mid[0]] * (1 - width_px)
    pts = np.round(np.array([a, b], np.float64) * 16).astype(np.int32)
    thickness = max(1, round(width_px))
    cv2.line(img, tuple(pts[0]), tuple(pts[1]), colour.tolist(), thickness, cv2.LINE_AA, 4)


def _material(rng: np.random.Generator, h: int, w: int, rgb, grain: float, cells: int):
    """Base material (H, W, 3): a colour mottled by fractal noise, with fine grain."""
    rgb = np.clip(np.asarray(rgb, np.float32) + rng.normal(0, 0.03, 3), 0, 1)
    mottle = 1 + rng.uniform(0.1, 0.35) * (fractal_noise(rng, h, w, cells)[..., None] - 0.5)
    fine = rng.normal(0, grain, (h, w, 1)).astype(np.float32)
    return np.clip(rgb * mottle + fine, 0, 1).astype(np.float32)


def _asphalt(rng, h, w):
    return _material(rng, h, w, np.array([0.2, 0.2, 0.21]) * rng.uniform(0.6, 1.6), 0.03, 6)


def _grass(rng, h, w):
    rgb = np.array([0.3, 0.42, 0.16]) * rng.uniform(0.6, 1.3)
    if rng.random() < 0.35:
        rgb = np.array([0.6, 0.52, 0.32]) * rng.uniform(0.7, 1.2)  # dry grass
    return _material(rng, h, w, rgb, 0.04, 8)


def draw_road(rng: np.random.Generator, img: np.ndarray, res: float, centre, angle: float) -> None:
    """A road strip (5-16 m) through `centre` (px) at `angle` (rad) with sidewalks, kerbs and
    lane markings (double yellow, dashed and solid white, crosswalks), in place."""
    h, w = img.shape[:2]
    d = np.array([np.cos(angle), np.sin(angle)])
    n = np.array([-d[1], d[0]])
    reach = 2.0 * (h + w)
    half = rng.uniform(2.5, 8.0) / res

    def strip(offset_px: float, half_px: float, rgb) -> None:
        c = np.asarray(centre) + n * offset_px
        quad = np.array(
            [c - d * reach - n * half_px, c + d * reach - n * half_px,
             c + d * reach + n * half_px, c - d * reach + n * half_px]
        )  # fmt: skip
        cv2.fillPoly(
            img, [np.round(quad * 16).astype(np.int32)], [float(c) for c in rgb], cv2.LINE_AA, 4
        )

    if rng.random() < 0.6:  # sidewalks of light concrete
        walk = rng.uniform(1.2, 3.0) / res
        concrete = np.clip(rng.uniform(0.55, 0.8) + rng.normal(0, 0.03, 3), 0, 1)
        for side in (-1, 1):
            strip(side * (half + walk / 2 + rng.uniform(0, 2.0) / res), walk / 2, concrete)
    tarmac = np.clip(rng.uniform(0.12, 0.38) + rng.normal(0, 0.01, 3), 0, 1)
    strip(0.0, half, tarmac)
    kerb = np.clip(rng.uniform(0.5, 0.85) + rng.normal(0, 0.02, 3), 0, 1)
    for side in (-1, 1):
        a = np.asarray(centre) + n * side * half
        _line(img, a - d * reach, a + d * reach, kerb, 0.15 / res)
    white = np.clip(rng.uniform(0.75, 1.0) * np.ones(3) + rng.normal(0, 0.02, 3), 0, 1)
    yellow = np.clip(np.array([0.9, 0.75, 0.2]) * rng.uniform(0.7, 1.1), 0, 1)
    stroke = rng.uniform(0.1, 0.2) / res
    lanes = int(rng.integers(1, 3))
    marks = []
    if rng.random() < 0.6:
        gap = rng.uniform(0.15, 0.3) / res
        marks += [(-gap / 2, yellow, False), (gap / 2, yellow, False)]
    elif rng.random() < 0.6:
        marks.append((0.0, white, True))
    for k in range(1, lanes):
        for side in (-1, 1):
            marks.append((side * half * k / lanes, white, True))
    if rng.random() < 0.6:
        edge = half - 0.4 / res
        marks += [(-edge, white, False), (edge, white, False)]
    dash, period = rng.uniform(2, 4) / res, rng.uniform(6, 12) / res
    for offset, rgb, dashed in marks:
        a = np.asarray(centre) + n * offset
        if not dashed:
            _line(img, a - d * reach, a + d * reach, rgb, stroke)
            continue
        for s in np.arange(-reach, reach, period):
            _line(img, a + d * s, a + d * (s + dash), rgb, stroke)
    if rng.random() < 0.3:  # a crosswalk across the road
        at = np.asarray(centre) + d * rng.uniform(-0.3, 0.3) * min(h, w)
        bar = rng.uniform(0.4, 0.6) / res
        for k in np.arange(-half, half, 2 * bar):
            p = at + n * (k + bar / 2)
            _line(img, p - d * rng.uniform(1.5, 2.5) / res, p + d * 2.0 / res, white, bar)


def draw_parking(rng: np.random.Generator, img: np.ndarray, res: float) -> None:
    """Rows of parking stalls: many parallel thin white lines 2.4-3 m apart, in place."""
    h, w = img.shape[:2]
    angle = rng.uniform(0, np.pi)
    d, n = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
    white = np.clip(rng.uniform(0.7, 1.0) + rng.normal(0, 0.03, 3), 0, 1)
    if rng.random() < 0.25:
        white = np.clip(np.array([0.9, 0.78, 0.25]) * rng.uniform(0.7, 1.1), 0, 1)
    stall_w, stall_l = rng.uniform(2.4, 3.0) / res, rng.uniform(4.5, 5.5) / res
    aisle = rng.uniform(6, 8) / res
    stroke = rng.uniform(0.1, 0.15) / res
    centre = np.array([w, h]) * rng.uniform(0.2, 0.8, 2)
    extent = max(h, w)
    for row in np.arange(-extent, extent, 2 * stall_l + aisle):
        base = centre + n * row
        for s in np.arange(-extent, extent, stall_w):
            a = base + d * s
            _line(img, a, a + n * stall_l, white, stroke)
            _line(img, a + n * (stall_l + aisle), a + n * (2 * stall_l + aisle), white, stroke)
        if rng.random() < 0.5:
            _line(img, base - d * extent, base + d * extent, white, stroke)


def draw_roofs(rng: np.random.Generator, img: np.ndarray, res: float, sun_xy: np.ndarray) -> None:
    """Rectangular buildings seen from above: gable roofs with a ridge line and two shades,
    flat roofs with parapets, seams and vents, each with a shadow, in place."""
    h, w = img.shape[:2]
    for _ in range(int(rng.integers(1, 6))):
        c = np.array([rng.uniform(0, w), rng.uniform(0, h)])
        angle = rng.uniform(0, np.pi)
        d, n = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
        length, depth = rng.uniform(8, 40) / res, rng.uniform(6, 18) / res
        quad = np.array(
            [c - d * length / 2 - n * depth / 2, c + d * length / 2 - n * depth / 2,
             c + d * length / 2 + n * depth / 2, c - d * length / 2 + n * depth / 2]
        )  # fmt: skip
        shadow = quad + sun_xy * rng.uniform(2, 10) / res
        dark = img * rng.uniform(0.35, 0.6)
        sh = np.zeros((h, w), np.uint8)
        cv2.fillPoly(sh, [np.round(shadow * 16).astype(np.int32)], 1, cv2.LINE_AA, 4)
        img[sh > 0] = dark[sh > 0]
        base = np.clip(
            rng.choice([0.25, 0.45, 0.6, 0.75]) * np.array([1.0, 1.0, 1.0])
            + rng.normal(0, 0.04, 3)
            + (np.array([0.25, 0.0, -0.1]) if rng.random() < 0.3 else 0),
            0,
            1,
        )
        if rng.random() < 0.55:  # gable roof: two shades split by the ridge
            for side, shade in ((-1, rng.uniform(0.7, 0.95)), (1, rng.uniform(1.0, 1.25))):
                half = np.array([quad[0], quad[1], c + d * length / 2, c - d * length / 2])
                if side > 0:
                    half = np.array([c - d * length / 2, c + d * length / 2, quad[2], quad[3]])
                rgb = np.clip(base * shade, 0, 1)
                cv2.fillPoly(
                    img,
                    [np.round(half * 16).astype(np.int32)],
                    [float(c) for c in rgb],
                    cv2.LINE_AA,
                    4,
                )
            ridge = np.clip(base * rng.uniform(0.5, 1.4), 0, 1)
            _line(img, c - d * length / 2, c + d * length / 2, ridge, rng.uniform(0.1, 0.3) / res)
        else:  # flat roof: parapet edge, seams, vents
            cv2.fillPoly(
                img,
                [np.round(quad * 16).astype(np.int32)],
                [float(c) for c in base],
                cv2.LINE_AA,
                4,
            )
            edge = np.clip(base * rng.uniform(0.6, 1.4), 0, 1)
            for i in range(4):
                _line(img, quad[i], quad[(i + 1) % 4], edge, rng.uniform(0.2, 0.5) / res)
            seam = np.clip(base * rng.uniform(0.8, 1.2), 0, 1)
            for s in np.arange(-length / 2, length / 2, rng.uniform(1.0, 4.0) / res):
                a = c + d * s
                _line(img, a - n * depth / 2, a + n * depth / 2, seam, 0.05 / res)
            for _ in range(int(rng.integers(0, 5))):
                v = c + d * rng.uniform(-0.4, 0.4) * length + n * rng.uniform(-0.4, 0.4) * depth
                size = rng.uniform(0.5, 2.0) / res
                cv2.rectangle(
                    img,
                    tuple(np.int32(v)),
                    tuple(np.int32(v + size)),
                    [rng.uniform(0.3, 0.9)] * 3,
                    -1,
                )


def draw_trees(rng: np.random.Generator, img: np.ndarray, res: float, sun_xy: np.ndarray) -> None:
    """Tree crowns from above (1.5-6 m radius), shaded, with their shadows, in place."""
    h, w = img.shape[:2]
    count = int(rng.integers(1, 25))
    centres = np.stack([rng.uniform(0, w, count), rng.uniform(0, h, count)], 1)
    radii = rng.uniform(1.5, 6.0, count) / res
    shadow = np.zeros((h, w), np.float32)
    crown = np.zeros((h, w), np.float32)
    for c, r in zip(centres, radii, strict=True):
        off = c + sun_xy * r * rng.uniform(1.0, 2.5)
        cv2.circle(shadow, tuple(np.int32(off)), int(r), 1.0, -1, cv2.LINE_AA)
        cv2.circle(crown, tuple(np.int32(c)), int(r), 1.0, -1, cv2.LINE_AA)
    img *= 1 - 0.5 * shadow[..., None]
    leaves = cv2.resize(vegetation(rng, h // 2, w // 2), (w, h)) * rng.uniform(0.6, 1.3)
    if rng.random() < 0.2:  # leafless crowns: grey-brown
        leaves = leaves.mean(axis=2, keepdims=True) * np.array([1.3, 1.1, 0.9]) + 0.1
    alpha = np.clip(crown, 0, 1)[..., None]
    img[:] = img * (1 - alpha) + np.clip(leaves, 0, 1) * alpha


def draw_field_rows(rng: np.random.Generator, img: np.ndarray, res: float) -> None:
    """Crop rows, ploughed furrows or mown stripes: parallel lines 0.5-4 m apart, in place."""
    h, w = img.shape[:2]
    angle = rng.uniform(0, np.pi)
    d, n = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
    spacing = rng.uniform(0.5, 4.0) / res
    rgb = np.clip(img.reshape(-1, 3).mean(0) * rng.uniform(0.5, 1.5), 0, 1)
    width = spacing * rng.uniform(0.15, 0.5)
    reach = 2.0 * (h + w)
    c = np.array([w, h]) / 2
    for s in np.arange(-reach, reach, spacing):
        a = c + n * s
        _line(img, a - d * reach, a + d * reach, rgb, width)


def ground_texture(
    rng: np.random.Generator, size_px: int, metres_per_px: float, pool: PhotoPool | None
) -> np.ndarray:
    """(size, size, 3) float32 ground seen from straight above at `metres_per_px`.

    One of ``GROUND_KINDS``: urban streets, a parking lot, suburb (grass, roofs, trees, a road),
    rural fields with rows, forest canopy, water, snow, or a real photograph as the ground
    (when the pool has any), most with roads, roofs or trees drawn over them.
    """
    s, res = size_px, metres_per_px
    kinds = GROUND_KINDS if pool is not None and len(pool) else GROUND_KINDS[:-1]
    weights = np.asarray(_GROUND_WEIGHTS[: len(kinds)])
    kind = str(rng.choice(kinds, p=weights / weights.sum()))
    angle = rng.uniform(0, np.pi)
    sun = rng.uniform(0, 2 * np.pi)
    sun_xy = np.array([np.cos(sun), np.sin(sun)])
    centre = np.array([s, s]) * rng.uniform(0.25, 0.75, 2)
    if kind in ("urban", "parking"):
        img = _asphalt(rng, s, s) if rng.random() < 0.6 else _grass(rng, s, s)
        if kind == "parking":
            draw_parking(rng, img, res)
        for k in range(int(rng.integers(1, 3))):
            draw_road(rng, img, res, centre + rng.normal(0, s / 4, 2), angle + k * np.pi / 2)
        if rng.random() < 0.6:
            draw_roofs(rng, img, res, sun_xy)
        if rng.random() < 0.5:
            draw_trees(rng, img, res, sun_xy)
    elif kind == "suburb":
        img = _grass(rng, s, s)
        draw_road(rng, img, res, centre, angle)
        draw_roofs(rng, img, res, sun_xy)
        draw_trees(rng, img, res, sun_xy)
    elif kind == "rural":
        earth = np.array([0.45, 0.35, 0.22]) * rng.uniform(0.6, 1.4)
        img = _material(rng, s, s, earth, 0.04, 4) if rng.random() < 0.5 else _grass(rng, s, s)
        draw_field_rows(rng, img, res)
        if rng.random() < 0.5:
            draw_road(rng, img, res, centre, angle)
        if rng.random() < 0.5:
            draw_trees(rng, img, res, sun_xy)
    elif kind == "forest":
        img = vegetation(rng, s, s) * rng.uniform(0.5, 1.1)
        draw_trees(rng, img, res, sun_xy)
        draw_trees(rng, img, res, sun_xy)
        if rng.random() < 0.3:
            draw_road(rng, img, res, centre, angle)
    elif kind == "water":
        rgb = np.array([0.15, 0.25, 0.3]) * rng.uniform(0.5, 1.6)
        img = _material(rng, s, s, rgb, 0.01, 2)
        ripples = fractal_noise(rng, s, s, 40)[..., None]
        img = np.clip(img + rng.uniform(0.02, 0.12) * (ripples - 0.5), 0, 1)
        if rng.random() < 0.5:  # a shore
            shore = _grass(rng, s, s)
            mask = (fractal_noise(rng, s, s, 3) > rng.uniform(0.4, 0.7))[..., None]
            img = np.where(mask, shore, img)
    elif kind == "snow":
        img = _material(rng, s, s, np.array([0.88, 0.9, 0.94]) * rng.uniform(0.85, 1.05), 0.015, 5)
        if rng.random() < 0.6:
            draw_road(rng, img, res, centre, angle)
        if rng.random() < 0.5:
            draw_trees(rng, img, res, sun_xy)
        for _ in range(int(rng.integers(0, 4))):  # tyre or ski tracks
            a = rng.uniform(0, s, 2)
            track = np.clip(img.reshape(-1, 3).mean(0) * 0.8, 0, 1)
            _line(img, a, a + rng.normal(0, s, 2), track, 0.2 / res)
    else:
        img = photo_crop(rng, pool, s, s)
        if rng.random() < 0.3:
            draw_road(rng, img, res, centre, angle)
    return np.ascontiguousarray(np.clip(img, 0, 1), dtype=np.float32)


def ground_view(
    rng: np.random.Generator,
    sky_img: np.ndarray,
    camera: PinholeCamera,
    world_from_camera: Pose,
    pool: PhotoPool | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The ground texture seen by the camera at `world_from_camera` (NED) over `sky_img`
    (H, W, 3) float32:
    (image, (H, W) bool mask of the pixels whose rays meet the ground within ``_FAR_M``).

    The ground is hazed with distance (visibility 0.8-6 km) towards the mean sky colour.
    """
    h, w = sky_img.shape[:2]
    rays = world_from_camera.rotate(camera.pixel_rays().reshape(-1, 3)).reshape(h, w, 3)
    position = world_from_camera.translation_m
    hit, length = ground_hits(rays, position)
    ground = np.isfinite(length)
    if not ground.any():
        return sky_img, ground
    pts = hit[ground]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    extent = float((hi - lo).max())
    side = min(_TEXTURE_PX, 2 * max(h, w))
    res = max(_MIN_RES_M, extent / side)
    size = int(min(side, np.ceil(extent / res) + 2))
    texture = ground_texture(rng, size, res, pool)
    origin = (lo + hi) / 2 - res * size / 2
    scale = 2  # render at twice the size and average down, so that far texture does not alias
    up = np.array([[scale, 0, 0.5], [0, scale, 0.5], [0, 0, 1.0]])
    homography = up @ ground_homography(
        world_from_camera.rotation.T, position, camera.intrinsic_matrix(), origin, res
    )
    warped = cv2.warpPerspective(
        texture, homography, (w * scale, h * scale), flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REFLECT_101,
    )  # fmt: skip
    warped = cv2.resize(warped, (w, h), interpolation=cv2.INTER_AREA)
    haze_rgb = sky_img[~ground].mean(axis=0) if (~ground).any() else np.full(3, 0.75)
    haze = (1 - np.exp(-np.where(ground, length, 0.0) / rng.uniform(800, 6000)))[..., None]
    out = np.where(ground[..., None], warped * (1 - haze) + haze_rgb * haze, sky_img)
    return out.astype(np.float32), ground
