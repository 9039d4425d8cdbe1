"""Light: the radiance each pixel of the simulated colour camera receives (linear RGB).

- Sky: a zenith-to-horizon gradient, the sun's disc and glow, and clouds on a layer 1.5 km up
  (a periodic noise tile fixed in the world), all from `World.lighting`.
- Backdrop: a distant tree line and hills 400 m away all around (a silhouette fixed in
  azimuth, foliage-textured and hazed), so the horizon is never a long straight edge.
- Surfaces: the material's texture (`hil.sensors.textures`, fixed in world coordinates) lit
  by Lambert's law, sun `E_sun max(0, n.s)` plus a sky ambient that favours upward faces;
  solids cast shadows on the ground (their box projected along the sun onto the ground plane).
- Aerial perspective: radiance fades into the horizon haze colour with distance.
- Wires: a cylinder's diffuse light (brighter when the sun is across the wire and on the
  camera's side), with their albedo, over the background by their coverage.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from geometry.camera import PinholeCamera
from geometry.pose import Pose
from hil.sensors.raycast import GROUND, NEAR_M, SKY, SceneHits
from hil.sensors.textures import TextureAtlas, fractal
from hil.world.model import World

BACKDROP_M = 400.0
_CLOUD_HEIGHT_M = 1500.0
_CLOUD_TILE_M = 6000.0
_SUN_RADIUS_RAD = 0.0047


@dataclass(frozen=True)
class SkyModel:
    """The world's fixed sky: colours, sun, cloud tile, backdrop silhouette (see module)."""

    sun_ned: np.ndarray
    zenith_rgb: np.ndarray
    horizon_rgb: np.ndarray
    sun_rgb: np.ndarray
    ambient_rgb: np.ndarray
    visibility_m: float
    cloud_cover: float
    clouds: np.ndarray  # (512, 512) float32 periodic, [0, 1]
    cloud_shade: np.ndarray  # (512, 512) float32
    silhouette_rad: np.ndarray  # (4096,) elevation of the backdrop's top by azimuth

    @classmethod
    def build(cls, world: World) -> SkyModel:
        light = world.lighting
        rng = np.random.default_rng([world.seed, 7001])
        cover = light.cloud_cover
        clear = 1.0 - cover
        zenith = clear * np.array([0.10, 0.22, 0.55]) + cover * np.array([0.45, 0.47, 0.50])
        horizon = clear * np.array([0.55, 0.65, 0.80]) + cover * np.array([0.62, 0.63, 0.65])
        horizon = horizon * (1 - 0.4 * light.haze) + 0.4 * light.haze * np.array([0.8, 0.8, 0.78])
        low_sun = np.exp(-light.sun_elevation_rad / 0.25)  # warmer light near the horizon
        sun = (3.2 * clear**1.5) * np.array([1.0, 0.95 - 0.15 * low_sun, 0.88 - 0.3 * low_sun])
        ambient = 0.55 * (zenith + horizon) * (0.8 + 0.6 * cover)
        hills = _periodic_profile(rng, 4096, 6, 5) * rng.uniform(3.0, 20.0)
        trees = _periodic_profile(rng, 4096, 300, 4) * rng.uniform(3.0, 9.0)
        gaps = _periodic_profile(rng, 4096, 40, 2) > rng.uniform(0.15, 0.35)  # open fields
        height = hills + np.where(gaps, trees + 4.0, 0.5 * trees)
        return cls(
            sun_ned=light.sun_direction_ned().astype(np.float32),
            zenith_rgb=zenith.astype(np.float32),
            horizon_rgb=horizon.astype(np.float32),
            sun_rgb=sun.astype(np.float32),
            ambient_rgb=ambient.astype(np.float32),
            visibility_m=float(300.0 * (10000.0 / 300.0) ** (1.0 - light.haze)),
            cloud_cover=cover,
            clouds=fractal(rng, 512, 4, 7),
            cloud_shade=fractal(rng, 512, 8, 5),
            silhouette_rad=np.arctan(height / BACKDROP_M).astype(np.float32),
        )


