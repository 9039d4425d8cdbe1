"""Parameters of the simulated cameras (SIL harness): the `[camera_sim]` settings.

The camera geometry itself (intrinsics, baseline, mount) is `mapping.camera_*`
(`geometry.camera.StereoCameraParams`), shared with the real camera so the simulation flies
what the product maps. Everything here is the simulated sensor's own behaviour: in particular
`disparity_noise_px` is the noise the simulator injects, independent of
`mapping.disparity_sigma_px`, the noise the mapper assumes (thesis 4.4.2 calibrates the one to
the other; `wireavoid calibrate-sigma` measures it).
"""

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class CameraSimParams(BaseModel):
    """Rendering and sensor-error model of the simulated stereo + colour camera."""

    model_config = ConfigDict(extra="forbid")

    seed: int = Field(0, description="seed of the sensor noise (with the frame stamp)")
    # --- colour camera ---
    exposure_target: float = Field(
        0.2, gt=0, lt=1, description="auto exposure: mean linear signal it aims for, 1 = full"
    )
    vignetting: float = Field(
        0.25, ge=0, le=0.9, description="light lost in the image corners, fraction"
    )
    blur_sigma_px: float = Field(
        0.45, ge=0, le=5, description="optics blur, Gaussian sigma in colour pixels, px"
    )
    read_noise_dn: float = Field(
        1.5, ge=0, le=50, description="sensor read noise, standard deviation in 8-bit levels, DN"
    )
    shot_noise_dn: float = Field(
        0.08, ge=0, le=5, description="shot noise variance per level of signal, DN"
    )
    photo_sources: list[str] = Field(
        default_factory=lambda: ["skimage"],
        description="photo pools ('skimage' or folders) whose photos named like a material "
        "(brick.png, grass.png, ...) texture it; the real-photo test set is never used",
    )
    # --- stereo disparity ---
    stereo_mode: Literal["model", "sgbm"] = Field(
        "model",
        description="model: true depth + the thesis' noise model; sgbm: render the rectified "
        "pair and run mapping's OpenCV SGBM (slow)",
    )
    disparity_noise_px: float = Field(
        0.3,
        ge=0,
        description="sigma of the injected disparity noise N(0, sigma^2) (4.4.2); the mapper "
        "assumes mapping.disparity_sigma_px, px",
    )
    max_range_m: float = Field(
        40.0, gt=0, description="returns farther than this give no disparity (0), m"
    )
    textureless_contrast_dn: float = Field(
        1.0,
        ge=0,
        le=50,
        description="disparity is invalid (NaN) where the colour image's local contrast (std "
        "over the matching window) is below this, 8-bit levels",
    )
    matching_window_px: int = Field(
        4, ge=2, le=32, description="window of that contrast, colour pixels, px"
    )
    stereo_min_wire_width_px: float = Field(
        3.0,
        ge=0,
        description="a wire appears in the disparity image only where it is at least this wide "
        "(stereo matching misses thin wires), px",
    )
    wire_specular: float = Field(
        0.0,
        ge=0,
        le=2,
        description="strength of the sun's glint on the wires (Kajiya-Kay's cylinder highlight: "
        "a sunlit metal conductor can be brighter than the sky behind it); 0 = matte wires",
    )
    wire_gloss: float = Field(
        16.0, ge=1, le=500, description="exponent of that glint: higher is a narrower highlight"
    )
    stereo_wire_fill: float = Field(
        0.5,
        ge=0,
        le=1,
        description="share of a wide wire's pixels stereo matches (the rest shows the "
        "background: holes), fraction",
    )
