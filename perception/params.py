"""Tunables of wire segmentation (thesis ch. 2, 4.4.1), composed into `Settings`."""

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

DEFAULT_MODEL = "k32-k32-d1-d2-d4-d8-d16-d1-k2"  # the shipped architecture (2.3.1, Table 2.3)
FAST_MODEL = "k32-k32-p2-d1-d2-d4-d8-d16-d1-k2"  # its pooled variant, shipped for 480x640 frames


class PerceptionParams(BaseModel):
    """Wire-segmentation parameters; each field names its unit and thesis reference."""

    model_config = ConfigDict(extra="forbid")

    model: str = Field(
        FAST_MODEL,
        description="zoo architecture whose shipped weights the segmenter loads (2.3.1): "
        f"{FAST_MODEL}, pooled, the flight loop's (half the latency at 240x320, better on real "
        f"photos), or {DEFAULT_MODEL}, the thesis' unpooled grid model",
    )
    confidence_threshold: float = Field(
        0.95, gt=0, lt=1, description="wire-probability threshold of the mask (4.4.1)"
    )
    mask_threshold_from_weights: bool = Field(
        True,
        description="threshold masks at the value recorded with the weights (chosen on real "
        "photographs, `wireavoid calibrate-threshold`) instead of confidence_threshold; "
        "weights without one use confidence_threshold",
    )
    no_wire_below: float = Field(
        1.0,
        gt=0,
        le=1,
        description="a pixel is evidence that no wire is there only below this wire "
        "probability; at or above it, but under the mask threshold, the map neither places a "
        "wire through it nor votes one away (beyond 4.4.5). At the mask threshold or above (the "
        "default): the thesis' two-way mask. 0.5 (with mapping.wire_free_weight 0.5), measured "
        "2026-12-04 on stacked-wires seed 5, where the wire level with the camera is scored "
        "0.5-0.95 in most frames: 1 strike in 5 flights against 3 in 6, none reaching the goal "
        "in 120 s; sweep seeds 0-3 14 of 24 against 15, no strike either way",
    )
    wire_continuation_factor: float = Field(
        4.0,
        ge=0,
        le=100,
        description="beyond 4.4.1: a straight wire component of the mask is continued past "
        "both ends by this many times its length (clipped at the image border), since a wire "
        "does not end in mid-air: the part of a wire the CNN misses against the tree line on the "
        "horizon is mapped from the part it finds. 0: off. Measured 2026-12-05, default "
        "scenarios seeds 0-11 side by side (72 flights): 44 succeeded and none struck, against "
        "46 and 8 flights with strikes at 0",
    )
    wire_continuation_stops_at_surfaces: bool = Field(
        True,
        description="a continuation stops where stereo sees a surface (most disparity "
        "pixels of a colour pixel hold a return, 3 such pixels in a row), so wires are "
        "continued across the sky and the far background, where the CNN misses them, not "
        "across the ground, where its straight false marks (shadows of trees, poles and wires) "
        "lie. On 432 SIL frames the continued mask's wire recall 0.545 and false share 0.34 "
        "against 0.583 and 0.50 without it (0.483 and 0.27 not continued). Sweeps side by side "
        "on 2026-12-07 (docs/closed-loop-log.md), seeds 0-11: 49 of 72, no strike, against "
        "40-43 of 72 and one strike without it",
    )
    wire_continuation_min_length_px: float = Field(
        30.0, ge=1, le=10_000, description="shortest mask component that is continued, px"
    )
    wire_continuation_max_angle_deg: float = Field(
        30.0,
        ge=0,
        le=90,
        description="steepest mask component that is continued, degrees from the image rows "
        "(wires crossing the path are near-horizontal in the image; ladder rails and poles are "
        "not)",
    )
    canny_low_threshold: float = Field(
        50.0, ge=0, le=1000, description="Canny hysteresis low threshold of RGBLE's E map (2.3.4)"
    )
    canny_high_threshold: float = Field(
        150.0, ge=0, le=1000, description="Canny hysteresis high threshold of RGBLE's E map (2.3.4)"
    )
    lsd_line_thickness_px: int = Field(
        1, ge=1, le=5, description="thickness of LSD segments drawn into RGBLE's L map, px (2.3.4)"
    )
    min_wire_component_px: int = Field(
        20,
        ge=0,
        le=100_000,
        description="speckle filter: 8-connected mask components smaller than this, px, are "
        "dropped (4.4.1)",
    )
    runtime: Literal["auto", "torch", "torch-bf16", "onnx", "onnx-int8", "tensorrt"] = Field(
        "auto",
        description="inference runtime: auto picks tensorrt > onnx > torch by availability; "
        "the reduced-precision CPU ones (torch-bf16, onnx-int8) only when named",
    )
    inference_threads: int = Field(
        0, ge=0, le=256, description="CPU threads of torch/ONNX Runtime inference; 0 = all cores"
    )
    baseline_min_component_px: int = Field(
        30,
        ge=0,
        le=100_000,
        description="Candamo baseline: edge components (8-connected) smaller than this, px, "
        "are removed (2.4.3)",
    )
    baseline_windows: int = Field(
        4, ge=1, le=16, description="Candamo baseline: Hough subwindows per image side (2.4.3: 4x4)"
    )
    baseline_hough_votes_fraction: float = Field(
        0.7,
        gt=0,
        le=2,
        description="Candamo baseline: Hough accumulator threshold as a fraction of the "
        "subwindow's shorter side, votes per px (2.4.3; tuned on synthetic seed 5)",
    )
    baseline_max_lines_per_window: int = Field(
        6, ge=1, le=100, description="Candamo baseline: strongest Hough lines kept per subwindow"
    )
    lsd_baseline_width_px: int = Field(
        2,
        ge=0,
        le=15,
        description="LSD baseline: width segments are drawn with, px; 0 = each segment's own "
        "LSD width estimate (scores 0.49 ODS-F on ttpla-sample against 0.54 at 2 px)",
    )
    lsd_baseline_full_length_px: float = Field(
        200.0,
        gt=0,
        le=100_000,
        description="LSD baseline: segment length that scores 1, px; shorter ones score "
        "length / this",
    )
    baseline_max_thickness_px: int = Field(
        5,
        ge=1,
        le=15,
        description="Candamo baseline: lines drawn 1..N px thick give the score levels (2.4.3)",
    )


