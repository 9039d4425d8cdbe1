"""The one obvious API of wire segmentation: image in, wire probability map or mask out.

    from perception.segmenter import WireSegmenter
    seg = WireSegmenter.load()                  # shipped default model, fastest runtime
    prob = seg.probability(frame_bgr)           # (H, W) float32 in [0, 1]  (thesis 2.3)
    mask = seg.mask(frame_bgr)                  # (H, W) bool after 4.4.1 post-processing

Loading reads the checkpoint and may export/cache an ONNX graph; `probability` and `mask`
do no I/O and are synchronous, so the companion calls them from a worker thread.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from torch import nn

from perception.checkpoint import load_checkpoint, shipped_checkpoint_path
from perception.inputs import NORMALISATION, input_channels, network_input
from perception.params import PerceptionParams
from perception.postprocess import wire_mask
from perception.runtimes import InferenceRuntime, RuntimeName, select_runtime


def padded_size(size_px: int, stride_px: int) -> int:
    """Smallest multiple of `stride_px` that is >= `size_px`."""
    return -(-size_px // stride_px) * stride_px


def as_rgb(image: np.ndarray, channel_order: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB of an (H, W, 3) BGR/RGB or (H, W) grey uint8 image."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"expected a uint8 image, got {image.dtype}")
    if image.ndim == 2:
        return np.repeat(image[:, :, None], 3, axis=2)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) or (H, W) image, got shape {image.shape}")
    if channel_order == "bgr":
        return np.ascontiguousarray(image[:, :, ::-1])
    if channel_order == "rgb":
        return image
    raise ValueError(f"channel_order must be 'bgr' or 'rgb', got {channel_order!r}")


@dataclass
class WireSegmenter:
    """A loaded wire-segmentation model on one inference runtime.

    `stride_px` is the model's total pooling factor: inputs are reflect-padded to a multiple
    of it and the probabilities cropped back, so any image size works and stays aligned.
    """

    runtime: InferenceRuntime
    arch: str
    input_mode: str
    stride_px: int
    params: PerceptionParams
    recorded_threshold: float | None = None
    """Mask threshold recorded with the weights (chosen on real photographs), if any."""

    @classmethod
    def load(
        cls,
        checkpoint: Path | str | None = None,
        runtime: RuntimeName | None = None,
        params: PerceptionParams | None = None,
        cache_dir: Path | None = None,
    ) -> WireSegmenter:
        """Segmenter of a checkpoint (None: the shipped weights of `params.model`).

        runtime: 'auto' | 'torch' | 'onnx' | 'tensorrt'; None takes `params.runtime`.
        cache_dir: where ONNX exports/TensorRT engines are cached (default ~/.cache/wireavoid).
        Raises ValueError when `params.model` has no shipped weights, or when the checkpoint's
        input normalisation is not the one `perception.inputs` applies.
        """
        params = params or PerceptionParams()
        if checkpoint is None:
            checkpoint = shipped_checkpoint_path(params.model)
            if not checkpoint.is_file():
                raise ValueError(f"no shipped weights for {params.model} (perception.model)")
        model, meta = load_checkpoint(checkpoint)
        mode = meta["input_mode"]
        expected = {k: list(v[: input_channels(mode)]) for k, v in NORMALISATION.items()}
        stored = {k: list(v) for k, v in meta.get("normalisation", expected).items()}
        if stored != expected:
            raise ValueError(
                f"{meta['path']} was trained with normalisation {stored}, "
                f"but perception.inputs applies {expected}"
            )
        segmenter = cls.from_model(model, mode, runtime, params, cache_dir, arch=meta["arch"])
        segmenter.recorded_threshold = meta.get("mask_threshold")
        return segmenter

    @classmethod
    def from_model(
        cls,
        model: nn.Module,
        input_mode: str = "rgb",
        runtime: RuntimeName | None = None,
        params: PerceptionParams | None = None,
        cache_dir: Path | None = None,
        arch: str | None = None,
    ) -> WireSegmenter:
        """Segmenter of an in-memory zoo model (e.g. freshly trained) on the chosen runtime."""
        params = params or PerceptionParams()
        input_channels(input_mode)  # ValueError on an unknown mode, before any export
        backend = select_runtime(
            runtime or params.runtime,
            model.eval(),
            input_mode,
            threads=params.inference_threads,
            cache_dir=cache_dir,
        )
        return cls(
            runtime=backend,
            arch=arch or getattr(model, "name", type(model).__name__),
            input_mode=input_mode,
            stride_px=int(getattr(model, "downsample", 1)),
            params=params,
        )

    def network_batch(self, images_rgb: list[np.ndarray]) -> np.ndarray:
        """(N, C, H', W') float32 network input of same-size RGB images, padded to the stride."""
        planes = np.stack([network_input(im, self.input_mode, self.params) for im in images_rgb])
        h, w = planes.shape[2:]
        pad_h, pad_w = padded_size(h, self.stride_px) - h, padded_size(w, self.stride_px) - w
        if pad_h or pad_w:
            planes = np.pad(planes, ((0, 0), (0, 0), (0, pad_h), (0, pad_w)), mode="reflect")
        return planes

    def probabilities(self, images: list[np.ndarray], channel_order: str = "bgr") -> np.ndarray:
        """(N, H, W) float32 wire probabilities in [0, 1] of N same-size uint8 images."""
        rgb = [as_rgb(im, channel_order) for im in images]
        h, w = rgb[0].shape[:2]
        if any(im.shape[:2] != (h, w) for im in rgb):
            raise ValueError("images of one batch must have the same size")
        prob = self.runtime.probability(self.network_batch(rgb))[:, :h, :w]
        return np.clip(prob, 0.0, 1.0, out=np.ascontiguousarray(prob, dtype=np.float32))

    def probability(self, image: np.ndarray, channel_order: str = "bgr") -> np.ndarray:
        """(H, W) float32 wire probability in [0, 1] of one (H, W, 3) or (H, W) uint8 image.

        channel_order: 'bgr' (OpenCV, cameras) or 'rgb'.
        """
        return self.probabilities([image], channel_order)[0]

    @property
    def mask_threshold(self) -> float:
        """The probability a mask pixel needs (4.4.1): the threshold recorded with the weights
        when there is one and `params.mask_threshold_from_weights`, else
        `params.confidence_threshold` (0.95)."""
        if self.params.mask_threshold_from_weights and self.recorded_threshold is not None:
            return float(self.recorded_threshold)
        return self.params.confidence_threshold

    def mask_of(self, prob: np.ndarray) -> np.ndarray:
        """(H, W) bool wire-obstacle mask of this model's (H, W) probability map (4.4.1)."""
        return wire_mask(prob, self.params, self.mask_threshold)

    def mask(self, image: np.ndarray, channel_order: str = "bgr") -> np.ndarray:
        """(H, W) bool wire-obstacle mask: thresholded and speckle-filtered probability (4.4.1)."""
        return self.mask_of(self.probability(image, channel_order))

    def possible_of(self, prob: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """(H, W) bool: the pixels this model does not rule out as wire, `mask` (`mask_of`
        `prob`) and those at or above `params.no_wire_below` (speckle-filtered like the mask):
        beyond 4.4.5, only the others are evidence that no wire is there."""
        if self.params.no_wire_below >= self.mask_threshold:
            return mask  # the thesis' two-way mask: nothing undecided
        return wire_mask(prob, self.params, self.params.no_wire_below) | mask
