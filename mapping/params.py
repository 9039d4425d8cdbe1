"""Tunables of the DROAN map (thesis 4.4). Composed into `companion.config.Settings`."""

from pydantic import BaseModel, Field


class MappingParams(BaseModel):
    """DROAN mapping parameters; each field names its unit and thesis reference."""

    robot_radius_m: float = Field(
        0.5, gt=0, description="r_v, C-space expansion radius (eq. 4.3), m"
    )
    disparity_sigma_px: float = Field(
        0.23, gt=0, description="sigma of the disparity error model N(d, sigma^2) (4.4.2), px"
    )
    sigma_multiplier: float = Field(
        1.0, ge=0, description="lambda, sigma multiplier of the expansion (4.4.3, eq. 4.3)"
    )
    occupancy_threshold: float = Field(
        1.0, gt=0, description="gamma, collision when M >= gamma (eq. 4.5)"
    )
    wire_depth_near_m: float = Field(4.0, gt=0, description="wire depth prior, near limit (4.4.3)")
    wire_depth_far_m: float = Field(20.0, gt=0, description="wire depth prior, far limit (4.4.3)")
    keyframe_translation_m: float = Field(
        0.5, gt=0, description="new pose-graph node after this translation (3.4.2, 4.4.6), m"
    )
    keyframe_rotation_deg: float = Field(
        18.0, gt=0, description="new pose-graph node after this rotation (3.4.2, 4.4.6), deg"
    )
    max_nodes: int = Field(20, ge=1, description="pose-graph size bound; oldest evicted (4.4.6)")