class SyntheticParams(BaseModel):
    """Ranges of the synthetic wire generator (2.3.2); distances in metres, sizes in pixels."""

    model_config = ConfigDict(extra="forbid")

    hfov_min_deg: float = Field(40.0, gt=5, lt=170, description="narrowest horizontal FOV, deg")
    hfov_max_deg: float = Field(110.0, gt=5, lt=170, description="widest horizontal FOV, deg")
    camera_altitude_min_m: float = Field(
        1.5, gt=0, description="lowest camera height above ground, m"
    )
    camera_altitude_max_m: float = Field(
        60.0, gt=0, description="highest camera height above ground, m"
    )
    pitch_max_deg: float = Field(30.0, ge=0, le=80, description="|camera pitch| bound, deg")
    roll_std_deg: float = Field(8.0, ge=0, le=45, description="camera roll standard deviation, deg")
    wire_distance_min_m: float = Field(
        2.5, gt=0, description="nearest wire anchor along the ray, m"
    )
    wire_distance_max_m: float = Field(250.0, gt=0, description="farthest wire anchor, m")
    wire_height_min_m: float = Field(1.0, ge=0, description="lowest wire anchor above ground, m")
    wire_height_max_m: float = Field(50.0, gt=0, description="highest wire anchor above ground, m")
    bundles_max: int = Field(
        3, ge=1, le=10, description="most wire bundles (independent spans) per image"
    )
    conductors_max: int = Field(6, ge=1, le=12, description="most parallel conductors in a bundle")
    conductor_spacing_min_m: float = Field(0.2, gt=0, description="closest conductor spacing, m")
    conductor_spacing_max_m: float = Field(4.0, gt=0, description="widest conductor spacing, m")
    span_min_m: float = Field(10.0, gt=0, description="shortest span between supports, m")
    span_max_m: float = Field(300.0, gt=0, description="longest span between supports, m")
    sag_ratio_max: float = Field(0.06, ge=0, le=0.3, description="largest sag / span of catenaries")
    straight_probability: float = Field(
        0.3, ge=0, le=1, description="share of bundles that are straight, taut lines"
    )
    diameter_min_m: float = Field(0.004, gt=0, description="thinnest wire diameter, m")
    diameter_max_m: float = Field(0.035, gt=0, description="thickest wire diameter, m")
    width_floor_min_px: float = Field(
        0.5, gt=0, le=3, description="lowest floor of the rendered wire width (far wires), px"
    )
    width_floor_max_px: float = Field(
        1.2, gt=0, le=5, description="highest floor of the rendered wire width, px"
    )
    contrast_min: float = Field(
        0.12, ge=0, le=1, description="least wire-background luminance difference (0-1 scale)"
    )
    contrast_max: float = Field(
        0.3, ge=0, le=1, description="most enforced wire-background luminance difference"
    )
    horizon_wire_probability: float = Field(
        0.0,
        ge=0,
        le=1,
        description="share of forward views whose first bundle hangs level at the camera's own "
        "height, so it lies along the horizon against the tree line and hills (a drone flying "
        "level with a wire; 0 keeps the thesis' anchors anywhere in view)",
    )
    horizon_contrast_min: float = Field(
        0.12,
        ge=0,
        le=1,
        description="least luminance difference enforced for those horizon wires (0-1 scale): "
        "a grey wire before hazed distant trees differs by ~0.03",
    )
    width_max_px: float = Field(12.0, gt=0, le=60, description="thickest rendered wire, px")
    no_wire_probability: float = Field(
        0.1, ge=0, le=1, description="share of images without wires (hard negatives)"
    )
    supersampling: int = Field(4, ge=1, le=8, description="anti-aliasing supersampling factor")
    photo_probability: float = Field(
        0.3, ge=0, le=1, description="share of backgrounds that are real photographs, when any"
    )
    aerial_probability: float = Field(
        0.0,
        ge=0,
        le=1,
        description="share of views pitched down at cluttered ground (roads, roofs, fields, "
        "canopy, water, snow), where drones fly; 0 keeps the thesis' forward views (2.3.2)",
    )
    aerial_pitch_min_deg: float = Field(
        25.0, ge=5, le=90, description="shallowest downward pitch of an aerial view, deg"
    )
    aerial_altitude_min_m: float = Field(
        6.0, gt=0, description="lowest camera height above ground of an aerial view, m"
    )
    aerial_altitude_max_m: float = Field(
        80.0, gt=0, description="highest camera height above ground of an aerial view, m"
    )
    aerial_width_floor_max_px: float = Field(
        4.0,
        gt=0,
        le=12,
        description="highest floor of the rendered wire width in aerial views, px (conductors "
        "seen from above are 1-10 px wide after blur and halo)",
    )
    wire_shadow_probability: float = Field(
        0.6,
        ge=0,
        le=1,
        description="share of aerial views in which wires and poles cast shadows on the ground "
        "(thin dark lines, never labelled)",
    )
    ground_shadow_probability: float = Field(
        0.0,
        ge=0,
        le=1,
        description="share of forward views over procedural ground in which wires and poles "
        "cast shadows on the ground below the horizon (thin dark lines, never labelled)",
    )
    perspective_cloud_probability: float = Field(
        0.0,
        ge=0,
        le=1,
        description="share of cloudy procedural skies whose clouds lie on a layer far above, "
        "seen in perspective: streaks with sharp lower edges towards the horizon (never "
        "labelled); the rest are flat fractal clouds",
    )
    fittings_probability: float = Field(
        0.0,
        ge=0,
        le=1,
        description="share of bundles with insulator strings at the supports and spacers "
        "between close conductors (drawn, never labelled)",
    )
    tower_probability: float = Field(
        0.0,
        ge=0,
        le=1,
        description="share of supported bundles hung from lattice towers instead of poles",
    )
    sensor_effects_probability: float = Field(
        0.0,
        ge=0,
        le=1,
        description="share of images with vignetting, over-exposure and resampling blur, "
        "on top of the lighting, blur, noise and JPEG every image gets",
    )