def _periodic_profile(rng: np.random.Generator, n: int, knots: int, octaves: int) -> np.ndarray:
    """`(n,)` periodic 1-D fractal noise in [0, 1] (linear between random knots)."""
    x = np.arange(n) / n
    out = np.zeros(n)
    amplitude = 1.0
    for _ in range(octaves):
        values = rng.random(knots + 1)
        values[-1] = values[0]
        out += amplitude * np.interp(x * knots, np.arange(knots + 1), values)
        amplitude *= 0.5
        knots *= 2
    out -= out.min()
    return out / max(out.max(), 1e-9)


def _tile_lookup(tile: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Nearest texel of a periodic square tile at texel coordinates (u, v)."""
    n = tile.shape[0]
    return tile[np.floor(v).astype(np.int64) % n, np.floor(u).astype(np.int64) % n]


def sky_radiance(sky: SkyModel, unit_dirs: np.ndarray) -> np.ndarray:
    """`(N, 3)` radiance of the sky towards `(N, 3)` unit NED directions (no backdrop, no
    sun disc: `surface_radiance` adds it per pixel)."""
    up = -unit_dirs[:, 2]
    elevation = np.clip(up, 0.0, 1.0)
    t = ((1.0 - elevation) ** 4)[:, None]
    rgb = sky.zenith_rgb * (1 - t) + sky.horizon_rgb * t
    cos_sun = np.clip(unit_dirs @ sky.sun_ned, -1.0, 1.0)
    angle = np.arccos(cos_sun)
    clear = 1.0 - sky.cloud_cover
    glow = clear * (1.5 * np.exp(-angle / 0.05) + 0.35 * np.exp(-angle / 0.35)) + 0.15 * np.exp(
        -angle / 0.6
    )
    rgb = rgb + glow[:, None] * sky.sun_rgb / 3.2
    cloudy = up > 0.01
    if cloudy.any() and sky.cloud_cover > 0:
        d = unit_dirs[cloudy]
        scale = _CLOUD_HEIGHT_M / up[cloudy] * sky.clouds.shape[0] / _CLOUD_TILE_M
        u, v = d[:, 1] * scale, d[:, 0] * scale
        density = _tile_lookup(sky.clouds, u, v)
        alpha = np.clip((density - (1.0 - sky.cloud_cover)) / 0.25, 0.0, 1.0)
        alpha *= np.clip(up[cloudy] / 0.12, 0.0, 1.0)
        shade = 0.65 + 0.35 * _tile_lookup(sky.cloud_shade, u * 2, v * 2)
        lit = 0.75 + 0.35 * glow[cloudy] + 0.4 * clear
        cloud = (shade * lit)[:, None] * np.array([0.95, 0.95, 0.97], np.float32)
        rgb[cloudy] = rgb[cloudy] * (1 - alpha[:, None]) + cloud * alpha[:, None]
    return rgb.astype(np.float32)


def _smooth_sky(sky: SkyModel, direction_planes: np.ndarray) -> np.ndarray:
    """`(H, W, 3)` sky radiance for every pixel, computed on 2x2 blocks (whose mean ray is
    the block centre's: rays are linear in the pixel) and interpolated back: the sky is
    smooth at that scale, and this is a quarter of the work."""
    _, h, w = direction_planes.shape
    small = np.stack(
        [
            cv2.resize(p, (-(-w // 2), -(-h // 2)), interpolation=cv2.INTER_AREA)
            for p in direction_planes
        ]
    )
    unit = small / np.sqrt((small**2).sum(axis=0))
    radiance = sky_radiance(sky, unit.reshape(3, -1).T).reshape(*small.shape[1:], 3)
    return cv2.resize(radiance, (w, h), interpolation=cv2.INTER_LINEAR)


def haze(sky: SkyModel, radiance: np.ndarray, distance_m: np.ndarray) -> np.ndarray:
    """Aerial perspective: `(N, 3)` radiance seen through `(N,)` m of air."""
    transmission = np.exp(-distance_m / sky.visibility_m)[:, None]
    return radiance * transmission + sky.horizon_rgb * (1.0 - transmission)


def ground_shadow(
    world: World, camera: PinholeCamera, world_from_cam: Pose, sky: SkyModel
) -> np.ndarray:
    """`(H, W) float32` in [0, 1]: how much of the sun the ground at each pixel loses to the
    solids' shadows (exact on the ground plane; only meaningful on ground pixels).

    A box's shadow on the ground is its bottom face projected along the sun swept to its top
    face's projection: the Minkowski sum of a rectangle and a segment, a convex hexagon.
    """
    h, w = camera.shape
    shadow = np.zeros((h, w), np.float32)
    s = sky.sun_ned.astype(np.float64)
    if s[2] > -1e-3 or sky.cloud_cover >= 1.0 or not world.solids:
        return shadow
    g = world.ground_down_m
    lo = np.array([solid.box.min_ned_m for solid in world.solids])
    hi = np.array([solid.box.max_ned_m for solid in world.solids])
    along = -s[:2] / s[2]  # ground shift per metre of height
    low = (g - np.minimum(hi[:, 2], g))[:, None] * along  # (S, 2) shift of the bottom face
    high = (g - lo[:, 2])[:, None] * along  # of the top face
    # rectangle corners counter-clockwise in (north, east), then swept from low to high: the
    # hexagon keeps the corners facing away from and towards the sweep
    n0, e0, n1, e1 = lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]
    rect = np.stack(
        [
            np.stack([n0, e0], 1),
            np.stack([n1, e0], 1),
            np.stack([n1, e1], 1),
            np.stack([n0, e1], 1),
        ],
        axis=1,
    )  # (S, 4, 2)
    polygons = np.concatenate([rect + low[:, None], rect + high[:, None]], axis=1)  # (S, 8, 2)
    points = np.concatenate([polygons, np.full((*polygons.shape[:2], 1), g)], axis=2)
    camera_from_world = world_from_cam.inverse()
    pc = camera_from_world.apply(points.reshape(-1, 3)).reshape(-1, 8, 3)
    for k in np.flatnonzero((pc[..., 2] > NEAR_M).any(axis=1)):
        flat = polygons[k].astype(np.float32)
        hull = cv2.convexHull(flat, returnPoints=False).ravel()
        ring = pc[k, hull]
        if (ring[:, 2] <= NEAR_M).any():
            ring = _clip_near(ring)
            if len(ring) < 3:
                continue
        uv = np.column_stack(
            [
                camera.fx_px * ring[:, 0] / ring[:, 2] + camera.cx_px,
                camera.fy_px * ring[:, 1] / ring[:, 2] + camera.cy_px,
            ]
        )
        pts = np.round(np.clip(uv, -1e5, 1e5) * 16).astype(np.int32)
        cv2.fillConvexPoly(shadow, pts, 1.0, cv2.LINE_AA, 4)
    return np.minimum(shadow, 1.0) * (1.0 - sky.cloud_cover)


def _clip_near(polygon_cam: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman clip of a camera-frame polygon to z >= NEAR_M."""
    out = []
    n = len(polygon_cam)
    for i in range(n):
        p, q = polygon_cam[i], polygon_cam[(i + 1) % n]
        p_in, q_in = p[2] >= NEAR_M, q[2] >= NEAR_M
        if p_in:
            out.append(p)
        if p_in != q_in:
            t = (NEAR_M - p[2]) / (q[2] - p[2])
            out.append(p + t * (q - p))
    return np.array(out).reshape(-1, 3)


@dataclass(frozen=True)
class SurfaceLook:
    """Per-surface look-up tables, indexed by `SceneHits.surface + 1` (sky, ground, solids,
    boards): atlas material row, albedo scale, texture-coordinate offsets (m)."""

    material: np.ndarray
    albedo: np.ndarray
    offset_m: np.ndarray

    @classmethod
    def build(cls, world: World, atlas: TextureAtlas) -> SurfaceLook:
        ground = atlas.index[world.ground_material]
        materials = [ground, ground] + [atlas.index[s.material] for s in world.solids]
        materials += [atlas.index["plain"]] * len(world.boards)
        albedo = [1.0, 1.0] + [s.albedo / 0.6 for s in world.solids] + [1.0] * len(world.boards)
        k = np.arange(len(materials), dtype=np.float64)
        offsets = np.stack([(k * 7.31) % 97.0, (k * 3.17) % 89.0], axis=1)
        offsets[:2] = 0.0
        return cls(np.array(materials), np.array(albedo, np.float32), offsets)


def surface_radiance(
    world: World,
    hits: SceneHits,
    camera: PinholeCamera,
    world_from_cam: Pose,
    atlas: TextureAtlas,
    look: SurfaceLook,
    sky: SkyModel,
) -> np.ndarray:
    """`(H, W, 3) float32` linear radiance of every pixel without wires (see module)."""
    h, w = camera.shape
    out = np.empty((h, w, 3), np.float32)
    planes = hits.direction_planes
    ray_length = np.sqrt(planes[0] * planes[0] + planes[1] * planes[1] + planes[2] * planes[2])
    distance = hits.depth_m * ray_length
    sin_elevation = -planes[2] / ray_length
    far = (hits.surface == SKY) | (distance > BACKDROP_M)
    # only pixels near the horizon can see the backdrop: angles for those alone
    band = far & (sin_elevation < np.sin(sky.silhouette_rad.max())) & (sin_elevation > -0.2)
    azimuth = np.arctan2(planes[1][band], planes[0][band])
    elevation = np.arcsin(np.clip(sin_elevation[band], -1.0, 1.0))
    slots = len(sky.silhouette_rad)
    index = ((azimuth % (2 * np.pi)) * (slots / (2 * np.pi))).astype(np.int64) % slots
    ridge = sky.silhouette_rad[index]
    below = elevation < ridge
    backdrop = np.zeros_like(band)
    backdrop[band] = below
    open_sky = (hits.surface == SKY) & ~backdrop
    if open_sky.any():
        out[open_sky] = _smooth_sky(sky, hits.direction_planes)[open_sky]
        # the sun's disc, at least a pixel wide (it blooms), drawn at full resolution
        cos_sun = (planes[:, open_sky].T @ sky.sun_ned) / ray_length[open_sky]
        radius = max(_SUN_RADIUS_RAD, 1.0 / camera.fx_px)
        disc = cos_sun > np.cos(radius)
        if disc.any():
            rows = np.flatnonzero(open_sky.ravel())[disc]
            out.reshape(-1, 3)[rows] += 60.0 * (1.0 - sky.cloud_cover)
    if backdrop.any():
        count = int(backdrop.sum())
        albedo = atlas.sample(
            np.full(count, atlas.index["foliage"]),
            azimuth[below] * BACKDROP_M,
            (ridge[below] - elevation[below]) * BACKDROP_M,
            np.full(count, BACKDROP_M / camera.fx_px),
        )
        lit = albedo * (sky.ambient_rgb + 0.5 * sky.sun_rgb * max(-float(sky.sun_ned[2]), 0.0))
        out[backdrop] = haze(sky, lit, np.full(count, BACKDROP_M))
    solid = ~open_sky & ~backdrop
    if solid.any():
        lit = _lit_surfaces(world, hits, camera, world_from_cam, atlas, look, sky, solid)
        out[solid] = haze(sky, lit, distance[solid])
    return out


def _lit_surfaces(
    world: World,
    hits: SceneHits,
    camera: PinholeCamera,
    world_from_cam: Pose,
    atlas: TextureAtlas,
    look: SurfaceLook,
    sky: SkyModel,
    which: np.ndarray,
) -> np.ndarray:
    """Lambert-lit textured radiance `(K, 3)` of the flat pixels selected by `which`."""
    surface = hits.surface[which]
    axis = hits.axis[which].astype(np.int64)
    sign = hits.sign[which].astype(np.float32)
    directions = hits.directions(which)
    depth = hits.depth_m[which]
    points = hits.origin_ned_m.astype(np.float32) + directions * depth[:, None]
    ray_length = np.sqrt((directions**2).sum(axis=1))
    slot = surface + 1
    # texture axes: faces normal to north -> (east, down); to east -> (north, down); else (n, e)
    rows = np.arange(len(points))
    a = points[rows, np.where(axis == 0, 1, 0)] + look.offset_m[slot, 0]
    b = points[rows, np.where(axis == 2, 1, 2)] + look.offset_m[slot, 1]
    cos_incidence = np.abs(directions[rows, axis]) / ray_length
    footprint = depth * ray_length / camera.fx_px / np.maximum(cos_incidence, 0.08)
    albedo = atlas.sample(look.material[slot], a, b, footprint) * look.albedo[slot][:, None]
    boards = surface > len(world.solids)
    if boards.any():
        black = hits.board_black[which][boards]
        albedo[boards] = np.where(black, 0.03, 0.75)[:, None]
    sunlit = np.maximum(sign * sky.sun_ned[axis], 0.0)
    up = np.where(axis == 2, -sign, 0.0)
    on_ground = surface == GROUND
    if on_ground.any():
        shadow = ground_shadow(world, camera, world_from_cam, sky)[which]
        sunlit = np.where(on_ground, sunlit * (1.0 - shadow), sunlit)
    irradiance = sky.ambient_rgb * (0.55 + 0.3 * up)[:, None] + sky.sun_rgb * sunlit[:, None]
    return albedo * irradiance


def wire_radiance(
    world: World,
    sky: SkyModel,
    tangent_ned: np.ndarray,
    wire: np.ndarray,
    view_ned: np.ndarray,
    specular: float,
    gloss: float,
) -> np.ndarray:
    """`(N, 3)` radiance of wire pixels: `tangent_ned` (N, 3) wire directions, `wire` (N,)
    indices, `view_ned` (N, 3) unit directions from the camera to the wire; `specular` and
    `gloss` add the sun's glint (`wire_glint`)."""
    albedo = np.array(world.wire_albedos, np.float32)[wire]
    s = sky.sun_ned
    along = tangent_ned @ s
    across = np.sqrt(np.maximum(1.0 - along**2, 0.0))  # sun perpendicular to the wire: bright
    # the share of the lit half-cylinder the camera sees (1 with the sun behind the camera)
    s_perp = s[None, :] - along[:, None] * tangent_ned
    view_along = (view_ned * tangent_ned).sum(1)
    v_perp = -view_ned + view_along[:, None] * tangent_ned
    cos_phase = (s_perp * v_perp).sum(1) / np.maximum(
        np.linalg.norm(s_perp, axis=1) * np.linalg.norm(v_perp, axis=1), 1e-6
    )
    diffuse = across * 0.5 * (1.0 + cos_phase) * 0.7
    irradiance = sky.ambient_rgb * 0.6 + sky.sun_rgb * diffuse[:, None]
    radiance = albedo[:, None] * irradiance
    if specular > 0:
        glint = wire_glint(along, -view_along, gloss)
        radiance = radiance + specular * glint[:, None] * sky.sun_rgb
    return radiance


def wire_glint(sun_along: np.ndarray, eye_along: np.ndarray, gloss: float) -> np.ndarray:
    """`(N,)` Kajiya-Kay highlight of a cylinder, (sin_L sin_E - cos_L cos_E)^gloss: a mirror
    cylinder reflects the sun into a cone about its axis (the reflection keeps the light's
    component along the axis, reversed), so it glints where the eye lies on that cone.
    `sun_along`, `eye_along`: cosines of the directions to the sun and to the eye with the
    wire's axis."""
    sin_sun = np.sqrt(np.maximum(1.0 - sun_along**2, 0.0))
    sin_eye = np.sqrt(np.maximum(1.0 - eye_along**2, 0.0))
    return np.maximum(sin_sun * sin_eye - sun_along * eye_along, 0.0) ** gloss
