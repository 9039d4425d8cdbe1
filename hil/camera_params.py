"""Parameters of the simulated cameras (SIL harness). Compose into `Settings` as `camera_sim`.

The camera geometry itself (intrinsics, baseline, mount) is `mapping.params.StereoCameraParams`,
shared with the real camera so the simulation flies what the product maps.
"""

from pydantic import BaseModel, ConfigDict, Field


class CameraSimParams(BaseModel):
    """Rendering and sensor-error model of the simulated stereo + colour camera."""

    model_config = ConfigDict(extra="forbid")

    seed: int = Field(0, description="seed of the disparity noise (with the frame stamp)")
    disparity_noise_px: float = Field(
        0.23, ge=0, description="sigma of the additive disparity noise N(0, sigma^2) (4.4.2), px"
    )
    max_range_m: float = Field(
        40.0, gt=0, description="returns farther than this give no disparity (0), m"
    )
    stereo_min_wire_width_px: float = Field(
        3.0,
        ge=0,
        description="a wire appears in the disparity image only where it is at least this wide "
        "(stereo matching misses thin wires), px",
    )
    wire_mask_min_coverage: float = Field(
        0.25, gt=0, le=1, description="pixel coverage above which a wire pixel is in the mask"
    )
    texture_cell_m: float = Field(
        0.06, gt=0, description="cell size of the procedural surface texture, m"
    )
