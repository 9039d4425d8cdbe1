"""Network inputs (thesis 2.3.4): normalised RGB, or RGBLE = RGB + line-segment map + edge map.

Normalisation (recorded in every checkpoint as ``NORMALISATION``): the RGB channels are
``(value / 255 - 0.5) / 0.25``; the L and E maps are binary {0, 1} maps normalised the same
way, ``(value - 0.5) / 0.5``, i.e. -1 off and +1 on. Thesis 2.3.4 used CannyLines/CannyPF;
here the L map comes from OpenCV's LSD and the E map from Canny on the grey image.
"""

from __future__ import annotations

from typing import Literal

import cv2
import numpy as np
import torch

from perception.params import PerceptionParams

InputMode = Literal["rgb", "rgble"]

INPUT_CHANNELS: dict[str, int] = {"rgb": 3, "rgble": 5}
"""Channels of the network input per mode."""

NORMALISATION: dict[str, list[float]] = {
    "mean": [0.5, 0.5, 0.5, 0.5, 0.5],
    "std": [0.25, 0.25, 0.25, 0.5, 0.5],
}
"""Per-channel (R, G, B, L, E) mean and std applied to values in [0, 1]."""


def input_channels(mode: str) -> int:
    """Number of channels of the network input in this mode; ValueError if unknown."""
    if mode not in INPUT_CHANNELS:
        raise ValueError(f"unknown input mode {mode!r}; expected one of {list(INPUT_CHANNELS)}")
    return INPUT_CHANNELS[mode]


def line_edge_maps(
    image_rgb: np.ndarray, params: PerceptionParams | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """LSD line-segment map and Canny edge map (2.3.4), both float32 (H, W) in {0, 1}."""
    params = params or PerceptionParams()
    grey = cv2.cvtColor(np.ascontiguousarray(image_rgb), cv2.COLOR_RGB2GRAY)
    lines = cv2.createLineSegmentDetector().detect(grey)[0]
    line_map = np.zeros(grey.shape, np.uint8)
    if lines is not None:
        segments = np.round(lines.reshape(-1, 2, 2)).astype(np.int32)
        cv2.polylines(line_map, list(segments), False, 1, params.lsd_line_thickness_px)
    edges = cv2.Canny(grey, params.canny_low_threshold, params.canny_high_threshold)
    return line_map.astype(np.float32), (edges > 0).astype(np.float32)


def network_input(
    image_rgb: np.ndarray, mode: InputMode = "rgb", params: PerceptionParams | None = None
) -> np.ndarray:
    """Normalised network input (C, H, W) float32 of an RGB uint8 image (H, W, 3) (2.3.4)."""
    if image_rgb.dtype != np.uint8 or image_rgb.ndim != 3 or image_rgb.shape[2] != 3:
        raise ValueError(f"expected uint8 (H, W, 3) RGB, got {image_rgb.dtype} {image_rgb.shape}")
    channels = input_channels(mode)
    planes = [image_rgb.astype(np.float32).transpose(2, 0, 1) / 255.0]
    if mode == "rgble":
        planes.append(np.stack(line_edge_maps(image_rgb, params)))
    stacked = np.concatenate(planes, axis=0)
    mean = np.asarray(NORMALISATION["mean"][:channels], np.float32)[:, None, None]
    std = np.asarray(NORMALISATION["std"][:channels], np.float32)[:, None, None]
    return (stacked - mean) / std


def batch_input(
    images_rgb: list[np.ndarray] | np.ndarray,
    mode: InputMode = "rgb",
    params: PerceptionParams | None = None,
) -> torch.Tensor:
    """Network input batch (N, C, H, W) float32 of N same-size RGB uint8 images."""
    return torch.from_numpy(np.stack([network_input(im, mode, params) for im in images_rgb]))
