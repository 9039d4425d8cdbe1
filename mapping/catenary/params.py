"""Tunables of multi-view catenary reconstruction (thesis ch. 3). Composed into `Settings`."""

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class CatenaryParams(BaseModel):
    """Catenary fitting parameters; each field names its unit and thesis reference."""

    model_config = ConfigDict(extra="forbid")

    points_per_curve: int = Field(
        64, ge=4, description="M, samples along the catenary per view (3.3.1, 3.3.2)"
    )
    half_span_m: float = Field(
        5.0,
        gt=0,
        description="half the fixed width of the sampled catenary, x_cat in [-h, h] (3.3.1), m",
    )
    segmentation_threshold: float = Field(
        0.5, gt=0, lt=1, description="binarisation threshold of the wire confidence map (3.3.2)"
    )
    sag_min_m: float = Field(
        0.5, gt=0, description="lower bound of the sag parameter a (eq. 3.1), m"
    )
    sag_max_m: float = Field(
        1.0e5, gt=0, description="upper bound of a; large a is a near-straight wire (3.4.1), m"
    )
    min_depth_m: float = Field(
        0.1,
        gt=0,
        description="camera depth below which a point is clamped before projection (3.3.2), m",
    )
    max_depth_m: float = Field(
        1000.0, gt=0, description="largest vertex depth, bounds the inverse depth (eq. 3.33), m"
    )
    exit_aware_extrapolation: bool = Field(
        True,
        description="off-image samples cost nothing where the seen wire leaves the image "
        "(3.7.1, wires longer than the view); False: eq. 3.4 as in the thesis",
    )
    exit_gate_px: float = Field(
        3.0,
        gt=0,
        description="distance from the seen wire's exit at which leaving costs fully (3.7.1), px",
    )
    parameterisation: Literal["world", "inverse_depth"] = Field(
        "inverse_depth",
        description="solve for Theta (eq. 3.2) or for inverse-depth Psi (eq. 3.33, 3.7.2)",
    )
    robust_loss: Literal["linear", "soft_l1", "huber", "cauchy", "arctan"] = Field(
        "cauchy",
        description="loss of the refinement after the r^T r solve (eq. 3.13); 'linear' "
        "skips it; a robust one lets samples beyond a truncated detection go",
    )
    robust_scale_px: float = Field(
        3.0, gt=0, description="residual scale of the robust loss (f_scale), px"
    )
    robust_refinement_evaluations: int = Field(
        10, ge=1, description="max_nfev of the robust refinement after the r^T r solve"
    )
    max_function_evaluations: int = Field(
        100, ge=1, description="max_nfev of the trust-region-reflective solver (3.3.3)"
    )
    tolerance: float = Field(
        1.0e-6, gt=0, description="ftol = xtol = gtol of scipy least_squares (3.3.3)"
    )
    pixel_sigma_px: float = Field(
        1.0, gt=0, description="1-sigma pixel noise of a wire detection, for eq. 3.39, px"
    )
    independent_samples_per_view: float = Field(
        2.0,
        gt=0,
        description="independent samples one view's projected curve counts as in eq. 3.39",
    )
    observation_gate_px: float = Field(
        3.0,
        gt=0,
        description="a sample within this distance of a wire pixel counts as observed (3.7.1), px",
    )
    max_condition_number: float = Field(
        1.0e9,
        gt=1,
        description="fits whose scaled information matrix is worse are ill-conditioned (Fig. 3.10)",
    )
    max_point_sigma_m: float = Field(
        0.75,
        gt=0,
        description="a fit is confident only if every observed point's 1-sigma is below (3.7.2), m",
    )
    max_rms_residual_px: float = Field(
        3.0, gt=0, description="a fit is confident only if its RMS residual is below (eq. 3.13), px"
    )
    min_confident_views: int = Field(
        6,
        ge=2,
        description="fewest keyframes for a confident fit: with 2-4 avoidance views, wrong "
        "local minima can look well-conditioned (Fig. 3.10 and 3.4.1 benchmarks)",
    )
    min_observed_points: int = Field(
        10, ge=2, description="fewest observed curve samples for a confident fit (3.7.1)"
    )
    init_depth_samples: int = Field(
        6, ge=1, description="depths tried per seed by the initialiser, within the wire prior"
    )
    max_starts: int = Field(
        3, ge=1, description="seeds tried, best first, until a fit is confident (3.3.3)"
    )
    init_sag_m: float = Field(
        200.0, gt=0, description="sag a of initial hypotheses (near-straight) (3.4.1), m"
    )
    hop_rounds: int = Field(
        3,
        ge=0,
        description="rounds of basin hopping after a fit that neither is confident nor explains "
        "the data (3.3.3, beyond the thesis); 0: a single local solve",
    )
    hop_starts: int = Field(
        3, ge=1, description="perturbed hypotheses solved per hopping round, best first"
    )
    hop_stop_rms_px: float = Field(
        0.5,
        gt=0,
        description="a fit with an RMS residual below this explains the data: no hopping, px",
    )
    max_keyframes: int = Field(16, ge=2, description="most recent keyframes used per fit (3.4.2)")
    instance_min_pixels: int = Field(
        25, ge=1, description="smallest connected wire component kept as an instance (3.7.3), px"
    )
    instance_min_length_px: float = Field(
        40.0, gt=0, description="shortest wire instance along its image axis (3.7.3), px"
    )
    merge_gate_px: float = Field(
        3.0,
        gt=0,
        description="fragments within this of each other's image curve are one wire (3.7.3), px",
    )
    association_gate_px: float = Field(
        4.0,
        gt=0,
        description="max mean reprojection distance to link instances across views (3.7.3), px",
    )
    use_in_collision_check: bool = Field(
        False,
        description="confident catenaries replace the 4-20 m wire slab in collision checks "
        "(3.7.2); the flight process refits them on a worker of its own (a refit: 0.65 s "
        "p50, 1.8 s p99 on 2 cores), so map inserts stay fast (16 ms p99 against 2.2 s "
        "refitting on the map's worker). Off by default: 24 of 36 sweep flights either way, "
        "no strike",
    )
    tube_sigma_multiplier: float = Field(
        3.0,
        ge=0,
        description="k, tube radius = robot radius + k sigma; 3 spans the 6-sigma band of 3.7.2",
    )
    explained_pixel_gate_px: float = Field(
        4.0,
        gt=0,
        description="wire pixels this close to a confident catenary's projection are explained, px",
    )

    @property
    def extrapolation_gate_px(self) -> float | None:
        """`exit_gate_px` when exit-aware extrapolation is on, else None (eq. 3.4)."""
        return self.exit_gate_px if self.exit_aware_extrapolation else None
