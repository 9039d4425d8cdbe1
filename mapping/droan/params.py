"""Tunables of the DROAN map (thesis 4.4). Composed into `companion.config.Settings`."""

from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict, Field, model_validator

from geometry.camera import StereoCameraParams


@dataclass(frozen=True, slots=True)
class StereoMatchParams:
    """OpenCV SGBM settings (a view of the `sgbm_*` fields below)."""

    block_size_px: int
    uniqueness_ratio_pct: int
    speckle_window_px: int
    speckle_range_px: float


class MappingParams(BaseModel):
    """DROAN mapping parameters; each field names its unit and thesis reference."""

    model_config = ConfigDict(extra="forbid")

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
    free_discount: float = Field(
        0.5,
        ge=0,
        le=1,
        description="discount of safe / potentially-safe evidence against occupied (Table 4.1)",
    )
    wire_free_weight: float = Field(
        0.25,
        ge=0,
        le=10,
        description="weight of a view's no-wire evidence against its wire evidence (+1) "
        "(4.4.5): a point stays occupied while over w/(1+w) of the views that see it place it "
        "on a wire ray. The thesis' 0.5 (1/3) let a wire detected in every other frame against "
        "a tree line vanish (a strike at 0.25 m); 0.25 keeps it down to 1/5. Views whose CNN "
        "did not rule a wire out abstain (perception.no_wire_below). Above 1 carves the slabs "
        "into the wires' positions",
    )
    occluded_discount: float = Field(
        0.0,
        ge=0,
        le=1,
        description="discount of potentially-safe (occluded, behind d_b) evidence; the thesis "
        "uses 0.5 (Table 4.1), 0 lets only views that saw a point clear it (unknown is not free)",
    )
    wire_position_margin_m: float = Field(
        0.25,
        ge=0,
        le=2,
        description="added to r_v in the wire prior's area expansion (4.4.3, eq. 4.3 at each "
        "depth of the slab): where a wire's pixels place it is less certain than a stereo "
        "return (the mask's width, pose interpolation, the CNN's blur), m",
    )
    wire_triangulation: bool = Field(
        False,
        description="wires are voted on thin rays by all views first and C-space expanded "
        "after (r_v + wire_position_margin_m around the points where the views agree; "
        "`mapping.droan.wire_triangulation`), instead of expanding each view's rays before "
        "the vote (4.4.3, Fig. 4.4), whose fans fuse into walls when the views are close",
    )
    wire_voxel_m: float = Field(
        0.2,
        gt=0,
        le=1,
        description="edge of the wire voxels (wire_triangulation); half their diagonal joins "
        "the expansion radius, m",
    )
    wire_vote_max: float = Field(
        3.0,
        ge=1,
        description="upper clamp of a wire voxel's summed votes (wire_triangulation): a wire "
        "seen over and over is voted away by (max - gamma) / wire_free_weight frames that "
        "rule it out",
    )
    wire_ray_tolerance_cells: int = Field(
        1,
        ge=0,
        le=4,
        description="a view's wire cells are dilated by this many expansion-grid cells before "
        "it votes on a candidate (wire_triangulation) or on the depths of another view's wire "
        "rays (wire_parallax_views): the mask's and the pose's error, cells",
    )
    wire_parallax_views: int = Field(
        0,
        ge=0,
        le=64,
        description="keyframes whose wire cells cut a new view's wire rays to the depths they "
        "do not rule out, before the C-space expansion (`mapping.droan.wire_depth`; the views "
        "nearest another are forgotten first, so those with parallax stay); 0: every wire ray "
        "spans the whole depth prior (4.4.3), count",
    )
    wire_parallax_min_views: int = Field(
        2,
        ge=1,
        le=256,
        description="views that saw a wire at its ray's best depth (where most views saw it) "
        "but not at another depth they looked at, needed to rule that depth out "
        "(wire_parallax_views), count",
    )
    wire_depth_near_m: float = Field(4.0, gt=0, description="wire depth prior, near limit (4.4.3)")
    wire_depth_far_m: float = Field(20.0, gt=0, description="wire depth prior, far limit (4.4.3)")
    max_range_m: float = Field(
        25.0,
        gt=0,
        description="sensing range: points farther than this from a node get no evidence from "
        "it (unknown); returns more than 2 sigma beyond it count as no return, m",
    )
    no_return_is_free: bool = Field(
        True,
        description="disparity 0 (no stereo return, e.g. sky) counts as free out to max_range_m; "
        "False treats it like an invalid (NaN) pixel, i.e. unknown",
    )
    median_filter_px: int = Field(
        3,
        ge=0,
        le=5,
        description="median filter of the disparity before max-pooling (0 off, 3 or 5): the "
        "pooling and area expansion take maxima, which would otherwise pick the +3 sigma noise "
        "tail; 0 when the camera already filters (OAK-D median), px",
    )
    pool_factor: int = Field(
        4,
        ge=1,
        le=16,
        description="block size of the conservative max-pooling before C-space expansion; "
        "node images are stored at this reduced resolution (1 = full resolution), px",
    )
    expansion_bin_fraction: float = Field(
        0.5,
        gt=0,
        le=1,
        description="disparity bins of the area expansion are at most this fraction of the "
        "expanded band width [d_b, d_f] at their disparity (4.4.3)",
    )
    keyframe_translation_m: float = Field(
        0.5, gt=0, description="new pose-graph node after this translation (3.4.2, 4.4.6), m"
    )
    keyframe_rotation_deg: float = Field(
        18.0, gt=0, description="new pose-graph node after this rotation (3.4.2, 4.4.6), deg"
    )
    max_nodes: int = Field(20, ge=1, description="pose-graph size bound; oldest evicted (4.4.6)")
    query_threads: int = Field(
        2,
        ge=1,
        description="threads sharing the points of a large batched query (the kernel releases the "
        "GIL; results are identical); 1 = serial (4.4.6)",
    )
    query_split_min_points: int = Field(
        2048, ge=1, description="smallest batch split across `query_threads` (4.4.6)"
    )
    max_node_age_s: float = Field(
        0.0, ge=0, description="nodes older than this are evicted; 0 disables the limit (4.4.6), s"
    )
    replace_latest_non_keyframe: bool = Field(
        True,
        description="a frame that is not a keyframe replaces the newest live node instead of "
        "being dropped, so the latest observation is always in the graph (4.4.6)",
    )
    pose_max_extrapolation_s: float = Field(
        0.05, ge=0, description="largest gap between an image stamp and the pose history, s"
    )
    pose_history_size: int = Field(
        400, ge=2, description="stamped poses kept to interpolate image poses (4.4.6)"
    )
    # --- the stereo camera and its mount (4.4.2, 4.6.1); defaults approximate an OAK-D at
    # 640x480 (about 72 deg HFOV, 7.5 cm baseline); the real camera's calibration overrides them
    camera_width_px: int = Field(640, ge=16, description="width of the disparity image, px")
    camera_height_px: int = Field(480, ge=16, description="height of the disparity image, px")
    camera_hfov_deg: float = Field(
        72.0, gt=10, lt=170, description="horizontal field of view of the rectified camera, deg"
    )
    camera_intrinsics_px: tuple[float, float, float, float] | None = Field(
        None,
        description="(fx, fy, cx, cy) of the rectified camera from its calibration (the OAK-D "
        "reports them), px; unset: square pixels and a centred principal point from "
        "camera_hfov_deg",
        examples=[(451.2, 452.8, 322.4, 236.9)],
    )
    camera_baseline_m: float = Field(0.075, gt=0, description="stereo baseline b (eq. 4.1), m")
    camera_mount_position_body_m: tuple[float, float, float] = Field(
        (0.1, 0.0, 0.0), description="camera centre in body FRD (x fwd, y right, z down), m"
    )
    camera_mount_pitch_deg: float = Field(
        0.0, ge=-90, le=90, description="camera tilt relative to body x, up positive, deg"
    )
    camera_mount_yaw_deg: float = Field(
        0.0, ge=-180, le=180, description="camera pan about body z (Z-Y-X), right positive, deg"
    )
    camera_mount_roll_deg: float = Field(
        0.0, ge=-180, le=180, description="camera roll about its optical axis (Z-Y-X), deg"
    )
    camera_max_disparity_px: int = Field(
        128, ge=16, description="disparity search range (SGBM numDisparities, multiple of 16), px"
    )
    # --- OpenCV SGBM on a rectified pair, when the camera does not compute disparity (4.4.2)
    sgbm_block_size_px: int = Field(5, ge=1, le=11, description="SGBM block size (odd), px")
    sgbm_uniqueness_ratio_pct: int = Field(
        10, ge=0, le=100, description="SGBM uniqueness margin of the best match, %"
    )
    sgbm_speckle_window_px: int = Field(
        100, ge=0, description="speckle filter: largest blob (px area) removed as noise"
    )
    sgbm_speckle_range_px: float = Field(
        2.0, ge=0, description="speckle filter: disparity step that separates blobs, px"
    )

    @property
    def camera(self) -> StereoCameraParams:
        """The `camera_*` fields as one value."""
        return StereoCameraParams(
            self.camera_width_px,
            self.camera_height_px,
            self.camera_hfov_deg,
            self.camera_baseline_m,
            self.camera_mount_position_body_m,
            self.camera_mount_pitch_deg,
            self.camera_max_disparity_px,
            self.camera_intrinsics_px,
            self.camera_mount_yaw_deg,
            self.camera_mount_roll_deg,
        )

    @property
    def stereo(self) -> StereoMatchParams:
        """The `sgbm_*` fields as one value."""
        return StereoMatchParams(
            self.sgbm_block_size_px,
            self.sgbm_uniqueness_ratio_pct,
            self.sgbm_speckle_window_px,
            self.sgbm_speckle_range_px,
        )

    @model_validator(mode="after")
    def _intrinsics_are_positive(self) -> "MappingParams":
        if self.camera_intrinsics_px is not None:
            fx, fy, _, _ = self.camera_intrinsics_px
            if not (fx > 0 and fy > 0):
                raise ValueError("camera_intrinsics_px needs fx > 0 and fy > 0")
        return self

    @model_validator(mode="after")
    def _median_is_odd(self) -> "MappingParams":
        if self.median_filter_px not in (0, 3, 5):
            raise ValueError("median_filter_px must be 0, 3 or 5")
        return self

    @model_validator(mode="after")
    def _wire_prior_is_ordered(self) -> "MappingParams":
        if not self.robot_radius_m < self.wire_depth_near_m < self.wire_depth_far_m:
            raise ValueError("need robot_radius_m < wire_depth_near_m < wire_depth_far_m")
        return self
