"""The simulated camera rig of the SIL harness: stereo disparity and a registered colour camera.

`SimulatedStereoCamera.render(stamp_s, world_from_body)` exposes one frame at the vehicle's
true pose (body FRD in NED; the cameras are mounted on the body and tilt with it):

- colour (`image_bgr`): the stereo reference camera pooled by `colour_downscale` (320x240 from
  640x480, registered as an OAK-D's depth-aligned colour). Linear radiance from
  `hil.sensors.shading` (sky, backdrop, textured and lit surfaces, shadows, haze) with wires
  drawn sub-pixel and anti-aliased (`hil.sensors.wires`), then the sensor: optics blur,
  vignetting, auto exposure, shot and read noise, saturation, gamma, 8 bits.
- disparity (`disparity_px`, the rig's resolution, float32 px): d = b f / z (eq. 4.1) of the
  true depth plus N(0, sigma^2) noise, sigma = `disparity_noise_px` (4.4.2; independent of the
  sigma the mapper assumes); 0 where nothing is within `max_range_m` (sky); NaN (invalid)
  where stereo cannot match: texture-less surfaces (local contrast of the colour image below
  `textureless_contrast_dn`) and over-exposed pixels. Wires only where at least
  `stereo_min_wire_width_px` wide, and then with holes (`stereo_wire_fill`). With
  `stereo_mode = "sgbm"` the rectified pair is rendered and OpenCV SGBM of
  `mapping.droan.stereo` computes the disparity instead.
- truth for tests and benchmarks: `wire_mask` and `depth_m` at the rig's resolution,
  `image_wire_mask` at the colour resolution (never fed to the flight software as detections).

Everything is deterministic from (world seed, `seed`, stamp).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import cv2
import numpy as np

from geometry.camera import PinholeCamera, StereoRig, world_from_camera
from geometry.pose import Pose
from hil.sensors.params import CameraSimParams
from hil.sensors.raycast import SceneHits, cast
from hil.sensors.shading import SkyModel, SurfaceLook, surface_radiance, wire_radiance
from hil.sensors.textures import TextureAtlas, photo_textures
from hil.sensors.wires import WireLayer, project_wires
from hil.world.model import World
from mapping.droan.params import MappingParams, StereoMatchParams
from mapping.droan.stereo import disparity_from_pair, sgbm_matcher

if TYPE_CHECKING:
    from hil.vehicle.multirotor import RigidBodyState

_COLOUR_SUPERSAMPLING = 4
_RIG_SUPERSAMPLING = 2
_NOISE, _SENSOR, _HOLES, _SENSOR_RIGHT = 0, 1, 2, 3
_GAMMA_DN = (255.0 * np.linspace(0.0, 1.0, 4096) ** (1 / 2.2)).astype(np.float32)
"""8-bit level of a linear signal in [0, 1] (display gamma 2.2), tabulated."""


@dataclass(frozen=True, slots=True)
class SimulatedFrame:
    """One simulated exposure of the rig at `stamp_s` (s, simulated time).

    disparity_px: `(H, W) float32` at the rig's resolution, px (NaN invalid, 0 no return).
    image_bgr: `(h, w, 3) uint8` colour image, h = H / colour_downscale.
    wire_mask: `(H, W) bool` true wire pixels registered to the disparity (truth).
    depth_m: `(H, W) float32` true camera-z depth of the scene without wires, inf = none.
    image_wire_mask: `(h, w) bool` true wire pixels of the colour image (truth).
    """

    stamp_s: float
    world_from_body: Pose
    world_from_camera: Pose
    disparity_px: np.ndarray
    image_bgr: np.ndarray
    wire_mask: np.ndarray
    depth_m: np.ndarray
    image_wire_mask: np.ndarray


@dataclass(frozen=True, slots=True)
class ColourExposure:
    """The colour camera's exposure: the image, its truth, and where stereo cannot match.

    image_bgr: `(h, w, 3) uint8`. wire_mask: `(h, w) bool` truth. textureless, overexposed:
    `(h, w) bool` where stereo finds nothing to match. gain: the auto exposure's gain.
    """

    image_bgr: np.ndarray
    wire_mask: np.ndarray
    textureless: np.ndarray
    overexposed: np.ndarray
    gain: float


@dataclass(frozen=True, slots=True)
class DisparityExposure:
    """The stereo camera's exposure, all `(H, W)` at the rig's resolution: `disparity_px`
    (float32 px, NaN invalid, 0 no return) and the truth `wire_mask` (bool) and `depth_m`."""

    disparity_px: np.ndarray
    wire_mask: np.ndarray
    depth_m: np.ndarray


@lru_cache(maxsize=8)
def _atlas(seed: int, sources: tuple[str, ...]) -> TextureAtlas:
    return TextureAtlas.build(seed, photo_textures(list(sources)))


class SimulatedStereoCamera:
    """Renders `SimulatedFrame`s of a `World` for vehicle poses (a camera source for SIL).

    rig: the stereo rig (its reference camera sets the disparity resolution).
    body_from_camera: the mount of the reference camera on the body (FRD).
    stereo_match: the SGBM settings for `stereo_mode = "sgbm"` (default `MappingParams()`'s).
    colour_downscale: the colour camera is the reference camera pooled by this integer factor
        (the product's `camera.colour_downscale`: what the OAK-D is configured to deliver).
    """

    def __init__(
        self,
        world: World,
        rig: StereoRig,
        body_from_camera: Pose,
        params: CameraSimParams,
        stereo_match: StereoMatchParams | None = None,
        max_disparity_px: int = 128,
        *,
        colour_downscale: int,
    ) -> None:
        self.world = world
        self.rig = rig
        self.body_from_camera = body_from_camera
        self.params = params
        self.colour_downscale = colour_downscale
        self.colour_camera = rig.camera.scaled(colour_downscale)
        self._stereo_match = stereo_match or MappingParams().stereo
        self._max_disparity_px = max_disparity_px
        self._atlas = _atlas(world.seed, tuple(params.photo_sources))
        self._look = SurfaceLook.build(world, self._atlas)
        self._sky = SkyModel.build(world)
        self._rays: dict[PinholeCamera, np.ndarray] = {}
        self._vignette: dict[PinholeCamera, np.ndarray] = {}

    def _pixel_planes(self, camera: PinholeCamera) -> np.ndarray:
        """`(2, H, W) float32` ray slopes of `camera`'s pixels (see `raycast.cast`)."""
        if camera not in self._rays:
            rays = camera.pixel_rays()
            self._rays[camera] = np.ascontiguousarray(rays[..., :2].transpose(2, 0, 1), np.float32)
        return self._rays[camera]

    def _vignetting(self, camera: PinholeCamera) -> np.ndarray:
        """`(H, W, 1) float32` relative illumination, cos^4-like falloff to the corners."""
        if camera not in self._vignette:
            x, y = self._pixel_planes(camera)
            cos = 1.0 / np.sqrt(x * x + y * y + 1.0)
            corner = float(cos.min())
            falloff = (cos**4 - corner**4) / max(1.0 - corner**4, 1e-6)
            self._vignette[camera] = (1.0 - self.params.vignetting * (1.0 - falloff))[
                ..., None
            ].astype(np.float32)
        return self._vignette[camera]

    def _rng(self, stamp_s: float, stream: int) -> np.random.Generator:
        return np.random.default_rng([self.params.seed, round(stamp_s * 1e6), stream])

    def _radiance(
        self, camera: PinholeCamera, pose: Pose, supersampling: int
    ) -> tuple[np.ndarray, SceneHits, WireLayer, np.ndarray]:
        """Linear radiance `(H, W, 3)` with wires, the scene hits, the wires, and the visible
        wire pixels `(H, W) bool` of `camera` at `pose`."""
        hits = cast(self.world, camera, pose, self._pixel_planes(camera))
        radiance = surface_radiance(
            self.world, hits, camera, pose, self._atlas, self._look, self._sky
        )
        wires = project_wires(self.world, camera, pose, supersampling)
        visible = np.isfinite(wires.depth_m) & (wires.depth_m < hits.depth_m)
        if visible.any():
            rows = np.flatnonzero(visible.ravel())
            view = hits.directions(visible)
            view = view / np.linalg.norm(view, axis=1, keepdims=True)
            lit = wire_radiance(
                self.world,
                self._sky,
                wires.tangent_ned.reshape(-1, 3)[rows],
                wires.wire.ravel()[rows],
                view,
                self.params.wire_specular,
                self.params.wire_gloss,
            )
            flat = radiance.reshape(-1, 3)
            cover = wires.coverage.ravel()[rows][:, None]
            flat[rows] = flat[rows] * (1.0 - cover) + lit * cover
        return radiance, hits, wires, visible

    def _expose(
        self, radiance: np.ndarray, camera: PinholeCamera, rng: np.random.Generator, gain: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """The sensor: blur, vignetting, gain, noise, saturation, gamma. Returns the `uint8`
        image and the noise-free 8-bit signal (float32), both `(H, W, 3)`."""
        p = self.params
        signal = radiance
        if p.blur_sigma_px > 0:
            signal = cv2.GaussianBlur(signal, (0, 0), p.blur_sigma_px)
        signal = np.clip(signal * self._vignetting(camera) * gain, 0.0, 1.0)
        clean = _GAMMA_DN[(signal * (len(_GAMMA_DN) - 1) + 0.5).astype(np.int32)]
        sigma = np.sqrt(p.read_noise_dn**2 + p.shot_noise_dn * clean)
        noisy = clean + sigma * rng.standard_normal(clean.shape, dtype=np.float32)
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8), clean

    def _gain(self, radiance: np.ndarray) -> float:
        """Auto exposure: the gain that brings the mean (clipped) signal to the target."""
        luminance = np.minimum(cv2.cvtColor(radiance, cv2.COLOR_RGB2GRAY), 2.0)
        return float(np.clip(self.params.exposure_target / max(luminance.mean(), 1e-4), 0.2, 50))

    def render_colour(self, stamp_s: float, world_from_body: Pose) -> ColourExposure:
        """The colour camera's exposure at `stamp_s` (s) from the vehicle pose."""
        pose = world_from_camera(world_from_body, self.body_from_camera)
        camera = self.colour_camera
        radiance, _, wires, visible = self._radiance(camera, pose, _COLOUR_SUPERSAMPLING)
        gain = self._gain(radiance)
        image, clean = self._expose(radiance, camera, self._rng(stamp_s, _SENSOR), gain)
        grey = cv2.cvtColor(clean, cv2.COLOR_RGB2GRAY)
        window = (self.params.matching_window_px,) * 2
        mean = cv2.blur(grey, window)
        contrast = np.sqrt(np.maximum(cv2.blur(grey * grey, window) - mean * mean, 0.0))
        brightest = np.maximum(np.maximum(clean[..., 0], clean[..., 1]), clean[..., 2])
        overexposed = cv2.dilate((brightest >= 254.0).astype(np.uint8), np.ones((3, 3)))
        return ColourExposure(
            image[..., ::-1].copy(),
            wires.label & visible,
            contrast < self.params.textureless_contrast_dn,
            overexposed > 0,
            gain,
        )

    def render_disparity(
        self, stamp_s: float, world_from_body: Pose, colour: ColourExposure
    ) -> DisparityExposure:
        """The stereo exposure at `stamp_s` (s); `colour` is the same instant's colour exposure
        (its texture and glare decide where stereo cannot match)."""
        pose = world_from_camera(world_from_body, self.body_from_camera)
        camera = self.rig.camera
        hits = cast(self.world, camera, pose, self._pixel_planes(camera))
        wires = project_wires(self.world, camera, pose, _RIG_SUPERSAMPLING)
        visible = np.isfinite(wires.depth_m) & (wires.depth_m < hits.depth_m)
        if self.params.stereo_mode == "sgbm":
            disparity = self._sgbm_disparity(stamp_s, pose, colour.gain)
        else:
            disparity = self._model_disparity(stamp_s, hits, wires, visible, colour)
        return DisparityExposure(disparity, wires.label & visible, hits.depth_m)

    def render(self, stamp_s: float, world_from_body: Pose) -> SimulatedFrame:
        """The frame exposed at `stamp_s` (s) with the vehicle at `world_from_body`."""
        colour = self.render_colour(stamp_s, world_from_body)
        stereo = self.render_disparity(stamp_s, world_from_body, colour)
        return SimulatedFrame(
            float(stamp_s),
            world_from_body,
            world_from_camera(world_from_body, self.body_from_camera),
            stereo.disparity_px,
            colour.image_bgr,
            stereo.wire_mask,
            stereo.depth_m,
            colour.wire_mask,
        )

    def _model_disparity(
        self,
        stamp_s: float,
        hits: SceneHits,
        wires: WireLayer,
        visible: np.ndarray,
        colour: ColourExposure,
    ) -> np.ndarray:
        """The thesis' sensor model (eq. 4.1 + N(0, sigma^2), 4.4.2), see module docstring."""
        p = self.params
        h, w = hits.depth_m.shape
        rng = self._rng(stamp_s, _HOLES)
        cells = rng.random((-(-h // 4), -(-w // 4)), dtype=np.float32)
        matched = np.repeat(np.repeat(cells, 4, 0), 4, 1)[:h, :w] < p.stereo_wire_fill
        stereo_wire = visible & (wires.width_px >= p.stereo_min_wire_width_px) & matched
        depth = np.where(stereo_wire, wires.depth_m, hits.depth_m)
        in_range = depth <= p.max_range_m
        noise = p.disparity_noise_px * self._rng(stamp_s, _NOISE).standard_normal(
            (h, w), dtype=np.float32
        )
        bf = np.float32(self.rig.bf_px_m)
        disparity = np.where(in_range, bf / np.where(in_range, depth, 1.0) + noise, 0.0)
        disparity = np.maximum(disparity, 0.0).astype(np.float32)
        k = self.colour_downscale

        def upscaled(mask: np.ndarray) -> np.ndarray:
            return np.repeat(np.repeat(mask, k, 0), k, 1)[:h, :w]

        # the sky is texture-less by nature (no return: 0); only its glare is invalid
        invalid = (upscaled(colour.textureless) & in_range) | upscaled(colour.overexposed)
        disparity[invalid & ~stereo_wire] = np.nan
        return disparity

    def _sgbm_disparity(self, stamp_s: float, pose: Pose, gain: float) -> np.ndarray:
        """OpenCV SGBM (`mapping.droan.stereo`) on the rendered rectified pair."""
        left, right = self._pair(stamp_s, pose, gain)
        matcher = sgbm_matcher(self._stereo_match, self._max_disparity_px)
        return disparity_from_pair(matcher, left, right)

    def _pair(self, stamp_s: float, left_pose: Pose, gain: float | None) -> tuple[np.ndarray, ...]:
        right_pose = left_pose.compose(self.rig.left_from_right())
        camera = self.rig.camera
        images = []
        for pose, stream in ((left_pose, _SENSOR), (right_pose, _SENSOR_RIGHT)):
            radiance = self._radiance(camera, pose, _RIG_SUPERSAMPLING)[0]
            gain = self._gain(radiance) if gain is None else gain
            image, _ = self._expose(radiance, camera, self._rng(stamp_s, stream), gain)
            images.append(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY))
        return images[0], images[1]

    def render_state(self, state: RigidBodyState) -> SimulatedFrame:
        """The frame exposed at the simulated vehicle's ground-truth state."""
        world_from_body = Pose.from_quaternion(state.attitude_wxyz, state.position_ned_m)
        return self.render(state.time_s, world_from_body)

    def render_pair(
        self, world_from_body: Pose, stamp_s: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rectified `(H, W) uint8` grey left and right images at the rig's resolution (for
        SGBM and calibration), exposed alike."""
        pose = world_from_camera(world_from_body, self.body_from_camera)
        return self._pair(stamp_s, pose, None)