class TrainingParams(BaseModel):
    """Training of a zoo model on synthetic data (2.3.3, 2.4.2); `wireavoid train` fills it."""

    model_config = ConfigDict(extra="forbid")

    model: str = Field(DEFAULT_MODEL, description="zoo name or grid label")
    input_mode: str = Field("rgb", pattern="^(rgb|rgble)$", description="network input (2.3.4)")
    steps: int = Field(2000, ge=1, description="optimiser steps (thesis: 2000 at batch 4, 2.4.2)")
    batch: int = Field(8, ge=1, le=1024, description="images per step and process")
    crop_height_px: int = Field(176, ge=16, le=4096, description="training image height, px")
    crop_width_px: int = Field(240, ge=16, le=4096, description="training image width, px")
    optimizer: str = Field(
        "adam", pattern="^(adam|adadelta)$", description="Adam, or AdaDelta as in 2.4.2"
    )
    learning_rate: float = Field(
        0.0, ge=0, le=10, description="0 = optimiser default (Adam 1e-3, AdaDelta 1.0)"
    )
    final_lr_fraction: float = Field(
        0.1, gt=0, le=1, description="cosine decay of the learning rate down to this fraction"
    )
    balance_beta_max: float = Field(
        0.99,
        gt=0.5,
        le=1,
        description="cap of the HED class-balance weight beta = |Y-|/|Y| (2.3.3), so that "
        "images without wires still train the negatives with weight >= 1 - cap",
    )
    seed: int = Field(
        0,
        ge=0,
        lt=1_000_000,
        description="seed of training data and initialisation; "
        "the held-out set uses seed 1,000,000",
    )
    checkpoint_every: int = Field(200, ge=1, description="steps between checkpoints")
    init_from: str = Field(
        "",
        description="checkpoint whose weights start a fresh run, layer by layer in order "
        "(e.g. a pooled variant warm-started from its unpooled twin); '' = random init",
    )
    workers: int = Field(1, ge=0, le=64, description="data-generation worker processes")
    bf16: bool = Field(True, description="bf16 autocast where the CPU/GPU supports it")
    photo_sources: list[str] = Field(
        default_factory=lambda: ["skimage"],
        description="real-photo backgrounds: 'skimage' and/or folders (2.3.2)",
    )
    frame_folders: list[str] = Field(
        default_factory=list,
        description="labelled image folders mixed into the synthetic batches (`wireavoid "
        "sil-frames` writes frames the simulated cameras render); never evaluation photographs",
    )
    frames_share: float = Field(
        0.0, ge=0, le=1, description="share of the training items cropped from frame_folders"
    )
    eval_count: int = Field(64, ge=0, description="held-out synthetic images evaluated at the end")
    eval_height_px: int = Field(240, ge=16, description="held-out image height, px")
    eval_width_px: int = Field(320, ge=16, description="held-out image width, px")
